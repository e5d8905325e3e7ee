"""The camera convention and the view grid (part of the public contract, see README).

Model space is the normalised mesh: bounding-box centre at the origin, farthest vertex at
distance 1, +Y up, +Z the model's front.

A view is ``(azimuth h, elevation v)`` in degrees, each in [0, 360). Its camera-to-world
pose is ``R_y(h) · R_x(−v) · translate(0, 0, d)`` with ``d = 3``; the camera looks down its
own −Z axis with +Y up (OpenGL/pyrender). ``R_y`` and ``R_x`` are right-handed rotations
about +Y and +X. Hence:

* (0, 0) looks at the front; growing ``h`` orbits towards +X; (0, 90) looks straight down;
* the camera sits at ``d · (sin h·cos v, sin v, cos h·cos v)``;
* (h + 180, −v) is the opposite direction with the same up vector: its silhouette is the
  left–right mirror of the silhouette of (h, v), i.e. the reversed distance curve;
* (h + 180, 180 − v) is the same direction as (h, v) with the image turned by 180°.

The projection is orthographic with ``xmag = ymag = 1``: pixel ``(u, w)`` (column, row) of
an ``S × S`` image sees the camera-frame point ``x = (u + ½)·2/S − 1``, ``y = 1 − (w + ½)·2/S``.

A grid of gap ``g`` holds the ``(360/g)²`` views with ``h, v ∈ {0, g, 2g, …}``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "GL_TO_CV",
    "camera_direction",
    "camera_pose",
    "grid_views",
    "sphere_views",
    "normalise_angle",
    "pixel_rays_to_camera",
    "rotation_x",
    "rotation_y",
]

#: The OpenGL-style viewdb camera frame to the OpenCV camera frame and back (flip y and z).
GL_TO_CV = np.diag([1.0, -1.0, -1.0])


def normalise_angle(angle: float) -> float:
    """Map an angle in degrees into [0, 360), snapping values within 1e-9 of 360 to 0."""
    a = float(angle) % 360.0
    return 0.0 if abs(a - 360.0) < 1e-9 or abs(a) < 1e-9 else a


def rotation_y(degrees: float) -> NDArray[np.float64]:
    """Right-handed 3×3 rotation about +Y."""
    t = np.radians(degrees)
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_x(degrees: float) -> NDArray[np.float64]:
    """Right-handed 3×3 rotation about +X."""
    t = np.radians(degrees)
    c, s = np.cos(t), np.sin(t)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def camera_pose(azimuth: float, elevation: float, distance: float = 3.0) -> NDArray[np.float64]:
    """Camera-to-world 4×4 pose ``R_y(h) · R_x(−v) · translate(0, 0, distance)``."""
    pose = np.eye(4)
    rot = rotation_y(azimuth) @ rotation_x(-elevation)
    pose[:3, :3] = rot
    pose[:3, 3] = rot @ np.array([0.0, 0.0, distance])
    return pose


def camera_direction(azimuth: float, elevation: float) -> NDArray[np.float64]:
    """Unit vector from the origin to the camera: ``(sin h·cos v, sin v, cos h·cos v)``."""
    h, v = np.radians(azimuth), np.radians(elevation)
    return np.array([np.sin(h) * np.cos(v), np.sin(v), np.cos(h) * np.cos(v)])


def grid_views(gap: float) -> list[tuple[float, float]]:
    """All ``(azimuth, elevation)`` pairs of the grid of ``gap`` degrees, azimuth-major.

    Raises
    ------
    ValueError
        If ``gap`` does not divide 360.
    """
    steps = 360.0 / gap
    if gap <= 0 or abs(steps - round(steps)) > 1e-9:
        raise ValueError(f"gap must divide 360 evenly, got {gap}")
    angles = [i * gap for i in range(round(steps))]
    return [(h, v) for h in angles for v in angles]


#: :func:`sphere_views`: the widest azimuth step near the poles, in grid gaps. Near a pole a
#: step of azimuth mostly turns the picture in its plane, which a gravity hint's narrow
#: window of turns must still reach.
POLAR_STRETCH = 3


def sphere_views(gap: float) -> list[tuple[float, float]]:
    """One ``(azimuth, elevation)`` of the grid of ``gap`` degrees per viewing direction,
    about ``gap`` apart over the sphere, azimuth-major.

    The square grid (:func:`grid_views`) sees every direction twice: ``(h, v)`` and
    ``(h + 180, 180 − v)`` are the same camera position turned half a turn in the
    picture's plane, which the in-plane search covers (and which a gravity hint never
    asks for: an upright camera has ``|v| ≤ 90``). Its rings of constant elevation also
    crowd towards the poles, where a step of ``gap`` in azimuth is ``gap·cos v`` of arc.
    So here the elevations are those of the grid in ``[−90, 90]`` (normalised to
    ``[0, 360)``), and at elevation ``v`` the azimuth step is ``m·gap`` with ``m`` the
    largest whole number at most ``1 / cos v`` (so the step is at most ``gap`` of arc)
    and at most :data:`POLAR_STRETCH`. Every view is a view of the square grid, and every
    direction is about as close to one as on the square grid; 2.5 times fewer views at 10°.

    Raises
    ------
    ValueError
        If ``gap`` does not divide 360.
    """
    grid = grid_views(gap)  # checks the gap
    steps = round(360.0 / gap)
    quarter = int(90.0 // gap)
    views: set[tuple[int, int]] = set()
    for ring in range(-quarter, quarter + 1):
        cos_v = math.cos(math.radians(ring * gap))
        stretch = POLAR_STRETCH if cos_v < 1.0 / POLAR_STRETCH else max(1, math.floor(1.0 / cos_v + 1e-9))
        # as grid indices, so the angles are the very floats of grid_views
        views.update((i * stretch, ring % steps) for i in range(math.ceil(steps / stretch)))
    return [hv for hv in grid if (round(hv[0] / gap), round(hv[1] / gap)) in views]


def pixel_rays_to_camera(
    u: NDArray[np.floating], w: NDArray[np.floating], depth: NDArray[np.floating],
    image_size: int, xmag: float = 1.0,
) -> NDArray[np.float64]:
    """Camera-frame 3-D points of pixels ``(u, w)`` (column, row; may be sub-pixel) at ``depth``.

    ``depth`` is the distance along the viewing axis (positive, as pyrender returns it), so
    the point is ``(x, y, −depth)`` in the camera frame.
    """
    half = image_size / 2.0
    x = ((np.asarray(u, dtype=np.float64) + 0.5) / half - 1.0) * xmag
    y = (1.0 - (np.asarray(w, dtype=np.float64) + 0.5) / half) * xmag
    return np.stack([x, y, -np.asarray(depth, dtype=np.float64)], axis=-1)
