"""A tier source narrowed to some of its objects: the groups of those objects alone,
renumbered, over the same rows.

A search of the subset (:func:`~viewdb.search.knn.knn_stack`) is exactly a search of the
whole source with every other object left out (``only``), but its cost no longer grows
with the objects left out: it never lists, browses or sorts their groups. The ``fast``
plan (:mod:`viewdb.search.fast`) searches its shortlist this way, so a shortlist of 20
objects costs the same in a catalogue of 200 as of 100,000.

Objects keep their numbers (per-object arrays are the source's size, cheap), rows keep
theirs (``row_owner``, the curves, view ids: the source's own arrays, not copied); only
the groups are renumbered, with their MBRs and curve ranges copied (a few hundred rows).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from .knn import QueryBoxes, TierSource

__all__ = ["SubsetSource", "groups_by_object", "runs_by_owner"]


def runs_by_owner(owner: NDArray[np.integer], n_objects: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The indices of ``owner`` ordered by their object (``order``) and where each object's
    run starts in that order (``starts``, ``n_objects + 1`` entries): object ``o``'s
    entries are ``order[starts[o]:starts[o + 1]]``, ascending."""
    order = np.argsort(owner, kind="stable").astype(np.int64)
    starts = np.searchsorted(np.asarray(owner)[order], np.arange(n_objects + 1)).astype(np.int64)
    return order, starts


def groups_by_object(source: TierSource) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The source's groups by object (:func:`runs_by_owner` of ``group_owner``)."""
    return runs_by_owner(source.group_owner, source.n_objects)


class SubsetSource:
    """The groups of ``objects`` (indices into ``source``'s objects) of ``source``
    (module doc); ``by_object``: :func:`groups_by_object` of the source, if already known."""

    def __init__(self, source: TierSource, objects: Sequence[int] | NDArray[np.int64],
                 by_object: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None) -> None:
        self.source = source
        order, starts = by_object if by_object is not None else groups_by_object(source)
        picked = np.unique(np.asarray(objects, dtype=np.int64))
        if len(picked) and (picked[0] < 0 or picked[-1] >= source.n_objects):
            raise ValueError(f"objects must be in [0, {source.n_objects}), got {picked[0]}..{picked[-1]}")
        runs = [order[starts[o] : starts[o + 1]] for o in picked.tolist()]
        #: the source's group of each of this subset's groups
        self.groups = np.sort(np.concatenate(runs)) if runs else np.zeros(0, dtype=np.int64)
        self.n_groups = len(self.groups)
        self.n_objects = source.n_objects
        self.group_owner = np.ascontiguousarray(source.group_owner[self.groups])
        self.group_start = np.ascontiguousarray(source.group_start[self.groups])
        self.group_count = np.ascontiguousarray(source.group_count[self.groups])
        self.row_owner = source.row_owner
        lo, hi, curve_lo, curve_hi = source.group_boxes()
        g = self.groups
        self._boxes = (np.ascontiguousarray(lo[g]), np.ascontiguousarray(hi[g]),
                       np.ascontiguousarray(curve_lo[g]), np.ascontiguousarray(curve_hi[g]))
        self._keyed: tuple[object, NDArray[np.float64], NDArray[np.float64]] | None = None

    def groups_within(
        self, query: QueryBoxes, radius: float, seen: NDArray[np.bool_]
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        if not self.n_groups:
            return np.zeros(0, dtype=np.int64), np.zeros(0)
        if self._keyed is None or self._keyed[0] is not query:
            # every group's bound and key, once per query: a search's threads and its
            # widening radii browse the same groups (the callers hold the source's lock)
            self._keyed = (query, *query.group_keys(*self._boxes))
        _, mind, keys = self._keyed
        hits = np.flatnonzero((mind <= radius) & ~seen).astype(np.int64)
        return hits, keys[hits]

    def rows(
        self, groups: NDArray[np.int64]
    ) -> tuple[NDArray[np.floating], NDArray[np.float64], NDArray[np.float64]]:
        return self.source.rows(self.groups[np.asarray(groups, dtype=np.int64)])

    def group_boxes(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float32], NDArray[np.float32]]:
        lo, hi, curve_lo, curve_hi = self._boxes
        return lo, hi, curve_lo, curve_hi

    def view_id(self, row: int) -> int:
        return self.source.view_id(row)

    def object_name(self, index: int) -> str:
        return self.source.object_name(index)

    def object_index(self, name: str) -> int | None:
        return self.source.object_index(name)
