"""The query's shapes: from the segmented silhouette to the distance curves searched.

A query's distance curve starts at the top of the centroid's vertical line, so an object
turned *in the image plane* gives a cyclically shifted curve that the (fixed-start) DTW
of the index does not match. :func:`rotated_curves` therefore also turns the silhouette
by a few in-plane angles (evenly spaced; 1 = upright only), and the pipeline keeps, per
object, the best view over all of them, remembering the turn that matched. An object
that other labelled objects occlude is also searched with its outline completed where
they may hide it (:func:`completed_mask`).
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..catalogue.features import distance_curve
from ..config import RecognitionConfig
from ..errors import FeatureError, ImageError, QueryError
from .segmentation import Segmentation

__all__ = ["completed_mask", "pose_mask", "rotated_curves"]

RECOGNITION = RecognitionConfig()
#: Photos of at most this many pixels are turned whole by :func:`rotated_curves`.
WHOLE_PHOTO_TURNS = 1 << 21


def rotated_curves(
    mask: NDArray[np.bool_], samples: int, rotations: int
) -> list[tuple[float, NDArray[np.float64]]]:
    """``(angle, curve)`` of the silhouette turned back by ``angle`` for ``rotations``
    evenly spaced angles (0 first). A turn that loses the silhouette is skipped."""
    if rotations < 1:
        raise QueryError(f"rotations must be at least 1, got {rotations}")
    ys, xs = np.nonzero(mask)
    if len(ys) and mask.size > WHOLE_PHOTO_TURNS:
        # a large photo is turned in the silhouette's box alone (turned whole, a 12-megapixel
        # photo took 0.34 s); a smaller one whole, as the benchmarks' photos were (in the box,
        # the turns' rounding differs: 2 of 240 synthetic photos' first answers change)
        mask = mask[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
        ys, xs = ys - ys.min(), xs - xs.min()
    cy, cx = float(ys.mean()), float(xs.mean())
    # pad to the diagonal so no turn clips the silhouette
    h, w = mask.shape
    pad = int(np.ceil(np.hypot(h, w) / 2 - min(h, w) / 2)) + 2
    canvas = np.pad(mask.astype(np.uint8) * 255, pad)
    centre = (cx + pad, cy + pad)
    out = []
    for i in range(rotations):
        angle = 360.0 * i / rotations
        if angle == 0.0:
            turned = canvas
        else:
            # cv2 turns counter-clockwise for positive angles: turn back by -angle
            m = cv2.getRotationMatrix2D(centre, -angle, 1.0)
            turned = np.asarray(cv2.warpAffine(canvas, m, (canvas.shape[1], canvas.shape[0]),
                                               flags=cv2.INTER_LINEAR), np.uint8)
        try:
            out.append((angle, distance_curve(turned > 127, samples)))
        except FeatureError:
            continue
    if not out:
        raise ImageError("the silhouette gives no usable contour")
    return out


def completed_mask(
    mask: NDArray[np.bool_], ignore: NDArray[np.bool_] | None,
    min_share: float = RECOGNITION.hidden_min_share,
) -> NDArray[np.bool_] | None:
    """The silhouette with the pixels that may hide it filled in where they lie inside its
    convex hull (an occluder's bite out of a convex outline), or None when nothing is
    filled: a second query shape for an object that other labelled objects occlude."""
    if ignore is None or not ignore.any():
        return None
    points = cv2.findNonZero(mask.astype(np.uint8))
    hull = np.zeros(mask.shape, np.uint8)
    cv2.fillConvexPoly(hull, cv2.convexHull(points), 1)
    filled = ignore & (hull > 0) & ~mask
    # only occluders that touch the object can hide part of it
    if filled.sum() < min_share * mask.sum():
        return None
    n, labels = cv2.connectedComponents((mask | filled).astype(np.uint8), connectivity=8)
    keep = labels == np.bincount(labels[mask]).argmax()
    out = mask | (filled & keep)
    return out if out.sum() > mask.sum() else None


def pose_mask(seg: Segmentation, mask: Any, label_map: Any) -> NDArray[np.bool_]:
    """The silhouette the pose is fitted to: a label map's object keeps its holes (the
    space inside a handle), which :func:`segment` fills for the outline's curve."""
    if label_map is None:
        return seg.mask
    return seg.mask & np.asarray(mask, dtype=bool)
