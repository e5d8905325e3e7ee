"""Subgroups: each index group's views split again into runs of a few similar curves,
each with its own per-sample range, so a search opens only the runs a query can reach.

A group (:mod:`.grouping`) holds up to 32 views of one object that lie close in the
indexed Fourier coordinates. Their curves still differ sample by sample, so the group's
per-sample range is wide, and a query's envelope meets it far more often than it meets
any of the members. On the 212-model 10° file, the group ranges a photo's 12 in-plane
turns could not rule out held 4 to 60 times more views than those whose own LB_Keogh
was under the search's final k-th distance.

Each group is therefore split again, by the same k-d rule as the groups (the widest
coordinate halved at its median, stable), over the views' segment means, until a run
holds at most :data:`SUBGROUP_VIEWS` views. A run's per-sample range (float32, rounded
outward) bounds each member's LB_Keogh from below exactly as a group's range does
(:func:`~viewdb.search.bounds.curve_box32`), so a search that skips a run whose bound
is past its limit skips only views it would have skipped one by one.

Layout: the runs of group ``g`` are ``first[g] .. first[g + 1] - 1``; run ``s`` holds
rows ``order[start[s] : start[s + 1]]``, all within the group's rows. How many runs a
group has, and their sizes, follow from its size alone (:func:`subgroup_layout`), so a
tier whose groups are read on demand fills in each group's order and ranges when it
reads the group's curves (:func:`fill_subgroups`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .jit import njit

__all__ = ["SUBGROUP_VIEWS", "Subgroups", "fill_subgroups", "subgroup_layout"]

#: The most views in one subgroup.
SUBGROUP_VIEWS = 8

#: A tier's subgroups: ``(first, start, order, lo, hi)`` (module doc).
Subgroups = tuple[
    NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.float32], NDArray[np.float32]
]


def _leaf_sizes(n: int, size: int) -> list[int]:
    # the sizes of the runs a k-d split of n rows leaves, left to right (as _fill_group)
    if n <= size:
        return [n]
    half = n // 2
    return _leaf_sizes(half, size) + _leaf_sizes(n - half, size)


def subgroup_layout(
    group_start: NDArray[np.int64], group_count: NDArray[np.int64], size: int = SUBGROUP_VIEWS
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """``(first, start)``: the first run of each group (``n_groups + 1``, the last the
    number of runs) and the first position of each run in ``order`` (``n_runs + 1``)."""
    if size < 1:
        raise ValueError(f"size must be at least 1, got {size}")
    counts = np.asarray(group_count, dtype=np.int64)
    leaves = {int(n): _leaf_sizes(int(n), size) for n in np.unique(counts)}
    # one row of run sizes per group size, then every group's row at once (a table
    # opening the 212-model file's 25,000 groups in well under a millisecond)
    width = max((len(v) for v in leaves.values()), default=1)
    table = np.zeros((max(leaves, default=0) + 1, width), dtype=np.int64)
    runs_of = np.zeros(len(table), dtype=np.int64)
    for n, v in leaves.items():
        table[n, : len(v)] = v
        runs_of[n] = len(v)
    per_group = runs_of[counts]
    first = np.concatenate([[0], np.cumsum(per_group)]).astype(np.int64)
    sizes = table[counts][np.arange(width)[None, :] < per_group[:, None]]
    start = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    # the groups' rows are contiguous and in order, so each run's start is absolute
    if len(counts) and not np.array_equal(start[first[:-1]], np.asarray(group_start, dtype=np.int64)):
        raise ValueError("groups must hold consecutive rows in order")
    return first, start


@njit(cache=True, nogil=True)
def _down32(x):  # pragma: no cover - compiled
    # float32 not above x
    y = np.float32(x)
    if np.float64(y) > x:
        y = np.nextafter(y, np.float32(-np.inf))
    return y


@njit(cache=True, nogil=True)
def _up32(x):  # pragma: no cover - compiled
    y = np.float32(x)
    if np.float64(y) < x:
        y = np.nextafter(y, np.float32(np.inf))
    return y


@njit(cache=True, nogil=True)
def _fill_group(  # pragma: no cover - compiled
    g, size, curves, means, group_start, group_count, first, start, order, lo, hi,
):
    a, n = group_start[g], group_count[g]
    for j in range(n):
        order[a + j] = a + j
    # split [a, a + n) of order recursively, left part first, until a run holds at most
    # `size` rows; the runs come out left to right, with subgroup_layout's sizes
    stack_lo = np.empty(64, np.int64)
    stack_hi = np.empty(64, np.int64)
    stack_lo[0], stack_hi[0] = a, a + n
    top = 1
    while top > 0:
        top -= 1
        lo_i, hi_i = stack_lo[top], stack_hi[top]
        m = hi_i - lo_i
        if m <= size:
            continue
        # the widest segment mean over these rows, halved at its median (stable order)
        axis, width = 0, -1.0
        for d in range(means.shape[1]):
            mn, mx = np.inf, -np.inf
            for j in range(lo_i, hi_i):
                v = means[order[j], d]
                mn, mx = min(mn, v), max(mx, v)
            if mx - mn > width:
                axis, width = d, mx - mn
        keys = np.empty(m)
        for j in range(m):
            keys[j] = means[order[lo_i + j], axis]
        by = np.argsort(keys, kind="mergesort")
        moved = order[lo_i:hi_i].copy()
        for j in range(m):
            order[lo_i + j] = moved[by[j]]
        half = m // 2
        # right half below the left on the stack: the left is split first
        stack_lo[top], stack_hi[top] = lo_i + half, hi_i
        stack_lo[top + 1], stack_hi[top + 1] = lo_i, lo_i + half
        top += 2
    for s in range(first[g], first[g + 1]):
        for t in range(curves.shape[1]):
            mn, mx = np.inf, -np.inf
            for j in range(start[s], start[s + 1]):
                v = np.float64(curves[order[j], t])
                mn, mx = min(mn, v), max(mx, v)
            lo[s, t] = _down32(mn)
            hi[s, t] = _up32(mx)


@njit(cache=True, nogil=True)
def _fill_kernel(  # pragma: no cover - compiled
    groups, size, curves, means, group_start, group_count, first, start, order, lo, hi,
):
    for i in range(groups.shape[0]):
        _fill_group(groups[i], size, curves, means, group_start, group_count, first, start, order, lo, hi)


def fill_subgroups(
    groups: NDArray[np.int64], curves: NDArray[np.floating], means: NDArray[np.float64],
    group_start: NDArray[np.int64], group_count: NDArray[np.int64],
    first: NDArray[np.int64], start: NDArray[np.int64],
    order: NDArray[np.int64], lo: NDArray[np.float32], hi: NDArray[np.float32],
    size: int = SUBGROUP_VIEWS,
) -> None:
    """Split each of ``groups`` into its runs (:func:`subgroup_layout`): its rows' places in
    ``order`` and each run's per-sample range in ``lo``/``hi`` (float32, outward), in place."""
    if len(groups):
        _fill_kernel(np.ascontiguousarray(groups, dtype=np.int64), size, curves, means, group_start,
                     group_count, first, start, order, lo, hi)
