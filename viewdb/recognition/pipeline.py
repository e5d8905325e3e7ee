"""The query pipeline: photo → segment → curves → search → re-rank → pose.

Each stage is one function; what needs the full catalogue goes to a server tier
(:class:`~viewdb.recognition.server_tier.ServerTier`): in this process
(:class:`~viewdb.recognition.local_tier.LocalServerTier`) or over HTTP
(:class:`viewdb.http.RemoteServer`), the same calls either way. The client half of CS1 and
CS2 runs on a :class:`~viewdb.recognition.client_tier.ClientTier`.

1. **segment** (:mod:`viewdb.recognition.image`): the object's silhouette (alpha channel,
   a mask, a label map's label, or automatically from the background).
2. **curves** (:mod:`viewdb.recognition.shapes`): its distance curve, also turned in the
   image plane by ``rotations`` angles (and, for an occluded labelled object, its
   completed outline).
3. **search** (:mod:`viewdb.recognition.retrieval`): each curve by the plan; the plan's
   best objects (a pool of at least k), each with its best view over all curves.
4. **re-rank**: by colour (:mod:`viewdb.recognition.colour`) when the photo has colour,
   then by how well each matched view fits the photo's shape
   (:mod:`viewdb.recognition.verify`); the best k are kept. An object cut from a prompt
   in a photo with colour is ranked by its colours first instead: the colour channel
   (:mod:`viewdb.search.colour_index`) names the objects whose stored colours lie
   nearest, each is searched exactly beside the outline's pool
   (:func:`_by_colour_channel`).
5. **pose** (:mod:`viewdb.pose.matched`): the top results' poses, chosen among their
   candidate same-shape views by SIFT or by outline; with ``rerank`` and intrinsics the
   results are re-ranked by the IoU of their perspective silhouette fit.

A photo of several objects (box or point prompts, every object, every label:
:mod:`viewdb.recognition.regions`) is decoded once and cut into regions; each region then
goes through stages 2–5 over the same tiers (:func:`run_regions`), the other regions
counting as what may hide it.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..catalogue.features import distance_curve, sample_bearings
from ..catalogue.look import look_features
from ..config import RecognitionConfig, SegmentationConfig
from ..errors import QueryError
from ..pose.estimate import PoseEstimate, QueryView
from ..search.colour_index import ColourMatch
from ..search.plans import MAX_CURVES, Candidate, RefineRequest
from ..search.shifts import ShiftWindow, shift_turn, shifted, turn_window
from .client_tier import ClientTier
from .colour import colour_distance, colour_signature, core_signature, has_colour, rerank
from .image import LoadedImage, load_image
from .options import QueryOptions
from .regions import Box, Point, Prompts, Region, find_regions, surround_spread
from .results import ObjectResult, QueryMatch, QueryResult
from .retrieval import merge, recognise_curve
from .segmentation import Segmentation, label_mask, segment
from .server_tier import Exchange, ServerTier
from .shapes import completed_mask, pose_mask, rotated_curves
from .verify import physical_view, rerank_by_fit

__all__ = [
    "QueryShape", "look_terms", "named_by_look", "pool_size", "region_shape", "run_query", "run_regions",
    "segment_photo", "segment_query", "shape_of",
]

#: A pool entry: an object's best candidate and the in-plane angle of the curve that found it.
Pooled = tuple[Candidate, float]


@dataclass
class _Traffic:
    """What a query sent to its server tier and got back, in how many round trips, the
    time spent on the network (wall-clock time less the server's own), and the server's
    time for the poses."""

    sent: int = 0
    received: int = 0
    trips: int = 0
    network_ms: float = 0.0
    pose_server_ms: float = 0.0
    #: The query image's size and the size it was sent at, when scaled to the server's cap.
    scaled: tuple[int, int, int, int] | None = None

    def add(self, sent: int, received: int, trips: int, network_ms: float) -> None:
        self.sent += sent
        self.received += received
        self.trips += trips
        self.network_ms += network_ms

    def exchanged(self, exchange: Exchange) -> None:
        self.add(exchange.sent, exchange.received, exchange.trips, exchange.wall_ms - exchange.server_ms)
        self.scaled = exchange.scaled or self.scaled


@dataclass(frozen=True)
class QueryShape:
    """Stages 1–2: the segmented photo and the curves searched."""

    image: LoadedImage
    segmentation: Segmentation
    #: What the re-rankings and the pose compare the results with.
    view: QueryView
    #: ``(in-plane angle, curve)`` of every curve searched.
    curves: list[tuple[float, NDArray[np.float64]]] = field(repr=False)
    #: Each turn's curve of the silhouette as segmented (the pose's nearest views).
    by_angle: dict[float, NDArray[np.float64]] = field(repr=False)
    #: For a shift search (``curves`` upright only): each curve's sample bearings
    #: (:func:`~viewdb.catalogue.features.sample_bearings`), which turn a shift stands for.
    bearings: list[NDArray[np.float64]] | None = field(default=None, repr=False)


def segment_photo(
    image: str | Path | NDArray[Any] | LoadedImage, *, mask: NDArray[Any] | str | Path | None = None,
    label_map: NDArray[Any] | str | Path | None = None, label: int | None = None,
) -> tuple[LoadedImage, Segmentation, QueryView]:
    """Stage 1: the photo, its segmentation, and the query view the re-rankings and the
    pose compare with (a label map's object keeps its holes and knows what may hide it)."""
    if (label_map is None) != (label is None):
        raise QueryError("a label map and a label go together: give both or neither")
    if label_map is not None and mask is not None:
        raise QueryError("give either a mask or a label map, not both")
    loaded = image if isinstance(image, LoadedImage) else load_image(image)
    ignore = None
    if label_map is not None:
        assert label is not None
        mask, ignore = label_mask(label_map, label, loaded)
    seg = segment(loaded, mask)
    return loaded, seg, QueryView(loaded.rgb, pose_mask(seg, mask, label_map), ignore, loaded.depth)


def segment_query(
    image: str | Path | NDArray[Any] | LoadedImage, samples: int, rotations: int, *,
    mask: NDArray[Any] | str | Path | None = None, label_map: NDArray[Any] | str | Path | None = None,
    label: int | None = None, hidden_min_share: float = RecognitionConfig().hidden_min_share,
    upright_only: bool = False,
) -> QueryShape:
    """Stages 1–2: segment the photo and make its curves (``samples`` per curve);
    ``upright_only``: the upright curves alone, with their bearings, for a shift search."""
    loaded, seg, view = segment_photo(image, mask=mask, label_map=label_map, label=label)
    return shape_of(loaded, seg, view, samples, rotations, hidden_min_share, upright_only)


def shape_of(
    loaded: LoadedImage, seg: Segmentation, view: QueryView, samples: int, rotations: int,
    hidden_min_share: float = RecognitionConfig().hidden_min_share, upright_only: bool = False,
) -> QueryShape:
    """Stage 2: the curves of a segmented object (``samples`` per curve): turned in the
    image plane, and completed where what may hide it bites into its outline;
    ``upright_only``: the upright curves alone, with their bearings, for a shift search."""
    completed = completed_mask(seg.mask, view.ignore, hidden_min_share)
    if upright_only:
        shapes = [seg.mask] + ([completed] if completed is not None else [])
        curves = [(0.0, distance_curve(m, samples)) for m in shapes]
        return QueryShape(loaded, seg, view, curves, dict(curves[:1]),
                          [sample_bearings(m, samples) for m in shapes])
    plain = rotated_curves(seg.mask, samples, rotations)
    curves = list(plain)
    if completed is not None:
        curves += rotated_curves(completed, samples, rotations)
    return QueryShape(loaded, seg, view, curves, dict(plain))


def _upright_only(options: QueryOptions) -> bool:
    """A shift search (``shifts`` or ``roll``) searches the upright curves alone."""
    return options.shifts is not None or options.roll is not None


def region_shape(loaded: LoadedImage, region: Region, samples: int, options: QueryOptions) -> QueryShape:
    """Stages 1–2 for one object of a photo of several: the other objects may hide it."""
    pose_mask = region.mask if region.pose_mask is None else region.pose_mask
    view = QueryView(loaded.rgb, pose_mask, region.others, loaded.depth)
    return shape_of(loaded, region.segmentation, view, samples, options.rotations,
                    options.recognition.hidden_min_share, _upright_only(options))


def _search(
    shape: QueryShape, options: QueryOptions, pool: int, server: ServerTier, client: ClientTier | None,
    traffic: _Traffic,
) -> tuple[list[Pooled], float, float]:
    """Stage 3: every curve by the plan, in one search over the stack of them
    (:func:`_search_stack`) or each bounded by the turns searched before it (the merged
    result is the same); the pool and the client's and the server's time."""
    if _stacked(shape, options):
        return _search_stack(shape, options, pool, server, client, traffic)
    per_curve: list[tuple[float, list[Candidate]]] = []
    client_ms = server_ms = 0.0
    for i, (_, curve) in enumerate(shape.curves):
        prior = [c for c, _ in merge(per_curve, pool)]
        window = _window(shape, i, options)
        found = recognise_curve(curve, pool, options.band, options.plan, server, client, prior, window,
                                **_cs2(options))
        per_curve += _at_turns(shape, i, window, found.results)
        client_ms += found.client_ms
        server_ms += found.server_ms
        traffic.add(found.bytes_sent, found.bytes_received, found.round_trips, found.network_ms)
    return merge(per_curve, pool), client_ms, server_ms


def _at_turns(
    shape: QueryShape, i: int, window: ShiftWindow | None, found: list[Candidate],
) -> list[tuple[float, list[Candidate]]]:
    """Curve ``i``'s results at their in-plane turns: the curve's own, or for a shift
    search each result at the turn its shift stands for (whose curve joins
    ``shape.by_angle``)."""
    angle, curve = shape.curves[i]
    if window is None:
        return [(angle, found)]
    assert shape.bearings is not None
    out = []
    for c in found:
        turn = shift_turn(shape.bearings[i], c.shift or 0)
        out.append((turn, [c]))
        shape.by_angle.setdefault(turn, shifted(curve, c.shift or 0))
    return out


def _stack_pooled(shape: QueryShape, found: list[Candidate]) -> list[Pooled]:
    """A stack search's results, each at the in-plane angle of the curve that matched."""
    return [(replace(c, curve_index=None), shape.curves[c.curve_index or 0][0]) for c in found]


def _cs2(options: QueryOptions) -> dict[str, Any]:
    """How the ``cs2`` plan searches (:func:`~viewdb.recognition.retrieval.recognise_curve`)."""
    return {"cs2": options.recognition.cs2, "shortlist": options.recognition.cs2_shortlist,
            "fast_shortlist": options.recognition.fast_shortlist}


def _stacked(shape: QueryShape, options: QueryOptions) -> bool:
    """Whether the turned curves are searched as one stack
    (:attr:`~viewdb.config.RecognitionConfig.turn_search`; the ``cs2`` walk walks each turn)."""
    walks = options.plan == "cs2" and options.recognition.cs2 == "walk"
    return (options.recognition.turn_search == "stack" and not walks and len(shape.curves) > 1
            and shape.bearings is None and len(shape.curves) <= MAX_CURVES)


def _search_stack(
    shape: QueryShape, options: QueryOptions, pool: int, server: ServerTier, client: ClientTier | None,
    traffic: _Traffic,
) -> tuple[list[Pooled], float, float]:
    """Stage 3 in one search: each view's distance is the smallest over the curves, each
    result at the in-plane angle of the curve that matched."""
    stack = np.stack([curve for _, curve in shape.curves])
    found = recognise_curve(stack, pool, options.band, options.plan, server, client, **_cs2(options))
    traffic.add(found.bytes_sent, found.bytes_received, found.round_trips, found.network_ms)
    return _stack_pooled(shape, found.results), found.client_ms, found.server_ms


def _window(shape: QueryShape, i: int, options: QueryOptions) -> ShiftWindow | None:
    """The shifts curve ``i`` is searched over: ``options.shifts``, those near the gravity
    hint's turn, or None (the curve as given: one of the turned curves)."""
    if options.roll is not None:
        assert shape.bearings is not None
        return turn_window(shape.bearings[i], options.roll, options.recognition.roll_tolerance)
    return options.shifts


#: Per object: (colour distance or fit, re-ranked score).
Scores = dict[str, tuple[float | None, float]]


def _by_colour(
    pooled: list[Pooled], shape: QueryShape, server: ServerTier, traffic: _Traffic,
) -> tuple[list[Pooled], Scores]:
    """Stage 4a: the pool re-ranked by colour (:func:`viewdb.recognition.colour.rerank`),
    comparing each object's side the photo shows; each one's colour distance and score."""
    views = [(c.object, *physical_view(c)) for c, _ in pooled]
    signatures, exchange = server.colours(views)
    traffic.exchanged(exchange)
    query = colour_signature(shape.view.color, shape.view.mask)
    order, colours, scores = rerank([c.distance for c, _ in pooled], query, signatures)
    by_object = {c.object: (d, s) for (c, _), d, s in zip(pooled, colours, scores, strict=True)}
    return [pooled[i] for i in order], by_object


#: The distance a colour channel's shortlist names its objects with: no bound at all.
_UNBOUNDED = 1e300


def _search_objects(
    shape: QueryShape, options: QueryOptions, names: Sequence[str], server: ServerTier, traffic: _Traffic,
) -> list[Pooled]:
    """Each of objects ``names`` with its best view over the query's curves, exactly (the
    server tier's search restricted to them, as CS2's shortlist is)."""
    if not names:
        return []
    client = [Candidate(name, _UNBOUNDED, 0.0, 0.0, False) for name in names]
    k = len(names)
    if shape.bearings is None and len(shape.curves) <= MAX_CURVES:
        stack = np.stack([curve for _, curve in shape.curves])
        request = RefineRequest.of_stack(stack, options.band, k, client, shortlist=True)
        reply, exchange = server.refine(request)
        traffic.exchanged(exchange)
        return _stack_pooled(shape, reply.results)
    per_curve: list[tuple[float, list[Candidate]]] = []
    for i, (_, curve) in enumerate(shape.curves):
        window = _window(shape, i, options)
        reply, exchange = server.refine(RefineRequest(curve, options.band, k, client, window, shortlist=True))
        traffic.exchanged(exchange)
        per_curve += _at_turns(shape, i, window, reply.results)
    return merge(per_curve, k)


def _colour_matches(
    shape: QueryShape, options: QueryOptions, server: ServerTier, traffic: _Traffic,
    box: tuple[int, int, int, int] | None = None,
) -> tuple[NDArray[np.float32], list[ColourMatch], dict[str, float]]:
    """The cut-out's colour signature, the colour channel's objects for it
    (:attr:`~viewdb.config.RecognitionConfig.colour_pool` of the ``colour_candidates``
    nearest by colour, :func:`named_by_look`; none when the catalogue has no coloured
    object, or the server predates the channel) and each coloured object's look distance
    to the pixels of ``box`` (none without a box or a look model,
    :mod:`viewdb.catalogue.look`)."""
    recognition = options.recognition
    query = core_signature(shape.view.color, shape.view.mask, recognition.colour_core)
    crop = _box_pixels(shape.view, box) if recognition.look_weight > 0 else None
    asked = recognition.colour_pool if crop is None else max(recognition.colour_pool,
                                                               recognition.colour_candidates)
    matches, exchange = server.colour_ranking(query, asked)
    traffic.exchanged(exchange)
    looks: dict[str, float] = {}
    if matches and crop is not None:
        looks, exchange = server.looks(look_features(crop))
        traffic.exchanged(exchange)
    return query, named_by_look(matches, looks, recognition), looks


def look_terms(
    looks: Mapping[str, float], names: Sequence[str], recognition: RecognitionConfig,
) -> list[float]:
    """What each of objects ``names`` adds to its colour-channel score for its look:
    ``look_weight`` × (its look distance − the ``look_reference`` quantile of ``looks``);
    an object without a look distance (a mesh without colour) adds 0, and so does every
    object without ``looks``."""
    if not looks:
        return [0.0] * len(names)
    reference = float(np.quantile(list(looks.values()), recognition.look_reference))
    return [recognition.look_weight * (looks.get(name, reference) - reference) for name in names]


def named_by_look(
    matches: Sequence[ColourMatch], looks: Mapping[str, float], recognition: RecognitionConfig,
) -> list[ColourMatch]:
    """The colour channel's objects: the ``colour_pool`` of ``matches`` (a colour ranking,
    nearest first) whose colour distance plus look term (:func:`look_terms`) is least,
    ties by name, then ordered by colour distance as ``matches`` are. Both parts are
    lower bounds of the object's score in :func:`_by_colour_channel`, whose outline
    part is never negative, so these are the objects the score can rank best."""
    terms = look_terms(looks, [m.object for m in matches], recognition)
    best = sorted(range(len(matches)), key=lambda i: (matches[i].distance + terms[i], matches[i].object))
    return [matches[i] for i in sorted(best[:recognition.colour_pool])]


def _box_pixels(view: QueryView, box: tuple[int, int, int, int] | None) -> NDArray[np.uint8] | None:
    """The photo's pixels in ``box``, or None without one or when under 2 × 2."""
    if box is None:
        return None
    height, width = view.color.shape[:2]
    x1, y1 = max(box[0], 0), max(box[1], 0)
    x2, y2 = min(box[2], width), min(box[3], height)
    return view.color[y1:y2, x1:x2] if x2 - x1 >= 2 and y2 - y1 >= 2 else None


def _by_colour_channel(
    pooled: list[Pooled], shape: QueryShape, options: QueryOptions, query: NDArray[np.float32],
    matches: list[ColourMatch], server: ServerTier, traffic: _Traffic, busy: bool = False,
    looks: dict[str, float] | None = None,
) -> tuple[list[Pooled], Scores]:
    """Stage 4 for an object cut from a prompt: the outline's pool and the colour
    channel's ``matches`` (:mod:`viewdb.search.colour_index`) for its signature
    ``query``, each searched exactly, ranked by colour distance plus
    ``prompt_outline_weight`` (``busy_outline_weight`` for an object in ``busy``
    surroundings) × log(outline distance / the best one's). An object whose
    mesh has no colour counts ``uncoloured_distance``; a coloured one the channel did not
    name, the larger of that and the channel's last distance. With ``looks`` (each
    coloured object's look distance), each adds ``look_weight`` × its look distance
    less the ``look_reference`` quantile of them (an object without one adds 0)."""
    recognition = options.recognition
    searched = {c.object for c, _ in pooled}
    pooled = pooled + _search_objects(shape, options, [m.object for m in matches if m.object not in searched],
                                      server, traffic)
    # what each counts (``counted``) and its matched view's distance (``shown``; None: no colour)
    counted: dict[str, float] = {m.object: m.distance for m in matches}
    shown: dict[str, float | None] = dict(counted)
    unnamed = [(c.object, *physical_view(c)) for c, _ in pooled if c.object not in counted]
    if unnamed:  # which of the others have colour at all
        signatures, exchange = server.colours(unnamed)
        traffic.exchanged(exchange)
        neutral = recognition.uncoloured_distance
        for (name, _, _), signature in zip(unnamed, signatures, strict=True):
            counted[name] = neutral if signature is None else max(neutral, matches[-1].distance)
            shown[name] = None if signature is None else colour_distance(query, signature)
    nearest = max(min(c.distance for c, _ in pooled), 1e-12)
    weight = recognition.busy_outline_weight if busy else recognition.prompt_outline_weight
    scores = [counted[c.object] + weight * float(np.log(max(c.distance, nearest) / nearest))
              for c, _ in pooled]
    terms = look_terms(looks or {}, [c.object for c, _ in pooled], recognition)
    scores = [score + term for score, term in zip(scores, terms, strict=True)]
    order = sorted(range(len(pooled)), key=lambda i: (scores[i], pooled[i][0].object))
    by_object = {c.object: (shown[c.object], s) for (c, _), s in zip(pooled, scores, strict=True)}
    return [pooled[i] for i in order], by_object


def _by_fit(
    pooled: list[Pooled], shape: QueryShape, colours: Scores, server: ServerTier, traffic: _Traffic,
) -> tuple[list[Pooled], Scores]:
    """Stage 4b: the pool re-ranked by shape fit (:func:`viewdb.recognition.verify.rerank_by_fit`)
    from their scores so far; each one's fit and verified score."""
    views = [(c.object, *physical_view(c)) for c, _ in pooled]
    fits, exchange = server.fits(shape.view, views)
    traffic.exchanged(exchange)
    scores = [colours[c.object][1] if c.object in colours else c.distance for c, _ in pooled]
    order, verified = rerank_by_fit(scores, fits)
    by_object = {c.object: (f, v) for (c, _), f, v in zip(pooled, fits, verified, strict=True)}
    return [pooled[i] for i in order], by_object


def _pose(
    ranked: list[Pooled], shape: QueryShape, options: QueryOptions, server: ServerTier, traffic: _Traffic,
) -> list[tuple[PoseEstimate | None, str | None]]:
    """Stage 5: the poses of the top results (``(None, None)`` for the others)."""
    posed = min(len(ranked), options.posed)
    if not posed:
        return [(None, None)] * len(ranked)
    top = ranked[:posed]
    poses, exchange = server.poses(shape.view, [c for c, _ in top], options.camera,
                                   [shape.by_angle.get(angle) for _, angle in top],
                                   rerank=options.rerank_by_iou)
    traffic.exchanged(exchange)
    traffic.pose_server_ms += exchange.server_ms
    return list(poses) + [(None, None)] * (len(ranked) - posed)


def _matches(
    ranked: list[Pooled], poses: Sequence[tuple[PoseEstimate | None, str | None]], colours: Scores,
    fitted: Scores, by_iou: bool,
) -> list[QueryMatch]:
    def match(rank: int, c: Candidate, angle: float) -> QueryMatch:
        pose, pose_error = poses[rank - 1]
        colour, colour_score = colours.get(c.object, (None, None))
        shape_fit, verified_score = fitted.get(c.object, (None, None))
        return QueryMatch(rank, c.object, c.distance, c.azimuth, c.elevation, c.mirrored, angle, pose,
                          pose_error, colour, colour_score, c.camera_distance, shape_fit, verified_score)

    matches = [match(rank, c, angle) for rank, (c, angle) in enumerate(ranked, 1)]
    if not by_iou:
        return matches

    def iou(m: QueryMatch) -> float:
        return m.pose.iou if m.pose is not None and m.pose.iou is not None else -1.0

    matches.sort(key=lambda m: (-iou(m), m.rank))
    return [replace(m, rank=i) for i, m in enumerate(matches, 1)]


def pool_size(options: QueryOptions, prompted: bool, recolour: bool, channel: bool = False) -> int:
    """How many objects the plan finds before the re-rankings keep the best k: k when
    nothing re-ranks them, else at least ``recognition.pool``, or
    ``recognition.prompt_pool`` for an object cut from a prompt that the colour channel
    does not rank (``channel``: it does, :func:`_by_colour_channel`)."""
    if not (recolour or options.verify):
        return options.k
    recognition = options.recognition
    return max(options.k, recognition.prompt_pool if prompted and not channel else recognition.pool)


def _colour_channel(options: QueryOptions, prompted: bool, recolour: bool) -> bool:
    """Whether an object is ranked by its colours first (:func:`_by_colour_channel`): cut
    from a prompt, in a photo with colour, with a colour pool."""
    return prompted and recolour and options.recognition.colour_pool > 0


def _recognise(
    shape: QueryShape, options: QueryOptions, server: ServerTier, client: ClientTier | None,
    traffic: _Traffic, prompted: bool = False, busy: bool = False,
    box: tuple[int, int, int, int] | None = None,
) -> tuple[list[QueryMatch], dict[str, float]]:
    """Stages 3–5 for one segmented object: its matches and each stage's time (ms).
    ``prompted``: the object was cut from a prompt (a box, a point), so its outline is
    less sure: in a photo with colour it is ranked by its colours first (the colour
    channel, :func:`_by_colour_channel`), else the pool is deeper
    (``recognition.prompt_pool``); ``busy``: its surroundings are busy, so its outline
    counts less still there."""
    start = time.perf_counter()
    recolour = options.colour and has_colour(shape.image.rgb)
    query, named, looks = (_colour_matches(shape, options, server, traffic, box)
                           if _colour_channel(options, prompted, recolour) else (None, [], {}))
    asked = time.perf_counter()
    pool = pool_size(options, prompted, recolour, channel=bool(named))
    ranked, client_ms, server_ms = _search(shape, options, pool, server, client, traffic)
    searched = time.perf_counter()
    colours: Scores = {}
    channel = bool(named) and bool(ranked)
    if channel:
        assert query is not None
        ranked, colours = _by_colour_channel(ranked, shape, options, query, named, server, traffic, busy,
                                             looks)
    elif recolour and ranked:
        ranked, colours = _by_colour(ranked, shape, server, traffic)
    coloured = time.perf_counter()
    fitted: Scores = {}
    if options.verify and len(ranked) > 1 and not channel:
        ranked, fitted = _by_fit(ranked, shape, colours, server, traffic)
    ranked = ranked[:options.k]
    recognised = time.perf_counter()
    poses = _pose(ranked, shape, options, server, traffic)
    matches = _matches(ranked, poses, colours, fitted, options.rerank_by_iou)
    end = time.perf_counter()
    colour_ms = (coloured - searched + asked - start) * 1e3
    return matches, {"client": client_ms, "server": server_ms, "colour": colour_ms,
                     "verify": (recognised - coloured) * 1e3, "pose": (end - recognised) * 1e3,
                     "total": (end - start) * 1e3}


def _prompt_box(prompt: Box | Point | None) -> tuple[int, int, int, int] | None:
    """A box prompt's pixels (whole pixels it touches); None for another prompt."""
    if not isinstance(prompt, Box):
        return None
    return (int(np.floor(prompt.x1)), int(np.floor(prompt.y1)),
            int(np.ceil(prompt.x2)), int(np.ceil(prompt.y2)))


def _image_name(image: str | Path | NDArray[Any] | LoadedImage, loaded: LoadedImage) -> str:
    return loaded.path or (str(image) if isinstance(image, (str, Path)) else "<array>")


def _transfer(traffic: _Traffic) -> dict[str, int]:
    out = {"bytes_sent": traffic.sent, "bytes_received": traffic.received, "round_trips": traffic.trips}
    if traffic.scaled is not None:  # the image was scaled down to the server's pixel cap
        out.update(zip(("image_width", "image_height", "sent_width", "sent_height"), traffic.scaled,
                       strict=True))
    return out


def _remote(server: ServerTier, traffic: _Traffic) -> dict[str, float]:
    return {"network": traffic.network_ms, "pose_server": traffic.pose_server_ms} if server.remote else {}


def run_query(
    image: str | Path | NDArray[Any] | LoadedImage, options: QueryOptions, server: ServerTier,
    client: ClientTier | None, samples: int, *, mask: NDArray[Any] | str | Path | None = None,
    label_map: NDArray[Any] | str | Path | None = None, label: int | None = None,
    prompts: Prompts | None = None, segmentation: SegmentationConfig | None = None,
) -> QueryResult:
    """Recognise the object a photo shows and estimate its pose (module doc): ``server``
    answers for the full catalogue, ``client`` runs CS1's and CS2's client half;
    ``samples`` per distance curve. ``label_map`` + ``label`` pick the object out of a label
    image (other labelled pixels may hide it), instead of ``mask``. With ``prompts`` (or a
    label map and ``prompts.every``) each object the prompts ask for is recognised
    (:func:`run_regions`)."""
    if prompts is not None:
        if mask is not None or label is not None:
            raise QueryError("prompts find the objects themselves: give no mask and no label with them")
        return run_regions(image, prompts, options, server, client, samples, label_map=label_map,
                           segmentation=segmentation)
    start = time.perf_counter()
    traffic = _Traffic()
    shape = segment_query(image, samples, options.rotations, mask=mask, label_map=label_map, label=label,
                          hidden_min_share=options.recognition.hidden_min_share,
                          upright_only=_upright_only(options))
    segmented = time.perf_counter()
    matches, stages = _recognise(shape, options, server, client, traffic)
    end = time.perf_counter()
    timing = {"segment": (segmented - start) * 1e3, **stages, "total": (end - start) * 1e3,
              **_remote(server, traffic)}
    return QueryResult(
        image=_image_name(image, shape.image), plan=options.plan, k=options.k, results=matches,
        timing_ms=timing, segmentation=shape.segmentation.method, transfer=_transfer(traffic),
        photo=shape.image.rgb,
    )


def run_regions(
    image: str | Path | NDArray[Any] | LoadedImage, prompts: Prompts, options: QueryOptions,
    server: ServerTier, client: ClientTier | None, samples: int, *,
    label_map: NDArray[Any] | str | Path | None = None, segmentation: SegmentationConfig | None = None,
) -> QueryResult:
    """Every object the prompts ask for (:func:`viewdb.recognition.regions.find_regions`),
    each recognised and posed as a single-object query is, from one decode of the photo
    and over the same tiers; the answer's ``objects`` hold them, its ``results`` is empty."""
    start = time.perf_counter()
    traffic = _Traffic()
    loaded = image if isinstance(image, LoadedImage) else load_image(image)
    regions = find_regions(loaded, prompts, label_map=label_map, config=segmentation)
    segmented = time.perf_counter()
    objects = []
    totals: dict[str, float] = dict.fromkeys(("client", "server", "colour", "verify", "pose"), 0.0)
    for region in regions:
        t0 = time.perf_counter()
        shape = region_shape(loaded, region, samples, options)
        prompted = region.prompt is not None
        cut_box = region.box
        busy = prompted and surround_spread(loaded.rgb, cut_box) >= options.recognition.busy_surround
        box = _prompt_box(region.prompt) or cut_box  # a point's or every object's look: its cut-out's
        matches, timing = _recognise(shape, options, server, client, traffic, prompted, busy, box)
        timing["segment"] = (time.perf_counter() - t0) * 1e3 - timing["total"]  # its curves
        timing["total"] += timing["segment"]
        for key, value in timing.items():
            totals[key] = totals.get(key, 0.0) + value
        objects.append(ObjectResult(region, matches, timing))
    end = time.perf_counter()
    totals.update(segment=totals.get("segment", 0.0) + (segmented - start) * 1e3, total=(end - start) * 1e3,
                  **_remote(server, traffic))
    method = "label" if label_map is not None else ("every" if prompts.every else "prompts")
    return QueryResult(
        image=_image_name(image, loaded), plan=options.plan, k=options.k, results=[], timing_ms=totals,
        segmentation=method, transfer=_transfer(traffic), objects=objects, photo=loaded.rgb,
    )
