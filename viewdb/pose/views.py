"""What pose estimation works on and returns: the segmented query (:class:`QueryView`),
the candidate views of one object (:class:`CandidateView`) and the pose found
(:class:`PoseEstimate`; frames and units: :mod:`viewdb.pose.frames`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from ..catalogue.appearance import Appearance

__all__ = ["CandidateView", "PoseEstimate", "QueryView"]


@dataclass(frozen=True, eq=False)
class QueryView:
    """The query image, already segmented."""

    #: RGB uint8 (H, W, 3).
    color: NDArray[np.uint8] = field(repr=False)
    #: The object's pixels, bool (H, W).
    mask: NDArray[np.bool_] = field(repr=False)
    #: Pixels that may hide the object (e.g. other labelled objects), bool (H, W) or None:
    #: the perspective silhouette fit leaves them out.
    ignore: NDArray[np.bool_] | None = field(default=None, repr=False)
    #: Each pixel's depth in the meshes' own units (NaN: no reading), float (H, W), or
    #: None: a pinhole pose's distance is then set from the depth
    #: (:mod:`viewdb.pose.depth_distance`).
    depth: NDArray[np.float64] | None = field(default=None, repr=False)
    #: What :func:`~viewdb.pose.estimate.estimate_pose` derives from the query (SIFT
    #: features, outline, internal edges), kept for its next calls: a query's results and
    #: their refinements are posed against the same photo. So a QueryView's arrays must not
    #: change once used.
    _derived: dict[Any, Any] = field(default_factory=dict, init=False, repr=False, compare=False)

    def derived(self, key: Any, make: Callable[[], Any]) -> Any:
        """``make()``, computed once per ``key`` for this query."""
        if key not in self._derived:
            self._derived[key] = make()
        return self._derived[key]


@dataclass(frozen=True, eq=False)
class CandidateView:
    """One candidate pose of one object (a grid view), with that view's features."""

    azimuth: float
    elevation: float
    #: The view's silhouette is the mirror of the matched view's (informational).
    mirrored: bool
    #: float32 (n, 5): x, y (view pixels), size, angle, response.
    keypoints: NDArray[np.float32] = field(repr=False)
    #: uint8 (n, 128).
    descriptors: NDArray[np.uint8] = field(repr=False)
    #: float32 (n, 3): each keypoint's model-space point.
    points3d: NDArray[np.float32] = field(repr=False)
    #: The view's silhouette, bool (S, S), for the shape fallback.
    mask: NDArray[np.bool_] = field(repr=False)
    #: S, the view image's width and height in pixels.
    image_size: int
    #: Half-extent of the view's orthographic volume in model units.
    xmag: float = 1.0
    #: The view's shaded render, uint8 RGB (S, S, 3) (or grey (S, S)), for the shape
    #: fallback's internal edges; without it (and without ``appearance``) only the outline
    #: is compared.
    color: NDArray[np.uint8] | None = field(default=None, repr=False)
    #: The view's stored appearance (:class:`viewdb.catalogue.appearance.Appearance`),
    #: whose internal edges the shape fallback compares when ``color`` is None.
    appearance: Appearance | None = field(default=None, repr=False)


@dataclass(frozen=True, eq=False)
class PoseEstimate:
    """The pose of the object in the query (frames and units: :mod:`viewdb.pose.frames`)."""

    azimuth: float
    elevation: float
    inplane: float
    scale: float
    #: 3×3 model-to-camera rotation.
    rotation: NDArray[np.float64] = field(repr=False)
    #: (3,) model-to-camera translation.
    translation: NDArray[np.float64] = field(repr=False)
    #: "sift" or "shape".
    method: str
    #: Query keypoints whose match (to any candidate) the final pose reprojects within
    #: ``pose_threshold`` (0 for shape).
    inliers: int
    #: Index of the chosen candidate in the sequence given.
    candidate: int
    #: "viewdb" (orthographic, no intrinsics) or "opencv" (pinhole, with intrinsics).
    frame: str
    #: Inlier ratio for sift (inliers / query keypoints matched to any candidate); for
    #: shape 1 − the normalised symmetric chamfer distance of the outlines (mean distance /
    #: sqrt(query area)) − ``detail_weight`` × that of the internal edges (when used, see
    #: :class:`~viewdb.config.PoseConfig`), clipped to [0, 1]: comparable between calls for one query;
    #: for a perspective silhouette fit (``refined == "silhouette"``) its IoU.
    score: float
    #: How the pose was refined in the pinhole camera: None, or "silhouette" (the IoU
    #: search of :mod:`viewdb.pose.silhouette`).
    refined: str | None = None
    #: The silhouette IoU of the final pose (perspective fits only).
    iou: float | None = None
    #: "normalised" (model space of the views) or "mesh" (the mesh file's own frame and
    #: units, ``original = centre + scale · normalised``): the units of ``translation``.
    units: str = "normalised"
    #: The pixels of a depth image that set the translation's length (None: no depth).
    depth_pixels: int | None = None
