"""Pose of a texture-less object in a calibrated photo from its silhouette alone.

A mesh without texture gives SIFT nothing to match, and its outline seen orthographically
from the view grid is ambiguous. With the camera's intrinsics the silhouette says much
more: a full perspective pose predicts exactly which pixels the object covers. This module
finds that pose in two steps.

1. **Orthographic search.** The mesh's silhouette is rendered from evenly spread viewing
   directions (a Fibonacci sphere, ``SilhouetteConfig.directions``) and each outline is aligned to
   the query's in the image plane (centroid, area, in-plane angle by the symmetric chamfer
   distance of :mod:`viewdb.pose.shape_pose`), giving ranked weak-perspective hypotheses
   ``(h, v, inplane, magnification, origin pixel)``.
2. **Lift and refine.** Each hypothesis is lifted to the pinhole camera (below), then the
   6-DoF pose is refined by a pattern search that maximises the silhouette IoU between the
   mesh's silhouette through the intrinsics (scan-converted on the CPU,
   :mod:`viewdb.catalogue.coverage`) and the query mask, in a
   window around the object. The best few hypotheses are refined coarsely, the best of
   those finely.

Lifting (weak perspective → pinhole). An orthographic view ``(h, v)`` turned by ``α`` in
the image and magnified ``λ`` (query pixels per view pixel) puts ``λ · S / (2 · xmag)``
query pixels on one model unit, so the model origin lies at depth ``z = f · 2 · xmag /
(λ · S)`` (``f`` the focal length in pixels) on the ray through the pixel where the
alignment puts the origin. That ray is not the optical axis: an object off the image
centre is seen *along the ray*, so the view's rotation is composed with the rotation
``R_ray`` that turns the optical axis onto the ray: ``R = R_ray · diag(1, −1, −1) ·
R_z(α) · R_x(v) · R_y(−h)``. The refinement keeps this split: it moves the origin's pixel
and depth, and the rotation relative to the ray.

Occlusion: pixels given in ``ignore`` (e.g. other labelled objects that may hide this
one) count neither for nor against a pose.

Poses are model-to-camera in the OpenCV frame, in normalised model units (see
:mod:`viewdb.camera`); :func:`to_mesh_units` converts to the mesh's own frame.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from ..catalogue.coverage import MeshTriangles, overlap, overlap_kernel
from ..catalogue.pinhole import Window
from ..config import PoseConfig, SilhouetteConfig
from ..errors import FeatureError, PoseError
from ..jit import njit
from ..pools import thread_pool
from ..typed import Intrinsics
from .frames import GL_TO_CV, view_rotation
from .shape_pose import align_shape, outline_of
from .views import CandidateView

__all__ = [
    "QUICK",
    "SilhouetteFit",
    "fibonacci_directions",
    "lift_alignment",
    "ray_rotation",
    "search_silhouette_pose",
    "to_mesh_units",
]

#: A quicker search, for checking many candidate objects: started from the best 5
#: alignments of the match's candidate poses' silhouettes (at most
#: :attr:`~viewdb.config.MatchedPoseConfig.max_candidates` views, already ranked by the outline
#: search; else 40 evenly spread directions), no fine step, about 4x fewer renders, of a
#: mesh decimated further.
QUICK = SilhouetteConfig(directions=40, start_directions="candidates", coarse_starts=5, fine_starts=0,
                         coarse_size=80, coarse_faces=2048)


OrthoRender = Callable[[float, float], NDArray[np.bool_]]


@dataclass(frozen=True, eq=False)
class SilhouetteFit:
    """A pinhole pose (OpenCV frame, normalised model units) and how well it fits."""

    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    #: Silhouette IoU with the query mask (ignored pixels left out), at the fine window.
    iou: float
    #: The orthographic hypothesis it started from: azimuth, elevation, in-plane angle.
    start: tuple[float, float, float]
    #: Renders used in all.
    renders: int


def fibonacci_directions(n: int) -> list[tuple[float, float]]:
    """``n`` evenly spread viewing directions as ``(azimuth, elevation)`` degrees."""
    out = []
    golden = math.pi * (3.0 - math.sqrt(5.0))
    for i in range(n):
        y = 1.0 - 2.0 * (i + 0.5) / n
        theta = golden * i
        r = math.sqrt(max(0.0, 1.0 - y * y))
        x, z = r * math.sin(theta), r * math.cos(theta)
        out.append((math.degrees(math.atan2(x, z)) % 360.0, math.degrees(math.asin(y)) % 360.0))
    return out


@njit(cache=True, nogil=True)
def ray_rotation(u, w, k):  # pragma: no cover - compiled
    """The smallest rotation turning the optical axis (0, 0, 1) onto the ray through pixel
    ``(u, w)`` of a camera with matrix ``k`` (a float array): about the axis ``z × d =
    (−d_y, d_x, 0)`` by the angle between them (Rodrigues' formula written out, compiled:
    a fit calls this for every pose it tries)."""
    dx, dy = (u - k[0, 2]) / k[0, 0], (w - k[1, 2]) / k[1, 1]
    norm = math.sqrt(dx * dx + dy * dy + 1.0)
    dx, dy, c = dx / norm, dy / norm, 1.0 / norm  # the unit ray; c = cos of the angle
    s2 = dx * dx + dy * dy  # sin² of the angle
    out = np.eye(3)
    if s2 < 1e-24:
        return out
    a = (1.0 - c) / s2  # (1 − cos) / sin², times the unnormalised axis (−dy, dx, 0) twice
    out[0, 0], out[0, 1], out[0, 2] = 1.0 - a * dx * dx, -a * dx * dy, dx
    out[1, 0], out[1, 1], out[1, 2] = -a * dx * dy, 1.0 - a * dy * dy, dy
    out[2, 0], out[2, 1], out[2, 2] = -dx, -dy, c
    return out


def lift_alignment(
    azimuth: float, elevation: float, inplane: float, lam: float,
    origin_px: Sequence[float] | NDArray[np.float64], image_size: int, xmag: float, k: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The pinhole pose ``(R, t)`` (OpenCV, normalised units) of an orthographic alignment:
    view ``(azimuth, elevation)`` turned by ``inplane`` counter-clockwise, magnified ``lam``
    query pixels per view pixel, model origin at query pixel ``origin_px`` (module doc)."""
    u, w = float(origin_px[0]), float(origin_px[1])
    f = (k[0, 0] + k[1, 1]) / 2.0
    z = f * 2.0 * xmag / (lam * image_size)
    r_rel = GL_TO_CV @ view_rotation(azimuth, elevation, inplane)
    rotation = ray_rotation(u, w, k) @ r_rel
    translation = z * np.array([(u - k[0, 2]) / k[0, 0], (w - k[1, 2]) / k[1, 1], 1.0])
    return rotation, translation


def to_mesh_units(
    rotation: NDArray[np.floating], translation: NDArray[np.floating],
    centre: Sequence[float], scale: float,
) -> NDArray[np.float64]:
    """The translation of a normalised-units pinhole pose in the mesh's own frame and units
    (``original = centre + scale · normalised``): ``t = scale · t_n − R · centre``. The
    rotation is the same in both frames."""
    r = np.asarray(rotation, dtype=np.float64)
    return float(scale) * np.asarray(translation, dtype=np.float64) - r @ np.asarray(centre, np.float64)


class _Objective:
    """1 − IoU of a mesh's silhouette (its triangles, scan-converted and compared in one
    compiled pass: :func:`viewdb.catalogue.coverage.overlap`, no silhouette image made)
    and the query's, in one window."""

    def __init__(self, triangles: MeshTriangles, query: NDArray[np.bool_],
                 ignore: NDArray[np.bool_] | None, window: Window, k: NDArray[np.float64]) -> None:
        self.triangles, self.window, self.k = triangles, window, k
        self.cam = window.intrinsics(k[0, 0], k[1, 1], k[0, 2], k[1, 2])
        q = np.clip(window.crop(query), 0.0, 1.0)
        if ignore is not None and ignore.any():
            self.valid = window.crop(ignore) < 0.5
        else:
            self.valid = np.ones(q.shape, bool)
        self.weights = np.ascontiguousarray(np.where(self.valid, q, 0.0), dtype=np.float64)
        self.q_total = float(self.weights.sum())
        self.evaluations = 0
        self.factor = float(window.factor)
        self.camera = np.array([float(x) for x in self.cam], dtype=np.float64)

    def pose(self, p: NDArray[np.float64], base: tuple[NDArray[np.float64], float, float, float]
             ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        r_rel, u0, w0, z0 = base
        return _pose_of(p, r_rel, u0, w0, z0, self.factor, self.k)

    def iou_at(self, p: NDArray[np.float64], base: tuple[NDArray[np.float64], float, float, float]) -> float:
        """:meth:`iou` of :meth:`pose` ``(p, base)``, the pose made and its silhouette
        counted in one compiled call (:func:`_evaluate`, as the compiled search makes each
        step: a pose behind the camera scores 0 and is not an evaluation)."""
        r_rel, u0, w0, z0 = base
        t = self.triangles
        value, evaluated = _evaluate(p, r_rel, u0, w0, z0, self.factor, self.k, t.vertices, t.faces,
                                     t.front, self.camera, self.weights, self.valid, self.q_total)
        self.evaluations += evaluated
        return value

    def iou(self, rotation: NDArray[np.float64], translation: NDArray[np.float64]) -> float:
        if not translation[2] > 1e-6:
            return 0.0
        self.evaluations += 1
        inter, covered = overlap(self.triangles, rotation, translation, self.cam, self.weights, self.valid)
        union = self.q_total - inter + covered  # the query, plus what it leaves uncovered
        return inter / union if union > 0 else 0.0

    def search(self, rotation: NDArray[np.float64], translation: NDArray[np.float64],
               min_steps: Sequence[float], start_steps: Sequence[float], max_evaluations: int,
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], float, int]:
        """:func:`_compass` from the pose ``(rotation, translation)``: the pose it ends at,
        its IoU and the evaluations it took (not added to :attr:`evaluations`: a search may
        run on another thread). Compiled whole and without the GIL, so the searches of
        several starts run on as many cores (:func:`_search_all`)."""
        base = _base(rotation, translation, self.k)
        r_rel, u0, w0, z0 = base
        steps = np.array([start_steps[0]] * 3 + [start_steps[1]] * 2 + [start_steps[2]], dtype=np.float64)
        floor = np.array([min_steps[0]] * 3 + [min_steps[1]] * 2 + [min_steps[2]], dtype=np.float64)
        t = self.triangles
        p, best, evaluations = _compass(r_rel, u0, w0, z0, self.factor, self.k, t.vertices, t.faces,
                                        t.front, self.camera, self.weights, self.valid, self.q_total,
                                        steps, floor, int(max_evaluations))
        rotation, translation = self.pose(p, base)
        return rotation, translation, best, evaluations


@njit(cache=True, nogil=True)
def _pose_of(p, r_rel, u0, w0, z0, factor, k):  # pragma: no cover - compiled
    """The pose ``(rotation, translation)`` at a pattern search's point ``p`` (rotation
    vector relative to the origin's ray, pixel offset in window pixels, log depth) from
    its ``base`` split ``(r_rel, u0, w0, z0)`` (:func:`_base`)."""
    u = u0 + p[3] / factor
    w = w0 + p[4] / factor
    z = z0 * math.exp(p[5])
    skew = np.zeros((3, 3))
    skew[0, 1], skew[0, 2], skew[1, 0] = -p[2], p[1], p[2]
    skew[1, 2], skew[2, 0], skew[2, 1] = -p[0], -p[1], p[0]
    theta = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    if theta < 1e-8:
        first, second = 1.0, 0.5
    else:
        first, second = math.sin(theta) / theta, (1.0 - math.cos(theta)) / theta**2
    turn = np.eye(3) + first * skew + second * (skew @ skew)  # Rodrigues' formula
    rotation = ray_rotation(u, w, k) @ turn @ r_rel
    translation = np.array([z * ((u - k[0, 2]) / k[0, 0]), z * ((w - k[1, 2]) / k[1, 1]), z])
    return rotation, translation


@njit(cache=True, nogil=True)
def _iou_at(p, r_rel, u0, w0, z0, factor, k, vertices, faces, front, camera, weights, valid,
            q_total):  # pragma: no cover - compiled
    """:meth:`_Objective.pose` then :meth:`_Objective.iou` for a mesh's triangles, in one
    compiled call; −1 for a pose whose origin is not in front of the camera."""
    rotation, translation = _pose_of(p, r_rel, u0, w0, z0, factor, k)
    if not translation[2] > 1e-6:
        return -1.0
    inter, covered = overlap_kernel(vertices, faces, front, rotation, translation, camera, 1e-3,
                                    weights, valid)
    union = q_total - inter + covered
    return inter / union if union > 0 else 0.0


def _base(rotation: NDArray[np.float64], translation: NDArray[np.float64], k: NDArray[np.float64]
          ) -> tuple[NDArray[np.float64], float, float, float]:
    """Split a pinhole pose into (rotation relative to the origin's ray, pixel, depth)."""
    t = np.asarray(translation, dtype=np.float64)
    u = k[0, 0] * t[0] / t[2] + k[0, 2]
    w = k[1, 1] * t[1] / t[2] + k[1, 2]
    return ray_rotation(u, w, k).T @ rotation, u, w, float(t[2])


@njit(cache=True, nogil=True)
def _evaluate(p, r_rel, u0, w0, z0, factor, k, vertices, faces, front, camera, weights, valid,
              q_total):  # pragma: no cover - compiled
    """``(IoU, 1)`` at ``p``, or ``(0, 0)`` behind the camera (not an evaluation)."""
    value = _iou_at(p, r_rel, u0, w0, z0, factor, k, vertices, faces, front, camera, weights, valid,
                    q_total)
    return (0.0, 0) if value < 0.0 else (value, 1)


@njit(cache=True, nogil=True)
def _compass(r_rel, u0, w0, z0, factor, k, vertices, faces, front, camera, weights, valid, q_total,
             steps, floor, max_evaluations):  # pragma: no cover - compiled
    """Compass search over ``p`` = (ω, pixel, log depth) from 0, maximising the IoU
    (:func:`_iou_at`): each coordinate is tried a step either way; a step that improves is
    taken again along the same direction; steps halve when none improves, until all are
    below ``floor`` or ``max_evaluations`` are spent. Returns ``(p, IoU, evaluations)``."""
    p = np.zeros(6)
    best, evaluations = _evaluate(p, r_rel, u0, w0, z0, factor, k, vertices, faces, front, camera,
                                  weights, valid, q_total)
    steps = steps.copy()
    while evaluations < max_evaluations:
        improved = False
        for i in range(6):
            if steps[i] < floor[i]:
                continue
            for sign in (1.0, -1.0):
                trial = p.copy()
                trial[i] += sign * steps[i]
                value, n = _evaluate(trial, r_rel, u0, w0, z0, factor, k, vertices, faces, front,
                                     camera, weights, valid, q_total)
                evaluations += n
                if value > best + 1e-6:
                    p, best, improved = trial, value, True
                    while evaluations < max_evaluations:  # keep going that way
                        trial = p.copy()
                        trial[i] += sign * steps[i]
                        value, n = _evaluate(trial, r_rel, u0, w0, z0, factor, k, vertices, faces,
                                             front, camera, weights, valid, q_total)
                        evaluations += n
                        if not value > best + 1e-6:
                            break
                        p, best = trial, value
                    break
        if not improved:
            if np.all(steps < floor):
                break
            steps = steps / 2.0
            if np.all(steps < floor):
                break
    return p, best, evaluations


def _search_all(
    objective: _Objective, starts: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]],
    min_steps: Sequence[float], start_steps: Sequence[float], max_evaluations: int, threads: int,
) -> list[tuple[NDArray[np.float64], NDArray[np.float64], float]]:
    """:meth:`_Objective.search` from each start, in order, on up to ``threads`` threads
    (the searches are independent and compiled without the GIL); their evaluations are
    added to the objective's."""
    def one(start: tuple[NDArray[np.float64], NDArray[np.float64]]):
        return objective.search(start[0], start[1], min_steps, start_steps, max_evaluations)

    found = _map(one, starts, threads)
    objective.evaluations += sum(n for *_, n in found)
    return [(r, t, iou) for r, t, iou, _ in found]


_T = TypeVar("_T")
_R = TypeVar("_R")


def _map(function: Callable[[_T], _R], items: Sequence[_T], threads: int) -> list[_R]:
    """``[function(item) for item in items]``, in order, on up to ``threads`` threads (at
    most the machine's CPUs)."""
    threads = min(threads, os.cpu_count() or 1, len(items))
    if threads > 1:
        # what a fit hands the pool reads nothing shared, no catalogue, and maps nothing again
        return list(thread_pool("viewdb-fit", threads).map(function, items))
    return [function(item) for item in items]


@dataclass(frozen=True)
class _Start:
    cost: float
    azimuth: float
    elevation: float
    inplane: float
    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]


def search_silhouette_pose(
    query: NDArray[np.bool_],
    intrinsics: Intrinsics,
    render_ortho: OrthoRender,
    triangles: MeshTriangles,
    image_size: int,
    xmag: float = 1.0,
    *,
    ignore: NDArray[np.bool_] | None = None,
    directions: Sequence[tuple[float, float]] | None = None,
    starts: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]] = (),
    config: PoseConfig | None = None,
    search: SilhouetteConfig | None = None,
    coarse_triangles: MeshTriangles | None = None,
    texture: Callable[[NDArray[np.float64], NDArray[np.float64]], float] | None = None,
) -> SilhouetteFit:
    """The pinhole pose of a mesh whose silhouette is ``query`` (module doc).

    ``render_ortho(h, v)`` renders the mesh's orthographic silhouette (``image_size``
    square, half-extent ``xmag``) in the viewdb convention; ``triangles`` are the mesh's
    (:class:`~viewdb.catalogue.coverage.MeshTriangles`), whose silhouette through the
    intrinsics is scan-converted and compared in one compiled pass. ``starts`` adds
    pinhole poses to refine (e.g. from SIFT). ``coarse_triangles`` (default
    ``triangles``) serve the coarse refinement, e.g. a decimated mesh's
    (:attr:`~viewdb.config.SilhouetteConfig.coarse_faces`). The views' outlines are aligned
    and the starts refined on up to :attr:`~viewdb.config.SilhouetteConfig.threads`
    threads; the answer does not depend on how many. ``texture(R, t)`` (e.g. a
    :class:`~viewdb.pose.texture_fit.TextureScore`, in ``[0, 1]``) scores how well a pose
    explains the photo inside the object: the refined hypotheses are then ranked, and the
    answer chosen, by IoU + :attr:`~viewdb.config.SilhouetteConfig.texture_weight` × it.

    Raises
    ------
    PoseError
        An empty query or no direction with a silhouette.
    """
    config = config or PoseConfig()
    search = search or SilhouetteConfig()
    mask = np.asarray(query, dtype=bool)
    if not mask.any():
        raise PoseError("the query mask is empty: no object to estimate a pose for")
    fx, fy, cx, cy = (float(x) for x in intrinsics)
    k = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    try:
        outline = outline_of(mask, config.contour_samples)
    except FeatureError as exc:
        raise PoseError(f"the query silhouette has no usable contour: {exc}") from exc
    empty = np.zeros((0, 5), np.float32)

    def aligned(view: tuple[float, float, NDArray[np.bool_]]) -> list[_Start]:
        h, v, silhouette = view
        try:
            view_outline = outline_of(silhouette, config.contour_samples)
        except FeatureError:
            return []
        cand = CandidateView(h, v, False, empty, np.zeros((0, 128), np.uint8), np.zeros((0, 3), np.float32),
                             silhouette, image_size, xmag)
        return [_Start(res.cost, h, v, res.angle,
                       *lift_alignment(h, v, res.angle, res.lam, res.origin_px, image_size, xmag, k))
                for res in align_shape(outline, view_outline, cand, config)[:2]]

    # the silhouettes read here (a catalogue is one thread's), aligned on the threads (the
    # distance maps and the chamfer scans release the GIL)
    views = [(h, v, render_ortho(h, v))
             for h, v in (directions if directions is not None else fibonacci_directions(search.directions))]
    found = [start for starts_of_view in _map(aligned, views, search.threads) for start in starts_of_view]
    if not found and not starts:
        raise PoseError("no viewing direction gives a silhouette to align the query with")
    found.sort(key=lambda s: s.cost)
    chosen = [(s.rotation, s.translation, (s.azimuth, s.elevation, s.inplane))
              for s in found[:search.coarse_starts]]
    chosen += [(np.asarray(r, np.float64), np.asarray(t, np.float64), (math.nan,) * 3) for r, t in starts]
    window = Window.around(mask, search.coarse_size)
    coarse = _Objective(coarse_triangles or triangles, mask, ignore, window, k)
    found_coarse = _search_all(coarse, [(rot, t) for rot, t, _ in chosen], search.coarse_min_steps,
                               search.start_steps, search.max_evaluations, search.threads)
    inside = texture if search.texture_weight > 0 else None

    def score(iou: float, rot: NDArray[np.float64], t: NDArray[np.float64]) -> float:
        return iou if inside is None else iou + search.texture_weight * inside(rot, t)

    refined = [(score(iou, r2, t2), iou, r2, t2, origin)
               for (r2, t2, iou), (_, _, origin) in zip(found_coarse, chosen, strict=True)]
    refined.sort(key=lambda x: -x[0])
    if search.fine_starts == 0:
        _, iou, rot, t, origin = refined[0]
        return SilhouetteFit(rot, t, iou, origin, coarse.evaluations + len(found))
    fine = _Objective(triangles, mask, ignore, Window.around(mask, search.fine_size), k)
    starts_fine = [(rot, t) for _, _, rot, t, _ in refined[:search.fine_starts]]
    found_fine = _search_all(fine, starts_fine, search.fine_min_steps, search.coarse_min_steps,
                             search.max_evaluations, search.threads)
    fits = [(score(iou, r2, t2), SilhouetteFit(r2, t2, iou, origin, 0))
            for (r2, t2, iou), (*_, origin) in zip(found_fine, refined[:search.fine_starts], strict=True)]
    best = max(fits, key=lambda fit: fit[0])[1]  # the first of equals, as the coarse order has it
    return replace(best, renders=coarse.evaluations + fine.evaluations + len(found))
