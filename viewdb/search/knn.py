"""Exact k-NN over distance curves: Algorithm 2 as a best-first search, and its reference.

One min-priority queue mixes four kinds of entries, each keyed by a lower bound of the
exact distance of everything below it (:mod:`viewdb.search.bounds` proves the chain):

* a **group** (an MBR around a few views of one object, :mod:`viewdb.search.grouping`),
  keyed by ``MINDIST`` of the query box (or the mirrored box) to the MBR;
* a **curve** (a view's curve, or its reverse for the mirror view), keyed by
  ``max(Fourier_Dist, LB_Keogh)``: both bound the exact distance, so their maximum does
  too. Algorithm 2 pushes the Fourier point first and the curve when that pops; here
  both bounds are computed at once, vectorised over a group's views when the group
  pops, and sorted: the queue holds one *cursor* per opened group, keyed by the bound
  of its next unrefined curve (a lazy merge of the sorted lists), which pops curves in
  exactly the order the per-curve entries would;
* a **curve with its DTW distance**, keyed by the exact distance.

When an exact entry reaches the top, no entry left can beat it, so its object is final
(Algorithm 2, lines 8–11); entries of objects already in the result are dropped (lines
5–6). The exact distance of a view is ``min(DTW(q, c), DTW(q, reverse(c)))`` with a
Sakoe–Chiba band of ``r`` samples.

Groups come from a :class:`TierSource`: an R-tree in the database
(:class:`viewdb.storage.tiers.StoredTier`) or arrays in memory (:class:`TierArrays`).
The queue is fed by **range browsing**: it holds every group whose MINDIST is at most a
radius ``rho``; entries are popped only while the top key is ``<= rho``, and when the
top exceeds ``rho`` (or the queue runs dry) ``rho`` grows and the source is asked for
the groups within the new radius. Every group with key ``<= rho`` is in the queue
whenever something is popped, so entries pop in exactly the order of a queue that held
all groups from the start: the result is that of Algorithm 2. :func:`brute_force_knn`
computes the same answer by scanning everything and is the oracle the tests use.
"""

from __future__ import annotations

import heapq
import math
import time
from collections.abc import Mapping
from collections.abc import Set as AbstractSet
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..features import mirror_curve
from .bounds import (
    _cascade_dtw_kernel,
    curve_box_lb_many,
    dtw,
    envelope,
    envelope_box,
    fourier_coordinates,
    group_bounds,
    mindist_many,
    mirror_box,
)
from .grouping import INDEXED_COEFFICIENTS, group_points, indexed_coordinates, indexed_rows, padded_mbr

__all__ = [
    "Group",
    "Neighbour",
    "QueryBoxes",
    "SearchStats",
    "TierArrays",
    "TierSource",
    "brute_force_knn",
    "knn",
    "objects_within",
]

#: First search radius of the range browsing (curves have mean 1; near views are ~0.1 apart).
INITIAL_RADIUS = 0.125


@dataclass(frozen=True)
class Neighbour:
    """One result: an object, its best view (an id of the source) and the exact distance."""

    object: str
    view: int
    distance: float
    mirrored: bool


@dataclass
class SearchStats:
    """What a search did: groups opened, bounds and DTWs computed, range expansions."""

    groups_visited: int = 0
    points_visited: int = 0
    lb_keogh: int = 0
    dtw: int = 0
    expansions: int = 0
    seconds: float = 0.0

    def to_dict(self) -> dict[str, float]:
        return dict(self.__dict__)


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

    @classmethod
    def of(cls, curve: NDArray[np.floating], band: int) -> QueryBoxes:
        q = np.ascontiguousarray(curve, dtype=np.float64)
        lower, upper = envelope(q, band)
        m = max(INDEXED_COEFFICIENTS) + 1
        lo, hi = envelope_box(lower, upper, fourier_coordinates(m, len(q)))
        mlo, mhi = mirror_box(lo, hi)
        rows = indexed_rows(m)
        return cls(q, band, lower, upper, mirror_curve(lower), mirror_curve(upper),
                   (lo[rows], hi[rows]), (mlo[rows], mhi[rows]))

    def group_keys(
        self, lo: NDArray[np.float64], hi: NDArray[np.float64],
        curve_lo: NDArray[np.float64], curve_hi: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        """Lower bounds of the distance to every view of groups given by their MBRs (rows of
        ``(g, d)``) and per-sample curve ranges (rows of ``(g, N)``), either orientation:
        the larger of MINDIST and the curve-box bound (module doc of
        :mod:`~viewdb.search.bounds`)."""
        mind = np.minimum(mindist_many(*self.box, lo, hi), mindist_many(*self.mirrored_box, lo, hi))
        if not len(curve_lo):
            return mind
        boxed = np.minimum(
            curve_box_lb_many(self.lower, self.upper, curve_lo, curve_hi),
            curve_box_lb_many(self.mirrored_lower, self.mirrored_upper, curve_lo, curve_hi),
        )
        return np.maximum(mind, boxed)


@dataclass(frozen=True)
class Group:
    """A few views of one object, as a search needs them."""

    object: int
    #: View ids (of the source), (n,).
    views: NDArray[np.int64]
    #: Distance curves, (n, N) float64 contiguous, and their mirrors.
    curves: NDArray[np.float64]
    mirrored: NDArray[np.float64]
    #: Indexed Fourier coordinates of ``curves``, (n, d).
    coords: NDArray[np.float64]

    @classmethod
    def of(cls, object: int, views: NDArray[np.int64], curves: NDArray[np.floating]) -> Group:
        c = np.ascontiguousarray(curves, dtype=np.float64)
        return cls(object, views, c, np.ascontiguousarray(np.roll(c[:, ::-1], 1, axis=1)),
                   np.ascontiguousarray(indexed_coordinates(c)))


class TierSource(Protocol):
    """Where a search gets its groups from."""

    #: Number of groups in the tier.
    n_groups: int

    def groups_within(
        self, query: QueryBoxes, radius: float, skip: AbstractSet[int] = frozenset()
    ) -> list[tuple[int, float, int]]:
        """``(group id, key, object)`` of (at least) every group whose MINDIST is ``<=
        radius``, except those in ``skip``; ``key`` is :meth:`QueryBoxes.group_keys` of the
        group."""
        ...

    def group(self, gid: int) -> Group: ...

    def object_name(self, index: int) -> str: ...

    def object_index(self, name: str) -> int | None: ...


@dataclass
class TierArrays:
    """A tier held in memory: curves with their owners, grouped like the stored R-trees.

    The reference implementation of :class:`TierSource` (and what tests build from
    random curves); :func:`brute_force_knn` scans it.
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
    curve_lo: NDArray[np.float64] = field(init=False)
    curve_hi: NDArray[np.float64] = field(init=False)

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
        self.curve_lo = np.array([self.curves[v].min(axis=0) for v in self.groups]).reshape(g, n)
        self.curve_hi = np.array([self.curves[v].max(axis=0) for v in self.groups]).reshape(g, n)

    @property
    def n_groups(self) -> int:
        return len(self.groups)

    def groups_within(
        self, query: QueryBoxes, radius: float, skip: AbstractSet[int] = frozenset()
    ) -> list[tuple[int, float, int]]:
        mind = query.group_keys(self.mbr_lo, self.mbr_hi, self.curve_lo[:0], self.curve_hi[:0])
        hits = np.array([g for g in np.flatnonzero(mind <= radius).tolist() if g not in skip],
                        dtype=np.int64)
        if not len(hits):
            return []
        keys = query.group_keys(self.mbr_lo[hits], self.mbr_hi[hits], self.curve_lo[hits],
                                self.curve_hi[hits])
        return [(int(g), float(key), int(self.owner[self.groups[g][0]]))
                for g, key in zip(hits.tolist(), keys.tolist(), strict=True)]

    def group(self, gid: int) -> Group:
        views = self.groups[gid]
        return Group.of(int(self.owner[views[0]]), views, self.curves[views])

    def object_name(self, index: int) -> str:
        return self.names[index]

    def object_index(self, name: str) -> int | None:
        return self.names.index(name) if name in self.names else None


def brute_force_knn(query: NDArray[np.floating], tier: TierArrays, k: int, r: int) -> list[Neighbour]:
    """The reference: exact distance to every view, best view per object, top k objects."""
    q = np.asarray(query, dtype=np.float64)
    best: dict[int, Neighbour] = {}
    for i, c in enumerate(tier.curves):
        d, dm = dtw(q, c, r), dtw(q, mirror_curve(c), r)
        dist, mirrored = (dm, True) if dm < d else (d, False)
        o = int(tier.owner[i])
        if o not in best or dist < best[o].distance:
            best[o] = Neighbour(tier.names[o], i, dist, mirrored)
    return sorted(best.values(), key=lambda nb: (nb.distance, nb.object))[:k]


_GROUP, _CURSOR, _EXACT = 0, 1, 2


def knn(
    query: NDArray[np.floating],
    source: TierSource,
    k: int,
    r: int,
    *,
    upper: float = math.inf,
    known: Mapping[int, float] | None = None,
) -> tuple[list[Neighbour], SearchStats]:
    """The k nearest distinct objects (Algorithm 2), exactly as :func:`brute_force_knn`.

    ``upper`` and ``known`` are what a CS1 client hands the server (Algorithm 3): an upper
    bound of the k-th distance (the client's k-th distance on the sparse tier, whose views
    are all in the full tier), and upper bounds of some objects' distances (object index
    → the client's distance). Groups whose key exceeds ``upper`` are never fetched; the
    result is unchanged as long as the bounds hold.

    DTW runs after the UCR cascade (LB_Keogh against the candidate's envelope) and
    abandons early past ``min(U, b_o)``: ``U`` the k-th smallest of the best distances
    found so far of distinct objects (the final k-th distance is at most ``U``) and
    ``b_o`` the best found so far for the candidate's object. A curve beyond that can
    neither enter the result nor improve its object, so it is dropped.
    """
    start = time.perf_counter()
    stats = SearchStats()
    qb = QueryBoxes.of(query, r)
    q, envelope_pair, mirrored_pair = qb.curve, (qb.lower, qb.upper), (qb.mirrored_lower, qb.mirrored_upper)
    # entries: (key, tiebreak, kind, gid, x): x is the object of a group entry and the
    # position in the group's sorted bounds of a cursor or exact entry
    heap: list[tuple[float, int, int, int, int]] = []
    counter = 0
    seen: set[int] = set()
    opened: dict[int, tuple[Group, NDArray[np.float64], NDArray[np.int64]]] = {}
    radius = -math.inf
    exhausted = source.n_groups == 0
    result: list[Neighbour] = []
    done: set[int] = set()
    # best distance known so far per object (computed here, or an upper bound handed in)
    found: dict[int, float] = dict(known or {})
    bound = sorted(found.values())[k - 1] if len(found) >= k else math.inf  # U: k-th of found
    if math.isfinite(upper):  # widened by a hair, like the limits below
        upper = upper * (1.0 + 1e-9) + 1e-12
    bound = min(bound, upper)
    while len(result) < k:
        while not exhausted and (not heap or heap[0][0] > radius):
            radius = min(max(2.0 * radius, heap[0][0] if heap else 0.0, INITIAL_RADIUS), upper)
            stats.expansions += 1
            for gid, key, owner in source.groups_within(qb, radius, seen):
                seen.add(gid)
                if key <= upper:
                    heap.append((key, counter, _GROUP, gid, owner))
                    counter += 1
            heapq.heapify(heap)
            exhausted = len(seen) >= source.n_groups or radius >= upper
        if not heap:
            break
        key, _, kind, gid, position = heapq.heappop(heap)
        if kind == _GROUP:
            if position in done:  # a group entry carries its object in the last slot
                continue
            group = source.group(gid)
            stats.groups_visited += 1
            n = len(group.views)
            stats.points_visited += n
            stats.lb_keogh += 2 * n
            keys = group_bounds(envelope_pair, mirrored_pair, qb.box, qb.mirrored_box,
                                group.coords, group.curves)
            order = np.argsort(keys, kind="stable")
            keys = keys[order]
            opened[gid] = (group, keys, order)
            heapq.heappush(heap, (float(keys[0]), counter, _CURSOR, gid, 0))
            counter += 1
            continue
        group, keys, order = opened[gid]
        owner = group.object
        if owner in done:
            continue
        n = len(group.views)
        slot = int(order[position])
        view, mirrored = slot % n, slot >= n
        if kind == _EXACT:
            done.add(owner)
            result.append(Neighbour(source.object_name(owner), int(group.views[view]), key, mirrored))
            continue
        # a cursor: refine its curve exactly, move on to the group's next curve
        # bounds and DTW sum the same squares in different orders: a bound may exceed the
        # distance it bounds by a few ulps, so a limit that *equals* a distance (an upper
        # bound handed in, or a tie) is widened by a hair before anything is dropped
        limit = min(bound, found.get(owner, math.inf)) * (1.0 + 1e-9) + 1e-12
        if key > limit:  # so are the group's later curves (sorted), and limits only shrink
            continue
        if position + 1 < len(keys):
            heapq.heappush(heap, (float(keys[position + 1]), counter, _CURSOR, gid, position + 1))
            counter += 1
        stats.dtw += 1
        curve = group.mirrored[view] if mirrored else group.curves[view]
        distance = float(_cascade_dtw_kernel(q, curve, r, limit))
        if distance > limit:  # abandoned (inf): it can neither enter the result nor improve
            continue
        heapq.heappush(heap, (distance, counter, _EXACT, gid, position))
        counter += 1
        if distance < found.get(owner, math.inf):
            found[owner] = distance
            if len(found) >= k and distance < bound:
                bound = min(bound, sorted(found.values())[k - 1])
    stats.seconds = time.perf_counter() - start
    return result, stats


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
    best: dict[int, float] = {}
    for _, key, owner in source.groups_within(qb, radius):
        if key <= radius and key < best.get(owner, math.inf):
            best[owner] = key
    return {source.object_name(o): key for o, key in sorted(best.items(), key=lambda x: x[1])}
