"""Exact k-NN over distance curves: Algorithm 2 as a best-first search, and its reference.

One min-priority queue mixes four kinds of entries, each keyed by a lower bound of the
exact distance of everything below it (:mod:`viewdb.search.bounds` proves the chain):

* an **object** (its views' MBR in Fourier space), keyed by ``MINDIST`` of the query box
  (or the mirrored box) to the MBR;
* a **curve** (a view's curve, or its reverse for the mirror view), keyed by
  ``max(Fourier_Dist, LB_Keogh)``: both bound the exact distance, so their maximum does
  too. Algorithm 2 pushes the Fourier point first and the curve when that pops; here
  both bounds are computed at once, vectorised over an object's views when the object
  pops, and sorted: the queue holds one *cursor* per opened object, keyed by the bound
  of its next unrefined curve (a lazy merge of the sorted lists), which pops curves in
  exactly the order the per-curve entries would, with a queue of objects, not views;
* a **curve with its DTW distance**, keyed by the exact distance.

When an exact entry reaches the top, no entry left can beat it, so its object is final
(Algorithm 2, lines 8–11); entries of objects already in the result are dropped (lines
5–6). The exact distance of a view is ``min(DTW(q, c), DTW(q, reverse(c)))`` with a
Sakoe–Chiba band of ``r`` samples. :func:`brute_force_knn` computes the same answer by
scanning everything and is the oracle the tests compare against.

This module works on in-memory arrays (:class:`TierArrays`); the R-tree pages of
:mod:`viewdb.storage.spatial` are the persistent form of the same grouping.
"""

from __future__ import annotations

import heapq
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..features import mirror_curve
from .bounds import (
    dtw,
    envelope,
    envelope_box,
    fourier_coordinates,
    fourier_dist_many,
    lb_keogh_many,
    mindist,
    mirror_box,
)

__all__ = ["Neighbour", "SearchStats", "TierArrays", "brute_force_knn", "knn"]

#: Fourier coefficients indexed: X_1..X_3 (X_0 is constant: curves have mean 1).
INDEXED_COEFFICIENTS = (1, 2, 3)


@dataclass(frozen=True)
class Neighbour:
    """One result: an object, its best view and the exact distance."""

    object: str
    view: int
    distance: float
    mirrored: bool


@dataclass
class SearchStats:
    objects_visited: int = 0
    points_visited: int = 0
    lb_keogh: int = 0
    dtw: int = 0
    seconds: float = 0.0


@dataclass
class TierArrays:
    """The views of one tier: curves, indexed Fourier coordinates, object grouping."""

    names: list[str]
    #: Object index of each view, (n,).
    owner: NDArray[np.int64]
    #: Distance curves, (n, N) float64.
    curves: NDArray[np.float64]
    #: The curves of the mirror views (reversed about the start), (n, N).
    mirrored: NDArray[np.float64] = field(init=False)
    coords: NDArray[np.float64] = field(init=False)
    mbr_lo: NDArray[np.float64] = field(init=False)
    mbr_hi: NDArray[np.float64] = field(init=False)
    _rows: NDArray[np.int64] = field(init=False)
    _F: NDArray[np.float64] = field(init=False)

    def __post_init__(self) -> None:
        n = self.curves.shape[1]
        self.curves = np.ascontiguousarray(self.curves, dtype=np.float64)
        self.mirrored = np.ascontiguousarray(np.roll(self.curves[:, ::-1], 1, axis=1))
        m = max(INDEXED_COEFFICIENTS) + 1
        self._F = fourier_coordinates(m, n)
        self._rows = np.array(
            [k for k in INDEXED_COEFFICIENTS] + [m + k for k in INDEXED_COEFFICIENTS]
        )
        self.coords = (self.curves @ self._F.T)[:, self._rows]
        groups = len(self.names)
        self.mbr_lo = np.full((groups, len(self._rows)), np.inf)
        self.mbr_hi = np.full((groups, len(self._rows)), -np.inf)
        np.minimum.at(self.mbr_lo, self.owner, self.coords)
        np.maximum.at(self.mbr_hi, self.owner, self.coords)

    def query_boxes(self, query: NDArray[np.float64], r: int):  # type: ignore[no-untyped-def]
        """The query envelope's box and its mirror, in the indexed coordinates."""
        lower, upper = envelope(query, r)
        lo, hi = envelope_box(lower, upper, self._F)
        mlo, mhi = mirror_box(lo, hi)
        return (lo[self._rows], hi[self._rows]), (mlo[self._rows], mhi[self._rows]), (lower, upper)


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


def knn(
    query: NDArray[np.floating], tier: TierArrays, k: int, r: int
) -> tuple[list[Neighbour], SearchStats]:
    """The k nearest distinct objects (Algorithm 2), exactly as :func:`brute_force_knn`."""
    start = time.perf_counter()
    stats = SearchStats()
    q = np.asarray(query, dtype=np.float64)
    box, mbox, (lower, upper) = tier.query_boxes(q, r)
    heap: list[tuple[float, int, int, int, int]] = []  # (key, tiebreak, kind, index, mirrored)
    counter = 0
    OBJECT, CURSOR, EXACT = 0, 2, 3
    cursors: dict[int, tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]] = {}
    for o in range(len(tier.names)):
        key = min(mindist(*box, tier.mbr_lo[o], tier.mbr_hi[o]),
                  mindist(*mbox, tier.mbr_lo[o], tier.mbr_hi[o]))
        heap.append((key, counter, OBJECT, o, 0))
        counter += 1
    heapq.heapify(heap)
    views_of = [np.flatnonzero(tier.owner == o) for o in range(len(tier.names))]
    result: list[Neighbour] = []
    done: set[int] = set()
    while heap and len(result) < k:
        key, _, kind, index, mirrored = heapq.heappop(heap)
        owner = index if kind in (OBJECT, CURSOR) else int(tier.owner[index])
        if owner in done:
            continue
        if kind == EXACT:
            done.add(owner)
            result.append(Neighbour(tier.names[owner], index, key, bool(mirrored)))
        elif kind == OBJECT:
            stats.objects_visited += 1
            views = views_of[index]
            stats.points_visited += len(views)
            stats.lb_keogh += 2 * len(views)
            points = tier.coords[views]
            keys = np.concatenate([
                np.maximum(fourier_dist_many(*box, points),
                           lb_keogh_many(lower, upper, tier.curves[views])),
                np.maximum(fourier_dist_many(*mbox, points),
                           lb_keogh_many(lower, upper, tier.mirrored[views])),
            ])
            order = np.argsort(keys, kind="stable")
            cursors[index] = (keys[order], np.concatenate([views, views])[order],
                              (order >= len(views)).astype(np.int64))
            heapq.heappush(heap, (float(cursors[index][0][0]), counter, CURSOR, index, 0))
            counter += 1
        elif kind == CURSOR:  # the object's next curve in bound order: refine it exactly
            keys, order_views, order_mirror = cursors[index]
            position = mirrored  # the cursor's position rides in the last slot
            view, m = int(order_views[position]), int(order_mirror[position])
            stats.dtw += 1
            curve = tier.mirrored[view] if m else tier.curves[view]
            heapq.heappush(heap, (dtw(q, curve, r), counter, EXACT, view, m))
            counter += 1
            if position + 1 < len(keys):
                heapq.heappush(heap, (float(keys[position + 1]), counter, CURSOR, index, position + 1))
                counter += 1
    stats.seconds = time.perf_counter() - start
    return result, stats
