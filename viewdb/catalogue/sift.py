"""SIFT features of a shaded view, each keypoint lifted to its 3-D point on the model.

Descriptors are stored as ``uint8``: OpenCV's SIFT already saturates every descriptor
element to an integer in [0, 255] (``SIFT_INT_DESCR_FCTR``), so the cast is lossless and
halves the storage of ``float16`` (``tests/test_sift.py`` checks both claims).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from ..camera import pixel_rays_to_camera

__all__ = ["SiftFeatures", "empty_features", "extract_sift", "lift_points"]

#: Columns of :attr:`SiftFeatures.keypoints`.
KEYPOINT_COLUMNS = ("x", "y", "size", "angle", "response")


@dataclass(frozen=True, eq=False)
class SiftFeatures:
    """Keypoints of one view. Row ``i`` of each array belongs to keypoint ``i``."""

    #: float32 (n, 5): x, y (pixels, column/row), size, angle (degrees), response.
    keypoints: NDArray[np.float32] = field(repr=False)
    #: uint8 (n, 128).
    descriptors: NDArray[np.uint8] = field(repr=False)
    #: float32 (n, 3): the keypoint's point on the normalised model (model space).
    points3d: NDArray[np.float32] = field(repr=False)

    def __len__(self) -> int:
        return int(self.keypoints.shape[0])

    def cv_keypoints(self) -> list[cv2.KeyPoint]:
        """The keypoints as OpenCV objects (for drawing or matching helpers)."""
        return [
            cv2.KeyPoint(float(x), float(y), float(s), float(a), float(r))
            for x, y, s, a, r in self.keypoints
        ]


def empty_features() -> SiftFeatures:
    return SiftFeatures(
        np.zeros((0, 5), np.float32), np.zeros((0, 128), np.uint8), np.zeros((0, 3), np.float32)
    )


_SIFT: dict[int, cv2.SIFT] = {}

#: Pixels of context kept around the object's bounding box for SIFT.
CROP_MARGIN = 24


def extract_sift(
    image: NDArray[np.uint8], mask: NDArray[np.bool_] | None, max_keypoints: int,
    upscale: float = 1.0,
) -> tuple[NDArray[np.float32], NDArray[np.uint8]]:
    """Detect SIFT keypoints inside ``mask`` and describe them.

    ``upscale`` > 1 enlarges the image (bicubic) before detection: a small object in a
    photo then shows its texture at about the scale of the stored views, which gives many
    more keypoints that match (positions and sizes are returned in the original pixels).

    Returns ``(keypoints (n, 5) float32, descriptors (n, 128) uint8)``; ``n`` may be 0
    (texture-less views often give no keypoints), never ``None``.
    """
    if not upscale >= 1.0:
        raise ValueError(f"upscale must be >= 1, got {upscale}")
    sift = _SIFT.get(max_keypoints)
    if sift is None:
        sift = _SIFT[max_keypoints] = cv2.SIFT.create(nfeatures=max_keypoints)
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
    x0 = y0 = 0
    cv_mask = None
    if mask is not None:
        # describe only the object's bounding box (plus a margin wider than SIFT's
        # support): about 2x faster on typical views, same keypoints inside the mask
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        if len(rows) == 0:
            return np.zeros((0, 5), np.float32), np.zeros((0, 128), np.uint8)
        h, w = mask.shape
        y0, y1 = max(rows[0] - CROP_MARGIN, 0), min(rows[-1] + 1 + CROP_MARGIN, h)
        x0, x1 = max(cols[0] - CROP_MARGIN, 0), min(cols[-1] + 1 + CROP_MARGIN, w)
        gray = gray[y0:y1, x0:x1]
        cv_mask = mask[y0:y1, x0:x1].astype(np.uint8)
    if upscale > 1.0:
        gray = cv2.resize(gray, None, fx=upscale, fy=upscale, interpolation=cv2.INTER_CUBIC)
        if cv_mask is not None:
            cv_mask = np.asarray(cv2.resize(cv_mask, (gray.shape[1], gray.shape[0]),
                                            interpolation=cv2.INTER_NEAREST), dtype=np.uint8)
    kps, desc = sift.detectAndCompute(np.ascontiguousarray(gray), cv_mask)
    if desc is None or not kps:
        return np.zeros((0, 5), np.float32), np.zeros((0, 128), np.uint8)
    kps, desc = kps[:max_keypoints], desc[:max_keypoints]
    f = float(upscale)
    keypoints = np.array(
        [((k.pt[0] + 0.5) / f - 0.5 + x0, (k.pt[1] + 0.5) / f - 0.5 + y0, k.size / f, k.angle,
          k.response) for k in kps],
        dtype=np.float32,
    )
    return keypoints, np.clip(np.rint(desc), 0, 255).astype(np.uint8)


def lift_points(
    xy: NDArray[np.floating], depth: NDArray[np.floating], pose: NDArray[np.float64], xmag: float
) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Model-space 3-D points of image points ``xy`` (n, 2) from an orthographic depth map.

    The depth of the nearest pixel is used; a point whose pixel is background takes the
    nearest object pixel of its 3×3 neighbourhood. Returns ``(points (n, 3), valid (n,))``;
    points with no object pixel nearby are invalid.
    """
    size = depth.shape[0]
    n = len(xy)
    points = np.zeros((n, 3), np.float32)
    valid = np.zeros(n, bool)
    if n == 0:
        return points, valid
    cols = np.clip(np.rint(xy[:, 0]).astype(int), 0, size - 1)
    rows = np.clip(np.rint(xy[:, 1]).astype(int), 0, size - 1)
    d = depth[rows, cols].astype(np.float64)
    for i in np.flatnonzero(d <= 0):
        r0, r1 = max(rows[i] - 1, 0), min(rows[i] + 2, size)
        c0, c1 = max(cols[i] - 1, 0), min(cols[i] + 2, size)
        patch = depth[r0:r1, c0:c1]
        if np.any(patch > 0):
            d[i] = float(patch[patch > 0].min())
    valid = d > 0
    # OpenCV puts pixel (c, r)'s centre at (c, r), as pixel_rays_to_camera's indices do
    cam = pixel_rays_to_camera(xy[:, 0], xy[:, 1], d, size, xmag)
    world = cam @ pose[:3, :3].T + pose[:3, 3]
    points[valid] = world[valid].astype(np.float32)
    return points, valid
