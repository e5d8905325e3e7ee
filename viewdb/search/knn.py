"""Exact k-NN over distance curves: Algorithm 2 as a best-first search, and its reference.

One min-priority order over entries keyed by lower bounds of the exact distance of
everything below them (:mod:`viewdb.search.bounds` proves the chain):

* a **group** (an MBR around a few views of one object, :mod:`viewdb.search.grouping`),
  keyed by the larger of ``MINDIST`` of the query box (or the mirrored box) to the MBR
  and the curve-box bound of the group's per-sample range;
* a **Fourier point** of a view (or of its mirror), keyed by the larger of
  ``Fourier_Dist`` and ``LB_PAA`` (its segment means against the envelope's);
* a **curve**, keyed by ``LB_Keogh``, refined to its DTW distance when it pops.

The queue and the refinement run compiled (:mod:`viewdb.search.refine`, which also says
when the search stops and why the answer is exact). The exact distance of a view is
``min(DTW(q, c), DTW(q, reverse(c)))`` with a Sakoe–Chiba band of ``band`` samples; the
result is the ``k`` distinct objects with the smallest distances, each with its best
view.

Groups come from a :class:`TierSource`: an R-tree in the database
(:class:`viewdb.storage.tiers.StoredTier`) or arrays in memory (:class:`TierArrays`).
They are fed by **range browsing**: the candidates are every group whose MINDIST is at
most a radius ``rho``; entries are taken only while the smallest key is ``<= rho``, and
when it exceeds ``rho`` the radius grows (doubling; a search given an upper bound of the
k-th distance starts at that bound, beyond which nothing can enter the result) and the
source is asked for the groups within the new radius. Every group with key ``<= rho`` is
a candidate whenever something is taken, so entries come in exactly the order of a queue
that held all groups from the start. :func:`brute_force_knn` computes the same answer by
scanning everything and is the oracle the tests use.

**Threads.** :func:`knn_stack` can split one search over threads
(:class:`~viewdb.config.SearchConfig`'s ``threads``): the objects are dealt to the threads
(by their numbers of views, so each thread has about as much to search), each thread
runs the search above over its objects' groups only, and all share the per-object arrays
(bounds and results: each thread writes only its own objects' entries). A thread's
k-th distance is computed from the shared bounds, so it is that of all threads' objects:
any k objects with exact distances at most ``U`` prove the global k-th distance at most
``U``, whichever thread found them. Each thread leaves the k-th distance it finds in a
shared cell and reads the cell at every step (:mod:`.multirefine`), so each prunes by the
smallest any has found. A read that misses another thread's latest write (or a write
that overwrites a smaller value) only prunes less: every value written is a k-th
distance some k objects prove.
Each thread stops when its smallest key exceeds that k-th distance, so every object of its
part within the final k-th distance is refined exactly, as in one search: the answer is the
same, ties included (tested against the single search and brute force).
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Mapping
from concurrent.futures import wait
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from ..catalogue.features import mirror_curve
from ..config import SearchConfig
from ..pools import thread_pool
from .bounds import (
    _group_keys_kernel,
    dtw,
    envelope,
    envelope_box,
    fourier_coordinates,
    mirror_box,
    outward32,
    paa_edges,
    paa_envelope,
    paa_means,
)
from .grouping import INDEXED_COEFFICIENTS, group_points, indexed_coordinates, indexed_rows, padded_mbr
from .multirefine import FULL, refine_stack
from .refine import DONE, EXHAUSTED, NEED, RADIUS, WIDEN_ABS, WIDEN_REL, refine_groups
from .shifts import CurveQuery, ShiftWindow, shifted_curves

__all__ = [
    "Neighbour",
    "QueryBoxes",
    "SearchStats",
    "TierArrays",
    "TierSource",
    "brute_force_knn",
    "knn",
    "knn_stack",
    "objects_within",
]

#: First search radius of the range browsing (curves have mean 1; near views are ~0.1 apart).
INITIAL_RADIUS = 0.125


@dataclass(frozen=True)
class Neighbour:
    """One result: an object, its best view (an id of the source) and the exact distance;
    ``shift``: the start sample of the query curve that matched (a shift search,
    :func:`knn`), or the row of the stack's curve (:func:`knn_stack`); 0 otherwise."""

    object: str
    view: int
    distance: float
    mirrored: bool
    shift: int = 0


@dataclass
class SearchStats:
    """What a search did: groups opened, bounds and DTWs computed, range expansions."""

    groups_visited: int = 0
    points_visited: int = 0
    lb_keogh: int = 0
    dtw: int = 0
    expansions: int = 0
    seconds: float = 0.0
    #: Further counters of a plan's own (the ``fast`` plan's shortlist), reported beside.
    extra: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, float]:
        out = {k: v for k, v in self.__dict__.items() if k != "extra"}
        return {**out, **self.extra}


@dataclass(frozen=True)
class QueryBoxes:
    """A query curve, its LB_Keogh envelope (and the envelope's mirror, see
    :func:`~viewdb.search.bounds.group_bounds`) and the envelope's box (and mirror) in the
    indexed coordinates."""

    curve: NDArray[np.float64]
    band: int
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    mirrored_lower: NDArray[np.float64]
    mirrored_upper: NDArray[np.float64]
    box: tuple[NDArray[np.float64], NDArray[np.float64]]
    mirrored_box: tuple[NDArray[np.float64], NDArray[np.float64]]
    #: The envelope's (and mirrored envelope's) range per segment and the segment widths
    #: (:func:`~viewdb.search.bounds.paa_envelope`, segments :func:`paa_edges` of N).
    segments: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
    mirrored_segments: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]

    @classmethod
    def of(cls, curve: NDArray[np.floating], band: int) -> QueryBoxes:
        q = np.ascontiguousarray(curve, dtype=np.float64)
        lower, upper = envelope(q, band)
        m = max(INDEXED_COEFFICIENTS) + 1
        lo, hi = envelope_box(lower, upper, fourier_coordinates(m, len(q)))
        mlo, mhi = mirror_box(lo, hi)
        rows = indexed_rows(m)
        mlower, mupper = mirror_curve(lower), mirror_curve(upper)
        edges = paa_edges(len(q))
        return cls(q, band, lower, upper, mlower, mupper,
                   (lo[rows], hi[rows]), (mlo[rows], mhi[rows]),
                   paa_envelope(lower, upper, edges), paa_envelope(mlower, mupper, edges))

    def group_keys(
        self, lo: NDArray[np.float64], hi: NDArray[np.float64],
        curve_lo: NDArray[np.floating], curve_hi: NDArray[np.floating],
        at: NDArray[np.int64] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """MINDIST and key of groups given by their MBRs (rows of ``(g, d)``) and
        per-sample curve ranges (rows of ``(g, N)``), either orientation, for the rows
        ``at`` (default all): the key is the larger of MINDIST and the curve-box bound
        (module doc of :mod:`~viewdb.search.bounds`), a lower bound of the distance of
        every view of the group. Inputs are trusted (float64 contiguous, finite)."""
        rows = np.arange(len(lo), dtype=np.int64) if at is None else at
        return _group_keys_kernel(
            self.box[0], self.box[1], self.mirrored_box[0], self.mirrored_box[1],
            self.lower, self.upper, self.mirrored_lower, self.mirrored_upper,
            lo, hi, curve_lo, curve_hi, rows,
        )


#: What :meth:`TierSource.rows` returns: the curves, indexed coordinates and segment means.
_Rows = tuple[NDArray[np.floating], NDArray[np.float64], NDArray[np.float64]]


class TierSource(Protocol):
    """Where a search gets its groups from.

    Groups are numbered ``0 .. n_groups - 1``; group ``g`` holds rows ``group_start[g] :
    group_start[g] + group_count[g]`` of the arrays :meth:`rows` returns, all views of
    object ``group_owner[g]`` (objects are numbered ``0 .. n_objects - 1``).
    """

    n_groups: int
    n_objects: int
    group_owner: NDArray[np.int64]
    group_start: NDArray[np.int64]
    group_count: NDArray[np.int64]
    #: Object of each row of :meth:`rows`.
    row_owner: NDArray[np.int64]

    def groups_within(
        self, query: QueryBoxes, radius: float, seen: NDArray[np.bool_]
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Groups (and their keys, :meth:`QueryBoxes.group_keys`) of (at least) every group
        whose MINDIST is ``<= radius``, except those marked in ``seen``."""
        ...

    def rows(
        self, groups: NDArray[np.int64]
    ) -> tuple[NDArray[np.floating], NDArray[np.float64], NDArray[np.float64]]:
        """The curves ``(V, N)``, indexed coordinates ``(V, d)`` and segment means ``(V, S)``
        (:func:`~viewdb.search.bounds.paa_means` over :func:`paa_edges` of N) of the tier's
        views; the rows of ``groups`` are filled in (others may not be)."""
        ...

    def group_boxes(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float32], NDArray[np.float32]]:
        """Every group's MBR (``lo``, ``hi``: ``(n_groups, d)``, float64) and per-sample curve
        range (``(n_groups, N)`` each, float32 holding the range: rounded outward)."""
        ...

    def view_id(self, row: int) -> int: ...

    def object_name(self, index: int) -> str: ...

    def object_index(self, name: str) -> int | None: ...


def _packed(
    groups: list[NDArray[np.int64]],
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Row order putting each group's members next to each other: (rows, starts, counts)."""
    counts = np.array([len(g) for g in groups], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    rows = np.concatenate(groups).astype(np.int64) if groups else np.zeros(0, np.int64)
    return rows, starts, counts


@dataclass
class TierArrays:
    """A tier held in memory: curves with their owners, grouped like the stored R-trees.

    The reference implementation of :class:`TierSource` (and what tests build from
    random curves); :func:`brute_force_knn` scans it. View ids are row numbers of
    ``curves``.
    """

    names: list[str]
    #: Object index of each view, (n,).
    owner: NDArray[np.int64]
    #: Distance curves, (n, N) float64.
    curves: NDArray[np.float64]
    group_views: int = 32
    groups: list[NDArray[np.int64]] = field(init=False)
    mbr_lo: NDArray[np.float64] = field(init=False)
    mbr_hi: NDArray[np.float64] = field(init=False)
    curve_lo: NDArray[np.float32] = field(init=False)
    curve_hi: NDArray[np.float32] = field(init=False)

    def __post_init__(self) -> None:
        self.curves = np.ascontiguousarray(self.curves, dtype=np.float64)
        self.owner = np.asarray(self.owner, dtype=np.int64)
        coords = indexed_coordinates(self.curves)
        self.groups = []
        for o in range(len(self.names)):
            views = np.flatnonzero(self.owner == o)
            self.groups += [views[g] for g in group_points(coords[views], self.group_views)]
        boxes = [padded_mbr(coords[g]) for g in self.groups]
        g, d, n = len(self.groups), coords.shape[1], self.curves.shape[1]
        self.mbr_lo = np.array([b[0] for b in boxes]).reshape(g, d)
        self.mbr_hi = np.array([b[1] for b in boxes]).reshape(g, d)
        self.curve_lo, self.curve_hi = outward32(
            np.array([self.curves[v].min(axis=0) for v in self.groups]).reshape(g, n),
            np.array([self.curves[v].max(axis=0) for v in self.groups]).reshape(g, n))
        self._rows, self.group_start, self.group_count = _packed(self.groups)
        self.group_owner = np.array([self.owner[v[0]] for v in self.groups], dtype=np.int64)
        self.row_owner = np.ascontiguousarray(self.owner[self._rows])
        self._curves = np.ascontiguousarray(self.curves[self._rows])
        self._coords = np.ascontiguousarray(coords[self._rows])
        self._means = paa_means(self._curves, paa_edges(n)) if len(self._curves) else np.zeros((0, 1))

    @property
    def n_groups(self) -> int:
        return len(self.groups)

    @property
    def n_objects(self) -> int:
        return len(self.names)

    def groups_within(
        self, query: QueryBoxes, radius: float, seen: NDArray[np.bool_]
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        mind, keys = query.group_keys(self.mbr_lo, self.mbr_hi, self.curve_lo, self.curve_hi)
        hits = np.flatnonzero((mind <= radius) & ~seen).astype(np.int64)
        return hits, keys[hits]

    def rows(
        self, groups: NDArray[np.int64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        return self._curves, self._coords, self._means

    def group_boxes(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float32], NDArray[np.float32]]:
        return self.mbr_lo, self.mbr_hi, self.curve_lo, self.curve_hi

    def view_id(self, row: int) -> int:
        return int(self._rows[row])

    def object_name(self, index: int) -> str:
        return self.names[index]

    def object_index(self, name: str) -> int | None:
        return self.names.index(name) if name in self.names else None


def brute_force_knn(query: NDArray[np.floating], tier: TierArrays, k: int, band: int) -> list[Neighbour]:
    """The reference: exact distance to every view, best view per object, top k objects."""
    q = np.asarray(query, dtype=np.float64)
    best: dict[int, Neighbour] = {}
    for i, c in enumerate(tier.curves):
        d, dm = dtw(q, c, band), dtw(q, mirror_curve(c), band)
        dist, mirrored = (dm, True) if dm < d else (d, False)
        o = int(tier.owner[i])
        if o not in best or dist < best[o].distance:
            best[o] = Neighbour(tier.names[o], i, dist, mirrored)
    return sorted(best.values(), key=lambda nb: (nb.distance, nb.object))[:k]


#: Groups made ready (read from the file if need be) per call of the compiled refinement.
CHUNK = 32
MAX_CHUNK = 1024


def knn(
    query: NDArray[np.floating],
    source: TierSource,
    k: int,
    band: int,
    *,
    upper: float = math.inf,
    known: Mapping[int, float] | None = None,
    initial_radius: float = INITIAL_RADIUS,
    shifts: ShiftWindow | None = None,
    block: int | None = None,
    only: NDArray[np.bool_] | None = None,
) -> tuple[list[Neighbour], SearchStats]:
    """The k nearest distinct objects (Algorithm 2), exactly as :func:`brute_force_knn`.

    ``upper`` and ``known`` are what a CS1 client hands the server (Algorithm 3): an upper
    bound of the k-th distance (the client's k-th distance on the sparse tier, whose views
    are all in the full tier), and upper bounds of some objects' distances (object index
    → the client's distance). Groups whose key exceeds ``upper`` are never fetched; the
    result is unchanged as long as the bounds hold.

    ``shifts``: the distance is the smallest over the circular shifts of the query in the
    window (:class:`~viewdb.search.shifts.ShiftWindow`; ``ShiftWindow()`` is every shift),
    found in one search (:func:`knn_stack`, ``block`` curves per block, default
    :class:`~viewdb.config.SearchConfig`'s); each result's ``shift`` is the start sample
    that matched, and ``upper``/``known`` must be distances under the same window. None:
    the curve as given, by the fixed-start search below.

    ``only``: a mask over the source's objects; the search is over those objects alone
    (exactly :func:`brute_force_knn` of a tier holding only them; None: every object).

    Candidate groups are refined in the order of their keys by the compiled loop of
    :func:`~viewdb.search.refine.refine_groups` (each group's views in the order of their
    own keys, the UCR cascade, DTW abandoning past ``min(U, b_o)``); see the module doc
    for the range browsing that feeds it and why the result is exact.
    """
    if shifts is not None:
        q = np.asarray(query, dtype=np.float64)
        starts = shifts.shifts(len(q))
        found, stats = knn_stack(shifted_curves(q, starts), source, k, band, upper=upper, known=known,
                                 initial_radius=initial_radius, block=block, only=only)
        return [replace(nb, shift=int(starts[nb.shift])) for nb in found], stats
    qb = QueryBoxes.of(query, band)
    envelope_pair = (qb.lower, qb.upper)
    mirrored_pair = (qb.mirrored_lower, qb.mirrored_upper)

    def step(search: _Search, order: NDArray[np.int64], keys: NDArray[np.float64], pos: int, ready: int,
             stop_key: float, rows: _Rows) -> tuple[int, int]:
        return refine_groups(
            qb.curve, band, envelope_pair, mirrored_pair, qb.box, qb.mirrored_box,
            qb.segments, qb.mirrored_segments, order, keys, pos, ready, stop_key,
            source.group_start, source.group_count, source.group_owner, source.row_owner,
            *rows, search.bound, search.exact, search.exact_row, search.exact_mirrored, k,
            search.cap, search.counters, search.heap,
        )

    return _Search(source, k, upper, known, 2).run(qb, step, initial_radius, _left_out(source, only))


def _left_out(source: TierSource, only: NDArray[np.bool_] | None) -> NDArray[np.bool_] | None:
    """The groups of the objects a search leaves out (None: none), from the mask ``only``
    over the source's objects."""
    if only is None:
        return None
    mask = np.asarray(only, dtype=np.bool_)
    if mask.shape != (source.n_objects,):
        raise ValueError(f"only must mask the source's {source.n_objects} objects, got shape {mask.shape}")
    return ~mask[source.group_owner]


def knn_stack(
    curves: NDArray[np.floating],
    source: TierSource,
    k: int,
    band: int,
    *,
    upper: float = math.inf,
    known: Mapping[int, float] | None = None,
    initial_radius: float = INITIAL_RADIUS,
    block: int | None = None,
    threads: int | None = None,
    only: NDArray[np.bool_] | None = None,
    priority: NDArray[np.int64] | None = None,
) -> tuple[list[Neighbour], SearchStats]:
    """The k nearest distinct objects to a stack of query curves ``(T, N)``: a view's
    distance is the smallest over the curves (and the view's mirror), found in one
    best-first search (:mod:`viewdb.search.shifts`, :mod:`viewdb.search.multirefine`);
    each result's ``shift`` is the row of the curve that matched. Exactly
    :func:`brute_force_knn` of each curve, merged; ``upper``/``known``/``only`` as in :func:`knn`.

    ``threads``: the search split over that many threads (module doc; at most one per
    object); the answer is the same. Default: :class:`~viewdb.config.SearchConfig`'s, at
    most the machine's CPUs, and one for a small source (:func:`search_threads`).
    ``priority``: objects likeliest to be near, nearest first (a ``fast`` shortlist), dealt
    to the threads in turn so that each has near objects to search (:func:`deal_objects`)."""
    config = SearchConfig()
    stack = CurveQuery.of(curves, band, config.shift_block if block is None else block)
    boxes = source.group_boxes()
    group_arrays = (source.group_start, source.group_count, source.group_owner, source.row_owner)

    def step(search: _Search, order: NDArray[np.int64], keys: NDArray[np.float64], pos: int, ready: int,
             stop_key: float, rows: _Rows) -> tuple[int, int]:
        while True:
            pos, status = refine_stack(
                stack, order, keys, pos, ready, stop_key, group_arrays, rows, boxes,
                (search.bound, search.exact, search.exact_row, search.exact_mirrored,
                 search.exact_curve, *search.heap, search.kth), k, search.cap, search.counters,
            )
            if status != FULL:
                return pos, status
            search.grow()

    if threads is not None and threads < 1:
        raise ValueError(f"threads must be at least 1, got {threads}")
    threads = search_threads(source, config) if threads is None else min(threads, source.n_objects)
    left_out = _left_out(source, only)
    if threads <= 1:
        return _Search(source, k, upper, known, 4).run(stack, step, initial_radius, left_out)
    return _parallel(source, k, upper, known, threads, stack, step, initial_radius, left_out, priority)


def search_threads(source: TierSource, config: SearchConfig) -> int:
    """The threads a search of ``source`` uses by default: ``config.threads``, at most the
    machine's CPUs and the source's objects, and one for a source of fewer than
    ``config.parallel_min_groups`` groups (not worth the threads' start)."""
    if source.n_groups < config.parallel_min_groups:
        return 1
    return max(1, min(config.threads, os.cpu_count() or 1, source.n_objects))


def deal_objects(
    source: TierSource, parts: int, left_out: NDArray[np.bool_] | None = None,
    priority: NDArray[np.int64] | None = None,
) -> NDArray[np.int64]:
    """The part (``0 .. parts - 1``) of each object: the objects dealt by their numbers of
    views, largest first, to the parts in turn and back (0, 1, …, p − 1, p − 1, …, 0, …),
    so each part has about as many views to search (``left_out``: groups not searched,
    whose views do not count). With ``priority`` (distinct objects), those are dealt
    first, in its order: the near objects, which cost the most, are shared out. On the
    240 synthetic photos, a ``fast`` shortlist dealt so took the mean search from 40 to
    32 ms (the median unchanged)."""
    counts = source.group_count if left_out is None else np.where(left_out, 0, source.group_count)
    views = np.bincount(source.group_owner, weights=counts, minlength=source.n_objects)
    order = np.argsort(-views, kind="stable")
    if priority is not None:
        first = np.asarray(priority, dtype=np.int64)
        order = np.concatenate([first, order[~np.isin(order, first)]])
    turn = np.r_[np.arange(parts), np.arange(parts)[::-1]]
    part = np.zeros(source.n_objects, dtype=np.int64)
    part[order] = turn[np.arange(source.n_objects) % len(turn)]
    return part


def _parallel(
    source: TierSource, k: int, upper: float, known: Mapping[int, float] | None, threads: int,
    query: Any, step: Any, initial_radius: float, left_out: NDArray[np.bool_] | None = None,
    priority: NDArray[np.int64] | None = None,
) -> tuple[list[Neighbour], SearchStats]:
    """One search split over ``threads`` threads, each over its objects' groups (module doc;
    ``left_out``: groups no thread searches; ``priority`` as in :func:`deal_objects`)."""
    first = _Search(source, k, upper, known, 4)
    searches = [first] + [_Search(source, k, upper, known, 4, shared=first) for _ in range(threads - 1)]
    group_part = deal_objects(source, threads, left_out, priority)[source.group_owner]
    if left_out is not None:
        group_part = np.where(left_out, -1, group_part)
    lock = threading.Lock()  # the source (an R-tree, a read connection) is one thread's at a time
    pool = thread_pool("viewdb-search", threads)  # a search's threads submit nothing
    runs = [pool.submit(search.run, query, step, initial_radius, group_part != t, lock)
            for t, search in enumerate(searches)]
    wait(runs)  # every part ends before the caller may close the source, even if one fails
    stats = [run.result()[1] for run in runs]
    total = SearchStats(seconds=max(s.seconds for s in stats))
    for name in ("groups_visited", "points_visited", "lb_keogh", "dtw", "expansions"):
        setattr(total, name, sum(getattr(s, name) for s in stats))
    return first.result(), total


class _Search:
    """The state of one search and its range browsing (module doc): per-object bounds
    and results, the heap of the compiled refinement, and the loop that lists groups
    within a growing radius and hands them to a refinement ``step``."""

    bound: NDArray[np.float64]
    exact: NDArray[np.float64]
    exact_row: NDArray[np.int64]
    exact_mirrored: NDArray[np.bool_]
    exact_curve: NDArray[np.int64]
    kth: NDArray[np.float64]

    def __init__(self, source: TierSource, k: int, upper: float, known: Mapping[int, float] | None,
                 heap_per_view: int, shared: _Search | None = None) -> None:
        self.source, self.k = source, k
        if shared is not None:  # another thread's part of the same search: one set of per-object arrays
            self.bound, self.exact, self.exact_row = shared.bound, shared.exact, shared.exact_row
            self.exact_mirrored, self.exact_curve = shared.exact_mirrored, shared.exact_curve
            self.kth = shared.kth
        else:
            self.bound = np.full(source.n_objects, math.inf)
            for o, d in (known or {}).items():
                self.bound[o] = min(self.bound[o], float(d))
            self.exact = np.full(source.n_objects, math.inf)
            self.exact_row = np.full(source.n_objects, -1, dtype=np.int64)
            self.exact_mirrored = np.zeros(source.n_objects, dtype=np.bool_)
            self.exact_curve = np.zeros(source.n_objects, dtype=np.int64)
            #: The k-th distance as the threads sharing this search last found it (stack searches).
            self.kth = np.full(1, math.inf)
        self.cap = upper * (1.0 + WIDEN_REL) + WIDEN_ABS if math.isfinite(upper) else math.inf
        self.counters = np.zeros(4, dtype=np.int64)
        views = int(source.group_count.sum())
        size = max(heap_per_view * views, 64)
        self.heap = (np.empty(size), np.empty(size, dtype=np.int64), np.zeros(1, dtype=np.int64))

    def grow(self) -> None:
        """Double the heap's capacity (its entries and size kept)."""
        keys, codes, size = self.heap
        n = int(size[0])
        bigger = (np.empty(2 * len(keys)), np.empty(2 * len(keys), dtype=np.int64), size)
        bigger[0][:n] = keys[:n]
        bigger[1][:n] = codes[:n]
        self.heap = bigger

    def run(
        self, qb: Any, step: Any, initial_radius: float, skip: NDArray[np.bool_] | None = None,
        lock: AbstractContextManager[Any] | None = None,
    ) -> tuple[list[Neighbour], SearchStats]:
        """The search; ``skip`` marks groups left to other threads, and ``lock`` guards
        each use of the source."""
        start = time.perf_counter()
        source, stats = self.source, SearchStats()
        lock = lock if lock is not None else nullcontext()
        seen = np.zeros(source.n_groups, dtype=np.bool_) if skip is None else skip.copy()
        order = np.zeros(0, dtype=np.int64)
        keys = np.zeros(0, dtype=np.float64)
        pos = ready = 0
        chunk = CHUNK
        radius = -math.inf
        exhausted = bool(seen.all())
        status = EXHAUSTED
        cap = self.cap
        while True:
            if status in (EXHAUSTED, RADIUS):
                if exhausted:
                    break
                # browse further: every group within the (grown) radius joins the candidates
                smallest = min(float(keys[pos]) if pos < len(keys) else math.inf,
                               float(self.heap[0][0]) if self.heap[2][0] else math.inf)
                # a known bound (a CS1 client's, earlier turns') is the radius at once: one
                # browse lists every group that may matter, instead of doubling up to it
                radius = min(max(2.0 * radius, smallest if math.isfinite(smallest) else 0.0,
                                 initial_radius, cap if math.isfinite(cap) else -math.inf), cap)
                stats.expansions += 1
                with lock:
                    found, found_keys = source.groups_within(qb, radius, seen)
                seen[found] = True
                keep = found_keys <= cap
                order = np.concatenate([order[pos:], found[keep]])
                keys = np.concatenate([keys[pos:], found_keys[keep]])
                by_key = np.argsort(keys, kind="stable")
                order, keys, pos, ready = order[by_key], keys[by_key], 0, 0
                exhausted = bool(seen.all()) or radius >= cap
            if ready < len(order) and (status == NEED or ready <= pos):
                # chunks double while a search goes on (read rows stay loaded for the next)
                end = min(len(order), max(ready, pos) + chunk)
                with lock:
                    rows = source.rows(order[ready:end])
                ready, chunk = end, min(2 * chunk, MAX_CHUNK)
            else:
                with lock:
                    rows = source.rows(order[:0])
            pos, status = step(self, order, keys, pos, ready, math.inf if exhausted else radius, rows)
            if status == DONE:
                break
        stats.groups_visited, stats.points_visited, stats.lb_keogh, stats.dtw = (
            int(x) for x in self.counters)
        stats.seconds = time.perf_counter() - start
        return self.result(), stats

    def result(self) -> list[Neighbour]:
        """The k objects of smallest exact distance found, each with its best view."""
        source = self.source
        exact = self.exact
        hits = sorted((float(exact[o]), source.object_name(int(o)), int(o))
                      for o in np.flatnonzero(np.isfinite(exact)))[: self.k]
        result = [Neighbour(name, source.view_id(int(self.exact_row[o])), d,
                            bool(self.exact_mirrored[o]), int(self.exact_curve[o]))
                  for d, name, o in hits]
        return result


def objects_within(
    query: NDArray[np.floating], source: TierSource, radius: float, r: int
) -> dict[str, float]:
    """Objects with a group whose MINDIST to the query box is at most ``radius``, each with
    its smallest such MINDIST (a lower bound of its exact distance).

    Every object whose exact distance is ``<= radius`` is among them (MINDIST bounds the
    distance of each of the group's views from below): the candidates a CS1 server must
    refine when the client's k-th distance is ``radius``.
    """
    if not radius >= 0:
        raise ValueError(f"radius must be >= 0, got {radius}")
    qb = QueryBoxes.of(query, r)
    found, keys = source.groups_within(qb, radius, np.zeros(source.n_groups, dtype=np.bool_))
    best: dict[int, float] = {}
    for g, key in zip(found.tolist(), keys.tolist(), strict=True):
        owner = int(source.group_owner[g])
        if key <= radius and key < best.get(owner, math.inf):
            best[owner] = key
    return {source.object_name(o): key for o, key in sorted(best.items(), key=lambda x: x[1])}
