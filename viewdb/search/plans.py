"""Query plans and the narrow interface between a client and a server (paper III.B–III.D).

Four plans answer "which k objects does this distance curve show":

``server``
    Algorithm 2 on the full tier alone (the paper's S1/S4).
``cs1``
    The client runs Algorithm 2 on its sparse tier and sends its result R; the server
    refines (Algorithm 3) with R's k-th distance as the upper bound and each object's
    client distance as that object's upper bound. The sparse tier's views are views of
    the full tier (same curves), so both bounds hold and the answer is exactly the
    ``server`` answer (:func:`refine`; tests compare them on many queries).
``cs2``
    Heuristic: the server searches only the objects of the client's shortlist. The
    client sends its nearest objects on the sparse tier (a longer list than k); the
    server runs CS1's bounded exact search over those objects alone
    (``RefineRequest.shortlist``). The answer is exact among them; an object the client
    ranks below its shortlist is missed. Or the paper's neighbour walk of Algorithm 4:
    from each object's best client view the server evaluates the neighbouring views on
    ever finer grids, halving the gap from the client grid down to the server grid, and
    keeps the best (:func:`walk`). Fewer distances computed; it may miss the best view
    or object.

``fast``
    Approximate: the server shortlists the objects whose views lie nearest the query in
    a turn-invariant embedding, by an approximate nearest-neighbour index built at ingest
    (``RefineRequest.fast``, the shortlist's size; :mod:`viewdb.search.fast`), and
    searches those objects exactly. Every distance it reports is a view's exact one;
    an object the index does not shortlist is missed.

Everything a client sends or receives is a plain dataclass with ``to_dict``/``from_dict``
(JSON-able), so putting HTTP between the halves is only transport.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..catalogue.features import mirror_curve
from ..config import LIMITS, SearchConfig, finite
from ..errors import QueryError
from .bounds import dtw
from .fast import FastIndex, fast_knn
from .knn import Neighbour, SearchStats, TierSource, knn, knn_stack
from .shifts import ShiftWindow, shifted, shifted_curves

__all__ = [
    "MAX_CURVES",
    "PLANS",
    "Candidate",
    "RefineRequest",
    "ServerReply",
    "WalkRequest",
    "next_gap",
    "refine",
    "walk",
]

PLANS = ("server", "cs1", "cs2", "fast")


def json_number(x: Any, what: str, low: float = -math.inf, high: float = math.inf) -> float:
    """A JSON number (not a string or a boolean) that is finite and in ``[low, high]``."""
    try:
        return finite(x, what, low, high)
    except ValueError as exc:
        raise QueryError(str(exc)) from None


def stats_from_dict(stats: Any) -> dict[str, float]:
    """A reply's ``stats``: its finite numbers by name (anything else is left out; the
    counters are for reading, never for deciding)."""
    if not isinstance(stats, dict):
        return {}
    out = {}
    for key, value in list(stats.items())[:64]:
        try:
            out[str(key)[:64]] = finite(value, "stat")
        except ValueError:
            continue
    return out


def _int(x: Any, what: str, low: int, high: int) -> int:
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)):
        raise QueryError(f"{what} must be an integer, got {x!r}"[:120])
    if not low <= int(x) <= high:
        raise QueryError(f"{what} must be in [{low}, {high}], got {x}"[:120])
    return int(x)


def curve_from_json(x: Any, samples: int | None = None) -> NDArray[np.float64]:
    """A distance curve: a list of numbers (not strings or booleans), each finite and in
    ``[0, n]`` (a curve has mean 1, so no sample of an ``n``-sample curve exceeds ``n``)."""
    numeric = (isinstance(x, np.ndarray) and x.dtype.kind in "iuf") or (
        isinstance(x, list) and all(isinstance(v, int | float) and not isinstance(v, bool) for v in x))
    if not numeric:
        raise QueryError("curve must be a list of numbers")
    try:
        curve = np.asarray(x, dtype=np.float64)
    except OverflowError:  # an integer beyond any float
        raise QueryError("curve must contain only finite numbers") from None
    if curve.ndim != 1 or len(curve) < 8 or (samples is not None and len(curve) != samples):
        raise QueryError(f"curve must have {samples or 'at least 8'} samples, got shape {curve.shape}")
    if not np.all(np.isfinite(curve)):
        raise QueryError("curve must contain only finite numbers")
    if curve.min() < 0 or curve.max() > len(curve):
        raise QueryError(f"curve samples must be in [0, {len(curve)}] (a distance curve has mean 1), "
                         f"got {curve.min():g} to {curve.max():g}")
    return curve


@dataclass(frozen=True)
class Candidate:
    """An object with its best view found so far and that view's exact distance.

    ``version`` names what the distance was computed on in the file it comes from: the
    content hash of the object's mesh and the settings that made its curves
    (:meth:`~viewdb.storage.tiers.TierReader.object_versions`; a client file names it, so a
    server can tell a stale client's bounds; None: unknown)."""

    object: str
    distance: float
    azimuth: float
    elevation: float
    mirrored: bool
    version: str | None = None
    #: The view is a perspective silhouette seen from this many bounding radii (None:
    #: an orthographic view).
    camera_distance: float | None = None
    #: The query curve matched started at this sample (a shift search,
    #: :class:`~viewdb.search.shifts.ShiftWindow`); None: the curve as given.
    shift: int | None = None
    #: The row of the request's stack of curves that matched (a stack search,
    #: :attr:`RefineRequest.curves`); None: a search of one curve.
    curve_index: int | None = None

    def to_dict(self) -> dict[str, Any]:
        out = {"object": self.object, "distance": self.distance, "azimuth": self.azimuth,
               "elevation": self.elevation, "mirrored": self.mirrored}
        if self.version is not None:
            out["version"] = self.version
        if self.camera_distance is not None:
            out["camera_distance"] = self.camera_distance
        if self.shift is not None:
            out["shift"] = self.shift
        if self.curve_index is not None:
            out["curve_index"] = self.curve_index
        return out

    @classmethod
    def from_dict(cls, data: Any) -> Candidate:
        if not isinstance(data, dict):
            raise QueryError("a candidate must be an object")
        try:
            name = data["object"]
            if not isinstance(name, str) or not name:
                raise QueryError("candidate object must be a non-empty string")
            mirrored = data.get("mirrored", False)
            if not isinstance(mirrored, bool):
                raise QueryError("candidate mirrored must be true or false")
            distance = json_number(data["distance"], "candidate distance")
            if distance < 0:
                raise QueryError("candidate distance must be >= 0")
            version = data.get("version")
            if version is not None and not (
                isinstance(version, str) and 0 < len(version) <= 128 and version.isalnum()
            ):
                raise QueryError("candidate version must be a short alphanumeric string")
            camera = data.get("camera_distance")
            if camera is not None and (
                isinstance(camera, bool) or not isinstance(camera, (int, float))
                or not 1 < json_number(camera, "candidate camera_distance") <= LIMITS.max_perspective_distance
            ):
                raise QueryError(f"candidate camera_distance must be a number greater than 1 and at "
                                 f"most {LIMITS.max_perspective_distance:g}, got {camera!r}"[:160])
            shift = data.get("shift")
            if shift is not None:
                shift = _int(shift, "candidate shift", 0, MAX_SAMPLES - 1)
            index = data.get("curve_index")
            if index is not None:
                index = _int(index, "candidate curve_index", 0, MAX_CURVES - 1)
            return cls(name, distance, json_number(data["azimuth"], "candidate azimuth"),
                       json_number(data["elevation"], "candidate elevation"), mirrored, version,
                       None if camera is None else float(camera), shift, index)
        except KeyError as exc:
            raise QueryError(f"candidate lacks {exc.args[0]!r}") from exc


def candidates_from_json(data: Any, limit: int) -> list[Candidate]:
    if not isinstance(data, list):
        raise QueryError("candidates must be a list")
    if len(data) > limit:
        raise QueryError(f"at most {limit} candidates, got {len(data)}")
    return [Candidate.from_dict(c) for c in data]


#: Largest k a request may ask for (and candidates it may carry).
MAX_K = 100
#: Widest Sakoe–Chiba band a request may ask for.
MAX_BAND = 64
#: Longest curve a candidate's shift may refer to.
MAX_SAMPLES = 4096
#: Most curves a request's stack may hold (e.g. 12 in-plane turns of a silhouette and of
#: its completed outline need 24).
MAX_CURVES = 72
#: Largest shortlist a ``fast`` request may ask for (objects).
MAX_FAST = 100_000


def _shifts(data: Any) -> ShiftWindow | None:
    """A request's optional shift window (absent or null: the curve as given)."""
    if data is None:
        return None
    window = ShiftWindow.from_dict(data)
    for name in ("centre", "half_width", "step"):
        value = getattr(window, name)
        if value is not None and not 0 <= value < MAX_SAMPLES:
            raise QueryError(f"shifts {name} must be in [0, {MAX_SAMPLES - 1}], got {value}")
    return window


def curves_from_json(x: Any, samples: int | None = None) -> NDArray[np.float64]:
    """A stack of 1 to :data:`MAX_CURVES` distance curves of one length, as ``(T, N)``."""
    if not isinstance(x, list) or not 1 <= len(x) <= MAX_CURVES:
        raise QueryError(f"curves must be a list of 1 to {MAX_CURVES} curves, got "
                         f"{len(x) if isinstance(x, list) else type(x).__name__}")
    stack = [curve_from_json(c, samples) for c in x]
    if len({len(c) for c in stack}) > 1:
        raise QueryError(f"curves must all have the same number of samples, got "
                         f"{sorted({len(c) for c in stack})}")
    return np.ascontiguousarray(stack)


@dataclass(frozen=True)
class RefineRequest:
    """CS1, client → server: the query curve and the client's top-k on its sparse tier
    (searched over the same ``shifts`` of the curve; None: the curve as given).

    With ``curves`` (``(T, N)``, at most :data:`MAX_CURVES`; :meth:`of_stack`) the
    distance is the smallest over that stack of curves, found in one search
    (:func:`~viewdb.search.knn.knn_stack`), and ``curve`` is its first row; on the wire
    the stack goes as ``"curves"`` instead of ``"curve"`` (a server that predates stacks
    refuses it as lacking ``"curve"`` rather than answering for one curve). A stack
    goes without ``shifts``.

    ``shortlist`` (CS2): the server searches only the objects the ``client`` candidates
    name, and the answer is exact among them; without it, every object it holds (CS1).

    ``fast`` (the ``fast`` plan): the server searches only the ``fast`` objects its
    approximate index shortlists (:mod:`viewdb.search.fast`), exactly; on the wire
    ``"fast": N``. A server that predates it ignores the key and answers exactly."""

    curve: NDArray[np.float64] = field(repr=False)
    band: int
    k: int
    client: list[Candidate]
    shifts: ShiftWindow | None = None
    curves: NDArray[np.float64] | None = field(default=None, repr=False)
    shortlist: bool = False
    fast: int | None = None

    def __post_init__(self) -> None:
        if self.curves is not None and self.shifts is not None:
            raise QueryError("a request searches either a stack of curves or shifts of one curve, not both")
        if self.fast is not None and self.shortlist:
            raise QueryError("a request is either a cs2 shortlist or fast, not both")
        if self.fast is not None and not 1 <= self.fast <= MAX_FAST:
            raise QueryError(f"fast must be in [1, {MAX_FAST}], got {self.fast}")

    @classmethod
    def of_stack(
        cls, curves: NDArray[np.floating], band: int, k: int, client: list[Candidate],
        shortlist: bool = False, fast: int | None = None,
    ) -> RefineRequest:
        """A request searching the smallest distance over the rows of ``curves``."""
        stack = np.ascontiguousarray(curves, dtype=np.float64)
        if stack.ndim != 2 or not 1 <= len(stack) <= MAX_CURVES:
            raise QueryError(f"a stack must hold 1 to {MAX_CURVES} curves, got shape {stack.shape}")
        return cls(stack[0], band, k, client, curves=stack, shortlist=shortlist, fast=fast)

    @property
    def stack(self) -> NDArray[np.float64]:
        """The curves searched, ``(T, N)`` (one row without ``curves``)."""
        return self.curves if self.curves is not None else np.asarray(self.curve, np.float64)[None, :]

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"band": self.band, "k": self.k, "client": [c.to_dict() for c in self.client]}
        if self.curves is None:
            out["curve"] = [float(x) for x in self.curve]
        else:
            out["curves"] = [[float(x) for x in c] for c in self.curves]
        if self.shifts is not None:
            out["shifts"] = self.shifts.to_dict()
        if self.shortlist:
            out["shortlist"] = True
        if self.fast is not None:
            out["fast"] = self.fast
        return out

    @classmethod
    def from_dict(cls, data: Any, samples: int | None = None) -> RefineRequest:
        if not isinstance(data, dict):
            raise QueryError("request must be an object")
        if "curves" in data and "curve" in data:
            raise QueryError("request must have either curve or curves, not both")
        try:
            band, k = _int(data["band"], "band", 0, MAX_BAND), _int(data["k"], "k", 1, MAX_K)
            client = candidates_from_json(data["client"], MAX_K)
            shifts = _shifts(data.get("shifts"))
            shortlist = data.get("shortlist", False)
            if not isinstance(shortlist, bool):
                raise QueryError(f"shortlist must be true or false, got {shortlist!r}"[:120])
            fast = data.get("fast")
            if fast is not None:
                fast = _int(fast, "fast", 1, MAX_FAST)
            if "curves" in data:
                if shifts is not None:
                    raise QueryError("a request with curves must not have shifts")
                stack = curves_from_json(data["curves"], samples)
                return cls.of_stack(stack, band, k, client, shortlist, fast)
            return cls(curve_from_json(data["curve"], samples), band, k, client, shifts, shortlist=shortlist,
                       fast=fast)
        except KeyError as exc:
            raise QueryError(f"request lacks {exc.args[0]!r}") from exc


@dataclass(frozen=True)
class WalkRequest:
    """CS2, client → server: the query curve, the client grid and the client's top-k."""

    curve: NDArray[np.float64] = field(repr=False)
    band: int
    k: int
    client_gap: float
    client: list[Candidate]

    def to_dict(self) -> dict[str, Any]:
        return {"curve": [float(x) for x in self.curve], "band": self.band, "k": self.k,
                "client_gap": self.client_gap, "client": [c.to_dict() for c in self.client]}

    @classmethod
    def from_dict(cls, data: Any, samples: int | None = None) -> WalkRequest:
        if not isinstance(data, dict):
            raise QueryError("request must be an object")
        try:
            gap = json_number(data["client_gap"], "client_gap")
            if not 0 < gap <= 180:
                raise QueryError(f"client_gap must be in (0, 180], got {gap}")
            return cls(curve_from_json(data["curve"], samples), _int(data["band"], "band", 0, MAX_BAND),
                       _int(data["k"], "k", 1, MAX_K), gap, candidates_from_json(data["client"], MAX_K))
        except KeyError as exc:
            raise QueryError(f"request lacks {exc.args[0]!r}") from exc


@dataclass(frozen=True)
class ServerReply:
    """Server → client: the answer, best first, and what it cost."""

    results: list[Candidate]
    stats: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"results": [c.to_dict() for c in self.results], "stats": dict(self.stats)}

    @classmethod
    def from_dict(cls, data: Any) -> ServerReply:
        if not isinstance(data, dict) or not isinstance(data.get("results"), list):
            raise QueryError("reply must be an object with a results list")
        return cls(candidates_from_json(data["results"], MAX_K), stats_from_dict(data.get("stats")))


def usable_client(
    request: RefineRequest, holds: Callable[[str], bool], versions: Mapping[str, str] | None = None,
) -> list[Candidate]:
    """The request's client candidates whose distances bound a server's (module doc of
    :func:`refine`), nearest first: of an object the server ``holds``, in the version
    the server holds (``versions``), at a shift the request's window allows and of a
    curve of the request's stack."""
    n = len(request.curve)
    allowed = {0} if request.shifts is None else set(request.shifts.shifts(n).tolist())
    rows = len(request.stack)
    return sorted(
        (c for c in request.client
         if holds(c.object)
         and (c.version is None or versions is None or versions.get(c.object) == c.version)
         and (c.shift is None or c.shift in allowed)
         and (c.curve_index is None or c.curve_index < rows)),
        key=lambda c: c.distance,
    )


def refine(
    source: TierSource, request: RefineRequest, versions: Mapping[str, str] | None = None,
    upper: float = math.inf, fast_index: FastIndex | None = None,
) -> tuple[list[Neighbour], SearchStats]:
    """CS1's server half (Algorithm 3): exact k-NN on ``source`` (the full tier) bounded by
    the client's k-th distance and its per-object distances.

    A client distance bounds the server's only if the server holds the same object: a
    candidate whose object the server lacks, or whose ``version`` differs from the
    server's (``versions``: object name → content hash; a client file exported before
    the object was replaced) is not used, so a stale client file makes the answer no
    less exact, only the bounds looser. Nor is a candidate whose ``shift`` lies outside
    the request's shift window: its distance is not one the window allows.

    With ``request.shifts`` the distance is the smallest over those shifts of the curve
    (:func:`~viewdb.search.knn.knn`), the client's too; with ``request.curves`` the
    smallest over that stack (:func:`~viewdb.search.knn.knn_stack`, each result's
    ``shift`` the row that matched). ``upper``: a further upper bound
    of the k-th distance from elsewhere (a sharded catalogue's other shards); objects
    farther than it may be left out of the answer.

    ``request.shortlist`` (CS2): only the objects the client candidates name are
    searched (whether or not their distances bound: a stale candidate's object is still
    searched), and the answer is exact among them.

    ``request.fast`` (the ``fast`` plan): only the objects ``fast_index`` shortlists
    (:func:`~viewdb.search.fast.fast_knn`), exactly; without an index (none valid for the
    source), every object, exactly."""
    client = usable_client(request, lambda name: source.object_index(name) is not None, versions)
    if len(client) >= request.k:
        upper = min(upper, client[request.k - 1].distance)
    known: dict[int, float] = {}
    for c in client:
        index = source.object_index(c.object)
        if index is not None:
            known[index] = min(c.distance, known.get(index, math.inf))
    if request.fast is not None:
        return _fast(source, request, fast_index, upper, known)
    only = None
    if request.shortlist:
        only = np.zeros(source.n_objects, dtype=np.bool_)
        for c in request.client:
            index = source.object_index(c.object)
            if index is not None:
                only[index] = True
    if request.curves is not None:
        return knn_stack(request.curves, source, request.k, request.band, upper=upper, known=known,
                         block=SearchConfig().stack_block, only=only)
    return knn(request.curve, source, request.k, request.band, upper=upper, known=known,
               shifts=request.shifts, only=only)


def _fast(
    source: TierSource, request: RefineRequest, index: FastIndex | None, upper: float,
    known: Mapping[int, float],
) -> tuple[list[Neighbour], SearchStats]:
    """:func:`refine` of a ``fast`` request: the stack, or the shifts of the curve as a
    stack (each result's ``shift`` then the start sample that matched)."""
    assert request.fast is not None
    if request.shifts is None:
        return fast_knn(request.stack, source, index, request.k, request.band, request.fast,
                        upper=upper, known=known)
    starts = request.shifts.shifts(len(request.curve))
    found, stats = fast_knn(shifted_curves(np.asarray(request.curve, np.float64), starts), source, index,
                            request.k, request.band, request.fast, upper=upper, known=known)
    return [replace(nb, shift=int(starts[nb.shift])) for nb in found], stats


def next_gap(gap: float, server_gap: float) -> float:
    """Half of ``gap``, snapped down to a multiple of the server grid (at least one step)."""
    steps = max(1, math.floor(gap / 2.0 / server_gap + 1e-9))
    return steps * server_gap


def _norm(angle: float) -> float:
    a = angle % 360.0
    return 0.0 if abs(a - 360.0) < 1e-9 else a


#: ``perspective_near(object, h, v, radius)``: the object's perspective views within
#: ``radius`` degrees of arc of direction ``(h, v)``, as ``(h, v, camera distance, curve)``.
PerspectiveNear = Callable[[str, float, float, float],
                           Sequence[tuple[float, float, float, NDArray[np.float64]]]]


def walk(
    request: WalkRequest,
    curve_at: Callable[[str, float, float], NDArray[np.float64] | None],
    server_gap: float,
    max_steps: int = 16,
    perspective_near: PerspectiveNear | None = None,
    perspective_radius: float = 0.0,
) -> tuple[list[Candidate], dict[str, float]]:
    """CS2's server half (Algorithm 4): a neighbour walk per client candidate.

    ``curve_at(object, h, v)`` gives the curve of a server-grid view (None for a view
    without a silhouette). At each grid gap, from the client's gap halved down to
    ``server_gap``, the walk moves to the best of the current view's 8 neighbours until
    none is better, then halves the gap. Then, with ``perspective_near(object, h, v,
    radius)`` (the object's perspective views within ``perspective_radius`` degrees of arc
    of where the walk ended, as ``(h, v, camera distance, curve)``), each of those is
    compared too and the best view kept: a photo's outline is a perspective one, which the
    orthographic grid alone misses. Returns the top-k objects by their best view. A
    candidate found by a shift search (its ``shift``) is walked with the query curve
    started at that sample.
    """
    evaluated: dict[tuple[str, float, float, int], tuple[float, bool]] = {}
    compared = 0

    def against(q: NDArray[np.float64], curve: NDArray[np.float64]) -> tuple[float, bool]:
        d = dtw(q, curve, request.band)
        dm = dtw(q, mirror_curve(curve), request.band)
        return (dm, True) if dm < d else (d, False)

    def distance(name: str, h: float, v: float, shift: int) -> tuple[float, bool]:
        key = (name, _norm(h), _norm(v), shift)
        if key not in evaluated:
            curve = curve_at(*key[:3])
            evaluated[key] = ((math.inf, False) if curve is None
                              else against(shifted(request.curve, shift), curve))
        return evaluated[key]

    results = []
    for cand in request.client:
        h, v = _norm(round(cand.azimuth / server_gap) * server_gap), _norm(
            round(cand.elevation / server_gap) * server_gap)
        shift = cand.shift or 0
        best, mirrored = distance(cand.object, h, v, shift)
        gap = max(request.client_gap, server_gap)
        while gap > server_gap + 1e-9:
            gap = next_gap(gap, server_gap)
            for _ in range(max_steps):
                moves = [(distance(cand.object, h + dh, v + dv, shift), h + dh, v + dv)
                         for dh in (-gap, 0.0, gap) for dv in (-gap, 0.0, gap) if dh or dv]
                (d, m), nh, nv = min(moves, key=lambda x: x[0][0])
                if d >= best:
                    break
                best, mirrored, h, v = d, m, _norm(nh), _norm(nv)
        camera: float | None = None
        if perspective_near is not None:
            q = shifted(request.curve, shift)
            for ph, pv, pd, curve in perspective_near(cand.object, h, v, perspective_radius):
                compared += 1
                d, m = against(q, curve)
                if d < best:
                    best, mirrored, h, v, camera = d, m, ph, pv, pd
        if math.isfinite(best):
            results.append(Candidate(cand.object, best, h, v, mirrored, camera_distance=camera,
                                     shift=cand.shift))
    results.sort(key=lambda c: (c.distance, c.object))
    return _one_per_object(results)[: request.k], {"dtw": float(2 * (len(evaluated) + compared))}


def _one_per_object(ranked: Sequence[Candidate]) -> list[Candidate]:
    """The first (best) candidate of each object, in order: a client that names an object
    twice (two starting views) gets it back once."""
    seen: set[str] = set()
    out = []
    for c in ranked:
        if c.object not in seen:
            seen.add(c.object)
            out.append(c)
    return out


def neighbours_to_candidates(
    found: Sequence[Neighbour],
    views: Mapping[int, tuple[float, float] | tuple[float, float, float | None]],
    versions: Mapping[str, str] | None = None,
    shifted: bool = False,
    stacked: bool = False,
) -> list[Candidate]:
    """k-NN results as candidates, given ``view id -> (azimuth, elevation[, camera
    distance])`` (and the objects' content hashes, ``versions``); ``shifted``: the results
    of a shift search, whose candidates carry the shift that matched; ``stacked``: of a
    stack search (:func:`~viewdb.search.knn.knn_stack`), whose candidates carry the row of
    the curve that matched."""
    out = []
    for n in found:
        azimuth, elevation, *camera = views[n.view]
        out.append(Candidate(n.object, n.distance, azimuth, elevation, n.mirrored,
                             None if versions is None else versions.get(n.object),
                             camera[0] if camera else None, n.shift if shifted else None,
                             n.shift if stacked else None))
    return out
