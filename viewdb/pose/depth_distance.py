"""How far away a posed object is, from a depth image.

A silhouette or SIFT pose sets the object's distance from its size in the photo, so a cut
that takes in a neighbour, or misses a part, moves the object nearer or farther. A depth
image (:mod:`viewdb.recognition.depth_image`) measures that distance. The pose's rotation
and the direction of its translation are kept; the translation is scaled by the factor
``λ`` that lays the posed mesh's visible surface on the measured depths:

* the mesh is drawn at the pose as a cloud of points sampled evenly over its surface
  (:func:`surface_points`, turned into the camera once; the nearest point per pixel,
  :func:`surface_depth`): each covered pixel of the object's mask has a depth
  ``z = t_z + δ``, ``δ`` that surface point's depth relative to the model origin's;
* scaling the translation by ``λ`` moves the surface to ``λ·t_z + δ``, so each pixel with
  a reading ``d`` asks for ``λ = (d − δ) / t_z``; the median of these answers (pixels of
  an occluder or of the background that the cut took in are outvoted), found twice, since
  the covered pixels change with the distance.

A factor outside [1/5, 5] means the depth and the photo disagree by more than a pose can
be wrong by, which is a depth image in other units than ``depth_scale`` says: the pose is
refused with a message saying so.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from ..catalogue.coverage import MeshTriangles
from ..errors import QueryError
from .intrinsics import Intrinsics
from .views import PoseEstimate

__all__ = ["distance_from_depth", "surface_depth", "surface_points"]

#: Covered mask pixels with a reading needed to trust the depth.
MIN_PIXELS = 30
#: The farthest the depth may move the pose, as a factor of its distance.
MAX_FACTOR = 5.0
#: Surface points drawn per pixel of the object's box (at least ``_MIN_POINTS``).
_POINTS_PER_PIXEL = 3.0
_MIN_POINTS, _MAX_POINTS = 20_000, 400_000


def surface_points(triangles: MeshTriangles, count: int) -> NDArray[np.float64]:
    """``count`` points spread evenly by area over the mesh's surface (a fixed seed), and
    its vertices: ``(count + V, 3)`` in model units; none when the mesh has no area."""
    v, f = triangles.vertices, triangles.faces
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    if not len(f) or area.sum() <= 0:
        return np.zeros((0, 3))
    rng = np.random.default_rng(0)
    face = rng.choice(len(f), size=count, p=area / area.sum())
    root, share = np.sqrt(rng.random(count)), rng.random(count)  # uniform over each triangle
    cloud = ((1 - root)[:, None] * a[face] + (root * (1 - share))[:, None] * b[face]
             + (root * share)[:, None] * c[face])
    return np.concatenate([cloud, v])


def surface_depth(points: NDArray[np.floating], intrinsics: Intrinsics, shape: tuple[int, int]
                  ) -> NDArray[np.float64]:
    """The depth (camera z) of the nearest of ``points`` (in the camera frame, OpenCV) at
    each pixel of an image of ``shape`` through the pinhole camera; NaN where none lands."""
    out = np.full(shape, np.nan)
    z = points[:, 2]
    front = z > 1e-9
    fx, fy, cx, cy = (float(x) for x in intrinsics)
    u = np.round(fx * points[front, 0] / z[front] + cx).astype(np.int64)
    w = np.round(fy * points[front, 1] / z[front] + cy).astype(np.int64)
    inside = (u >= 0) & (u < shape[1]) & (w >= 0) & (w < shape[0])
    flat = np.full(shape[0] * shape[1], np.inf)
    np.minimum.at(flat, w[inside] * shape[1] + u[inside], z[front][inside])
    seen = np.isfinite(flat)
    out.reshape(-1)[seen] = flat[seen]
    return out


def distance_from_depth(estimate: PoseEstimate, triangles: MeshTriangles, mask: NDArray[np.bool_],
                        depth: NDArray[np.floating], intrinsics: Intrinsics) -> PoseEstimate:
    """``estimate`` (a pinhole pose, normalised units) moved along its viewing ray so that
    its visible surface lies on ``depth`` (the same units; NaN: no reading) over the
    object's ``mask`` (module doc); with ``depth_pixels``, the pixels that decided it.
    Unchanged when fewer than :data:`MIN_PIXELS` pixels have a reading; a
    :class:`~viewdb.errors.QueryError` when the depth disagrees by more than
    :data:`MAX_FACTOR`."""
    ys, xs = np.nonzero(mask)
    if not len(ys):
        return estimate
    box = (int(ys.max() - ys.min() + 1) * int(xs.max() - xs.min() + 1))
    count = int(min(_MAX_POINTS, max(_MIN_POINTS, _POINTS_PER_PIXEL * box)))
    # the surface turned into the camera once: only the distance changes below
    turned = surface_points(triangles, count) @ np.asarray(estimate.rotation, np.float64).T
    translation = np.asarray(estimate.translation, np.float64)
    factor, used = 1.0, 0
    for _ in range(2):
        t = translation * factor
        rendered = surface_depth(turned + t, intrinsics, mask.shape)
        both = mask & np.isfinite(rendered) & np.isfinite(depth)
        used = int(both.sum())
        if used < MIN_PIXELS or t[2] <= 0:
            return estimate
        asked = (depth[both] - (rendered[both] - t[2])) / t[2]
        factor *= float(np.median(asked))
        if not 1.0 / MAX_FACTOR <= factor <= MAX_FACTOR:
            raise QueryError(f"the depth image puts the object {factor:.3g} times as far as its outline "
                             "does: is `depth_scale` the meshes' units per depth unit?")
    return replace(estimate, translation=translation * factor, scale=estimate.scale / factor,
                   depth_pixels=used)
