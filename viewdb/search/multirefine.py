"""The compiled refinement of a search over a stack of query curves (:mod:`.shifts`).

The same best-first loop as :mod:`viewdb.search.refine` (read its module doc first: the
candidate groups arrive sorted by key, the limits ``min(U, bound[o])``, the stop rule and
the exactness argument are the same), over entries of five kinds, each keyed by a lower
bound of the distance of everything it stands for (:mod:`viewdb.search.shifts` proves each)
and never below its parent's key:

========  ===========================  ============================================
entry     stands for                   key
========  ===========================  ============================================
GB        a group against a block      group key, MINDIST of the block's union box,
                                       curve-box bound of the block's wedge
GBC       (the same, bound known)      + the smallest curve-box bound of the block's
                                       curves, each against its own envelope
VB        a view against a block       + Fourier_Dist, LB_PAA of the block's wedge
VBC       (the same, bound known)      + LB_Keogh of the block's wedge
VC        a view against one curve     + LB_Keogh of the curve's envelope
========  ===========================  ============================================

each for the view as stored or mirrored. Opening a group pushes its GB entries (one per
block and orientation); a GB of a block of several curves computes the group's curve-box
bound against each of them and comes back as a GBC when the smallest is larger than its
key (or goes on at once); a GB (GBC) pops into VB entries of the group's views; a VB computes
its LB_Keogh against the wedge and comes back as a VBC (or goes on at once when that is
no larger than the next key), which pops into VC entries, one per curve of the block
whose own LB_Keogh is under the limit (for a block of one curve the wedge *is* the
curve's envelope); a VC is refined to its exact DTW by the UCR cascade against that
curve (LB_Keogh the other way, then DTW abandoned on its cumulative bound). So a view is
compared with a single curve only when the wedge of its block could not rule the whole
block out. (Computing the view's own envelope to key VC entries by the reverse LB_Keogh
as well cost more than it saved: the cascade computes it anyway.)

Per object the loop keeps, besides ``bound`` and ``exact`` (as :mod:`.refine`), the
curve ``exact_curve[o]`` of the best view; among entries at exactly the same distance
the lowest curve, then the lowest row, then the unmirrored view wins, whatever order
they were refined in (every entry at an object's final distance is refined, whatever
the bounds), so bounded (CS1) and unbounded searches report the same view and shift,
and a stack reports what one search per curve, merged in the stack's order keeping the
first of equals, reports.

The heap holds at most a few entries per pushed parent; when a pop could overflow it the
kernel returns :data:`FULL` before popping and the caller grows the heap.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..jit import njit
from .bounds import cascade_env_kernel, curve_box32, fourier_dist2, lb_keogh2, lb_paa2
from .refine import DONE, EXHAUSTED, NEED, RADIUS, heap_pop, heap_push, kth_distance, load_row, widen
from .shifts import CurveQuery

__all__ = ["FULL", "refine_stack", "scan_stack"]

#: An array handed to the compiled kernels as it is (dtypes as the docstrings say).
Array = NDArray[Any]

#: :func:`refine_stack` status besides those of :mod:`.refine`: the heap may overflow.
FULL = 4

# entry kinds (the low 3 bits of a code; bit 3 is "mirrored", the rest the payload)
_GB, _VB, _VBC, _VC, _GBC = 0, 1, 2, 3, 4


@njit(cache=True, nogil=True)
def _first(row, mirrored, curve, other_row, other_mirrored, other_curve):  # pragma: no cover
    # canonical order among entries at exactly the same distance: curve, row, unmirrored
    # (what separate searches of the curves in turn, merged keeping the first, report)
    if curve != other_curve:
        return curve < other_curve
    if row != other_row:
        return row < other_row
    return other_mirrored and not mirrored


@njit(cache=True, nogil=True)
def _mindist2(lo, hi, g, blo, bhi):  # pragma: no cover - compiled
    # squared MINDIST of the block's union box [blo, bhi] to the MBR of group g
    a = 0.0
    for j in range(lo.shape[1]):
        e = max(blo[j] - hi[g, j], 0.0) + max(lo[g, j] - bhi[j], 0.0)
        a += e * e
    return a


@njit(cache=True, nogil=True)
def _code(payload, m, kind):  # pragma: no cover - compiled
    return ((payload << 1 | m) << 3) | kind


@njit(cache=True, nogil=True)
def _open_group(  # pragma: no cover - compiled
    g, gk, limit2, mbr_lo, mbr_hi, range_lo, range_hi, wbox_lo, wbox_hi, wedge32_lo, wedge32_hi,
    hkey, hcode, size,
):
    # one GB entry per block and orientation still under the limit, keyed by max(MINDIST(block
    # box, MBR of g), curve-box bound(block wedge, range of g)); the latter in float32
    # (bounds.curve_box32) and first: it is the one that prunes (MINDIST is skipped when it
    # does), and the search computes one per opened group, block and orientation
    n_blocks = wbox_lo.shape[1]
    for b in range(n_blocks):
        for m in range(2):
            kb = curve_box32(range_lo, range_hi, g, wedge32_lo[m, b], wedge32_hi[m, b])
            if kb > limit2:
                continue
            kb = max(kb, _mindist2(mbr_lo, mbr_hi, g, wbox_lo[m, b], wbox_hi[m, b]))
            if kb <= limit2:
                size = heap_push(hkey, hcode, size, max(math.sqrt(kb), gk),
                                  _code(g * n_blocks + b, m, _GB))
    return size


@njit(cache=True, nogil=True)
def _group_curves_key2(range_lo, range_hi, g, lo, hi, t0, t1, limit2):  # pragma: no cover - compiled
    # the smallest over curves t0..t1-1 of the squared curve-box bound of group g against
    # each curve's own envelope (each abandoned past limit2)
    best = np.inf
    for t in range(t0, t1):
        a = 0.0
        for j in range(range_lo.shape[1]):
            e = max(range_lo[g, j] - hi[t, j], 0.0) + max(lo[t, j] - range_hi[g, j], 0.0)
            a += e * e
            if a > limit2 or a >= best:
                break
        best = min(best, a)
    return best


@njit(cache=True, nogil=True)
def _push_views(  # pragma: no cover - compiled
    g, b, m, key, limit2, group_start, group_count, coords, means, wbox_lo, wbox_hi, wseg_lo,
    wseg_hi, widths, hkey, hcode, size,
):
    # a GB entry: the group's views against the block, by Fourier_Dist and LB_PAA
    n_blocks = wbox_lo.shape[1]
    for row in range(group_start[g], group_start[g] + group_count[g]):
        fd = fourier_dist2(coords, row, wbox_lo[m, b], wbox_hi[m, b])
        if fd > limit2:
            continue
        pd = lb_paa2(means, row, wseg_lo[m, b], wseg_hi[m, b], widths, limit2)
        if pd <= limit2:
            size = heap_push(hkey, hcode, size, max(math.sqrt(max(fd, pd)), key),
                              _code(row * n_blocks + b, m, _VB))
    return size


@njit(cache=True, nogil=True)
def _push_curves(  # pragma: no cover - compiled
    row, b, m, key, limit2, block_start, block_end, curves, env_lo, env_hi, n_curves,
    hkey, hcode, size, stats,
):
    # a VBC entry: the view against each curve of the block, by the curve's LB_Keogh (a
    # block of one curve: the wedge was that curve's envelope)
    if block_end[b] - block_start[b] == 1:
        return heap_push(hkey, hcode, size, key, _code(row * n_curves + block_start[b], m, _VC))
    for t in range(block_start[b], block_end[b]):
        stats[2] += 1
        lb = max(key * key, lb_keogh2(curves, row, env_lo[m, t], env_hi[m, t], limit2))
        if lb <= limit2:
            size = heap_push(hkey, hcode, size, math.sqrt(lb), _code(row * n_curves + t, m, _VC))
    return size


@njit(cache=True, nogil=True)
def _group_block(  # pragma: no cover - compiled
    fresh, g, b, m, top, limit2, block_start, block_end, range_lo, range_hi, env_lo, env_hi,
    group_start, group_count, coords, means, wbox_lo, wbox_hi, wseg_lo, wseg_hi, widths,
    hkey, hcode, size, stats,
):
    # a GB entry (``fresh``) of a block of several curves: the group against each of them,
    # queued again as a GBC if the smallest bound is larger than its key; a GBC (or a GB
    # no larger): the group's views
    if fresh and block_end[b] - block_start[b] > 1:
        kt = _group_curves_key2(range_lo, range_hi, g, env_lo[m], env_hi[m], block_start[b],
                                block_end[b], limit2)
        if kt > limit2:
            return size
        if math.sqrt(kt) > top:
            n_blocks = wbox_lo.shape[1]
            return heap_push(hkey, hcode, size, math.sqrt(kt), _code(g * n_blocks + b, m, _GBC))
    stats[1] += group_count[g]
    return _push_views(g, b, m, top, limit2, group_start, group_count, coords, means, wbox_lo, wbox_hi,
                       wseg_lo, wseg_hi, widths, hkey, hcode, size)


@njit(cache=True, nogil=True)
def _view_block(  # pragma: no cover - compiled
    fresh, row, b, m, top, limit2, block_start, block_end, curves, wedge_lo, wedge_hi, env_lo, env_hi,
    n_curves, hkey, hcode, size, stats,
):
    # a VB entry (``fresh``): LB_Keogh against the block's wedge, queued again as a VBC if
    # that is larger than its key; a VBC (or a VB no larger): its curves
    if fresh:
        stats[2] += 1
        lb = lb_keogh2(curves, row, wedge_lo[m, b], wedge_hi[m, b], limit2)
        if lb > limit2:
            return size
        if math.sqrt(lb) > top:
            n_blocks = wedge_lo.shape[1]
            return heap_push(hkey, hcode, size, math.sqrt(lb), _code(row * n_blocks + b, m, _VBC))
    return _push_curves(row, b, m, top, limit2, block_start, block_end, curves, env_lo, env_hi, n_curves,
                        hkey, hcode, size, stats)


@njit(cache=True, nogil=True)
def _refine_view(  # pragma: no cover - compiled
    Q, r, row, t, m, o, limit, curves, env_lo, env_hi, scratch,
    bound, exact, exact_row, exact_mirrored, exact_curve, k, cap, U, kth,
):
    # a VC entry: the exact DTW (UCR cascade); the object's result and bound; returns U,
    # also left in kth[0] for the threads sharing the search (knn.py)
    load_row(curves, row, m == 1, scratch)
    dist = cascade_env_kernel(Q[t], scratch, r, limit, env_lo[0, t], env_hi[0, t], True)
    if dist > limit:
        return U
    if dist < exact[o] or (dist == exact[o] and _first(
            row, m == 1, t, exact_row[o], exact_mirrored[o], exact_curve[o])):
        exact[o] = dist
        exact_row[o] = row
        exact_mirrored[o] = m == 1
        exact_curve[o] = t
    if dist < bound[o]:
        bound[o] = dist
        if dist < U:
            U = kth_distance(bound, k, cap)
            kth[0] = min(kth[0], U)
    return U


@njit(cache=True, nogil=True)
def _room(block_start, block_end, group_count):  # pragma: no cover - compiled
    # the most entries one step pushes
    widest = 1
    for b in range(block_start.shape[0]):
        widest = max(widest, block_end[b] - block_start[b])
    most = 0
    for g in range(group_count.shape[0]):
        most = max(most, group_count[g])
    return max(2 * block_start.shape[0], most, widest) + 1


# The loop of refine.py (module doc) over the entries above; each kind's work is a helper.
@njit(cache=True, nogil=True)
def _stack_kernel(  # pragma: no cover - compiled
    Q, r, env_lo, env_hi, box_lo, box_hi, seg_lo, seg_hi, widths,
    block_start, block_end, wedge_lo, wedge_hi, wedge32_lo, wedge32_hi, wbox_lo, wbox_hi, wseg_lo, wseg_hi,
    order, keys, start_at, ready, stop_key,
    group_start, group_count, group_owner, row_owner, curves, coords, means,
    mbr_lo, mbr_hi, range_lo, range_hi,
    bound, exact, exact_row, exact_mirrored, exact_curve, k, cap, stats, hkey, hcode, hsize, kth,
):
    n_curves = Q.shape[0]
    n_blocks = block_start.shape[0]
    scratch = np.empty(Q.shape[1])
    room = _room(block_start, block_end, group_count)
    U = min(kth_distance(bound, k, cap), kth[0])
    size = hsize[0]
    i = start_at
    status = EXHAUSTED
    while True:
        U = min(U, kth[0])  # the threads sharing the search lower it too (knn.py)
        if size + room > hkey.shape[0]:
            status = FULL
            break
        if i < ready:
            gk = keys[i]
        elif ready < order.shape[0]:
            status = NEED
            break
        else:
            gk = np.inf
        top = hkey[0] if size > 0 else np.inf
        if size == 0 and gk == np.inf:
            status = EXHAUSTED
            break
        if min(gk, top) > widen(U):
            status = DONE if widen(U) <= stop_key else RADIUS
            break
        if top > gk:  # open the next group
            if gk > stop_key:
                status = RADIUS
                break
            g = order[i]
            i += 1
            limit = widen(min(U, bound[group_owner[g]]))
            if gk <= limit:
                stats[0] += 1
                size = _open_group(g, gk, limit * limit, mbr_lo, mbr_hi, range_lo, range_hi, wbox_lo,
                                   wbox_hi, wedge32_lo, wedge32_hi, hkey, hcode, size)
            continue
        if top > stop_key:
            status = RADIUS
            break
        code = hcode[0]
        size = heap_pop(hkey, hcode, size)
        kind = code & 7
        m = (code >> 3) & 1
        payload = code >> 4
        per = n_curves if kind == _VC else n_blocks
        row, b = payload // per, payload % per  # (group, block) for a GB entry
        o = group_owner[row] if kind == _GB or kind == _GBC else row_owner[row]
        limit = widen(min(U, bound[o]))
        if top > limit:
            continue
        if kind == _GB or kind == _GBC:
            size = _group_block(kind == _GB, row, b, m, top, limit * limit, block_start, block_end, range_lo,
                                range_hi, env_lo, env_hi, group_start, group_count, coords, means, wbox_lo,
                                wbox_hi, wseg_lo, wseg_hi, widths, hkey, hcode, size, stats)
        elif kind != _VC:
            size = _view_block(kind == _VB, row, b, m, top, limit * limit, block_start, block_end, curves,
                               wedge_lo, wedge_hi, env_lo, env_hi, n_curves, hkey, hcode, size, stats)
        else:
            stats[3] += 1
            U = _refine_view(Q, r, row, b, m, o, limit, curves, env_lo, env_hi, scratch, bound, exact,
                             exact_row, exact_mirrored, exact_curve, k, cap, U, kth)
    hsize[0] = size
    return i, status


def refine_stack(
    query: CurveQuery, order: Array, keys: Array, start_at: int, ready: int, stop_key: float,
    source_groups: tuple[Array, Array, Array, Array], rows: tuple[Array, Array, Array],
    groups: tuple[Array, Array, Array, Array],
    state: tuple[Array, Array, Array, Array, Array, Array, Array, Array, Array],
    k: int, cap: float, stats: Array,
) -> tuple[int, int]:
    """One call of the compiled refinement for a :class:`~viewdb.search.shifts.CurveQuery`;
    returns ``(next group position, status)`` with the statuses of
    :func:`~viewdb.search.refine.refine_groups` and :data:`FULL`.

    ``source_groups`` is ``(group_start, group_count, group_owner, row_owner)``, ``rows``
    the source's ``(curves, coords, means)``, ``groups`` its ``(mbr_lo, mbr_hi, curve_lo,
    curve_hi)`` and ``state`` ``(bound, exact, exact_row, exact_mirrored, exact_curve,
    heap keys, heap codes, heap size, kth)``, all updated in place; ``kth[0]`` is an upper
    bound of the k-th distance that the threads sharing one search (:mod:`.knn`) lower as
    each finds it. Inputs are trusted.
    """
    q = query
    i, status = _stack_kernel(
        q.curves, q.band, q.env_lo, q.env_hi, q.box_lo, q.box_hi, q.seg_lo, q.seg_hi, q.widths,
        q.block_start, q.block_end, q.wedge_lo, q.wedge_hi, q.wedge32_lo, q.wedge32_hi, q.wbox_lo, q.wbox_hi,
        q.wseg_lo, q.wseg_hi, order, keys, start_at, ready, stop_key,
        *source_groups, *rows, *groups, *state[:5], k, cap, stats, *state[5:],
    )
    return int(i), int(status)


@njit(cache=True, nogil=True)
def _scan_stack_kernel(Q, lower, upper, curves, r, out):  # pragma: no cover - compiled
    scratch = np.empty(Q.shape[1])
    for row in range(curves.shape[0]):
        best = np.inf
        for m in range(2):
            load_row(curves, row, m == 1, scratch)
            for t in range(Q.shape[0]):
                d = cascade_env_kernel(Q[t], scratch, r, best, lower[t], upper[t], True)
                if d < best:
                    best = d
        out[row] = best


def scan_stack(query, curves: np.ndarray) -> np.ndarray:
    """The exact distance of every row of ``curves`` to a
    :class:`~viewdb.search.shifts.CurveQuery` (the smallest DTW over its curves and the
    row's mirror), with no index and no bound shared between rows (each row's DTWs only
    abandon past that row's best so far): the brute-force baseline of the benchmarks."""
    out = np.empty(len(curves))
    _scan_stack_kernel(query.curves, query.env_lo[0], query.env_hi[0], np.ascontiguousarray(curves),
                       query.band, out)
    return out
