"""Posing a recognised match from the catalogue that holds its mesh.

For a match (an object and its best view) the candidate same-shape poses of the matched
view (the paper's eqs. 1–2), and those of the object's next nearest views by the query
curve, are fetched or regenerated from the mesh (:class:`~viewdb.catalogue.reading.CatalogueReader`),
and :func:`viewdb.pose.estimate.estimate_pose` picks the pose by SIFT (ratio test +
RANSAC, then a full 6-DoF fit) or, for texture-less views, by comparing outlines
(``method: "shape"``). A shape pose is then refined: without intrinsics by walking the
viewing direction off the grid (:func:`refine_shape`), with intrinsics by the perspective
silhouette fit (:func:`viewdb.pose.silhouette.search_silhouette_pose`).

:func:`pose_matches` is what a server does for a ``pose`` request; with ``rerank`` it also
fits every match's perspective silhouette so the caller can rank them by IoU.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from ..catalogue.pinhole import get_pinhole_renderer
from ..catalogue.reading import CandidatePose, CatalogueReader
from ..catalogue.render import get_renderer
from ..config import PosingConfig, SilhouetteConfig
from ..errors import QueryError, ViewDBError
from ..search.plans import Candidate
from .estimate import CandidateView, PoseConfig, PoseEstimate, QueryView, estimate_pose
from .frames import GL_TO_CV, inplane_angle, rotation_to_view
from .intrinsics import Intrinsics
from .silhouette import QUICK, search_silhouette_pose, to_mesh_units

__all__ = ["in_mesh_units", "pose_known", "pose_match", "pose_matches", "pose_silhouette", "refine_shape"]

#: A pose start: rotation and translation (normalised units).
Start = tuple[NDArray[np.float64], NDArray[np.float64]]

POSING = PosingConfig()


def _candidate_poses(
    catalogue: CatalogueReader, match: Candidate, curve: NDArray[np.float64] | None, posing: PosingConfig,
) -> list[CandidatePose]:
    """The matched view's same-shape poses (the matched view first), then those of the
    object's nearest views by ``curve``."""
    poses = catalogue.candidate_poses(match.object, match.azimuth, match.elevation)
    poses.sort(key=lambda p: (p.azimuth, p.elevation) != (match.azimuth, match.elevation))
    if curve is not None:
        seen = {(p.azimuth, p.elevation) for p in poses}
        for h, v, _ in catalogue.nearest_views(match.object, curve, posing.near_views):
            for p in catalogue.candidate_poses(match.object, h, v):
                if (p.azimuth, p.elevation) not in seen:
                    seen.add((p.azimuth, p.elevation))
                    poses.append(p)
    return poses[:posing.max_candidates]


def _candidate_view(catalogue: CatalogueReader, name: str, azimuth: float, elevation: float,
                    mirrored: bool, *, features: bool = True) -> CandidateView:
    """A view as :func:`estimate_pose` compares it: its SIFT features and its render."""
    config = catalogue.config
    rendered = catalogue.render(name, azimuth, elevation)
    if features:
        view = catalogue.view(name, azimuth, elevation)
        keypoints, descriptors, points3d = view.keypoints, view.descriptors, view.points3d
    else:
        keypoints = np.zeros((0, 5), np.float32)
        descriptors = np.zeros((0, 128), np.uint8)
        points3d = np.zeros((0, 3), np.float32)
    return CandidateView(
        azimuth=azimuth % 360.0, elevation=elevation % 360.0, mirrored=mirrored,
        keypoints=keypoints, descriptors=descriptors, points3d=points3d, mask=rendered.mask,
        image_size=config.render.image_size, xmag=config.render.xmag, color=rendered.color,
    )


def pose_match(
    catalogue: CatalogueReader, query: QueryView, match: Candidate, config: PoseConfig,
    intrinsics: Intrinsics | None, search: SilhouetteConfig | None = None,
    starts: Sequence[Start] = (), curve: NDArray[np.float64] | None = None,
    posing: PosingConfig = POSING,
) -> PoseEstimate:
    """The pose of one match (module doc); ``curve``: the query's curve at the in-plane
    turn that matched (adds the nearest views' poses as candidates)."""
    candidates = []
    for p in _candidate_poses(catalogue, match, curve, posing):
        try:
            candidates.append(_candidate_view(catalogue, match.object, p.azimuth, p.elevation, p.mirrored))
        except ViewDBError:
            continue  # e.g. no silhouette at that view
    estimate = estimate_pose(query, candidates, config, intrinsics)
    if intrinsics is not None:
        if estimate.method == "shape":
            estimate = pose_silhouette(catalogue, match.object, query, config, intrinsics, search,
                                       [(estimate.rotation, estimate.translation), *starts],
                                       estimate.candidate, posing)
        return in_mesh_units(catalogue, match.object, estimate)
    if estimate.method == "shape":
        estimate = refine_shape(catalogue, match.object, query, candidates[estimate.candidate], estimate,
                                config, posing)
    return estimate


def pose_silhouette(
    catalogue: CatalogueReader, name: str, query: QueryView, config: PoseConfig,
    intrinsics: Intrinsics, search: SilhouetteConfig | None, starts: Sequence[Start],
    candidate: int = 0, posing: PosingConfig = POSING,
) -> PoseEstimate:
    """Texture-less object, calibrated camera: the pinhole pose whose rendered silhouette
    fits the query's best (:func:`viewdb.pose.silhouette.search_silhouette_pose`), started
    from evenly spread viewing directions and from ``starts``; normalised units."""
    mesh = catalogue.mesh(name)
    size = posing.silhouette_search_size
    ortho = get_renderer(replace(catalogue.config.render, image_size=size))
    pinhole = get_pinhole_renderer()
    fit = search_silhouette_pose(
        query.mask, intrinsics,
        lambda h, v: ortho.render(mesh, h, v, shaded=False).mask,
        lambda r, t, k, s: pinhole.render(mesh, r, t, k, s)[0],
        size, catalogue.config.render.xmag, ignore=query.ignore,
        starts=starts, config=config, search=search,
    )
    h, v, a = rotation_to_view(GL_TO_CV @ fit.rotation)
    width = query.mask.shape[1]
    scale = 2.0 * intrinsics[0] / (width * float(fit.translation[2]))
    return PoseEstimate(h, v, a, scale, fit.rotation, fit.translation, "shape", 0, candidate,
                        "opencv", fit.iou, refined="silhouette", iou=fit.iou)


def in_mesh_units(catalogue: CatalogueReader, name: str, estimate: PoseEstimate) -> PoseEstimate:
    """A pinhole pose in the mesh file's own frame and units (``t = scale·t_n − R·centre``)."""
    info = catalogue.object(name)
    t = to_mesh_units(estimate.rotation, estimate.translation, info.centre, info.scale)
    return replace(estimate, translation=t, units="mesh")


def refine_shape(
    catalogue: CatalogueReader, name: str, query: QueryView, start: CandidateView,
    estimate: PoseEstimate, config: PoseConfig, posing: PosingConfig = POSING,
) -> PoseEstimate:
    """Texture-less objects: walk the viewing direction off the grid, rendering the mesh
    around the best outline match (steps halving from half the grid gap down to
    :attr:`~viewdb.config.PosingConfig.shape_refine_step`) and keeping whichever outline
    fits the query best."""
    h, v, best = start.azimuth, start.elevation, estimate
    step = catalogue.config.gap / 2.0
    while step >= posing.shape_refine_step - 1e-9:
        around = []
        for dh in (-step, 0.0, step):
            for dv in (-step, 0.0, step):
                if dh or dv:
                    view = _candidate_view(catalogue, name, h + dh, v + dv, False, features=False)
                    if view.mask.any():
                        around.append(view)
        if around:
            found = estimate_pose(query, around, config, None,
                                  inplane_near=inplane_angle(best.rotation, h, v))
            if found.score > best.score:
                best, h, v = found, around[found.candidate].azimuth, around[found.candidate].elevation
                continue  # moved: try the same step around the new view
        step /= 2.0
    return best


def _iou(estimate: PoseEstimate | None) -> float:
    return estimate.iou if estimate is not None and estimate.iou is not None else -1.0


def _refit_best(
    catalogue: CatalogueReader, query: QueryView, matches: Sequence[Candidate],
    out: list[tuple[PoseEstimate | None, str | None]], config: PoseConfig, intrinsics: Intrinsics,
    posing: PosingConfig,
) -> None:
    """Fit again, with the full silhouette search started from the quick pose, the best
    :attr:`~viewdb.config.PosingConfig.rerank_full` quick fits and the plan's first match
    (a quick fit can miss a thin part, e.g. a handle, and must not demote it alone)."""
    ranked = sorted(range(len(matches)), key=lambda i: (-_iou(out[i][0]), i))
    full = set(ranked[:posing.rerank_full]) | ({0} if matches else set())
    for i in sorted(full, key=ranked.index):
        estimate = out[i][0]
        if estimate is None or estimate.refined != "silhouette":
            continue
        info = catalogue.object(matches[i].object)
        r = estimate.rotation  # the quick pose, back in normalised units, starts the full search
        t_n = (estimate.translation + r @ np.asarray(info.centre)) / info.scale
        try:
            out[i] = (pose_match(catalogue, query, matches[i], config, intrinsics, None, [(r, t_n)],
                                 posing=posing), None)
        except ViewDBError as exc:
            out[i] = (None, exc.message)


def pose_matches(
    catalogue: CatalogueReader, query: QueryView, matches: Sequence[Candidate],
    intrinsics: Intrinsics | None = None, config: PoseConfig | None = None,
    curves: Sequence[NDArray[np.float64] | None] | None = None, *, rerank: bool = False,
    posing: PosingConfig = POSING,
) -> list[tuple[PoseEstimate | None, str | None]]:
    """``(pose, None)`` or ``(None, why not)`` for each match (a server's answer to a
    ``pose`` request). ``curves``: per match, the query's curve at the turn that matched
    (adds its nearest views' poses), or None. ``rerank`` (with intrinsics): every match is
    fitted quickly (:data:`viewdb.pose.silhouette.QUICK`), the best and the first again with
    the full search, so the caller can rank them by the fits' IoU."""
    config = config or PoseConfig()
    samples = catalogue.config.features.curve_samples
    if curves is not None and len(curves) != len(matches):
        raise QueryError(f"got {len(curves)} curves for {len(matches)} matches")
    for curve in curves or ():
        if curve is not None and len(curve) != samples:
            raise QueryError(f"a curve has {len(curve)} samples; this file's curves have {samples}")
    rerank = rerank and intrinsics is not None
    out: list[tuple[PoseEstimate | None, str | None]] = []
    for i, c in enumerate(matches):
        try:
            out.append((pose_match(catalogue, query, c, config, intrinsics, QUICK if rerank else None,
                                   curve=None if curves is None else curves[i], posing=posing), None))
        except ViewDBError as exc:
            out.append((None, exc.message))
    if rerank:
        assert intrinsics is not None
        _refit_best(catalogue, query, matches, out, config, intrinsics, posing)
    return out


def pose_known(
    catalogue: CatalogueReader, query: QueryView, name: str, intrinsics: Intrinsics,
    config: PoseConfig | None = None, posing: PosingConfig = POSING,
) -> PoseEstimate:
    """The pinhole pose of a *known* object ``name`` from the query's silhouette alone (no
    recognition): OpenCV frame, the mesh's own units."""
    catalogue.object(name)  # NotFound for an unknown name
    estimate = pose_silhouette(catalogue, name, query, config or PoseConfig(), intrinsics, None, (),
                               0, posing)
    return in_mesh_units(catalogue, name, estimate)
