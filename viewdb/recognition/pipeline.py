"""The query engine: photo → segmentation → distance curves → plan → pose.

A query image is segmented (:mod:`viewdb.recognition.image`); its silhouette's distance curve
starts at the top of the centroid's vertical line, so an object turned *in the image
plane* gives a cyclically shifted curve that the (fixed-start) DTW of the index does not
match. The engine therefore also tries the silhouette turned by a few in-plane angles
(``rotations``, evenly spaced; 1 = upright only) and keeps, per object, the best view over
all of them, remembering the turn that matched. Each turn is one search by the chosen
plan (:meth:`viewdb.ViewDB.recognise`); CS1 stays exact per turn, so CS1 still equals the
``server`` plan.

The plan finds its best :data:`POOL` objects (at least k) when they are re-ranked: a
photo with colour by outline distance times colour mismatch against each one's matched
view (:mod:`viewdb.recognition.colour`), then every photo by how well each one's matched view,
rendered, fits the photo's outline and internal edges (:mod:`viewdb.recognition.verify`); the best
k are kept. Both need the meshes (a full file or a server).

For each of the top results the candidate same-shape poses of the matched view (the
paper's eqs. 1–2) are fetched or regenerated from the mesh, and :mod:`viewdb.pose.estimate` picks
the pose by SIFT (ratio test + RANSAC, then a full 6-DoF fit) or, for texture-less
views, by comparing outlines (``method: "shape"``).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..catalogue.features import distance_curve, sample_bearings
from ..catalogue.pinhole import get_pinhole_renderer
from ..catalogue.render import get_renderer
from ..config import SearchConfig
from ..errors import FeatureError, ImageError, QueryError, ViewDBError
from ..pose.estimate import (
    GL_TO_CV,
    CandidateView,
    PoseConfig,
    PoseEstimate,
    QueryView,
    estimate_pose,
    inplane_angle,
    rotation_to_view,
)
from ..pose.intrinsics import Intrinsics, parse_intrinsics
from ..pose.silhouette import QUICK, SilhouetteConfig, search_silhouette_pose, to_mesh_units
from ..search.plans import Candidate
from ..search.shifts import ShiftWindow, shift_turn, shifted, turn_window
from .colour import colour_signature, has_colour, rerank
from .image import LoadedImage, Segmentation, label_mask, load_image, segment
from .verify import physical_view, rerank_by_fit

if TYPE_CHECKING:
    from ..api import ServerTier, ViewDB
    from .server_tier import Exchange

__all__ = [
    "QueryMatch", "QueryResult", "completed_mask", "pose_matches", "pose_object", "rotated_curves",
    "run_query",
]

#: Most candidate poses examined per result (a sphere has every grid view as one).
MAX_POSE_CANDIDATES = 24


@dataclass(frozen=True)
class QueryMatch:
    """One recognised object: its best view, the in-plane turn that matched, its pose."""

    rank: int
    object: str
    distance: float
    azimuth: float
    elevation: float
    mirrored: bool
    #: The query's silhouette matched the view after turning it back by this angle.
    inplane: float
    pose: PoseEstimate | None = None
    #: Why there is no pose (e.g. a client file without meshes), if there is none.
    pose_error: str | None = None
    #: Colour distance between the photo and the matched view (:mod:`viewdb.recognition.colour`),
    #: None when the results were not re-ranked by colour or the mesh has no colour.
    colour: float | None = None
    #: What the results are ranked by when re-ranked by colour
    #: (:func:`viewdb.recognition.colour.rerank`); None: by ``distance`` alone.
    colour_score: float | None = None
    #: The matched view is a perspective silhouette from this many bounding radii
    #: (:class:`~viewdb.config.PerspectiveConfig`); None: an orthographic view.
    camera_distance: float | None = None
    #: How well the matched view, rendered, fits the photo's shape (:mod:`viewdb.recognition.verify`,
    #: in [0, 1]); None when the results were not verified or the view has no silhouette.
    shape_fit: float | None = None
    #: What the results are ranked by when verified (:func:`viewdb.recognition.verify.rerank_by_fit`).
    verified_score: float | None = None

    @property
    def score(self) -> float:
        """What the results are ranked by: ``distance``, lengthened by the colour
        mismatch when they were re-ranked by colour, and by the shape misfit when they
        were verified."""
        if self.verified_score is not None:
            return self.verified_score
        return self.distance if self.colour_score is None else self.colour_score

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "rank": self.rank, "object": self.object, "distance": self.distance,
            "view": {"azimuth": self.azimuth, "elevation": self.elevation,
                     "mirrored": self.mirrored, "inplane": self.inplane,
                     "camera_distance": self.camera_distance},
            "colour_distance": self.colour, "shape_fit": self.shape_fit, "score": self.score,
            "pose": None,
        }
        p = self.pose
        if p is not None:
            out["pose"] = {
                "azimuth": p.azimuth, "elevation": p.elevation, "inplane": p.inplane,
                "method": p.method, "inliers": int(p.inliers), "scale": p.scale,
                "score": p.score, "frame": p.frame, "units": p.units, "refined": p.refined,
                "iou": p.iou,
                "rotation": [[float(x) for x in row] for row in p.rotation],
                "translation": [float(x) for x in p.translation],
            }
        if self.pose_error is not None:
            out["pose_error"] = self.pose_error
        return out


@dataclass(frozen=True)
class QueryResult:
    """The answer to one query (``to_dict`` is the ``viewdb query --json`` shape)."""

    image: str
    plan: str
    k: int
    results: list[QueryMatch]
    timing_ms: dict[str, float]
    segmentation: str
    #: What went over the (would-be) wire: bytes each way and round trips (CS1/CS2).
    transfer: dict[str, int] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "image": self.image, "plan": self.plan, "k": self.k,
            "results": [r.to_dict() for r in self.results],
            "timing_ms": {k: round(v, 3) for k, v in self.timing_ms.items()},
            "segmentation": self.segmentation, "transfer": dict(self.transfer),
        }


def rotated_curves(
    mask: NDArray[np.bool_], samples: int, rotations: int
) -> list[tuple[float, NDArray[np.float64]]]:
    """``(angle, curve)`` of the silhouette turned back by ``angle`` for ``rotations``
    evenly spaced angles (0 first). A turn that loses the silhouette is skipped."""
    if rotations < 1:
        raise QueryError(f"rotations must be at least 1, got {rotations}")
    ys, xs = np.nonzero(mask)
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
            turned = cv2.warpAffine(canvas, m, (canvas.shape[1], canvas.shape[0]),
                                    flags=cv2.INTER_LINEAR)
        try:
            out.append((angle, distance_curve(turned > 127, samples)))
        except FeatureError:
            continue
    if not out:
        raise ImageError("the silhouette gives no usable contour")
    return out


def _pose_mask(seg: Segmentation, mask: Any, label_map: Any) -> NDArray[np.bool_]:
    """The silhouette the pose is fitted to: a label map's object keeps its holes (the
    space inside a handle), which :func:`segment` fills for the outline's curve."""
    if label_map is None:
        return seg.mask
    return seg.mask & np.asarray(mask, dtype=bool)


#: Re-ranking: results fitted again with the full silhouette search after the quick one.
RERANK_FULL = 1


def _rerank(
    db: ViewDB, query: QueryView, matches: list[QueryMatch], found: dict[str, Candidate],
    config: PoseConfig, camera: tuple[float, float, float, float],
) -> list[QueryMatch]:
    """Sort the results by the IoU of their perspective silhouette fit (module doc)."""
    def iou(m: QueryMatch) -> float:
        return m.pose.iou if m.pose is not None and m.pose.iou is not None else -1.0

    ranked = sorted(matches, key=lambda m: (-iou(m), m.rank))
    # the full search for the best quick fits and for the plan's own first result (a quick
    # fit can miss a thin part, e.g. a handle, and must not demote the right object alone)
    full = {m.object for m in ranked[:RERANK_FULL]} | {m.object for m in matches if m.rank == 1}
    out = []
    for m in ranked:
        if m.object in full and m.pose is not None and m.pose.refined == "silhouette":
            info = db.object(m.object)
            # the quick pose, back in normalised units, starts the full search
            r = m.pose.rotation
            t_n = (m.pose.translation + r @ np.asarray(info.centre)) / info.scale
            try:
                m = replace(m, pose=_pose(db, query, found[m.object], config, camera, None, [(r, t_n)]))
            except ViewDBError as exc:
                m = replace(m, pose=None, pose_error=exc.message)
        out.append(m)
    out.sort(key=lambda m: (-iou(m), m.rank))
    return [replace(m, rank=i) for i, m in enumerate(out, 1)]


def completed_mask(
    mask: NDArray[np.bool_], ignore: NDArray[np.bool_] | None
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
    if filled.sum() < HIDDEN_MIN_SHARE * mask.sum():
        return None
    n, labels = cv2.connectedComponents((mask | filled).astype(np.uint8), connectivity=8)
    keep = labels == np.bincount(labels[mask]).argmax()
    out = mask | (filled & keep)
    return out if out.sum() > mask.sum() else None


#: An occluder's pixels inside the silhouette's convex hull make a completed query shape
#: only when they are at least this share of the silhouette's area.
HIDDEN_MIN_SHARE = 0.02


def _merge(per_turn: Sequence[tuple[float, list[Candidate]]], k: int) -> list[tuple[Candidate, float]]:
    best: dict[str, tuple[Candidate, float]] = {}
    for angle, found in per_turn:
        for c in found:
            if c.object not in best or c.distance < best[c.object][0].distance:
                best[c.object] = (c, angle)
    return sorted(best.values(), key=lambda x: (x[0].distance, x[0].object))[:k]


#: Objects the plan finds (at least k) before the colour and shape re-rankings keep the
#: best k.
POOL = 5


def _by_colour(
    merged: list[tuple[Candidate, float]], query: NDArray[np.float32],
    signatures: Sequence[NDArray[np.float32] | None],
) -> tuple[list[tuple[Candidate, float]], dict[str, tuple[float | None, float]]]:
    """``merged`` re-ranked by colour (:func:`viewdb.recognition.colour.rerank`), and each object's
    colour distance (None: its mesh has no colour) and score."""
    order, colours, scores = rerank([c.distance for c, _ in merged], query, signatures)
    by_object = {c.object: (d, sc) for (c, _), d, sc in zip(merged, colours, scores, strict=True)}
    return [merged[i] for i in order], by_object


def _by_fit(
    merged: list[tuple[Candidate, float]], scores: Sequence[float], fits: Sequence[float | None],
) -> tuple[list[tuple[Candidate, float]], dict[str, tuple[float | None, float]]]:
    """``merged`` re-ranked by shape fit (:func:`viewdb.recognition.verify.rerank_by_fit`) from their
    ``scores``, and each object's fit and verified score."""
    order, verified = rerank_by_fit(scores, fits)
    by_object = {c.object: (f, v) for (c, _), f, v in zip(merged, fits, verified, strict=True)}
    return [merged[i] for i in order], by_object


#: Besides the matched view's same-shape poses, those of the object's next nearest views
#: (by the query curve) are candidates too: a silhouette often matches several sides of
#: an object about equally, and SIFT can tell them apart.
NEAR_VIEWS = 4


def _pose(
    db: ViewDB, query: QueryView, match: Candidate, config: PoseConfig,
    intrinsics: tuple[float, float, float, float] | None, search: SilhouetteConfig | None = None,
    starts: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]] = (),
    curve: NDArray[np.float64] | None = None,
) -> PoseEstimate:
    poses = db.candidate_poses(match.object, match.azimuth, match.elevation)
    # the matched view first, then the rest in their (deterministic) order
    poses.sort(key=lambda p: (p.azimuth, p.elevation) != (match.azimuth, match.elevation))
    if curve is not None:
        seen = {(p.azimuth, p.elevation) for p in poses}
        for h, v, _ in db.nearest_views(match.object, curve, NEAR_VIEWS):
            for p in db.candidate_poses(match.object, h, v):
                if (p.azimuth, p.elevation) not in seen:
                    seen.add((p.azimuth, p.elevation))
                    poses.append(p)
    candidates = []
    for p in poses[:MAX_POSE_CANDIDATES]:
        try:
            view = db.view(match.object, p.azimuth, p.elevation)
            rendered = db.render(match.object, p.azimuth, p.elevation)
        except ViewDBError:
            continue  # e.g. no silhouette at that view
        candidates.append(CandidateView(
            azimuth=p.azimuth, elevation=p.elevation, mirrored=p.mirrored,
            keypoints=view.keypoints, descriptors=view.descriptors, points3d=view.points3d,
            mask=rendered.mask, image_size=db.config.render.image_size, xmag=db.config.render.xmag,
            color=rendered.color,
        ))
    estimate = estimate_pose(query, candidates, config, intrinsics)
    if intrinsics is not None:
        if estimate.method == "shape":
            estimate = _fit_silhouette(db, match.object, query, estimate, config, intrinsics, search,
                                       starts)
        return _in_mesh_units(db, match.object, estimate)
    if estimate.method == "shape":
        estimate = _refine_shape(db, match.object, query, candidates[estimate.candidate], estimate,
                                 config, intrinsics)
    return estimate


#: Image size of the orthographic silhouettes the perspective silhouette search aligns.
SILHOUETTE_SEARCH_SIZE = 128


def _fit_silhouette(
    db: ViewDB, name: str, query: QueryView, estimate: PoseEstimate, config: PoseConfig,
    intrinsics: tuple[float, float, float, float], search: SilhouetteConfig | None = None,
    starts: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]] = (),
) -> PoseEstimate:
    """Texture-less object, calibrated camera: the pinhole pose whose rendered silhouette
    fits the query's best (:func:`viewdb.pose.silhouette.search_silhouette_pose`), started
    from evenly spread viewing directions and from the outline estimate."""
    return _silhouette_estimate(db, name, query, config, intrinsics, search,
                                [(estimate.rotation, estimate.translation), *starts], estimate.candidate)


def _silhouette_estimate(
    db: ViewDB, name: str, query: QueryView, config: PoseConfig,
    intrinsics: tuple[float, float, float, float], search: SilhouetteConfig | None,
    starts: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]], candidate: int = 0,
) -> PoseEstimate:
    mesh = db.mesh(name)
    ortho = get_renderer(replace(db.config.render, image_size=SILHOUETTE_SEARCH_SIZE))
    pinhole = get_pinhole_renderer()
    fit = search_silhouette_pose(
        query.mask, intrinsics,
        lambda h, v: ortho.render(mesh, h, v, shaded=False).mask,
        lambda r, t, k, size: pinhole.render(mesh, r, t, k, size)[0],
        SILHOUETTE_SEARCH_SIZE, db.config.render.xmag, ignore=query.ignore,
        starts=starts, config=config, search=search,
    )
    h, v, a = rotation_to_view(GL_TO_CV @ fit.rotation)
    width = query.mask.shape[1]
    scale = 2.0 * intrinsics[0] / (width * float(fit.translation[2]))
    return PoseEstimate(h, v, a, scale, fit.rotation, fit.translation, "shape", 0, candidate,
                        "opencv", fit.iou, refined="silhouette", iou=fit.iou)


def pose_object(
    db: ViewDB,
    image: str | Path | NDArray[Any] | LoadedImage,
    name: str,
    intrinsics: Intrinsics | str | Path | Sequence[Any],
    *,
    mask: NDArray[Any] | str | Path | None = None,
    label_map: NDArray[Any] | str | Path | None = None,
    label: int | None = None,
    pose_config: PoseConfig | None = None,
) -> PoseEstimate:
    """The pinhole pose of a *known* object ``name`` in a calibrated photo, from its
    silhouette (no recognition): OpenCV frame, the mesh's own units."""
    if (label_map is None) != (label is None):
        raise QueryError("a label map and a label go together: give both or neither")
    if label_map is not None and mask is not None:
        raise QueryError("give either a mask or a label map, not both")
    camera = parse_intrinsics(intrinsics)
    db.object(name)  # NotFound for an unknown name
    loaded = image if isinstance(image, LoadedImage) else load_image(image)
    ignore = None
    if label_map is not None:
        assert label is not None
        mask, ignore = label_mask(label_map, label, loaded)
    seg = segment(loaded, mask)
    query = QueryView(loaded.rgb, _pose_mask(seg, mask, label_map), ignore)
    estimate = _silhouette_estimate(db, name, query, pose_config or PoseConfig(), camera, None, ())
    return _in_mesh_units(db, name, estimate)


def _in_mesh_units(db: ViewDB, name: str, estimate: PoseEstimate) -> PoseEstimate:
    """A pinhole pose in the mesh file's own frame and units (``t = scale·t_n − R·centre``)."""
    info = db.object(name)
    t = to_mesh_units(estimate.rotation, estimate.translation, info.centre, info.scale)
    return replace(estimate, translation=t, units="mesh")


#: The off-grid shape refinement stops at this step (degrees).
SHAPE_REFINE_STEP = 2.0


def _refine_shape(
    db: ViewDB, name: str, query: QueryView, start: CandidateView, estimate: PoseEstimate,
    config: PoseConfig, intrinsics: tuple[float, float, float, float] | None,
) -> PoseEstimate:
    """Texture-less objects: walk the viewing direction off the grid, rendering the mesh
    around the best outline match (steps halving from half the grid gap down to
    :data:`SHAPE_REFINE_STEP`) and keeping whichever outline fits the query best."""
    h, v, best = start.azimuth, start.elevation, estimate
    step = db.config.gap / 2.0
    size, xmag = db.config.render.image_size, db.config.render.xmag
    while step >= SHAPE_REFINE_STEP - 1e-9:
        around = []
        for dh in (-step, 0.0, step):
            for dv in (-step, 0.0, step):
                if not (dh or dv):
                    continue
                rendered = db.render(name, h + dh, v + dv)
                mask = rendered.mask
                if mask.any():
                    around.append(CandidateView(
                        azimuth=(h + dh) % 360.0, elevation=(v + dv) % 360.0, mirrored=False,
                        keypoints=np.zeros((0, 5), np.float32), descriptors=np.zeros((0, 128), np.uint8),
                        points3d=np.zeros((0, 3), np.float32), mask=mask, image_size=size, xmag=xmag,
                        color=rendered.color))
        if around:
            found = estimate_pose(query, around, config, intrinsics,
                                  inplane_near=inplane_angle(best.rotation, h, v))
            if found.score > best.score:
                best, h, v = found, around[found.candidate].azimuth, around[found.candidate].elevation
                continue  # moved: try the same step around the new view
        step /= 2.0
    return best


def pose_matches(
    db: ViewDB, query: QueryView, matches: Sequence[Candidate],
    intrinsics: tuple[float, float, float, float] | None = None, config: PoseConfig | None = None,
    curves: Sequence[NDArray[np.float64] | None] | None = None,
) -> list[tuple[PoseEstimate | None, str | None]]:
    """``(pose, None)`` or ``(None, why not)`` for each match, from the full file ``db``
    (what a server does for a remote client's ``pose`` request). ``curves``: per match,
    the query's curve at the turn that matched (adds its nearest views' poses), or None."""
    config = config or PoseConfig()
    samples = db.config.features.curve_samples
    if curves is not None and len(curves) != len(matches):
        raise QueryError(f"got {len(curves)} curves for {len(matches)} matches")
    for curve in curves or ():
        if curve is not None and len(curve) != samples:
            raise QueryError(f"a curve has {len(curve)} samples; this file's curves have {samples}")
    out: list[tuple[PoseEstimate | None, str | None]] = []
    for i, c in enumerate(matches):
        try:
            out.append((_pose(db, query, c, config, intrinsics,
                              curve=None if curves is None else curves[i]), None))
        except ViewDBError as exc:
            out.append((None, exc.message))
    return out


@dataclass
class _Traffic:
    """What a query sent to its server and got back, in how many round trips, and the
    time spent on the network (wall-clock time less the server's own)."""

    sent: int = 0
    received: int = 0
    trips: int = 0
    network_ms: float = 0.0

    def add(self, sent: int, received: int, trips: int, network_ms: float) -> None:
        self.sent += sent
        self.received += received
        self.trips += trips
        self.network_ms += network_ms

    def exchanged(self, exchange: Exchange) -> None:
        self.add(exchange.sent, exchange.received, 1, exchange.wall_ms - exchange.server_ms)


def run_query(
    db: ViewDB,
    image: str | Path | NDArray[Any] | LoadedImage,
    *,
    k: int = 5,
    plan: str = "server",
    client: ViewDB | None = None,
    mask: NDArray[Any] | str | Path | None = None,
    band: int = 6,
    rotations: int = 12,
    pose: bool = True,
    intrinsics: Intrinsics | str | Path | Sequence[Any] | None = None,
    pose_config: PoseConfig | None = None,
    server: ServerTier | None = None,
    label_map: NDArray[Any] | str | Path | None = None,
    label: int | None = None,
    rerank: bool = False,
    colour: bool = True,
    verify: bool = True,
    pose_top: int | None = None,
    shifts: ShiftWindow | None = None,
    roll: float | None = None,
) -> QueryResult:
    """Recognise the object a query image shows and estimate its pose (see module doc).

    ``label_map`` + ``label`` pick the object out of a label image (its pixels equal to
    ``label``; other labelled pixels may hide it and are left out of the perspective
    silhouette fit), instead of ``mask``. ``intrinsics``: ``(fx, fy, cx, cy)``, a 3×3
    matrix, ``"fx,fy,cx,cy"`` or a JSON/YAML file (:func:`viewdb.pose.intrinsics.parse_intrinsics`).

    ``rerank`` (with intrinsics): the plan's k objects are re-ranked by how well their
    silhouette fits the query under a perspective pose (IoU): each is fitted quickly
    (:data:`viewdb.pose.silhouette.QUICK`), the best :data:`RERANK_FULL` and the plan's
    first result again with the full search, and the results sorted by IoU (``distance``
    stays the curve distance).

    ``colour``: when the photo has colour, the plan's best :data:`POOL` (at least k)
    objects are re-ranked by outline distance times colour mismatch (:mod:`viewdb.recognition.colour`).
    ``verify``: they are re-ranked by how well each one's matched view fits the photo's
    shape (:mod:`viewdb.recognition.verify`). Both need the meshes (a full file or a server); the best
    k are kept.

    ``pose_top``: pose only the best this many results (None: all k; ``rerank`` poses all
    k); the others get no pose. Posing costs about 0.4 s per result on two cores.

    With ``server`` (e.g. :class:`viewdb.http.RemoteServer`), ``db`` is the client file:
    the client half of the plan runs on it, the server half and the pose on ``server``.

    ``shifts`` (instead of ``rotations``): one search over these circular shifts of the
    upright curve (:class:`~viewdb.search.shifts.ShiftWindow`; ``ShiftWindow()`` is every
    in-plane turn), each result's in-plane turn the one its shift stands for. ``roll``: a
    gravity hint, the in-plane turn (degrees, clockwise on screen, as ``inplane``) that
    makes the photo upright; only the shifts within
    :attr:`~viewdb.config.SearchConfig.roll_tolerance` of it are searched (0: upright).
    """
    start = time.perf_counter()
    if pose_top is not None and pose_top < 0:
        raise QueryError(f"pose_top must be at least 0, got {pose_top}")
    if (label_map is None) != (label is None):
        raise QueryError("a label map and a label go together: give both or neither")
    if label_map is not None and mask is not None:
        raise QueryError("give either a mask or a label map, not both")
    camera = None if intrinsics is None else parse_intrinsics(intrinsics)
    loaded = image if isinstance(image, LoadedImage) else load_image(image)
    ignore = None
    if label_map is not None:
        assert label is not None
        mask, ignore = label_mask(label_map, label, loaded)
    seg: Segmentation = segment(loaded, mask)
    completed = completed_mask(seg.mask, ignore)
    samples = db.config.features.curve_samples
    if shifts is None and roll is None:
        plain = rotated_curves(seg.mask, samples, rotations)
        curves = list(plain)
        if completed is not None:
            curves += rotated_curves(completed, samples, rotations)
    else:  # one search over the shifts of each silhouette's upright curve
        shapes = [seg.mask] + ([completed] if completed is not None else [])
        upright = [(distance_curve(m, samples), sample_bearings(m, samples)) for m in shapes]
        plain = [(0.0, upright[0][0])]
    segmented = time.perf_counter()
    meshes = server is not None or db.role == "full"
    recolour = colour and meshes and has_colour(loaded.rgb)
    verifying = verify and meshes
    pool = max(k, POOL) if recolour or verifying else k
    per_turn = []
    client_ms = server_ms = 0.0
    traffic = _Traffic()
    pose_server_ms = 0.0
    by_angle = dict(plain)  # each turn's curve of the silhouette as segmented
    searches = ([(angle, curve, None, None) for angle, curve in curves] if shifts is None and roll is None
                else [(0.0, curve, bearings, shifts if roll is None else
                       turn_window(bearings, roll, SearchConfig().roll_tolerance))
                      for curve, bearings in upright])
    for angle, curve, bearings, window in searches:
        # the turns so far bound this one's search (the merged result is unchanged)
        prior = [c for c, _ in _merge(per_turn, pool)]
        if server is None:
            found = db.recognise(curve, pool, band=band, plan=plan, client=client, prior=prior,
                                 shifts=window)
        else:
            found = db.recognise(curve, pool, band=band, plan=plan, server=server, prior=prior,
                                 shifts=window)
        if window is None:
            per_turn.append((angle, found.results))
        for c in found.results if window is not None else ():  # the turn each shift stands for
            turn = shift_turn(bearings, c.shift or 0)
            per_turn.append((turn, [c]))
            by_angle.setdefault(turn, shifted(curve, c.shift or 0))
        client_ms += found.client_ms
        server_ms += found.server_ms
        traffic.add(found.bytes_sent, found.bytes_received, int(plan != "server" or server is not None),
                    found.network_ms)
    merged = _merge(per_turn, pool)
    searched = time.perf_counter()
    query = QueryView(loaded.rgb, _pose_mask(seg, mask, label_map), ignore)
    # the side of each object the photo shows (for a mirrored match, the opposite one):
    # the view both re-rankings compare it with
    shown = {c.object: (c.object, *physical_view(c)) for c, _ in merged}
    colours: dict[str, tuple[float | None, float]] = {}
    if recolour and merged:
        views = [shown[c.object] for c, _ in merged]
        if server is None:
            signatures = db.view_colours(views)
        else:
            signatures, exchange = server.colours(views)
            traffic.exchanged(exchange)
        merged, colours = _by_colour(merged, colour_signature(query.color, query.mask), signatures)
    coloured = time.perf_counter()
    fitted: dict[str, tuple[float | None, float]] = {}
    if verifying and len(merged) > 1:
        views = [shown[c.object] for c, _ in merged]
        if server is None:
            fits = db.view_fits(query, views)
        else:
            fits, exchange = server.fits(query, views)
            traffic.exchanged(exchange)
        scores = [colours[c.object][1] if c.object in colours else c.distance for c, _ in merged]
        merged, fitted = _by_fit(merged, scores, fits)
    merged = merged[:k]
    recognised = time.perf_counter()
    matches: list[QueryMatch] = []
    verify = rerank and pose and camera is not None
    posed = len(merged) if pose else 0  # how many of the results get a pose
    if pose_top is not None and not verify:  # re-ranking needs every result's pose
        posed = min(posed, pose_top)
    if posed and server is not None:  # the server has the meshes: it poses
        poses, exchange = server.poses(query, [c for c, _ in merged[:posed]], camera,
                                       [by_angle.get(angle) for _, angle in merged[:posed]])
        poses = poses + [(None, None)] * (len(merged) - posed)
        traffic.exchanged(exchange)
        pose_server_ms = exchange.server_ms
        matches = [QueryMatch(rank, c.object, c.distance, c.azimuth, c.elevation, c.mirrored,
                              angle, *poses[rank - 1], *colours.get(c.object, (None, None)),
                              c.camera_distance, *fitted.get(c.object, (None, None)))
                   for rank, (c, angle) in enumerate(merged, 1)]
    else:
        config = pose_config or PoseConfig()
        for rank, (c, angle) in enumerate(merged, 1):
            estimate, problem = None, None
            if rank <= posed:
                try:
                    estimate = _pose(db, query, c, config, camera, QUICK if verify else None,
                                     curve=by_angle.get(angle))
                except ViewDBError as exc:
                    problem = exc.message
            matches.append(QueryMatch(rank, c.object, c.distance, c.azimuth, c.elevation,
                                      c.mirrored, angle, estimate, problem,
                                      *colours.get(c.object, (None, None)), c.camera_distance,
                                      *fitted.get(c.object, (None, None))))
        if verify:
            assert camera is not None
            matches = _rerank(db, query, matches, {c.object: c for c, _ in merged}, config, camera)
    end = time.perf_counter()
    remote = {} if server is None else {"network": traffic.network_ms, "pose_server": pose_server_ms}
    name = loaded.path or (str(image) if isinstance(image, (str, Path)) else "<array>")
    return QueryResult(
        image=name, plan=plan, k=k, results=matches,
        timing_ms={
            "segment": (segmented - start) * 1e3, "client": client_ms, "server": server_ms,
            "colour": (coloured - searched) * 1e3, "verify": (recognised - coloured) * 1e3,
            "pose": (end - recognised) * 1e3,
            "total": (end - start) * 1e3, **remote,
        },
        segmentation=seg.method,
        transfer={"bytes_sent": traffic.sent, "bytes_received": traffic.received,
                  "round_trips": traffic.trips},
    )
