"""Keeping the ``fast`` plan's index in step with its tier without building it again.

The index's keys name views. Each group of the tier (its views, in row order) holds a
run of keys, recorded in a :class:`KeyTable` beside the index: per group, in the tier's
order, the digest of its curves, its first key and its number of views. A new index's
keys are its rows. When the tier changes (an ingest adds, replaces or removes objects),
:func:`plan_update` matches the new tier's groups to the table's by their curves' digest
and size: a group with the same curves keeps its keys (the same curves embed alike), the
views of any other group are added under new keys (:func:`update_fast_index`), and the
keys of groups gone stay in the graph, dead: the search maps them to no row
(:attr:`~viewdb.search.fast.FastIndex.row_of_key`) and passes over them. Once the dead
keys pass :attr:`~viewdb.config.FastConfig.dead_share` of the index, it is built anew,
so a search never meets more than that share of dead views.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..config import FastConfig
from .ann import ViewIndex
from .embedding import embed_curves
from .fast import FastIndex
from .knn import TierSource

__all__ = ["KeyTable", "group_digests", "plan_update", "runs", "update_fast_index"]


@dataclass(frozen=True)
class KeyTable:
    """Per group of a tier, in its order: the digest of its curves, the first of its run
    of keys and its number of views; and ``keys``, the index's key count (every key
    below it is in the index, a live group's or a dead one)."""

    digests: NDArray[np.uint64]
    first: NDArray[np.int64]
    counts: NDArray[np.int64]
    keys: int

    @classmethod
    def fresh(cls, digests: NDArray[np.uint64], counts: NDArray[np.int64]) -> KeyTable:
        """The table of an index built anew: each view's key is its row."""
        counts = np.asarray(counts, dtype=np.int64)
        first = np.cumsum(counts) - counts
        return cls(np.asarray(digests, dtype=np.uint64), first, counts, int(counts.sum()))

    @property
    def rows(self) -> int:
        """The live views: the tier's rows."""
        return int(self.counts.sum())

    @property
    def dead(self) -> int:
        """The keys in the index that name no row."""
        return self.keys - self.rows

    def row_of_key(self) -> NDArray[np.int64] | None:
        """Each key's row (-1 for a dead key); None when every key is its own row."""
        if self.keys == self.rows and np.array_equal(self.first, np.cumsum(self.counts) - self.counts):
            return None
        out = np.full(self.keys, -1, dtype=np.int64)
        out[runs(self.first, self.counts)] = np.arange(self.rows, dtype=np.int64)
        return out

    def to_array(self) -> NDArray[np.int64]:
        """The table as ``(groups, 3)`` int64 (digest bits, first key, views), as files keep it."""
        return np.stack([self.digests.view(np.int64), self.first, self.counts], axis=1)

    @classmethod
    def from_array(cls, table: NDArray[np.int64], keys: int) -> KeyTable:
        """The table :meth:`to_array` wrote, for an index of ``keys`` keys. Raises ValueError
        if it does not describe runs of keys within ``keys`` that do not overlap."""
        table = np.asarray(table, dtype=np.int64).reshape(-1, 3)
        first, counts = table[:, 1].copy(), table[:, 2].copy()
        order = np.argsort(first, kind="stable")
        ends = first[order] + counts[order]
        if len(table) and (counts.min() < 0 or first.min() < 0 or ends.max() > keys
                           or np.any(first[order][1:] < ends[:-1])):
            raise ValueError("the key table's runs overlap or pass the index's keys")
        return cls(table[:, 0].copy().view(np.uint64), first, counts, int(keys))


def runs(first: NDArray[np.integer], counts: NDArray[np.integer]) -> NDArray[np.int64]:
    """The integers of the runs ``first[i] .. first[i] + counts[i] - 1``, run after run."""
    first, counts = np.asarray(first, dtype=np.int64), np.asarray(counts, dtype=np.int64)
    total = int(counts.sum())
    return np.repeat(first - (np.cumsum(counts) - counts), counts) + np.arange(total, dtype=np.int64)


def group_digests(source: TierSource) -> NDArray[np.uint64]:
    """Per group of ``source`` (every group read), a 64-bit digest of its curves."""
    curves = source.rows(np.arange(source.n_groups, dtype=np.int64))[0]
    out = np.empty(source.n_groups, dtype=np.uint64)
    for g, (start, count) in enumerate(zip(source.group_start.tolist(), source.group_count.tolist(),
                                           strict=True)):
        block = np.ascontiguousarray(curves[start : start + count], dtype=np.float32)
        out[g] = int.from_bytes(hashlib.blake2b(block.tobytes(), digest_size=8).digest(), "little")
    return out


def plan_update(
    old: KeyTable, digests: NDArray[np.uint64], counts: NDArray[np.int64],
) -> tuple[KeyTable, NDArray[np.bool_]]:
    """The key table of the tier whose groups have ``digests`` and ``counts`` (in its
    order), keeping the keys of ``old``'s groups with the same curves (each old run used
    once), and which of its groups need their views added (their runs are new keys, from
    ``old.keys`` on, in the tier's order)."""
    counts = np.asarray(counts, dtype=np.int64)
    free: dict[tuple[int, int], list[int]] = {}
    for d, f, c in zip(old.digests.tolist(), old.first.tolist(), old.counts.tolist(), strict=True):
        free.setdefault((d, c), []).append(f)
    for kept in free.values():
        kept.reverse()  # popped in the old table's order
    first = np.empty(len(counts), dtype=np.int64)
    added = np.zeros(len(counts), dtype=np.bool_)
    key = old.keys
    for g, (d, c) in enumerate(zip(np.asarray(digests).tolist(), counts.tolist(), strict=True)):
        unused = free.get((d, c))
        if unused:
            first[g] = unused.pop()
        else:
            first[g], added[g] = key, True
            key += c
    return KeyTable(np.asarray(digests, dtype=np.uint64), first, counts, key), added


def update_fast_index(
    old: ViewIndex, table: KeyTable, source: TierSource, config: FastConfig,
    digests: NDArray[np.uint64] | None = None,
) -> tuple[FastIndex, KeyTable] | None:
    """The index of ``source`` grown from ``old`` (a copy in memory whose keys ``table``
    describes) and its key table; None when building anew is due instead: the dead keys
    would pass ``config.dead_share`` of the index, or no group is kept. ``digests``: the
    groups' (:func:`group_digests`), if known."""
    digests = group_digests(source) if digests is None else digests
    new, added = plan_update(table, digests, source.group_count)
    if added.all() or new.dead > config.dead_share * new.keys:
        return None
    rows = runs(source.group_start[added], new.counts[added])
    if len(rows):
        curves = source.rows(np.flatnonzero(added).astype(np.int64))[0]
        vectors = embed_curves(np.asarray(curves[rows]), config.coefficients, config.quantiles)
        old.add(runs(new.first[added], new.counts[added]), vectors, config.build_threads)
    return FastIndex.of(old, source, config, new.row_of_key()), new
