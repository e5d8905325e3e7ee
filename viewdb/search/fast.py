"""The ``fast`` plan's search: an approximate shortlist of objects, then the exact search
over them.

1. Each query curve's turn- and mirror-free embedding (:mod:`viewdb.search.embedding`) asks
   the tier's approximate index (:class:`~viewdb.search.ann.ViewIndex`, keyed by row) for
   its nearest views; each object is ranked by its nearest view over every query curve,
   and the first ``shortlist`` objects are kept (:func:`shortlist_objects`).
2. Those objects alone are searched exactly (:func:`~viewdb.search.knn.knn_stack` over a
   :class:`~viewdb.search.subset.SubsetSource`): the answer is exactly the brute force
   over the shortlisted objects, each with its best view and its exact DTW distance.
   The search starts with a radius: the first k objects' nearest views, measured exactly
   (:func:`view_distances`), bound their distances and so the k-th (as a CS1 client's
   bounds do, :func:`~viewdb.search.knn.knn`), and groups past it are never refined.

So every distance reported is a true one, and only the shortlist is approximate: when the
exact answer's k objects are all shortlisted the answer *is* the exact one, and a
shortlist of every object gives the ``server`` plan's answer (tests hold both). A search
without an index (none built, a stale one) is the exact search of every object.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..catalogue.features import mirror_curve
from ..config import FastConfig, SearchConfig
from ..jit import njit
from .ann import ViewIndex
from .bounds import dtw_kernel
from .embedding import embed_curves
from .knn import Neighbour, SearchStats, TierSource, knn_stack
from .subset import SubsetSource, groups_by_object, runs_by_owner

__all__ = ["FastIndex", "build_fast_index", "embed_all", "fast_knn", "merged_queries", "rank_exactly",
           "shortlist_objects"]


@dataclass(frozen=True)
class FastIndex:
    """A tier's approximate index with what the ``fast`` search needs beside it: the
    object of each key (the tier's ``row_owner``) and the groups of each object
    (:func:`~viewdb.search.subset.groups_by_object`), and the settings it is asked with."""

    index: ViewIndex
    row_owner: NDArray[np.int64]
    by_object: tuple[NDArray[np.int64], NDArray[np.int64]]
    config: FastConfig
    #: each key's row, -1 for a key no row holds (an index grown in place,
    #: :mod:`viewdb.search.fast_update`); None when every key is its row
    row_of_key: NDArray[np.int64] | None = None
    #: every view's embedding, in row order, and the rows ordered by object (computed on
    #: first need: :func:`rank_exactly`), shared by the copies :meth:`dataclasses.replace` makes
    cache: dict[str, NDArray] = field(default_factory=dict, compare=False, repr=False)

    def embeddings(
        self, source: TierSource,
    ) -> tuple[NDArray[np.float32], NDArray[np.int64], NDArray[np.int64]]:
        """Every view's embedding (rows of ``source``), the rows ordered by object and where
        each object's run starts in that order (``n_objects + 1`` entries)."""
        if "vectors" not in self.cache:
            self.cache["vectors"] = embed_all(source, self.config)
        if "order" not in self.cache:
            self.cache["order"], self.cache["starts"] = runs_by_owner(self.row_owner, source.n_objects)
        return self.cache["vectors"], self.cache["order"], self.cache["starts"]

    @classmethod
    def of(
        cls, index: ViewIndex, source: TierSource, config: FastConfig,
        row_of_key: NDArray[np.int64] | None = None,
    ) -> FastIndex:
        """``index`` of the rows of ``source``, under keys that are the rows or, given
        ``row_of_key``, the keys it maps to rows."""
        keys = len(source.row_owner) if row_of_key is None else len(row_of_key)
        if index.size != keys:
            raise ValueError(f"the index holds {index.size} views, its keys name {keys}")
        return cls(index, np.asarray(source.row_owner, dtype=np.int64), groups_by_object(source), config,
                   row_of_key)

    def nearest_rows(
        self, vectors: NDArray[np.float32], count: int,
    ) -> tuple[NDArray[np.int64], NDArray[np.float32]]:
        """The index's nearest views to each of ``vectors`` as rows of the tier (-1 past the
        end, for a dead key, or for a key out of range: a damaged file costs recall only),
        and their squared distances (:meth:`~viewdb.search.ann.ViewIndex.nearest`)."""
        keys, distances = self.index.nearest(vectors, count, self.config.expansion_search)
        table = self.row_of_key
        limit = len(self.row_owner) if table is None else len(table)
        valid = (keys >= 0) & (keys < limit)
        if table is not None:
            keys = table[np.where(valid, keys, 0)]
        return np.where(valid, keys, -1), distances


#: Curves embedded at a time while an index is built (bounds the memory beside the tier's).
_EMBED_BLOCK = 65536


def embed_all(source: TierSource, config: FastConfig) -> NDArray[np.float32]:
    """The embedding (``config``'s) of every view of ``source``, in row order (every group read)."""
    curves = source.rows(np.arange(source.n_groups, dtype=np.int64))[0]
    rows = len(source.row_owner)
    vectors = np.empty((rows, config.coefficients + config.quantiles), dtype=np.float32)
    for start in range(0, rows, _EMBED_BLOCK):
        block = curves[start : start + _EMBED_BLOCK]
        vectors[start : start + len(block)] = embed_curves(block, config.coefficients, config.quantiles)
    return vectors


def build_fast_index(source: TierSource, config: FastConfig) -> FastIndex:
    """The ``fast`` index of every view of ``source`` (its rows, every group read)."""
    vectors = embed_all(source, config)
    index = ViewIndex.build(vectors, config.connectivity, config.expansion_add, config.build_threads)
    built = FastIndex.of(index, source, config)
    built.cache["vectors"] = vectors
    return built


def merged_queries(vectors: NDArray[np.float32], radius: float) -> NDArray[np.float32]:
    """The query embeddings to ask the index with: the rows of ``vectors`` gathered greedily
    (each joins the first gathering whose first row lies within ``radius``, else starts
    one), each gathering by its mean (a photo's in-plane turns embed alike, its completed
    outline elsewhere)."""
    firsts: list[int] = []
    members: list[list[int]] = []
    for i, v in enumerate(vectors):
        near = [j for j, f in enumerate(firsts) if float(np.sum((vectors[f] - v) ** 2)) <= radius * radius]
        if near:
            members[near[0]].append(i)
        else:
            firsts.append(i)
            members.append([i])
    return np.stack([vectors[m].mean(axis=0) for m in members]).astype(np.float32)


def shortlist_objects(
    curves: NDArray[np.floating], index: FastIndex, size: int, source: TierSource, least: int = 1,
) -> tuple[NDArray[np.int64], int]:
    """The ``size`` objects (indices of ``source``, best first) whose nearest indexed view is
    nearest any of ``curves`` ``(T, N)`` in the embedding (the curves' embeddings merged,
    :func:`merged_queries`), and how many views the index was asked for per query (0:
    ranked exactly). The index is asked again, for twice as many, until its views name
    ``size`` objects, up to :attr:`~viewdb.config.FastConfig.exact_share` of its views
    (the last time for exactly that many). If those name fewer objects (the photo's
    nearest views crowd into a few objects), the shortlist is the objects they name, if
    at least ``least``. A catalogue too small to be asked for ``size`` ×
    ``views_per_object`` views within that share, or views that name fewer than ``least``
    objects, are ranked by every view instead (:func:`rank_exactly`)."""
    objects, _, count = _shortlist(curves, index, size, source, least)
    return objects, count


def _shortlist(
    curves: NDArray[np.floating], index: FastIndex, size: int, source: TierSource, least: int,
) -> tuple[NDArray[np.int64], NDArray[np.int64] | None, int]:
    """:func:`shortlist_objects`, with each shortlisted object's nearest view (its row;
    None when ranked exactly)."""
    config = index.config
    q = merged_queries(embed_curves(curves, config.coefficients, config.quantiles), config.merge_radius)
    size = min(size, source.n_objects)
    count = max(size * config.views_per_object, 1)
    most = int(config.exact_share * index.index.size)  # exact_share is at most 1
    while count <= most:
        found, distances = index.nearest_rows(q, count)
        valid = found >= 0
        order = np.argsort(distances[valid], kind="stable")
        rows = found[valid][order]
        _, first = np.unique(index.row_owner[rows], return_index=True)
        nearest = rows[np.sort(first)]
        if len(nearest) >= size or count == most:
            if len(nearest) < min(least, size):
                break
            # (ranking every view instead embeds the whole tier once: 1.6 s at 557,273 views)
            nearest = nearest[:size].astype(np.int64)
            return index.row_owner[nearest].astype(np.int64), nearest, count
        count = min(2 * count, most)
    return rank_exactly(q, index, source)[:size], None, 0


def rank_exactly(queries: NDArray[np.float32], index: FastIndex, source: TierSource) -> NDArray[np.int64]:
    """Every object of ``source`` that has views, by its nearest view's embedding to any of
    ``queries``, nearest first (ties by object index)."""
    vectors, order, starts = index.embeddings(source)
    norms = np.einsum("ij,ij->i", vectors, vectors)
    d = np.min(norms[None, :] - 2.0 * (queries @ vectors.T), axis=0)[order]
    held = np.flatnonzero(starts[1:] > starts[:-1])
    best = np.minimum.reduceat(d, starts[held]) if len(held) else np.zeros(0)
    return held[np.argsort(best, kind="stable")].astype(np.int64)


def fast_knn(
    curves: NDArray[np.floating], source: TierSource, index: FastIndex | None, k: int, band: int,
    shortlist: int, *, upper: float = math.inf, known: Mapping[int, float] | None = None,
) -> tuple[list[Neighbour], SearchStats]:
    """The k nearest objects to a stack of curves ``(T, N)`` among the ``shortlist``
    objects ``index`` finds (module doc), exactly as :func:`~viewdb.search.knn.knn_stack`
    over those objects; ``upper``/``known`` as there. Without ``index``, or with a
    shortlist of every object, the exact search of every object. Returns the results,
    with the exact search's counters and the shortlist's in ``stats.extra``
    (``shortlisted``, ``ann_ms``, ``fast_index``: 1 if the index was used)."""
    stack = np.ascontiguousarray(np.atleast_2d(curves), dtype=np.float64)
    block = SearchConfig().stack_block
    if index is None or shortlist >= source.n_objects:
        found, stats = knn_stack(stack, source, k, band, upper=upper, known=known, block=block)
        stats.extra.update(shortlisted=float(source.n_objects), fast_index=float(index is not None))
        return found, stats
    start = time.perf_counter()
    objects, nearest, _ = _shortlist(stack, index, max(shortlist, k), source, k)
    subset = SubsetSource(source, objects, index.by_object)
    listed = set(objects.tolist())
    bounds = {o: d for o, d in (known or {}).items() if o in listed}
    if nearest is not None and len(nearest) >= k:
        # the first k objects' nearest views, measured exactly: each bounds its object's
        # distance, the largest the k-th, so the search starts with that radius (measuring
        # every shortlisted object's view as well narrowed it no further on photos)
        firsts = objects[:k].tolist()
        for o, d in zip(firsts, view_distances(stack, source, nearest[:k], band), strict=True):
            bounds[o] = min(d, bounds.get(o, math.inf))
        upper = min(upper, max(bounds[o] for o in firsts))
    ann_ms = (time.perf_counter() - start) * 1e3
    found, stats = knn_stack(stack, subset, k, band, upper=upper, known=bounds, block=block, priority=objects)
    stats.extra.update(shortlisted=float(len(objects)), ann_ms=ann_ms, fast_index=1.0)
    return found, stats


def view_distances(
    stack: NDArray[np.float64], source: TierSource, rows: NDArray[np.int64], band: int,
) -> list[float]:
    """The exact distance of each view (a row of ``source``) to a stack of curves, as the
    search measures it: the least DTW over the curves and the view's mirror."""
    starts, counts = source.group_start, source.group_count
    groups = [_group_of(starts, counts, row) for row in rows.tolist()]
    curves = source.rows(np.unique(np.array(groups, dtype=np.int64)))[0]
    views = np.ascontiguousarray(np.asarray(curves[rows], dtype=np.float64))
    shown = np.ascontiguousarray(np.stack([views, mirror_curve(views)], axis=1))
    queries = np.ascontiguousarray(stack, dtype=np.float64)
    out = np.empty(len(rows))
    _least_dtw(queries, shown, min(int(band), queries.shape[1] - 1), out)
    return out.tolist()


def _group_of(starts: NDArray[np.integer], counts: NDArray[np.integer], row: int) -> int:
    """The group that holds ``row``: found by bisection where the groups lie in row order
    (a tier file's do), else by a scan."""
    g = int(np.searchsorted(starts, row, side="right")) - 1
    if 0 <= g < len(starts) and starts[g] <= row < starts[g] + counts[g]:
        return g
    return int(np.flatnonzero((starts <= row) & (row < starts + counts))[0])


@njit(cache=True, nogil=True)
def _least_dtw(queries, shown, band, out):  # pragma: no cover - compiled
    """``out[i]``: the least DTW distance between any of ``queries`` ``(T, N)`` and any
    curve of ``shown[i]`` ``(2, N)`` (a view and its mirror), each search bounded by the
    best so far (:func:`~viewdb.search.bounds.dtw_kernel`)."""
    for i in range(shown.shape[0]):
        best = math.inf
        for m in range(shown.shape[1]):
            for t in range(queries.shape[0]):
                best = min(best, dtw_kernel(queries[t], shown[i, m], band, best))
        out[i] = best
