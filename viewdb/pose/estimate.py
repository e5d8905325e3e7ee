"""Pose of a recognised object in a query image: SIFT against candidate views, or its shape.

After Tak & Hwang, section III.E: a query matched to a view of an object could be in any of
that view's candidate poses (:meth:`viewdb.ViewDB.candidate_poses`); SIFT matches between
the query and each candidate's view pick the pose, and the stored 3-D point of every view
keypoint turns the matches into 2-D–3-D correspondences that refine it off the grid.
Texture-less objects give too few keypoints; their pose comes from aligning silhouettes,
and among candidates whose silhouettes agree, from the edges inside them.

Frames and units (public contract)
----------------------------------
Model space is the normalised mesh (:mod:`viewdb.camera`): bounding-box centre at the
origin, farthest vertex at distance 1, +Y up, +Z the model's front. Every pose is
**model-to-camera**, ``x_cam = R · x_model + t``.

``frame == "viewdb"`` (no intrinsics given): the camera frame of the views, OpenGL style
(x right, y up, looking down −Z), and the query is modelled as an *orthographic* camera
like the views. A query that looks exactly like grid view ``(h, v)`` has
``R = R_view(h, v)ᵀ = R_x(v) · R_y(−h)`` (``R_view = camera_pose(h, v)[:3, :3]``); turned
in the image plane by ``α`` degrees counter-clockwise as seen on screen it has
``R = R_z(α) · R_x(v) · R_y(−h)`` (:func:`view_rotation`, inverse :func:`rotation_to_view`).

* ``scale`` is the magnification relative to a view render of the query's *width*:
  1.0 means the object appears as large as in a view image of that width, i.e. the
  query's half-width spans ``xmag_q = 1 / scale`` model units (square pixels, so the
  half-height spans ``H / W / scale``).
* Query pixel ``(u, w)`` (column, row; OpenCV keypoint coordinates, pixel centres on
  integers as in :func:`viewdb.camera.pixel_rays_to_camera`) sees the camera-frame point
  ``x = ((u + ½) − W/2) · (2/W) / scale``, ``y = (H/2 − (w + ½)) · (2/W) / scale``.
* ``translation = (tx, ty, −3)``: ``tx, ty`` are the camera-frame x, y of the model origin
  in model units (from where the origin projects in the image); the z component is minus
  the views' camera distance, 3, which an orthographic image cannot measure.

``frame == "opencv"`` (intrinsics ``(fx, fy, cx, cy)`` given): the OpenCV pinhole frame
(x right, y down, z forward); ``R, t`` as returned by :func:`cv2.solvePnPRansac` (refined)
for the query keypoints and the matched view keypoints' 3-D points, in normalised model
units. ``azimuth``, ``elevation`` and ``inplane`` are still those of the viewdb-frame
rotation ``diag(1, −1, −1) · R``, and ``scale = 2·fx / (W·t_z)`` (the same magnification at
the depth of the model origin). The shape fallback, which has no depth, reports the
weak-perspective pinhole pose with that scale in this frame too.

Angles are degrees in [0, 360). ``(h, v, α)`` and ``(h + 180, 180 − v, α + 180)`` are the
same rotation; results report the one with ``cos v ≥ 0`` (v in [0, 90] ∪ [270, 360)), so a
query matched at grid view (30, 150) reads as (210, 30) turned by a further 180°.

How (see :func:`estimate_pose`): SIFT matches to every candidate view propose poses (a 2-D
similarity refined to a scaled-orthographic pose, or PnP); each proposal is scored by the
query keypoints it explains among the matches of *all* candidates (one object, one model
space); the best is refit and accepted with ``PoseConfig.min_inliers``. Otherwise the
query silhouette is aligned to each candidate's (chamfer distance) at its grid direction,
and alignments that fit about equally well are ranked by that distance plus the distance
between the internal edges (creases, shading, texture) of the query and of the candidate's
shaded render.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from ..camera import normalise_angle, pixel_rays_to_camera, rotation_x, rotation_y
from ..catalogue.features import largest_contour
from ..catalogue.sift import extract_sift
from ..errors import FeatureError, PoseError, QueryError
from .intrinsics import check_intrinsics

__all__ = [
    "CandidateView",
    "OrthographicFit",
    "PnPFit",
    "PoseConfig",
    "PoseEstimate",
    "QueryView",
    "estimate_pose",
    "inplane_angle",
    "shape_fit",
    "rotation_angle",
    "rotation_to_view",
    "rotation_z",
    "solve_orthographic",
    "solve_pnp",
    "view_rotation",
]

#: The views' camera distance (:class:`viewdb.config.RenderConfig.camera_distance`).
CAMERA_DISTANCE = 3.0
#: The OpenGL-style viewdb camera frame to the OpenCV camera frame (and back).
GL_TO_CV = np.diag([1.0, -1.0, -1.0])
#: Matches a candidate needs to propose a pose hypothesis.
MIN_HYPOTHESIS_MATCHES = 4
#: Best-supported hypotheses refined on the pooled matches, and refit rounds for each.
REFINED_HYPOTHESES = 3
POOLED_ROUNDS = 3


@dataclass(frozen=True)
class PoseConfig:
    """Tunables of :func:`estimate_pose`. Pixel tolerances are fractions of the query
    object's extent (the larger side of its mask's bounding box), floored at
    :attr:`min_threshold_px`, so they hold for any image size."""

    #: SIFT keypoints extracted from the query (views store up to 128).
    max_keypoints: int = 512
    #: Lowe's ratio test between the best and the second best match.
    ratio: float = 0.75
    #: Geometrically consistent matches needed to accept the SIFT pose.
    min_inliers: int = 8
    #: RANSAC tolerance of the 2-D similarity from a grid view to the query. Loose: an
    #: off-grid query differs from the nearest view by parallax a similarity cannot model.
    similarity_threshold: float = 0.04
    #: Reprojection tolerance of the refined 3-D pose (orthographic or PnP).
    pose_threshold: float = 0.015
    #: Floor of both tolerances, in query pixels.
    min_threshold_px: float = 2.0
    #: Refine the orthographic pose off the grid from the 2-D–3-D correspondences, scoring
    #: proposals on the matches of all candidates. False is the grid-only baseline: the
    #: similarity's pose ``R_z(α)·R_viewᵀ`` of the candidate with most RANSAC inliers.
    #: (The PnP path, with intrinsics, always refines.)
    refine: bool = True
    #: Shape fallback: in-plane angle search, coarse step then fine step (degrees).
    coarse_step: float = 5.0
    fine_step: float = 0.5
    #: Shape fallback: points sampled along each outer contour for the chamfer distance.
    contour_samples: int = 256
    #: Shape fallback: weight of the internal-edge distance added to the outline distance
    #: (both over the object's sqrt(area)) for the alignments whose outlines fit about as
    #: well as the best (:data:`SHAPE_TIE_RATIO`): Canny edges inside the query's silhouette
    #: against those of each candidate's shaded render (:attr:`CandidateView.color`) under
    #: the outline alignment, a symmetric oriented chamfer distance. It tells apart poses
    #: whose outlines agree (a chair from the front and from the back). 0: the outline
    #: alone. Measured on 216 off-grid renders of the sample models, segmented as queries
    #: are, among the candidate poses of the nearest grid view: a wrong pose picked 25
    #: times, against 98 by the outline alone; flat for weights 0.5-2, truncations
    #: 0.05-0.2, orientation shares 0-0.5.
    detail_weight: float = 1.0
    #: Each edge pixel's distance is truncated at this fraction of sqrt(area) ...
    detail_truncation: float = 0.1
    #: ... and mixed with this share of its difference in direction to the nearest edge
    #: pixel of the other image (0°: none, 90°: the truncated distance).
    detail_orientation: float = 0.5

    def __post_init__(self) -> None:
        if self.max_keypoints < 1:
            raise ValueError(f"max_keypoints must be at least 1, got {self.max_keypoints}")
        if not 0.0 < self.ratio <= 1.0:
            raise ValueError(f"ratio must be in (0, 1], got {self.ratio}")
        if self.min_inliers < 4:
            raise ValueError(f"min_inliers must be at least 4, got {self.min_inliers}")
        if not (self.similarity_threshold > 0 and self.pose_threshold > 0):
            raise ValueError("thresholds must be positive")
        if not 0.0 < self.fine_step <= self.coarse_step <= 90.0:
            raise ValueError("need 0 < fine_step <= coarse_step <= 90")
        if self.contour_samples < 16:
            raise ValueError(f"contour_samples must be at least 16, got {self.contour_samples}")
        if not (self.detail_weight >= 0 and self.detail_truncation > 0 and 0 <= self.detail_orientation <= 1):
            raise ValueError("need detail_weight >= 0, detail_truncation > 0, 0 <= detail_orientation <= 1")


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
    #: What :func:`estimate_pose` derives from the query (SIFT features, outline, internal
    #: edges), kept for its next calls: a query's results and their refinements are
    #: posed against the same photo. So a QueryView's arrays must not change once used.
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
    #: fallback's internal edges; without it only the outline is compared.
    color: NDArray[np.uint8] | None = field(default=None, repr=False)


@dataclass(frozen=True, eq=False)
class PoseEstimate:
    """The pose of the object in the query (see the module docstring for frames)."""

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
    #: :class:`PoseConfig`), clipped to [0, 1]: comparable between calls for one query;
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


# ---------------------------------------------------------------------- rotations
def rotation_z(degrees: float) -> NDArray[np.float64]:
    """Right-handed 3×3 rotation about +Z (counter-clockwise on screen in the viewdb frame)."""
    t = math.radians(degrees)
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def view_rotation(azimuth: float, elevation: float, inplane: float = 0.0) -> NDArray[np.float64]:
    """Model-to-camera rotation ``R_z(α) · R_x(v) · R_y(−h)`` of view ``(h, v)`` turned by
    ``α`` counter-clockwise in the image; ``α = 0`` gives ``camera_pose(h, v)[:3, :3]ᵀ``."""
    return rotation_z(inplane) @ rotation_x(elevation) @ rotation_y(-azimuth)


def inplane_angle(rotation: NDArray[np.float64], azimuth: float, elevation: float) -> float:
    """The in-plane angle ``α`` (degrees) that best writes ``rotation`` (viewdb frame) as
    ``view_rotation(azimuth, elevation, α)``: exact when the rotation views that direction."""
    m = np.asarray(rotation, np.float64) @ view_rotation(azimuth, elevation).T
    return math.degrees(math.atan2(m[1, 0], m[0, 0]))


def _angle_gap(a: float, b: float) -> float:
    d = abs(a - b) % 360.0
    return min(d, 360.0 - d)


def rotation_to_view(
    rotation: NDArray[np.floating], reference: tuple[float, float] | None = None
) -> tuple[float, float, float]:
    """``(azimuth, elevation, inplane)`` with ``R = R_z(inplane) · R_x(v) · R_y(−h)``.

    Every rotation has two such triples, ``(h, v, α)`` and ``(h + 180, 180 − v, α + 180)``;
    without ``reference`` the one with ``cos v ≥ 0`` (v in [0, 90] ∪ [270, 360)) is
    returned, with it the one whose ``(h, v)`` is nearer ``reference``. Looking straight
    up or down (``cos v = 0``) only ``h + α`` is determined; ``h`` is then the reference
    azimuth, or 0. Angles are in [0, 360).
    """
    r = np.asarray(rotation, dtype=np.float64)
    if r.shape != (3, 3):
        raise ValueError(f"rotation must be 3x3, got shape {r.shape}")
    d = r[2]  # the camera's +Z (towards the camera) in model space
    horizontal = math.hypot(d[0], d[2])
    elevation = math.degrees(math.atan2(d[1], horizontal))
    if horizontal > 1e-9:
        azimuth = math.degrees(math.atan2(d[0], d[2]))
    else:
        azimuth = reference[0] if reference is not None else 0.0
    m = r @ (rotation_x(elevation) @ rotation_y(-azimuth)).T
    inplane = math.degrees(math.atan2(m[1, 0], m[0, 0]))
    first = (normalise_angle(azimuth), normalise_angle(elevation), normalise_angle(inplane))
    if reference is None:
        return first
    second = (
        normalise_angle(azimuth + 180.0), normalise_angle(180.0 - elevation),
        normalise_angle(inplane + 180.0),
    )

    def gap(t: tuple[float, float, float]) -> float:
        return _angle_gap(t[0], reference[0]) + _angle_gap(t[1], reference[1])

    return second if gap(second) < gap(first) - 1e-9 else first


def rotation_angle(a: NDArray[np.floating], b: NDArray[np.floating]) -> float:
    """The angle in degrees of the rotation ``aᵀ · b`` (0 when ``a == b``)."""
    m = np.asarray(a, dtype=np.float64).T @ np.asarray(b, dtype=np.float64)
    c = (np.trace(m) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


# ---------------------------------------------------------------------- geometry helpers
def _query_normalised(xy: NDArray[np.floating], width: int, height: int) -> NDArray[np.float64]:
    """Query pixel coordinates → the orthographic image plane in units of the half-width,
    y up (multiply by ``1/scale`` for camera-frame model units)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return np.stack(
        [(xy[:, 0] + 0.5 - width / 2.0) * 2.0 / width, (height / 2.0 - xy[:, 1] - 0.5) * 2.0 / width],
        axis=1,
    )


def _query_pixels(q: NDArray[np.floating], width: int, height: int) -> NDArray[np.float64]:
    """Inverse of :func:`_query_normalised`."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 2)
    return np.stack(
        [q[:, 0] * width / 2.0 + width / 2.0 - 0.5, height / 2.0 - 0.5 - q[:, 1] * width / 2.0], axis=1
    )


def _view_plane(xy: NDArray[np.floating], image_size: int, xmag: float) -> NDArray[np.float64]:
    """View pixel coordinates → the view camera's x, y in model units."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return pixel_rays_to_camera(xy[:, 0], xy[:, 1], np.zeros(len(xy)), image_size, xmag)[:, :2]


def _threshold(config: PoseConfig, fraction: float, extent: float) -> float:
    return max(config.min_threshold_px, fraction * extent)


def _check_intrinsics(intrinsics: Sequence[float]) -> NDArray[np.float64]:
    try:
        values = tuple(intrinsics)
    except TypeError:
        values = ()
    try:
        fx, fy, cx, cy = check_intrinsics(values)
    except QueryError as exc:
        raise PoseError(exc.message) from exc
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


# ---------------------------------------------------------------------- orthographic pose
@dataclass(frozen=True, eq=False)
class OrthographicFit:
    """A scaled-orthographic pose: ``q = scale · (R · X)_xy + offset`` in query-normalised
    coordinates (:func:`_query_normalised`); the model origin projects to ``offset``."""

    rotation: NDArray[np.float64]
    scale: float
    offset: NDArray[np.float64]
    #: Indices (into the correspondences given) within the threshold of the fit.
    inliers: NDArray[np.int64]


def solve_orthographic(
    query_points: NDArray[np.floating],
    object_points: NDArray[np.floating],
    initial: OrthographicFit,
    threshold: float,
    rounds: int = 2,
) -> OrthographicFit:
    """Refine a scaled-orthographic pose over 2-D–3-D correspondences (no matching).

    ``query_points`` (n, 2) are query-normalised coordinates (half-width units, y up),
    ``object_points`` (n, 3) model-space points, ``threshold`` the inlier tolerance in the
    same units. Starting from ``initial`` (its inliers are used first), each round fits
    ``R = exp([ω]) · R₀``, scale and offset by robust least squares (soft-L1 at the
    threshold), then takes as inliers every correspondence within the threshold. Returns
    ``initial`` unchanged when fewer than 3 inliers remain.
    """
    q = np.asarray(query_points, dtype=np.float64).reshape(-1, 2)
    x = np.asarray(object_points, dtype=np.float64).reshape(-1, 3)
    fit = initial
    for _ in range(max(1, rounds)):
        idx = fit.inliers
        if len(idx) < 3:
            return fit
        problem = _OrthographicProblem(q[idx], x[idx], fit.rotation, threshold)
        p0 = np.array([0.0, 0.0, 0.0, math.log(fit.scale), *fit.offset])
        sol = least_squares(problem.residuals, p0, jac=problem.jacobian, loss="soft_l1",
                            f_scale=1.0, method="trf", max_nfev=100)
        rot = _rodrigues(sol.x[:3]) @ fit.rotation
        scale = math.exp(sol.x[3])
        offset = sol.x[4:6].copy()
        err = np.linalg.norm(scale * (x @ rot[:2].T) + offset - q, axis=1)
        fit = OrthographicFit(rot, scale, offset, np.flatnonzero(err <= threshold))
    return fit


def _skew(w: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _rodrigues(w: NDArray[np.float64]) -> NDArray[np.float64]:
    """exp([w]×), the rotation by |w| radians about w."""
    theta = float(np.linalg.norm(w))
    k = _skew(w)
    if theta < 1e-8:
        return np.eye(3) + k + k @ k / 2.0
    return np.eye(3) + math.sin(theta) / theta * k + (1.0 - math.cos(theta)) / theta**2 * (k @ k)


def _left_jacobian(w: NDArray[np.float64]) -> NDArray[np.float64]:
    """J with d(exp([w]×)·y)/dw = −[exp([w]×)·y]× · J (the left Jacobian of SO(3))."""
    theta = float(np.linalg.norm(w))
    k = _skew(w)
    if theta < 1e-6:
        return np.eye(3) + k / 2.0 + k @ k / 6.0
    return (np.eye(3) + (1.0 - math.cos(theta)) / theta**2 * k
            + (theta - math.sin(theta)) / theta**3 * (k @ k))


class _OrthographicProblem:
    """Residuals ``(s·(R·X)_xy + o − q) / threshold`` with ``R = exp([ω]×)·R₀`` over
    ``p = (ω, log s, o)``, and their exact Jacobian (scipy's least_squares)."""

    def __init__(self, q: NDArray[np.float64], x: NDArray[np.float64], r0: NDArray[np.float64],
                 threshold: float) -> None:
        self.q, self.y0, self.inv = q, x @ r0.T, 1.0 / threshold

    def residuals(self, p: NDArray[np.float64]) -> NDArray[np.float64]:
        y = self.y0 @ _rodrigues(p[:3]).T
        return ((math.exp(p[3]) * y[:, :2] + p[4:6] - self.q) * self.inv).ravel()

    def jacobian(self, p: NDArray[np.float64]) -> NDArray[np.float64]:
        y = self.y0 @ _rodrigues(p[:3]).T
        s = math.exp(p[3])
        n = len(y)
        zero = np.zeros(n)
        # rows x and y of −[y]× per point, then · J_l(ω)
        neg_skew = np.stack([np.stack([zero, y[:, 2], -y[:, 1]], axis=1),
                             np.stack([-y[:, 2], zero, y[:, 0]], axis=1)], axis=1)  # (n, 2, 3)
        jac = np.zeros((n, 2, 6))
        jac[:, :, :3] = s * neg_skew @ _left_jacobian(p[:3])
        jac[:, :, 3] = s * y[:, :2]
        jac[:, 0, 4] = 1.0
        jac[:, 1, 5] = 1.0
        return (jac * self.inv).reshape(2 * n, 6)


# ---------------------------------------------------------------------- PnP
@dataclass(frozen=True, eq=False)
class PnPFit:
    """A pinhole pose in the OpenCV frame: ``x_cam = R · X + t``."""

    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    #: Indices (into the correspondences given) within the threshold of the refined pose.
    inliers: NDArray[np.int64]


def solve_pnp(
    image_points: NDArray[np.floating],
    object_points: NDArray[np.floating],
    intrinsics: Sequence[float],
    threshold: float,
) -> PnPFit | None:
    """Pose from 2-D–3-D correspondences (no matching): :func:`cv2.solvePnPRansac` (EPnP
    minimal sets, tolerance ``threshold`` pixels), then Levenberg–Marquardt on the
    inliers. ``image_points`` (n, 2) are pixels (x right, y down), ``object_points``
    (n, 3) model-space points, ``intrinsics`` ``(fx, fy, cx, cy)`` without distortion.
    Returns None when fewer than 6 correspondences are given or RANSAC finds no pose.
    """
    k = _check_intrinsics(intrinsics)
    img = np.ascontiguousarray(np.asarray(image_points, dtype=np.float64).reshape(-1, 1, 2))
    obj = np.ascontiguousarray(np.asarray(object_points, dtype=np.float64).reshape(-1, 1, 3))
    if len(img) < 6 or len(img) != len(obj):
        return None
    try:
        ok, rvec, tvec, inl = cv2.solvePnPRansac(
            obj, img, k, None, iterationsCount=500, reprojectionError=float(threshold),
            confidence=0.999, flags=cv2.SOLVEPNP_EPNP,
        )
    except cv2.error:
        return None
    if not ok or inl is None or len(inl) < 4:
        return None
    idx = inl.ravel()
    try:
        rvec, tvec = cv2.solvePnPRefineLM(obj[idx], img[idx], k, None, rvec, tvec)
    except cv2.error:
        pass
    proj, _ = cv2.projectPoints(obj, rvec, tvec, k, None)
    err = np.linalg.norm(proj.reshape(-1, 2) - img.reshape(-1, 2), axis=1)
    rot, _ = cv2.Rodrigues(rvec)
    return PnPFit(rot, tvec.reshape(3).astype(np.float64), np.flatnonzero(err <= threshold))


# ---------------------------------------------------------------------- SIFT path
def _match(
    query_desc: NDArray[np.float32], view_desc: NDArray[np.uint8], ratio: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Lowe-ratio matches ``(query indices, view indices)``; a view keypoint is kept once
    (its best query match), so one feature cannot vote many times."""
    if len(query_desc) == 0 or len(view_desc) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    pairs = matcher.knnMatch(query_desc, np.ascontiguousarray(view_desc, dtype=np.float32), k=2)
    best: dict[int, tuple[float, int]] = {}
    for p in pairs:
        if len(p) == 2 and p[0].distance < ratio * p[1].distance:
            m = p[0]
            if m.trainIdx not in best or m.distance < best[m.trainIdx][0]:
                best[m.trainIdx] = (m.distance, m.queryIdx)
    if not best:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    view_idx = np.fromiter(best.keys(), np.int64)
    query_idx = np.fromiter((best[int(i)][1] for i in view_idx), np.int64)
    return query_idx, view_idx


@dataclass(frozen=True, eq=False)
class _Hypothesis:
    """A pose proposed by one candidate's matches (rotation and translation in the result's
    frame: viewdb for orthographic, opencv for PnP)."""

    candidate: int
    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    scale: float
    #: The candidate's own matches that the pose explains, and their share (tie-break).
    own_inliers: int
    own_ratio: float


class _Query:
    """The query's keypoints and what projecting model points into it takes."""

    def __init__(
        self, keypoints: NDArray[np.float32], width: int, height: int,
        k_matrix: NDArray[np.float64] | None,
    ) -> None:
        self.px = keypoints[:, :2].astype(np.float64)
        self.width, self.height = width, height
        self.norm = _query_normalised(self.px, width, height)
        self.k = k_matrix

    def project(self, hyp: _Hypothesis, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Query pixels of model points under ``hyp`` (inf behind a pinhole camera)."""
        r, t = hyp.rotation, hyp.translation
        if self.k is None:
            return _query_pixels(hyp.scale * (points @ r[:2].T + t[:2]), self.width, self.height)
        cam = points @ r.T + t
        z = np.where(cam[:, 2] > 1e-9, cam[:, 2], np.nan)
        out = np.stack([self.k[0, 0] * cam[:, 0] / z + self.k[0, 2],
                        self.k[1, 1] * cam[:, 1] / z + self.k[1, 2]], axis=1)
        return np.where(np.isfinite(out), out, np.inf)


def _hypothesis(
    index: int, cand: CandidateView, query: _Query, qi: NDArray[np.int64], vi: NDArray[np.int64],
    sim_thr: float, pose_thr: float, config: PoseConfig,
) -> _Hypothesis | None:
    """The pose one candidate's matches give (None if they give none)."""
    points = cand.points3d[vi].astype(np.float64)
    if query.k is not None:
        fit = solve_pnp(query.px[qi], points, (query.k[0, 0], query.k[1, 1], query.k[0, 2],
                                               query.k[1, 2]), pose_thr)
        if fit is None or not fit.translation[2] > 0 or len(fit.inliers) < 4:
            return None
        scale = 2.0 * query.k[0, 0] / (query.width * float(fit.translation[2]))
        return _Hypothesis(index, fit.rotation, fit.translation, scale, len(fit.inliers),
                           len(fit.inliers) / len(qi))
    px = query.width / 2.0  # query pixels per normalised unit
    src = _view_plane(cand.keypoints[vi, :2], cand.image_size, cand.xmag)
    dst = query.norm[qi]
    m, mask = cv2.estimateAffinePartial2D(
        src.astype(np.float32), dst.astype(np.float32), method=cv2.RANSAC,
        ransacReprojThreshold=sim_thr / px, maxIters=2000, confidence=0.995,
    )
    if m is None or mask is None or int(mask.sum()) < 3:
        return None
    a, b = float(m[0, 0]), float(m[1, 0])
    scale = math.hypot(a, b)
    if not scale > 0:
        return None
    alpha = math.degrees(math.atan2(b, a))
    r0 = rotation_z(alpha) @ view_rotation(cand.azimuth, cand.elevation)
    fit = OrthographicFit(r0, scale, m[:, 2].astype(np.float64), np.flatnonzero(mask.ravel()))
    if config.refine:
        fit = solve_orthographic(dst, points, fit, pose_thr / px)
    t = np.array([fit.offset[0] / fit.scale, fit.offset[1] / fit.scale, -CAMERA_DISTANCE])
    return _Hypothesis(index, fit.rotation, t, fit.scale, len(fit.inliers), len(fit.inliers) / len(qi))


def _support(
    hyp: _Hypothesis, query: _Query, pool_q: NDArray[np.int64], pool_x: NDArray[np.float64],
    threshold: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The query keypoints ``hyp`` explains (some match of theirs, in any candidate, lands
    within ``threshold`` pixels) and, for each, the pooled match that lands nearest."""
    err = np.linalg.norm(query.project(hyp, pool_x) - query.px[pool_q], axis=1)
    ok = np.flatnonzero(err <= threshold)
    if len(ok) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = ok[np.lexsort((err[ok], pool_q[ok]))]
    first = np.ones(len(order), bool)
    first[1:] = pool_q[order][1:] != pool_q[order][:-1]
    chosen = order[first]
    return pool_q[chosen], chosen


def _refine_pooled(
    hyp: _Hypothesis, query: _Query, q_idx: NDArray[np.int64], points: NDArray[np.float64],
    threshold: float,
) -> _Hypothesis:
    """Refit ``hyp`` on the pooled correspondences it explains."""
    if query.k is not None:
        if len(q_idx) < 4:
            return hyp
        rvec, _ = cv2.Rodrigues(hyp.rotation)
        try:
            rvec, tvec = cv2.solvePnPRefineLM(
                np.ascontiguousarray(points.reshape(-1, 1, 3)),
                np.ascontiguousarray(query.px[q_idx].reshape(-1, 1, 2)), query.k, None,
                rvec, hyp.translation.reshape(3, 1).copy(),
            )
        except cv2.error:
            return hyp
        t = tvec.reshape(3).astype(np.float64)
        if not t[2] > 0:
            return hyp
        rot, _ = cv2.Rodrigues(rvec)
        scale = 2.0 * query.k[0, 0] / (query.width * float(t[2]))
        return _Hypothesis(hyp.candidate, rot, t, scale, hyp.own_inliers, hyp.own_ratio)
    px = query.width / 2.0
    start = OrthographicFit(hyp.rotation, hyp.scale, hyp.scale * hyp.translation[:2],
                            np.arange(len(q_idx)))
    fit = solve_orthographic(query.norm[q_idx], points, start, threshold / px, rounds=1)
    t = np.array([fit.offset[0] / fit.scale, fit.offset[1] / fit.scale, -CAMERA_DISTANCE])
    return _Hypothesis(hyp.candidate, fit.rotation, t, fit.scale, hyp.own_inliers, hyp.own_ratio)


def _sift_pose(
    query: _Query, descriptors: NDArray[np.uint8], candidates: Sequence[CandidateView],
    extent: float, config: PoseConfig,
) -> tuple[_Hypothesis, int, float] | None:
    """The best SIFT pose, its support (query keypoints explained) and its inlier ratio."""
    sim_thr = _threshold(config, config.similarity_threshold, extent)
    pose_thr = _threshold(config, config.pose_threshold, extent)
    pooled = config.refine or query.k is not None
    q_desc = descriptors.astype(np.float32)
    hyps: list[_Hypothesis] = []
    pool_q: list[NDArray[np.int64]] = []
    pool_x: list[NDArray[np.float64]] = []
    for index, cand in enumerate(candidates):
        qi, vi = _match(q_desc, cand.descriptors, config.ratio)
        if len(qi) == 0:
            continue
        pool_q.append(qi)
        pool_x.append(cand.points3d[vi].astype(np.float64))
        if len(qi) >= MIN_HYPOTHESIS_MATCHES:
            hyp = _hypothesis(index, cand, query, qi, vi, sim_thr, pose_thr, config)
            if hyp is not None:
                hyps.append(hyp)
    if not hyps:
        return None
    if not pooled:  # the grid-view similarity alone: rank by the candidate's own inliers
        best = max(hyps, key=lambda h: (h.own_inliers, h.own_ratio))
        return best, best.own_inliers, best.own_ratio
    all_q, all_x = np.concatenate(pool_q), np.concatenate(pool_x)
    matched = len(np.unique(all_q))

    def rank(h: _Hypothesis) -> tuple[int, float]:
        return len(_support(h, query, all_q, all_x, pose_thr)[0]), h.own_ratio

    hyps.sort(key=rank, reverse=True)
    best, best_rank = hyps[0], rank(hyps[0])
    for hyp in hyps[:REFINED_HYPOTHESES]:
        current = rank(hyp)
        for _ in range(POOLED_ROUNDS):
            q_idx, chosen = _support(hyp, query, all_q, all_x, pose_thr)
            refined = _refine_pooled(hyp, query, q_idx, all_x[chosen], pose_thr)
            refined_rank = rank(refined)
            if refined_rank[0] < current[0]:
                break
            improved = refined_rank[0] > current[0]
            hyp, current = refined, refined_rank
            if not improved:
                break
        if current > best_rank:
            best, best_rank = hyp, current
    return best, best_rank[0], best_rank[0] / matched


# ---------------------------------------------------------------------- shape path
@dataclass(frozen=True, eq=False)
class _Outline:
    """A silhouette's outer contour (pixels, y down), its area, centroid and edge distances."""

    points: NDArray[np.float64]
    area: float
    centroid: NDArray[np.float64]
    distance: NDArray[np.float32]


def _outline(mask: NDArray[np.bool_], samples: int) -> _Outline:
    poly = largest_contour(mask)  # raises FeatureError when there is no usable region
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area2 = float(cross.sum())
    centroid = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (3.0 * area2)
    # equally spaced points along the polygon
    seg = np.hypot(xn - x, yn - y)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.linspace(0.0, cum[-1], samples, endpoint=False)
    closed = np.vstack([poly, poly[:1]])
    pts = np.stack([np.interp(s, cum, closed[:, 0]), np.interp(s, cum, closed[:, 1])], axis=1)
    edges = np.full(mask.shape, 255, np.uint8)
    ring = np.rint(closed).astype(np.int32).reshape(-1, 1, 2)
    cv2.polylines(edges, [ring], isClosed=True, color=0, thickness=1)
    dist = cv2.distanceTransform(edges, cv2.DIST_L2, 5)  # within 2 % of exact, 10x faster
    return _Outline(pts, abs(area2) / 2.0, centroid, dist)


def _sample_distance(dist: NDArray[np.float32], pts: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance-map values at points (..., 2) (nearest pixel); points outside the image get
    the value at the nearest border pixel plus their distance to it."""
    h, w = dist.shape
    x, y = pts[..., 0], pts[..., 1]
    cx, cy = np.clip(x, 0, w - 1), np.clip(y, 0, h - 1)
    inside = dist[np.rint(cy).astype(np.int64), np.rint(cx).astype(np.int64)].astype(np.float64)
    return inside + np.hypot(x - cx, y - cy)


def _rotate_up(d: NDArray[np.float64], degrees: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotate y-down offsets (n, 2) counter-clockwise on screen by each angle → (T, n, 2)."""
    t = np.radians(degrees)[:, None]
    c, s = np.cos(t), np.sin(t)
    x, y = d[None, :, 0], -d[None, :, 1]  # to y up
    return np.stack([c * x - s * y, -(s * x + c * y)], axis=-1)  # back to y down


def _chamfer(query: _Outline, view: _Outline, lam: float, angles: NDArray[np.float64]) -> NDArray[np.float64]:
    """Symmetric mean chamfer distance (query pixels) for each in-plane angle, with the view
    scaled by ``lam`` and its centroid put on the query's."""
    to_query = query.centroid + lam * _rotate_up(view.points - view.centroid, angles)
    d1 = _sample_distance(query.distance, to_query).mean(axis=1)
    to_view = view.centroid + _rotate_up(query.points - query.centroid, -angles) / lam
    d2 = lam * _sample_distance(view.distance, to_view).mean(axis=1)
    return (d1 + d2) / 2.0


#: Shape fallback: in-plane angles kept per candidate (local minima of the outline distance
#: within :data:`SHAPE_ANGLE_SLACK` of its best), so that when a silhouette looks alike
#: turned (a square, a rectangle) the internal edges can choose the turn too.
SHAPE_ANGLES = 4
SHAPE_ANGLE_SLACK = 0.05
#: Shape fallback near a known pose (``inplane_near``): the in-plane angles searched lie
#: within this many degrees of it.
SHAPE_NEAR_WINDOW = 15.0
#: Shape fallback: the internal edges decide among the alignments whose outline distance
#: is within this ratio (plus margin) of the best; an outline that fits clearly worse is
#: not rescued by its edges (thin objects have few edges inside, and a candidate view far
#: from the query's direction has edges in the wrong places).
SHAPE_TIE_RATIO = 0.1
SHAPE_TIE_MARGIN = 0.003
#: Internal edges: Canny hysteresis thresholds (on the L2 magnitude of the 3×3 Sobel
#: gradient of the grey image, after a 3×3 Gaussian blur). The query's are found at the
#: level of its image pyramid nearest each view's scale. Thresholds of 15/45 and colour
#: edges were measured no better on the sample models.
EDGE_THRESHOLDS = (30.0, 90.0)
#: Edges closer to the silhouette than this fraction of the view's image size (at least
#: 2 pixels) are the outline's, which the outline distance already scores.
EDGE_MARGIN = 0.012
#: A query has internal detail (and the edge term is used) when its interior holds at
#: least this many edge pixels per pixel of sqrt(area), at about the views' resolution.
MIN_DETAIL_EDGES = 0.1


@dataclass(frozen=True, eq=False)
class _ShapeResult:
    cost: float  # normalised outline chamfer
    angle: float
    lam: float  # query pixels per view pixel
    origin_px: NDArray[np.float64]  # where the model origin lands in the query
    similarity: NDArray[np.float64]  # 2×3: view pixels → query pixels


def _similarity(query: _Outline, view: _Outline, lam: float, angle: float) -> NDArray[np.float64]:
    """The 2×3 map of view pixels to query pixels that :func:`_chamfer` scores: the view's
    centroid onto the query's, scaled by ``lam``, turned counter-clockwise on screen."""
    t = math.radians(angle)
    c, s = math.cos(t), math.sin(t)
    rm = lam * np.array([[c, s], [-s, c]])  # y down
    return np.hstack([rm, (query.centroid - rm @ view.centroid)[:, None]])


def _align_shape(
    query: _Outline, view: _Outline, cand: CandidateView, config: PoseConfig,
    near: float | None = None,
) -> list[_ShapeResult]:
    """The in-plane alignments of a view's outline to the query's, best first: every local
    minimum of the coarse angle search within :data:`SHAPE_ANGLE_SLACK` of the best (at
    most :data:`SHAPE_ANGLES`), each refined by the fine step. With ``near``, only the
    best angle within :data:`SHAPE_NEAR_WINDOW` of it."""
    lam = math.sqrt(query.area / view.area)
    norm = math.sqrt(query.area)
    if near is None:
        coarse = np.arange(0.0, 360.0, config.coarse_step)
        cost = _chamfer(query, view, lam, coarse) / norm
        minima = np.flatnonzero((cost <= np.roll(cost, 1)) & (cost <= np.roll(cost, -1)))
        minima = minima[np.argsort(cost[minima], kind="stable")]
        minima = minima[cost[minima] <= cost[minima[0]] + SHAPE_ANGLE_SLACK]
        minima = minima[:SHAPE_ANGLES]
    else:
        half = math.floor(SHAPE_NEAR_WINDOW / config.coarse_step) * config.coarse_step
        coarse = near + np.arange(-half, half + 1e-9, config.coarse_step)
        cost = _chamfer(query, view, lam, coarse) / norm
        minima = np.array([int(np.argmin(cost))])
    # refine every minimum in one batch of angles
    steps = np.arange(-config.coarse_step, config.coarse_step + 1e-9, config.fine_step)
    fine = (coarse[minima][:, None] + steps[None, :]).ravel()
    fine_cost = (_chamfer(query, view, lam, fine) / norm).reshape(len(minima), len(steps))
    centre = np.array([cand.image_size / 2.0 - 0.5, cand.image_size / 2.0 - 0.5, 1.0])
    out: list[_ShapeResult] = []
    for i in range(len(minima)):
        j = int(np.argmin(fine_cost[i]))
        angle = normalise_angle(float(fine[i * len(steps) + j]))
        if any(_angle_gap(angle, r.angle) < config.coarse_step for r in out):
            continue  # a plateau's second point, or two minima refined to one
        sim = _similarity(query, view, lam, angle)
        out.append(_ShapeResult(float(fine_cost[i, j]), angle, lam, sim @ centre, sim))
    out.sort(key=lambda r: r.cost)
    return out


# ---------------------------------------------------------------------- internal edges
def _grey(color: NDArray[np.uint8]) -> NDArray[np.uint8]:
    return color if color.ndim == 2 else cv2.cvtColor(color, cv2.COLOR_RGB2GRAY)


@dataclass(frozen=True, eq=False)
class _Detail:
    """Internal edges of an image (a window of it): the edge pixels ``(x, y)`` with their
    directions (gradient angle modulo π, y down), and per pixel whether it is inside the
    silhouette away from its outline, the distance to the nearest edge pixel and that
    pixel's direction."""

    points: NDArray[np.float64]
    theta: NDArray[np.float64]
    interior: NDArray[np.bool_]
    distance: NDArray[np.float32]
    nearest_theta: NDArray[np.float32]


def _detail(grey: NDArray[np.uint8], mask: NDArray[np.uint8], image_size: int) -> _Detail:
    """Canny edges of ``grey`` inside ``mask`` eroded by :data:`EDGE_MARGIN` of
    ``image_size`` (the outline's own edges are left to the outline distance)."""
    r = max(2, int(round(EDGE_MARGIN * image_size)))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    interior = cv2.erode(mask, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0) > 0
    blurred = cv2.GaussianBlur(grey, (3, 3), 0)
    lo, hi = EDGE_THRESHOLDS
    edges = (cv2.Canny(blurred, lo, hi, L2gradient=True) > 0) & interior
    ys, xs = np.nonzero(edges)  # row-major, as distanceTransformWithLabels numbers them
    if len(xs) == 0:
        far = np.full(mask.shape, np.inf, np.float32)
        return _Detail(np.zeros((0, 2)), np.zeros(0), interior, far, np.zeros(mask.shape, np.float32))
    gx = cv2.Sobel(blurred, cv2.CV_32F, 1, 0)[ys, xs]
    gy = cv2.Sobel(blurred, cv2.CV_32F, 0, 1)[ys, xs]
    theta = np.mod(np.arctan2(gy, gx), np.pi).astype(np.float64)
    distance, labels = cv2.distanceTransformWithLabels(
        np.where(edges, 0, 255).astype(np.uint8), cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    nearest = theta.astype(np.float32)[labels - 1]
    return _Detail(np.stack([xs, ys], axis=1).astype(np.float64), theta, interior, distance, nearest)


def _lookup(
    detail: _Detail, pts: NDArray[np.float64]
) -> tuple[NDArray[np.bool_], NDArray[np.intp], NDArray[np.intp]]:
    """Which points (n, 2) fall inside ``detail``'s interior, and their nearest pixels."""
    h, w = detail.interior.shape
    x, y = np.rint(pts[:, 0]).astype(np.intp), np.rint(pts[:, 1]).astype(np.intp)
    ok = (x >= 0) & (x < w) & (y >= 0) & (y < h)
    x, y = np.where(ok, x, 0), np.where(ok, y, 0)
    return ok & detail.interior[y, x], x, y


@dataclass(frozen=True, eq=False)
class _ViewDetail:
    detail: _Detail
    #: The window's top-left corner in the view (x, y).
    corner: NDArray[np.float64]
    #: sqrt of the view's silhouette area, in its pixels.
    norm: float


def _view_detail(cand: CandidateView, area: float, truncation: float) -> _ViewDetail | None:
    """The candidate render's internal edges, in a window around its silhouette (padded by
    the truncation distance, so query edges near its border still find theirs)."""
    if cand.color is None:
        return None
    color = np.asarray(cand.color)
    mask = np.asarray(cand.mask, dtype=bool)
    if color.dtype != np.uint8 or color.shape[:2] != mask.shape or color.ndim not in (2, 3):
        raise PoseError(f"candidate ({cand.azimuth}, {cand.elevation}): colour {color.dtype} "
                        f"{color.shape} is not uint8 RGB or grey of its mask's size {mask.shape}")
    norm = math.sqrt(area)
    pad = int(math.ceil(truncation * norm)) + 2
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    y0, x0 = max(0, int(rows[0]) - pad), max(0, int(cols[0]) - pad)
    y1, x1 = min(mask.shape[0], int(rows[-1]) + 1 + pad), min(mask.shape[1], int(cols[-1]) + 1 + pad)
    detail = _detail(np.ascontiguousarray(_grey(color)[y0:y1, x0:x1]),
                     np.ascontiguousarray(mask[y0:y1, x0:x1].astype(np.uint8)), cand.image_size)
    return _ViewDetail(detail, np.array([x0, y0], np.float64), norm)


class _QueryDetail:
    """The query's internal edges, cropped to the object, at the levels of an image
    pyramid: a view of scale ``lam`` (query pixels per view pixel) is compared with the
    level nearest its resolution, so edges are found at about the same scale in both."""

    def __init__(self, color: NDArray[np.uint8], mask: NDArray[np.bool_], area: float) -> None:
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        y0, x0 = max(0, int(rows[0]) - 4), max(0, int(cols[0]) - 4)
        y1, x1 = int(rows[-1]) + 5, int(cols[-1]) + 5
        self.offset = np.array([x0, y0], np.float64)
        grey = np.ascontiguousarray(_grey(color)[y0:y1, x0:x1])
        m = np.ascontiguousarray(mask[y0:y1, x0:x1].astype(np.uint8) * 255)
        self.levels = [(grey, m)]
        while min(grey.shape) >= 32 and len(self.levels) < 8:
            grey, m = cv2.pyrDown(grey), cv2.pyrDown(m)
            self.levels.append((grey, np.where(m > 127, 255, 0).astype(np.uint8)))
        self._details: dict[tuple[int, int], _Detail] = {}
        # is there any detail inside, at about the resolution of a 256-pixel view?
        k = int(np.clip(round(math.log2(max(math.sqrt(area) / 128.0, 1.0))), 0, len(self.levels) - 1))
        self.active = len(self.level(k, 256).points) >= MIN_DETAIL_EDGES * math.sqrt(area) / 2**k

    def level(self, k: int, image_size: int) -> _Detail:
        if (k, image_size) not in self._details:
            self._details[k, image_size] = _detail(*self.levels[k], image_size)
        return self._details[k, image_size]

    def cost(self, res: _ShapeResult, cand: CandidateView, view: _ViewDetail, truncation: float,
             orientation: float) -> float:
        """Symmetric oriented chamfer distance between the query's internal edges and the
        view's under the outline alignment ``res``, where both interiors overlap, over the
        view's sqrt(area): each edge pixel costs ``(1 − orientation) · min(d, τ) +
        orientation · τ · Δθ / 90°`` for the distance ``d`` (view pixels) to the nearest
        edge pixel of the other image and their difference in direction ``Δθ`` (90° when
        ``d ≥ τ``: no match), with ``τ = truncation · sqrt(area)``; so an edge pixel costs at
        most ``τ``, and an image without edges there costs ``τ``."""
        k = int(np.clip(round(math.log2(res.lam)), 0, len(self.levels) - 1))
        f = 2.0**k
        query = self.level(k, cand.image_size)
        # view window pixels -> level-k pixels of the query crop
        a = res.similarity.copy()
        a[:, 2] += a[:, :2] @ view.corner - self.offset
        a /= f
        a[:, 2] += 0.5 / f - 0.5  # pyrDown keeps pixel centres at 2^k (x + 1/2) - 1/2
        inv = cv2.invertAffineTransform(a)
        per_view_px = res.lam / f
        turn = math.radians(res.angle)  # a view direction θ is θ − turn in the query
        tau = truncation * view.norm

        def directed(d: NDArray[np.float64], dtheta: NDArray[np.float64]) -> float:
            if len(d) == 0:
                return tau
            dtheta = np.mod(dtheta, np.pi)
            dtheta = np.where(d < tau, np.minimum(dtheta, np.pi - dtheta), np.pi / 2)
            return float(((1.0 - orientation) * np.minimum(d, tau)
                          + orientation * tau * dtheta / (np.pi / 2)).mean())

        v = view.detail
        inside, x, y = _lookup(query, v.points @ a[:, :2].T + a[:, 2])
        to_query = directed(query.distance[y, x][inside] / per_view_px,
                            v.theta[inside] - turn - query.nearest_theta[y, x][inside])
        inside, x, y = _lookup(v, query.points @ inv[:, :2].T + inv[:, 2])
        to_view = directed(v.distance[y, x][inside].astype(np.float64),
                           query.theta[inside] + turn - v.nearest_theta[y, x][inside])
        return (to_query + to_view) / 2.0 / view.norm


# ---------------------------------------------------------------------- the estimate
#: A query object smaller than the candidate views by at least this factor is enlarged
#: before SIFT, by at most the second (see :func:`_sift_upscale`).
MIN_SIFT_UPSCALE = 1.5
MAX_SIFT_UPSCALE = 3.0


def _sift_upscale(extent: float, candidates: Sequence[CandidateView]) -> float:
    """How much to enlarge the query before SIFT so that its object is about as large as
    in the candidate views (a photo's object often spans a fraction of the views' size,
    and SIFT then finds few keypoints that match); only when it is at least
    :data:`MIN_SIFT_UPSCALE` times smaller, by at most :data:`MAX_SIFT_UPSCALE`."""
    sizes = []
    for c in candidates:
        rows, cols = np.flatnonzero(c.mask.any(axis=1)), np.flatnonzero(c.mask.any(axis=0))
        if len(rows):
            sizes.append(max(rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1))
    if not sizes or extent <= 0:
        return 1.0
    ratio = float(np.median(sizes)) / extent
    # about the views' size already: as it is (interpolation only adds edge keypoints)
    return 1.0 if ratio < MIN_SIFT_UPSCALE else min(ratio, MAX_SIFT_UPSCALE)


def estimate_pose(
    query: QueryView,
    candidates: Sequence[CandidateView],
    config: PoseConfig | None = None,
    intrinsics: tuple[float, float, float, float] | None = None,
    *,
    inplane_near: float | None = None,
) -> PoseEstimate:
    """The pose of the object in ``query``, choosing among ``candidates``.

    ``candidates`` are candidate poses of **one** object (e.g. from
    :meth:`viewdb.ViewDB.candidate_poses`): their 3-D points share one model space. To
    choose between objects, estimate once per object.

    SIFT first. The query's keypoints are matched to each candidate view's (Lowe ratio).
    Each candidate's matches propose a pose: without ``intrinsics`` a RANSAC 2-D
    similarity from the view to the query (in-plane angle, scale, shift) starts a robust
    scaled-orthographic fit over the matched 3-D points, which moves the pose off the
    grid; with ``intrinsics`` PnP RANSAC. Every proposal is scored on the matches of *all*
    candidates: its support is the number of query keypoints with a match landing within
    ``pose_threshold`` of where the pose projects that match's 3-D point (candidates of one
    object share model space, so correct matches from neighbouring views vote for the same
    pose while confusions between look-alike parts rarely agree). The best-supported
    proposals are refit on the matches they explain, and the best (ties: the larger share
    of its own candidate's matches) is accepted with at least ``config.min_inliers``.

    Otherwise the silhouettes decide: the query's outer contour is aligned to each
    candidate's by centroid, area and in-plane angle (symmetric chamfer distance; every
    angle that fits nearly as well as the best is kept, up to :data:`SHAPE_ANGLES`). When
    every candidate carries its shaded render (:attr:`CandidateView.color`) and the query
    has edges inside its silhouette, the alignments whose outlines fit about as well as
    the best (:data:`SHAPE_TIE_RATIO`) are also scored by the distance between those
    internal edges and the render's under the alignment (an oriented chamfer distance,
    weighted by ``config.detail_weight``): silhouettes that agree (a chair from the front
    and from the back, the faces of a cube) are told apart by their creases, shading and
    texture. The best alignment gives the pose at that candidate's grid direction.
    ``inplane_near`` (degrees, for refining a known pose over nearby views): the outline is
    aligned only at in-plane angles within :data:`SHAPE_NEAR_WINDOW` of it, plus the fine
    search's one coarse step (the angle of
    ``R_z`` in ``rotation = R_z(angle) · view_rotation(h, v)`` of each candidate).

    Raises
    ------
    PoseError
        No candidates, an empty or malformed query, or no candidate with a silhouette.
    """
    config = config or PoseConfig()
    if len(candidates) == 0:
        raise PoseError("no candidate views to estimate a pose from")
    color = np.asarray(query.color)
    mask = np.asarray(query.mask, dtype=bool)
    if mask.ndim != 2 or color.shape[:2] != mask.shape:
        raise PoseError(f"query colour {color.shape} and mask {mask.shape} do not match")
    if color.dtype != np.uint8 or not (color.ndim == 2 or (color.ndim == 3 and color.shape[2] == 3)):
        raise PoseError(f"query colour must be uint8 RGB (H, W, 3) or grey (H, W), got "
                        f"{color.dtype} {color.shape}")
    if not mask.any():
        raise PoseError("the query mask is empty: no object to estimate a pose for")
    k_matrix = None if intrinsics is None else _check_intrinsics(intrinsics)
    height, width = mask.shape
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    extent = float(max(rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1))

    found = None
    if any(len(c.descriptors) for c in candidates):  # else nothing to match (e.g. refining)
        upscale = _sift_upscale(extent, candidates)
        keypoints, descriptors = query.derived(
            ("sift", config.max_keypoints, upscale),
            lambda: extract_sift(color, mask, config.max_keypoints, upscale))
        found = _sift_pose(_Query(keypoints, width, height, k_matrix), descriptors, candidates,
                           extent, config)
    if found is not None and found[1] >= config.min_inliers:
        hyp, support, ratio = found
        if k_matrix is None:
            h, v, a = rotation_to_view(hyp.rotation)
            frame = "viewdb"
        else:
            h, v, a = rotation_to_view(GL_TO_CV @ hyp.rotation)
            frame = "opencv"
        return PoseEstimate(h, v, a, hyp.scale, hyp.rotation, hyp.translation, "sift", support,
                            hyp.candidate, frame, ratio)
    return _shape_pose(query, color, mask, candidates, config, k_matrix, inplane_near)


def shape_fit(query: QueryView, view: CandidateView, config: PoseConfig | None = None) -> float:
    """How well one view explains the query's shape: the score (``1 - cost``, in [0, 1])
    of :func:`estimate_pose`'s shape method on this view alone, i.e. its best alignment
    of the outline and, when the view carries its shaded render, of the internal edges.
    The view's SIFT features are not used. The query's outline and edges are derived once
    per :class:`QueryView`, so fitting many views to one query costs one alignment each.

    Raises
    ------
    PoseError
        The query or the view has no usable silhouette.
    """
    config = config or PoseConfig()
    mask = np.asarray(query.mask, dtype=bool)
    if not mask.any():
        raise PoseError("the query mask is empty: no shape to fit")
    return _shape_pose(query, np.asarray(query.color), mask, [view], config, None).score


def _shape_pose(
    query: QueryView, color: NDArray[np.uint8], mask: NDArray[np.bool_],
    candidates: Sequence[CandidateView], config: PoseConfig, k_matrix: NDArray[np.float64] | None,
    near: float | None = None,
) -> PoseEstimate:
    try:
        outline = query.derived(("outline", config.contour_samples),
                                lambda: _outline(mask, config.contour_samples))
    except FeatureError as exc:
        raise PoseError(f"the query silhouette has no usable contour: {exc}") from exc
    hyps: list[tuple[float, int, _ShapeResult]] = []
    views: dict[int, _Outline] = {}
    for index, cand in enumerate(candidates):
        try:
            views[index] = _outline(np.asarray(cand.mask, dtype=bool), config.contour_samples)
        except FeatureError:
            continue
        hyps.extend((res.cost, index, res)
                    for res in _align_shape(outline, views[index], cand, config, near))
    if not hyps:
        raise PoseError("no candidate view has a silhouette to align the query with")
    hyps.sort(key=lambda x: x[0])  # stable: ties keep the candidates' order
    use_detail = config.detail_weight > 0 and all(candidates[i].color is not None for i in views)
    query_detail = (query.derived(("detail",), lambda: _QueryDetail(color, mask, outline.area))
                    if use_detail else None)
    if query_detail is None or not query_detail.active:
        cost, index, res = hyps[0]
    else:
        # among the alignments whose outlines fit about as well as the best, outline +
        # weighted edge distance; the edge term is >= 0, so an alignment whose outline
        # alone is already worse than the best total cannot win
        ties = hyps[0][0] * (1.0 + SHAPE_TIE_RATIO) + SHAPE_TIE_MARGIN
        details: dict[int, _ViewDetail | None] = {}
        best: tuple[float, int, _ShapeResult] | None = None
        for outline_cost, index, res in hyps:
            if outline_cost > ties or (best is not None and outline_cost >= best[0]):
                break
            cand = candidates[index]
            if index not in details:
                details[index] = _view_detail(cand, views[index].area, config.detail_truncation)
            view_detail = details[index]
            assert view_detail is not None
            edge_cost = query_detail.cost(res, cand, view_detail, config.detail_truncation,
                                          config.detail_orientation)
            total = outline_cost + config.detail_weight * edge_cost
            if best is None or total < best[0]:
                best = (total, index, res)
        assert best is not None
        cost, index, res = best
    cand = candidates[index]
    height, width = mask.shape
    rotation = rotation_z(res.angle) @ view_rotation(cand.azimuth, cand.elevation)
    h, v, a = rotation_to_view(rotation)
    scale = res.lam * cand.image_size / (cand.xmag * width)
    score = min(1.0, max(0.0, 1.0 - cost))
    if k_matrix is None:
        offset = _query_normalised(res.origin_px, width, height)[0]
        translation = np.array([offset[0] / scale, offset[1] / scale, -CAMERA_DISTANCE])
        return PoseEstimate(h, v, a, scale, rotation, translation, "shape", 0, index, "viewdb", score)
    # weak perspective: the model origin at the depth where fx pixels span scale·W/2 per unit
    fx, fy, cx, cy = k_matrix[0, 0], k_matrix[1, 1], k_matrix[0, 2], k_matrix[1, 2]
    tz = 2.0 * fx / (scale * width)
    u, w = res.origin_px
    translation = np.array([(u - cx) * tz / fx, (w - cy) * tz / fy, tz])
    return PoseEstimate(h, v, a, scale, GL_TO_CV @ rotation, translation, "shape", 0, index,
                        "opencv", score)
