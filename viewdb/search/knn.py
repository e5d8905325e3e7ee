"""Exact k-NN over distance curves: Algorithm 2 as a best-first search, and its reference.

One min-priority queue mixes four kinds of entries, each keyed by a lower bound of the
exact distance of everything below it (:mod:`viewdb.search.bounds` proves the chain):

* an **object** (its views' MBR in Fourier space), keyed by ``MINDIST`` of the query box
  (or the mirrored box) to the MBR;
* a **Fourier point** of one view, keyed by ``Fourier_Dist`` (box or mirrored box);
* a **curve** (a view's curve, or its reverse for the mirror view), keyed by LB_Keogh;
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
    lb_keogh,
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
    coords: NDArray[np.float64] = field(init=False)
    mbr_lo: NDArray[np.float64] = field(init=False)
    mbr_hi: NDArray[np.float64] = field(init=False)
    _rows: NDArray[np.int64] = field(init=False)
    _F: NDArray[np.float64] = field(init=False)

    def __post_init__(self) -> None:
        n = self.curves.shape[1]
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
    OBJECT, POINT, CURVE, EXACT = 0, 1, 2, 3
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
        owner = index if kind == OBJECT else int(tier.owner[index])
        if owner in done:
            continue
        if kind == EXACT:
            done.add(owner)
            result.append(Neighbour(tier.names[owner], index, key, bool(mirrored)))
        elif kind == OBJECT:
            stats.objects_visited += 1
            views = views_of[index]
            d = np.minimum(fourier_dist_many(*box, tier.coords[views]),
                           fourier_dist_many(*mbox, tier.coords[views]))
            for v, dv in zip(views, d, strict=True):
                heapq.heappush(heap, (float(dv), counter, POINT, int(v), 0))
                counter += 1
        elif kind == POINT:
            stats.points_visited += 1
            c = tier.curves[index]
            for m, curve in ((0, c), (1, mirror_curve(c))):
                stats.lb_keogh += 1
                heapq.heappush(heap, (lb_keogh(lower, upper, curve), counter, CURVE, index, m))
                counter += 1
        else:  # CURVE: refine to the exact distance
            stats.dtw += 1
            c = tier.curves[index]
            curve = mirror_curve(c) if mirrored else c
            heapq.heappush(heap, (dtw(q, curve, r), counter, EXACT, index, mirrored))
            counter += 1
    stats.seconds = time.perf_counter() - start
    return result, stats
