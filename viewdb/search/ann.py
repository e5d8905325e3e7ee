"""The approximate nearest-neighbour index of the ``fast`` plan: an HNSW graph (USearch)
over the embeddings of a tier's views (:mod:`viewdb.search.embedding`), keyed by the
tier's row numbers.

Why USearch (``usearch`` on PyPI): a maintained, single-purpose HNSW library with wheels
for every platform viewdb runs on and no OpenMP runtime of its own (numba's threads stay
alone); an index serialises to one buffer that a later process *views* in place (a
mapped file: opening costs milliseconds and reads only the pages a search touches),
which is how viewdb already keeps its tier files (:mod:`viewdb.storage.tier_file`).
hnswlib loads the whole graph into memory on every open and has had no release since
2023; FAISS's HNSW is as good but a much larger dependency, with its own OpenMP.

The library is imported on first use (:func:`viewdb.lazy.lazy_module`), so ``import
viewdb`` and the exact plans never load it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..lazy import lazy_module

usearch_index = lazy_module("usearch.index")

__all__ = ["ViewIndex"]


class ViewIndex:
    """An HNSW index of embeddings under integer keys: ``0 .. size - 1`` as built (a
    view's row), any unused key as added (:meth:`add`)."""

    def __init__(self, index: Any, keep: Any = None) -> None:
        """``index``: a ``usearch.index.Index``; ``keep``: what its viewed buffer lives in
        (a mapping kept open as long as the index)."""
        self._index = index
        self._keep = keep

    @classmethod
    def build(
        cls, vectors: NDArray[np.floating], connectivity: int, expansion_add: int, threads: int = 0,
    ) -> ViewIndex:
        """An index of the rows of ``vectors`` ``(V, d)``, row ``i`` under key ``i``;
        ``threads``: those that insert (0: every core)."""
        x = np.ascontiguousarray(vectors, dtype=np.float32)
        index = usearch_index.Index(ndim=x.shape[1], metric="l2sq", dtype="f32", connectivity=connectivity,
                                    expansion_add=expansion_add, enable_key_lookups=False)
        if len(x):
            index.add(np.arange(len(x), dtype=np.uint64), x, threads=threads)
        return cls(index)

    @classmethod
    def view(cls, buffer: memoryview, keep: Any = None) -> ViewIndex:
        """The index serialised in ``buffer`` (:meth:`to_bytes`), used in place (not copied);
        ``keep`` (the buffer's owner, e.g. a mapping) is held as long as the index.
        Raises ValueError if the buffer does not hold an index."""
        index = usearch_index.Index(enable_key_lookups=False)
        try:
            index.view(buffer)
        except (RuntimeError, ValueError) as exc:
            raise ValueError(f"not a USearch index: {exc}") from exc
        return cls(index, keep if keep is not None else buffer)

    @classmethod
    def load(cls, buffer: memoryview | bytes, expansion_add: int) -> ViewIndex:
        """A copy in memory of the index serialised in ``buffer``, which :meth:`add` may grow
        (adding with ``expansion_add`` candidates). Raises ValueError if the buffer does not
        hold an index."""
        index = usearch_index.Index(enable_key_lookups=False)
        try:
            index.load(bytearray(buffer))
        except (RuntimeError, ValueError) as exc:
            raise ValueError(f"not a USearch index: {exc}") from exc
        index.expansion_add = int(expansion_add)
        return cls(index)

    def add(self, keys: NDArray[np.integer], vectors: NDArray[np.floating], threads: int = 0) -> None:
        """Insert the rows of ``vectors`` ``(n, d)`` under ``keys`` (none in the index yet);
        ``threads``: those that insert (0: every core). Raises ValueError for an index used in
        place (:meth:`view`) or vectors of another width."""
        if self._keep is not None:
            raise ValueError("an index used in place cannot grow: load a copy")
        x = np.ascontiguousarray(vectors, dtype=np.float32)
        if x.ndim != 2 or x.shape[1] != self.ndim or len(x) != len(keys):
            raise ValueError(f"{len(keys)} keys need ({len(keys)}, {self.ndim}) vectors, got {x.shape}")
        if len(x):
            self._index.add(np.asarray(keys, dtype=np.uint64), x, threads=threads)

    def to_bytes(self) -> bytes:
        """The index serialised (what :meth:`view` reads)."""
        return bytes(self._index.save())

    @property
    def size(self) -> int:
        return int(self._index.size)

    @property
    def ndim(self) -> int:
        return int(self._index.ndim)

    def nearest(
        self, vectors: NDArray[np.floating], count: int, expansion: int,
    ) -> tuple[NDArray[np.int64], NDArray[np.float32]]:
        """The (approximately) ``count`` nearest rows of each query vector (rows of
        ``vectors`` ``(Q, d)``), nearest first, as ``(Q, count)`` rows (-1 past the end)
        and squared distances; ``expansion``: candidates the graph search keeps (at least
        ``count`` are)."""
        q = np.ascontiguousarray(np.atleast_2d(vectors), dtype=np.float32)
        count = max(1, min(int(count), self.size))
        self._index.expansion_search = max(int(expansion), count)
        keys = np.full((len(q), count), -1, dtype=np.int64)
        distances = np.full((len(q), count), np.inf, dtype=np.float32)
        if not len(q) or not self.size:
            return keys, distances
        found = self._index.search(q, count, threads=1)
        # one query gives its matches (as many as found), several a padded batch with counts
        counts = np.asarray(getattr(found, "counts", [len(found.keys)])).reshape(len(q))
        got = np.asarray(found.keys, dtype=np.int64).reshape(len(q), -1)
        near = np.asarray(found.distances, dtype=np.float32).reshape(len(q), -1)
        valid = np.arange(got.shape[1])[None, :] < counts[:, None]
        keys[:, : got.shape[1]] = np.where(valid, got, -1)
        distances[:, : got.shape[1]] = np.where(valid, near, np.inf)
        return keys, distances
