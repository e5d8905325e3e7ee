"""The compiled inner loop of the k-NN search: Algorithm 2's queue, over groups of views.

:func:`refine_groups` runs the best-first refinement of Algorithm 2 in one compiled call,
so a search costs no Python per view. One min-priority queue (an array heap that
persists between calls) holds

* **Fourier points** of a view or of its mirror, keyed by ``max(Fourier_Dist, LB_PAA,
  group key)`` (each bounds the exact distance of the view from below; LB_PAA, over the
  view's segment means, is computed only when Fourier_Dist is under the limit);
* **curves**, keyed by their LB_Keogh (computed when the point reaches the top, and
  abandoned as soon as it passes the current limit);

and the candidate **groups** arrive as a list sorted by their keys
(:meth:`~viewdb.search.knn.QueryBoxes.group_keys`): whichever of the queue's top and the
next group has the smaller key goes first, exactly as if the groups were queue entries
too. A group is opened by queueing the points of its views and mirrors; a curve is
refined by the UCR cascade (reverse LB_Keogh, then DTW abandoned on the cumulative
bound). A point, curve or group whose key exceeds the current limit is dropped.

Bookkeeping, per object ``o``:

* ``bound[o]``: the smallest distance known so far to be *achieved* by one of ``o``'s
  views (a distance computed here, or an upper bound handed in by a CS1 client);
* ``exact[o]``, ``exact_row[o]``, ``exact_mirrored[o]``: the smallest distance computed
  here, and where (among views at exactly that distance, the lowest row, unmirrored
  first: every view at an object's final distance is refined whatever the bounds, so
  the view reported is the same for every search order, e.g. CS1's and the server's).

``U``, the ``k``-th smallest ``bound`` (capped by ``cap``), bounds the final ``k``-th
distance from above, so an entry whose key exceeds ``U`` cannot enter the result, and
one whose key exceeds ``bound[o]`` cannot improve its object: the limit of an entry of
object ``o`` is ``min(U, bound[o])``. Limits are widened by a hair (``WIDEN_*``)
because a bound and the distance it bounds sum the same squares in different orders
(last-ulp differences), so a view whose distance *equals* a limit is still refined.

The search is finished when the smallest key left exceeds ``U`` *and* ``U`` is within
the caller's search radius ``stop_key`` (groups not listed yet have keys above the
radius); when the smallest key exceeds the radius first, the caller widens the radius
and lists more groups. Every object whose exact distance is at most the final ``k``-th
distance has a view whose keys never exceed its limit, so it is refined exactly: the
result equals the brute-force one (tests: ``tests/test_knn.py``).
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from .bounds import cascade_env_kernel, dtw_kernel, fourier_dist2, lb_keogh2, lb_paa2

__all__ = ["DONE", "EXHAUSTED", "NEED", "RADIUS", "WIDEN_ABS", "WIDEN_REL", "refine_groups", "scan_all"]

#: :func:`refine_groups` statuses (see there).
EXHAUSTED, RADIUS, DONE, NEED = 0, 1, 2, 3

#: A limit ``x`` is applied as ``x * (1 + WIDEN_REL) + WIDEN_ABS``.
WIDEN_REL = 1e-9
WIDEN_ABS = 1e-12


@njit(cache=True, nogil=True)
def widen(x):  # pragma: no cover - compiled
    return x * (1.0 + WIDEN_REL) + WIDEN_ABS


@njit(cache=True, nogil=True)
def _first(row, mirrored, other_row, other_mirrored):  # pragma: no cover - compiled
    # the canonical order among views at exactly the same distance (a symmetric
    # silhouette's curve is its own mirror): lower row first, then unmirrored; so the
    # reported view does not depend on the order the search happened to refine them in
    if row != other_row:
        return row < other_row
    return other_mirrored and not mirrored


@njit(cache=True, nogil=True)
def kth_distance(bound, k, cap):  # pragma: no cover - compiled
    # the k-th smallest of ``bound`` (inf if fewer than k are finite), at most ``cap``
    if bound.shape[0] < k:
        return cap
    s = np.sort(bound)[k - 1]
    return min(s, cap)


@njit(cache=True, nogil=True)
def load_row(curves, row, mirrored, out):  # pragma: no cover - compiled
    # the curve of ``row`` (or its mirror, c'[i] = c[-i mod N]) as float64 into ``out``
    n = out.shape[0]
    if mirrored:
        out[0] = curves[row, 0]
        for t in range(1, n):
            out[t] = curves[row, n - t]
    else:
        for t in range(n):
            out[t] = curves[row, t]


@njit(cache=True, nogil=True)
def heap_push(hkey, hcode, size, key, code):  # pragma: no cover - compiled
    i = size
    while i > 0:
        parent = (i - 1) // 2
        if hkey[parent] <= key:
            break
        hkey[i] = hkey[parent]
        hcode[i] = hcode[parent]
        i = parent
    hkey[i] = key
    hcode[i] = code
    return size + 1


@njit(cache=True, nogil=True)
def heap_pop(hkey, hcode, size):  # pragma: no cover - compiled
    # removes the root (read it before calling); returns the new size
    size -= 1
    key = hkey[size]
    code = hcode[size]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and hkey[child + 1] < hkey[child]:
            child += 1
        if hkey[child] >= key:
            break
        hkey[i] = hkey[child]
        hcode[i] = hcode[child]
        i = child
    if size > 0:
        hkey[i] = key
        hcode[i] = code
    return size


# One compiled loop on purpose (exempt from the complexity caps): split into helper kernels,
# even inlined ones, it measured about 10 % slower per k-NN query.
@njit(cache=True, nogil=True)
def _refine_kernel(  # noqa: C901, PLR0915  # pragma: no cover - compiled
    q, r, lower, upper, mlower, mupper, blo, bhi, mblo, mbhi, plo, phi, mplo, mphi, pwidth,
    order, keys, start_at, ready, stop_key,
    group_start, group_count, group_owner, row_owner, curves, coords, means,
    bound, exact, exact_row, exact_mirrored, k, cap, stats, hkey, hcode, hsize,
):
    n_samples = q.shape[0]
    scratch = np.empty(n_samples)
    U = kth_distance(bound, k, cap)
    size = hsize[0]
    i = start_at
    status = EXHAUSTED
    while True:
        if i < ready:
            gk = keys[i]
        elif ready < order.shape[0]:
            status = NEED
            break
        else:
            gk = np.inf
        top = hkey[0] if size > 0 else np.inf
        if size == 0 and gk == np.inf:  # the caller may know more groups
            status = EXHAUSTED
            break
        if min(gk, top) > widen(U):
            # nothing known can enter the result; groups not yet listed have keys above
            # the radius, so they cannot either once U is within it
            status = DONE if widen(U) <= stop_key else RADIUS
            break
        if top <= gk:  # refine the view (or mirror) with the smallest key
            if top > stop_key:
                status = RADIUS
                break
            code = hcode[0]
            size = heap_pop(hkey, hcode, size)
            row = code >> 2
            mirrored = (code & 1) == 1
            o = row_owner[row]
            limit = widen(min(U, bound[o]))
            if top > limit:
                continue  # it can neither enter the result nor improve its object
            if (code & 2) == 0:  # a Fourier point: its curve's LB_Keogh comes next
                stats[2] += 1
                lb = lb_keogh2(curves, row, mlower if mirrored else lower,
                                mupper if mirrored else upper, limit * limit)
                if lb > limit * limit:
                    continue
                lb = math.sqrt(lb)
                if lb > top:  # queue the curve behind what is now smaller
                    size = heap_push(hkey, hcode, size, lb, code | 2)
                    continue
            load_row(curves, row, mirrored, scratch)
            stats[3] += 1
            dist = cascade_env_kernel(q, scratch, r, limit, lower, upper, True)
            if dist > limit:
                continue  # abandoned
            if dist < exact[o] or (dist == exact[o] and _first(row, mirrored, exact_row[o],
                                                               exact_mirrored[o])):
                exact[o] = dist
                exact_row[o] = row
                exact_mirrored[o] = mirrored
            if dist < bound[o]:
                bound[o] = dist
                if dist < U:
                    U = kth_distance(bound, k, cap)
            continue
        # open the group with the smallest key: queue the Fourier points of its views and
        # mirrors still under the limit
        if gk > stop_key:
            status = RADIUS
            break
        g = order[i]
        i += 1
        o = group_owner[g]
        limit = widen(min(U, bound[o]))
        if gk > limit:
            continue
        limit2 = limit * limit
        s = group_start[g]
        n = group_count[g]
        stats[0] += 1
        stats[1] += n
        for slot in range(2 * n):
            mirrored = slot >= n
            row = s + (slot - n if mirrored else slot)
            fd = fourier_dist2(coords, row, mblo if mirrored else blo, mbhi if mirrored else bhi)
            if fd > limit2:
                continue
            pd = lb_paa2(means, row, mplo if mirrored else plo, mphi if mirrored else phi, pwidth, limit2)
            if pd > limit2:
                continue
            # a point's key is at least its group's (both bound every view of the group)
            size = heap_push(hkey, hcode, size, max(math.sqrt(max(fd, pd)), gk),
                              4 * row + (1 if mirrored else 0))
    hsize[0] = size
    return i, status


def refine_groups(
    q, r, envelope, mirrored_envelope, box, mirrored_box, segments, mirrored_segments,
    order, keys, start_at, ready, stop_key,
    group_start, group_count, group_owner, row_owner, curves, coords, means,
    bound, exact, exact_row, exact_mirrored, k, cap, stats, heap,
) -> tuple[int, int]:
    """Algorithm 2's refinement: pop views in the order of their keys, opening candidate
    groups (``order``, keys ``keys`` ascending, the first ``ready`` of them loaded) as
    their keys come up; returns ``(next group position, status)``:

    * :data:`DONE`: nothing left can enter the result;
    * :data:`NEED`: the next group is not loaded yet (position ``ready``);
    * :data:`RADIUS`: the smallest key left exceeds ``stop_key`` (groups beyond the
      search radius may not be in the list yet);
    * :data:`EXHAUSTED`: the list and the queue of views are empty.

    ``heap`` is ``(keys, codes, size)`` (arrays of a capacity of twice the views, and a
    one-element size) and persists between calls; a code is ``4 * row + 2 * (LB_Keogh
    known) + mirrored``.
    Updates ``bound``, ``exact``, ``exact_row``, ``exact_mirrored`` (per object, module
    doc) and ``stats`` (groups, views, LB_Keogh, DTW) in place. Group ``g`` holds rows
    ``group_start[g] : group_start[g] + group_count[g]`` of ``curves`` (float32 or float64),
    ``coords`` and ``means`` (segment means, against ``segments`` / ``mirrored_segments``:
    ``(lo, hi, widths)`` of :func:`~viewdb.search.bounds.paa_envelope`); ``row_owner`` is
    each row's object. Inputs are trusted.
    """
    i, status = _refine_kernel(
        q, r, envelope[0], envelope[1], mirrored_envelope[0], mirrored_envelope[1],
        box[0], box[1], mirrored_box[0], mirrored_box[1],
        segments[0], segments[1], mirrored_segments[0], mirrored_segments[1], segments[2],
        order, keys, start_at, ready,
        stop_key, group_start, group_count, group_owner, row_owner, curves, coords, means,
        bound, exact, exact_row, exact_mirrored, k, cap, stats, heap[0], heap[1], heap[2],
    )
    return int(i), int(status)


@njit(cache=True, nogil=True)
def _scan_kernel(q, curves, r, out):  # pragma: no cover - compiled
    scratch = np.empty(q.shape[0])
    for row in range(curves.shape[0]):
        load_row(curves, row, False, scratch)
        a = dtw_kernel(q, scratch, r, np.inf)
        load_row(curves, row, True, scratch)
        b = dtw_kernel(q, scratch, r, np.inf)
        out[row] = min(a, b)


def scan_all(q: np.ndarray, curves: np.ndarray, r: int) -> np.ndarray:
    """The exact distance ``min(DTW(q, c), DTW(q, mirror(c)))`` of every row of
    ``curves``, by the same compiled DTW, no bounds: the brute-force baseline of the
    benchmarks."""
    out = np.empty(len(curves))
    _scan_kernel(np.ascontiguousarray(q, dtype=np.float64), np.ascontiguousarray(curves), int(r), out)
    return out
