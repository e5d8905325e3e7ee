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

import cv2
import numpy as np
from numpy.typing import NDArray

from ..camera import normalise_angle
from ..catalogue.appearance import carries_colour, margin_pixels
from ..catalogue.pinhole import get_pinhole_renderer
from ..catalogue.reading import CandidatePose, CatalogueReader
from ..config import MatchedPoseConfig, SilhouetteConfig
from ..errors import QueryError, ViewDBError
from ..search.plans import Candidate
from .depth_distance import distance_from_depth
from .estimate import CandidateView, PoseConfig, PoseEstimate, QueryView, estimate_pose, sift_estimate
from .frames import GL_TO_CV, inplane_angle, rodrigues, rotation_to_view
from .intrinsics import Intrinsics
from .silhouette import QUICK, fibonacci_directions, search_silhouette_pose, to_mesh_units
from .texture_fit import TextureScore

__all__ = [
    "appearance_view", "grid_directions", "grid_silhouette", "in_mesh_units", "interpolate_shape",
    "pose_known", "pose_match", "pose_matches", "pose_silhouette", "refine_shape", "stored_edges_usable",
    "walk_shape",
]

#: A pose start: rotation and translation (normalised units).
Start = tuple[NDArray[np.float64], NDArray[np.float64]]

POSING = MatchedPoseConfig()


def _candidate_poses(
    catalogue: CatalogueReader, match: Candidate, curve: NDArray[np.float64] | None,
    posing: MatchedPoseConfig,
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


def stored_edges_usable(catalogue: CatalogueReader, config: PoseConfig) -> bool:
    """Whether the stored appearance's internal edges are those ``config`` asks for: the
    same Canny thresholds, and a margin no narrower (a wider one leaves some out)."""
    stored, size = catalogue.config.appearance, catalogue.config.render.image_size
    return (tuple(config.edge_thresholds) == tuple(stored.edge_thresholds)
            and margin_pixels(config.edge_margin, size) >= margin_pixels(stored.edge_margin, size))


def appearance_view(
    catalogue: CatalogueReader, name: str, azimuth: float, elevation: float, config: PoseConfig,
    *, mirrored: bool = False, features: bool = False,
) -> CandidateView:
    """A view as :func:`estimate_pose` compares it: its silhouette and internal edges from
    its appearance (stored, or made from its render:
    :meth:`~viewdb.catalogue.reading.CatalogueReader.appearance`), or its render when
    ``config`` asks for other edges than the stored ones; with ``features`` its SIFT
    features too."""
    render = catalogue.config.render
    stored = catalogue.appearance(name, azimuth, elevation)
    color = (None if stored_edges_usable(catalogue, config)
             else catalogue.render(name, azimuth, elevation).color)
    if features:
        view = catalogue.view(name, azimuth, elevation)
        keypoints, descriptors, points3d = view.keypoints, view.descriptors, view.points3d
    else:
        keypoints = np.zeros((0, 5), np.float32)
        descriptors = np.zeros((0, 128), np.uint8)
        points3d = np.zeros((0, 3), np.float32)
    return CandidateView(
        azimuth=azimuth % 360.0, elevation=elevation % 360.0, mirrored=mirrored,
        keypoints=keypoints, descriptors=descriptors, points3d=points3d, mask=stored.mask,
        image_size=render.image_size, xmag=render.xmag, color=color,
        appearance=stored if color is None else None,
    )


def _sift_first(
    catalogue: CatalogueReader, name: str, query: QueryView, candidates: list[CandidateView],
    pruned: list[int], config: PoseConfig, intrinsics: Intrinsics | None,
) -> PoseEstimate:
    """:func:`estimate_pose` over ``candidates``, the SIFT features of the ``pruned`` ones
    (not stored: regenerated from a render) fetched only when the stored ones give no SIFT
    pose."""
    found = sift_estimate(query, candidates, config, intrinsics)
    if found is not None:
        return found
    regenerated = False
    for i in pruned:
        try:
            view = catalogue.view(name, candidates[i].azimuth, candidates[i].elevation)
        except ViewDBError:
            continue
        candidates[i] = replace(candidates[i], keypoints=view.keypoints, descriptors=view.descriptors,
                                points3d=view.points3d)
        regenerated = True
    if not regenerated:  # the same SIFT would fail again: the silhouettes decide
        candidates = [replace(c, descriptors=np.zeros((0, 128), np.uint8)) for c in candidates]
    return estimate_pose(query, candidates, config, intrinsics)


def pose_match(
    catalogue: CatalogueReader, query: QueryView, match: Candidate, config: PoseConfig,
    intrinsics: Intrinsics | None, search: SilhouetteConfig | None = None,
    starts: Sequence[Start] = (), curve: NDArray[np.float64] | None = None,
    posing: MatchedPoseConfig = POSING, *, sift: bool = True,
) -> PoseEstimate:
    """The pose of one match (module doc); ``curve``: the query's curve at the in-plane
    turn that matched (adds the nearest views' poses as candidates). Without ``sift`` the
    candidates are compared by their outlines alone (their SIFT features not read); with
    intrinsics and a ``search`` started from the candidates
    (:attr:`~viewdb.config.SilhouetteConfig.start_directions`), the silhouette fit aligns
    their stored silhouettes itself (no outline pose, no render of a view the file does
    not store)."""
    poses = _candidate_poses(catalogue, match, curve, posing)
    if intrinsics is not None and not sift and search is not None and search.start_directions == "candidates":
        directions = list(dict.fromkeys((p.azimuth % 360.0, p.elevation % 360.0) for p in poses))
        estimate = pose_silhouette(catalogue, match.object, query, config, intrinsics, search, starts,
                                   posing=posing, directions=directions)
        return in_mesh_units(catalogue, match.object, estimate, query, intrinsics)
    candidates, pruned = [], []
    for p in poses:
        try:
            candidates.append(appearance_view(catalogue, match.object, p.azimuth, p.elevation, config,
                                              mirrored=p.mirrored, features=p.stored and sift))
        except ViewDBError:
            continue  # e.g. no silhouette at that view
        if not p.stored:
            pruned.append(len(candidates) - 1)
    estimate = _sift_first(catalogue, match.object, query, candidates,
                           pruned if posing.regenerate == "always" else [], config, intrinsics)
    if intrinsics is not None:
        if estimate.method == "shape":
            estimate = pose_silhouette(catalogue, match.object, query, config, intrinsics, search,
                                       [(estimate.rotation, estimate.translation), *starts],
                                       estimate.candidate, posing)
        return in_mesh_units(catalogue, match.object, estimate, query, intrinsics)
    if estimate.method == "shape":
        estimate = refine_shape(catalogue, match.object, query, candidates[estimate.candidate], estimate,
                                config, posing)
    return estimate


def pose_silhouette(
    catalogue: CatalogueReader, name: str, query: QueryView, config: PoseConfig,
    intrinsics: Intrinsics, search: SilhouetteConfig | None, starts: Sequence[Start],
    candidate: int = 0, posing: MatchedPoseConfig = POSING,
    directions: Sequence[tuple[float, float]] | None = None,
) -> PoseEstimate:
    """Texture-less object, calibrated camera: the pinhole pose whose rendered silhouette
    fits the query's best (:func:`viewdb.pose.silhouette.search_silhouette_pose`; for a
    mesh with colour of its own, with the photo inside it: :mod:`viewdb.pose.texture_fit`), started
    from the grid views ``directions`` (default: those nearest evenly spread viewing
    directions; their silhouettes from the stored appearance: :func:`grid_silhouette`)
    and from ``starts``; normalised units."""
    mesh = catalogue.mesh(name)
    pinhole = get_pinhole_renderer()
    render = catalogue.config.render
    search = search or SilhouetteConfig()
    if directions is None:
        directions = grid_directions(catalogue.config.gap, search.directions)
    scored = search.texture_weight > 0 and np.asarray(query.mask).any() and carries_colour(mesh)
    texture = TextureScore(mesh, query, intrinsics, search.texture_size) if scored else None
    fit = search_silhouette_pose(
        query.mask, intrinsics, lambda h, v: grid_silhouette(catalogue, name, h, v),
        pinhole.triangles(mesh),
        render.image_size, render.xmag, ignore=query.ignore,
        directions=directions,
        starts=starts, config=config, search=search,
        coarse_triangles=pinhole.triangles(mesh, search.coarse_faces or None),
        texture=texture,
    )
    h, v, a = rotation_to_view(GL_TO_CV @ fit.rotation)
    width = query.mask.shape[1]
    scale = 2.0 * intrinsics[0] / (width * float(fit.translation[2]))
    return PoseEstimate(h, v, a, scale, fit.rotation, fit.translation, "shape", 0, candidate,
                        "opencv", fit.iou, refined="silhouette", iou=fit.iou)


def grid_directions(gap: float, n: int) -> list[tuple[float, float]]:
    """The grid views nearest ``n`` evenly spread viewing directions
    (:func:`viewdb.pose.silhouette.fibonacci_directions`), each once."""
    out: dict[tuple[float, float], None] = {}
    for h, v in fibonacci_directions(n):
        out[(normalise_angle(round(h / gap) * gap), normalise_angle(round(v / gap) * gap))] = None
    return list(out)


def grid_silhouette(
    catalogue: CatalogueReader, name: str, azimuth: float, elevation: float
) -> NDArray[np.bool_]:
    """The silhouette of grid view ``(h, v)`` from the stored views' appearance: its own, or
    for a view the skim plan pruned its stand-in's (mirrored left to right if the plan
    says so: the same silhouette, :mod:`viewdb.catalogue.skimming`)."""
    view = (azimuth, elevation)
    stored, mirrored = catalogue.view_plan(name).mapping.get(view, (view, False))
    mask = catalogue.appearance(name, *stored).mask
    return np.ascontiguousarray(mask[:, ::-1]) if mirrored else mask


def in_mesh_units(catalogue: CatalogueReader, name: str, estimate: PoseEstimate,
                  query: QueryView | None = None, intrinsics: Intrinsics | None = None) -> PoseEstimate:
    """A pinhole pose in the mesh file's own frame and units (``t = scale·t_n − R·centre``);
    with a ``query`` that has a depth image (and the ``intrinsics``), first moved to the
    distance the depth measures (:mod:`viewdb.pose.depth_distance`)."""
    info = catalogue.object(name)
    if query is not None and query.depth is not None and intrinsics is not None:
        triangles = get_pinhole_renderer().triangles(catalogue.mesh(name))
        estimate = distance_from_depth(estimate, triangles, query.mask, query.depth / float(info.scale),
                                       intrinsics)
    t = to_mesh_units(estimate.rotation, estimate.translation, info.centre, info.scale)
    return replace(estimate, translation=t, units="mesh")


def refine_shape(
    catalogue: CatalogueReader, name: str, query: QueryView, start: CandidateView,
    estimate: PoseEstimate, config: PoseConfig, posing: MatchedPoseConfig = POSING,
) -> PoseEstimate:
    """Texture-less objects: the viewing direction off the grid, from the fits of the grid
    views around the best outline match (``posing.shape_refine``: ``"interpolate"``, from
    their appearance, :func:`interpolate_shape`; ``"walk"``, rendering off-grid views,
    :func:`walk_shape`; ``"none"``: stay on the grid)."""
    if posing.shape_refine == "walk":
        return walk_shape(catalogue, name, query, start, estimate, config, posing)
    if posing.shape_refine == "none":
        return estimate
    return interpolate_shape(catalogue, name, query, start, estimate, config, posing)


def _fit_at(
    catalogue: CatalogueReader, name: str, query: QueryView, azimuth: float, elevation: float,
    config: PoseConfig, near: float,
) -> PoseEstimate | None:
    """The shape pose at one grid view, in-plane near ``near`` (None: no silhouette)."""
    try:
        view = appearance_view(catalogue, name, azimuth, elevation, config)
        if not view.mask.any():
            return None
        return estimate_pose(query, [view], config, None, inplane_near=near)
    except ViewDBError:
        return None


def _rotation_vector(rotation: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.asarray(cv2.Rodrigues(np.asarray(rotation, np.float64))[0], np.float64).ravel()


def interpolate_shape(
    catalogue: CatalogueReader, name: str, query: QueryView, start: CandidateView,
    estimate: PoseEstimate, config: PoseConfig, posing: MatchedPoseConfig = POSING,
) -> PoseEstimate:
    """Texture-less objects: the viewing direction off the grid without rendering.

    The four grid neighbours ``(h ± gap, v)``, ``(h, v ± gap)`` of the best outline match
    are fitted to the query by their outlines alone (from their appearance, in-plane near
    the match's; the internal edges make the fits of nearby views noisy: measured, the
    direction's mean error 2.4° with them, 2.0° without, 1.4° for the rendering walk, on
    off-grid renders of a texture-less object), and the match moves to a neighbour that
    fits better (at most ``posing.shape_climb`` times). Then along each axis a parabola
    through the costs (1 − score) of the view and its two neighbours puts the minimum at
    most half a gap off the view, and the pose turns that share of the way towards the
    neighbour on that side (rotation vectors, model frame). Scale and translation are the
    view's; the score is the shape pose's at the view reached."""
    gap = catalogue.config.gap
    full, config = config, replace(config, detail_weight=0.0)
    h, v = start.azimuth, start.elevation
    near = inplane_angle(estimate.rotation, h, v)
    centre = _fit_at(catalogue, name, query, h, v, config, near) or estimate
    moved = False
    steps = ((gap, 0.0), (-gap, 0.0), (0.0, gap), (0.0, -gap))
    around: dict[tuple[float, float], PoseEstimate | None] = {}
    for _ in range(posing.shape_climb + 1):
        around = {(dh, dv): _fit_at(catalogue, name, query, h + dh, v + dv, config, near)
                  for dh, dv in steps}
        fitted = [(fit.score, step) for step, fit in around.items() if fit is not None]
        if not fitted or max(fitted)[0] <= centre.score:
            break
        score, (dh, dv) = max(fitted)
        found = around[(dh, dv)]
        assert found is not None
        h, v, centre, moved = h + dh, v + dv, found, True
        near = inplane_angle(centre.rotation, h, v)
    turn = np.zeros(3)
    for plus, minus in (((gap, 0.0), (-gap, 0.0)), ((0.0, gap), (0.0, -gap))):
        up, down = around.get(plus), around.get(minus)
        if up is None or down is None:
            continue
        c_up, c0, c_down = 1.0 - up.score, 1.0 - centre.score, 1.0 - down.score
        curvature = c_up - 2.0 * c0 + c_down
        if curvature <= 0:
            continue
        share = float(np.clip(0.5 * (c_down - c_up) / curvature, -0.5, 0.5))  # of a gap, + towards up
        towards = up if share > 0 else down
        turn += abs(share) * _rotation_vector(centre.rotation.T @ towards.rotation)
    rotation = centre.rotation @ rodrigues(turn)
    azimuth, elevation, inplane = rotation_to_view(rotation)
    # the score as the shape pose gives it (edges included when they are), at the view reached
    scored = (_fit_at(catalogue, name, query, h, v, full, near) if moved else None) or estimate
    return replace(centre, azimuth=azimuth, elevation=elevation, inplane=inplane, rotation=rotation,
                   candidate=estimate.candidate, score=scored.score)


def walk_shape(
    catalogue: CatalogueReader, name: str, query: QueryView, start: CandidateView,
    estimate: PoseEstimate, config: PoseConfig, posing: MatchedPoseConfig = POSING,
) -> PoseEstimate:
    """Texture-less objects: walk the viewing direction off the grid, rendering the mesh
    around the best outline match (steps halving from half the grid gap down to
    :attr:`~viewdb.config.MatchedPoseConfig.shape_refine_step`) and keeping whichever outline
    fits the query best (a render per step: slow)."""
    h, v, best = start.azimuth, start.elevation, estimate
    step = catalogue.config.gap / 2.0
    render = catalogue.config.render
    empty = (np.zeros((0, 5), np.float32), np.zeros((0, 128), np.uint8), np.zeros((0, 3), np.float32))
    while step >= posing.shape_refine_step - 1e-9:
        around = []
        for dh in (-step, 0.0, step):
            for dv in (-step, 0.0, step):
                if dh or dv:
                    rendered = catalogue.render(name, h + dh, v + dv)
                    if rendered.mask.any():
                        around.append(CandidateView((h + dh) % 360.0, (v + dv) % 360.0, False, *empty,
                                                    rendered.mask, render.image_size, render.xmag,
                                                    rendered.color))
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
    posing: MatchedPoseConfig,
) -> None:
    """Fit again, with the full silhouette search started from the quick pose, the best
    :attr:`~viewdb.config.MatchedPoseConfig.rerank_full` quick fits: the matches are ranked by
    their quick fits (every one fitted alike), and those best few again among themselves
    by their full fits, which also sharpen their poses."""
    ranked = sorted(range(len(matches)), key=lambda i: (-_iou(out[i][0]), i))
    for i in ranked[:posing.rerank_full]:
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
    posing: MatchedPoseConfig = POSING,
) -> list[tuple[PoseEstimate | None, str | None]]:
    """``(pose, None)`` or ``(None, why not)`` for each match (a server's answer to a
    ``pose`` request). ``curves``: per match, the query's curve at the turn that matched
    (adds its nearest views' poses), or None. ``rerank`` (with intrinsics): every match is
    fitted quickly (:data:`viewdb.pose.silhouette.QUICK`, started from the alignments of its
    candidate views' outlines: a pose by SIFT would not be fitted, hence not ranked), the
    best again with the full search, so the caller can rank them by the fits' IoU."""
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
                                   curve=None if curves is None else curves[i], posing=posing,
                                   sift=not rerank), None))
        except ViewDBError as exc:
            out.append((None, exc.message))
    if rerank:
        assert intrinsics is not None
        _refit_best(catalogue, query, matches, out, config, intrinsics, posing)
    return out


def pose_known(
    catalogue: CatalogueReader, query: QueryView, name: str, intrinsics: Intrinsics,
    config: PoseConfig | None = None, posing: MatchedPoseConfig = POSING,
) -> PoseEstimate:
    """The pinhole pose of a *known* object ``name`` from the query's silhouette alone (no
    recognition): OpenCV frame, the mesh's own units."""
    catalogue.object(name)  # NotFound for an unknown name
    estimate = pose_silhouette(catalogue, name, query, config or PoseConfig(), intrinsics, None, (),
                               0, posing)
    return in_mesh_units(catalogue, name, estimate, query, intrinsics)
