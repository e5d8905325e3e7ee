"""Rotations, camera frames and image coordinates of the pose stage.

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
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..camera import GL_TO_CV, normalise_angle, pixel_rays_to_camera, rotation_x, rotation_y
from ..errors import PoseError, QueryError
from .intrinsics import check_intrinsics

__all__ = [
    "CAMERA_DISTANCE",
    "GL_TO_CV",
    "angle_gap",
    "inplane_angle",
    "intrinsics_matrix",
    "query_normalised",
    "query_pixels",
    "rodrigues",
    "rotation_angle",
    "rotation_to_view",
    "rotation_z",
    "skew",
    "view_plane",
    "view_rotation",
]

#: The views' camera distance (:class:`viewdb.config.RenderConfig.camera_distance`).
CAMERA_DISTANCE = 3.0


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


def angle_gap(a: float, b: float) -> float:
    """The smaller difference of two angles in degrees, in [0, 180]."""
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
        return angle_gap(t[0], reference[0]) + angle_gap(t[1], reference[1])

    return second if gap(second) < gap(first) - 1e-9 else first


def rotation_angle(a: NDArray[np.floating], b: NDArray[np.floating]) -> float:
    """The angle in degrees of the rotation ``aᵀ · b`` (0 when ``a == b``)."""
    m = np.asarray(a, dtype=np.float64).T @ np.asarray(b, dtype=np.float64)
    c = (np.trace(m) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def skew(w: NDArray[np.float64]) -> NDArray[np.float64]:
    """``[w]×``, the matrix of the cross product ``w × ·``."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def rodrigues(w: NDArray[np.float64]) -> NDArray[np.float64]:
    """exp([w]×), the rotation by |w| radians about w."""
    theta = float(np.linalg.norm(w))
    k = skew(w)
    if theta < 1e-8:
        return np.eye(3) + k + k @ k / 2.0
    return np.eye(3) + math.sin(theta) / theta * k + (1.0 - math.cos(theta)) / theta**2 * (k @ k)


# ---------------------------------------------------------------------- image coordinates
def query_normalised(xy: NDArray[np.floating], width: int, height: int) -> NDArray[np.float64]:
    """Query pixel coordinates → the orthographic image plane in units of the half-width,
    y up (multiply by ``1/scale`` for camera-frame model units)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return np.stack(
        [(xy[:, 0] + 0.5 - width / 2.0) * 2.0 / width, (height / 2.0 - xy[:, 1] - 0.5) * 2.0 / width],
        axis=1,
    )


def query_pixels(q: NDArray[np.floating], width: int, height: int) -> NDArray[np.float64]:
    """Inverse of :func:`query_normalised`."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 2)
    return np.stack(
        [q[:, 0] * width / 2.0 + width / 2.0 - 0.5, height / 2.0 - 0.5 - q[:, 1] * width / 2.0], axis=1
    )


def view_plane(xy: NDArray[np.floating], image_size: int, xmag: float) -> NDArray[np.float64]:
    """View pixel coordinates → the view camera's x, y in model units."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return pixel_rays_to_camera(xy[:, 0], xy[:, 1], np.zeros(len(xy)), image_size, xmag)[:, :2]


def intrinsics_matrix(intrinsics: Sequence[float]) -> NDArray[np.float64]:
    """The 3×3 camera matrix of ``(fx, fy, cx, cy)``; ``PoseError`` unless they are a
    camera within :data:`~viewdb.config.LIMITS` (:func:`~viewdb.pose.intrinsics.check_intrinsics`)."""
    try:
        values = tuple(intrinsics)
    except TypeError:
        values = ()
    try:
        fx, fy, cx, cy = check_intrinsics(values)
    except QueryError as exc:
        raise PoseError(exc.message) from exc
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
