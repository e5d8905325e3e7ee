"""Distances and lower bounds for the k-NN search (Tak & Hwang, III.A, Algorithm 2).

Algorithm 2 ranks index entries by a chain of ever tighter, ever dearer lower bounds of
the dynamic time warping distance between the query curve ``q`` and a stored curve
``c`` (both of length ``N``, fixed start point, so this is ordinary *non-cyclic* DTW)::

    MINDIST(box, MBR)  <=  Fourier_Dist(box, F c)  <=  LB_Keogh(L, U, c)  <=  DTW_r(q, c)

for every MBR containing the candidate's coordinates ``F c``; and next to Fourier_Dist,
``LB_PAA <= LB_Keogh`` over the curve's segment means (section below), so the search keys
a view by the larger of the two.  The bounds follow
Keogh & Ratanamahatana, "Exact indexing of dynamic time warping", KAIS 7, 2005
(LB_Keogh, the envelope, MINDIST) and Zhu & Shasha, "Warping indexes with envelope
transforms for query by humming", SIGMOD 2003 (the *envelope transform*: the box of
feature values reachable from the envelope, which is what :func:`envelope_box`
computes for the DFT features of the index).

Conventions
-----------
DTW
    :func:`dtw` is DTW with a Sakoe-Chiba band of ``r`` samples (cells ``|i - j| <= r``),
    cost ``(q_i - c_j)^2`` per cell, steps (1,0), (0,1), (1,1), path from ``(0, 0)`` to
    ``(N-1, N-1)``; it returns the *square root* of the least path cost, so ``r = 0`` is
    exactly the Euclidean distance and every bound here is in the same units.
Coordinates
    The index stores, for each view, the real vector
    ``F c = [Re X_0, ..., Re X_{m-1}, Im X_0, ..., Im X_{m-1}]`` where
    ``X = np.fft.fft(c, norm="ortho")`` (:func:`viewdb.catalogue.features.fourier_point`); see
    :func:`fourier_coordinates` and :func:`complex_to_coordinates`.  ``Im X_0`` is
    always 0 for a real curve; it is *kept*, so the layout is a plain ``2m`` vector
    (the row of ``F`` is zero, the box and all points have 0 there, it never adds to a
    distance).  Curves are stored as float32 but everything here computes in float64.

Why the chain holds
-------------------
``LB_Keogh <= DTW`` (Keogh & Ratanamahatana, Prop. 1).  With ``U_j = max q[j-r:j+r+1]``
and ``L_j = min(...)``, every warping path in the band matches each ``c_j`` with at
least one ``q_i``, ``|i - j| <= r``, hence ``L_j <= q_i <= U_j`` and
``(q_i - c_j)^2 >= dist(c_j, [L_j, U_j])^2``.  The cells for different ``j`` are
different cells of the path and all costs are >= 0, so the path costs at least
``LB_Keogh^2``.  :func:`lb_keogh_reverse` is the same with the roles swapped (DTW with a
symmetric band is symmetric) and :func:`lb_kim` uses the two cells ``(0, 0)`` and
``(N-1, N-1)`` every path contains.

``Fourier_Dist <= LB_Keogh``.  Let ``x* = clip(c, L, U)``, the point of the envelope
``{x : L <= x <= U}`` nearest to ``c``; by definition ``||x* - c|| = LB_Keogh(L, U, c)``.
Each coordinate is a linear functional ``F_k . x``, and :func:`envelope_box` is its
exact range over the envelope, so ``F x*`` lies in the box ``[lo, hi]`` and
``Fourier_Dist(box, F c) <= ||F x* - F c|| = ||F (x* - c)||``.  Finally ``F`` is a
contraction: ``||F v||^2 = sum_{k<m} |V_k|^2 <= sum_{k<N} |V_k|^2 = ||v||^2`` by
Parseval for the orthonormal DFT.  (The rows of ``F`` are orthogonal but *not* unit
length: the ``Re``/``Im`` rows of ``0 < k < N/2`` have norm ``1/sqrt 2``.  Weighting them
by ``sqrt 2`` would still be a contraction for ``m <= (N+1)/2`` and give a tighter bound,
but the stored coordinates are the unweighted ones, as in the paper.)

``MINDIST <= Fourier_Dist``: ``F c`` lies in the MBR, so the box is at least as close to
the MBR as to the point.

Plain Fourier distance ``||F q - F c||`` does **not** lower-bound DTW: e.g. a spike
at ``t = 10`` and the same spike at ``t = 11`` have DTW 0 for ``r >= 1`` but different
DFTs.  Only the distance to the *box* of the query's envelope does.

Mirrored views
--------------
The mirrored view's curve is ``c'[i] = c[(-i) % N]`` (:func:`viewdb.catalogue.features.mirror_curve`),
whose DFT is ``conj(X)``, so ``F c' = S F c`` with ``S = diag(I_m, -I_m)``, an isometry.
Hence ``Fourier_Dist(box, F c') = Fourier_Dist(S box, F c)`` and
``MINDIST(box, S MBR) = MINDIST(S box, MBR)``, where ``S box`` is :func:`mirror_box`
(``lo'_Im = -hi_Im``, ``hi'_Im = -lo_Im``, the ``Re`` half unchanged).  The search
therefore needs only the index of the stored views: it queries it with both ``box``
and ``mirror_box(box)``, and, since Algorithm 2 pushes ``S`` and ``S'`` from one Fourier
point (lines 15-19), the key of a point or node must be the *smaller* of the two
distances to stay a lower bound for both.  ``DTW`` of the mirror must be computed on
``mirror_curve(c)`` itself (the mirror is not an order-preserving re-indexing, so there is
no shortcut for a warping path).  ``LB_Keogh`` is a sum of one term per sample, so for a
permutation ``P`` of the samples ``LB_Keogh(L, U, P c) = LB_Keogh(P^-1 L, P^-1 U, c)``;
the mirror is an involution (``P^-1 = P``), so the mirrored bound is LB_Keogh of the
stored curve against the *mirrored envelope* (:func:`group_bounds`).

Segment means (LB_PAA)
----------------------
Split the samples into consecutive segments ``J`` of widths ``w_J``; let ``m_J`` be the
mean of ``c`` over ``J`` and ``[L_J, U_J] = [min L, max U]`` over ``J``.  Then
``LB_PAA^2 = sum_J w_J dist(m_J, [L_J, U_J])^2 <= LB_Keogh^2`` (Keogh et al., "Dimensionality
reduction for fast similarity search", KAIS 3, 2001, for the envelope): for ``t`` in ``J``,
``dist(c_t, [L_t, U_t]) >= dist(c_t, [L_J, U_J])``, and ``x -> dist(x, I)^2`` is convex, so
by Jensen the mean of ``dist(c_t, [L_J, U_J])^2`` over ``J`` is at least
``dist(m_J, [L_J, U_J])^2``.  It costs one term per segment instead of per sample, and is
far tighter than ``Fourier_Dist`` (whose box relaxes the envelope globally): with 32
segments of 128-sample curves it passes 3-18 % of the views that ``Fourier_Dist`` passes
at a query's 5th distance.  Mirrored views use the mirrored envelope, as for LB_Keogh.

Group bounds
------------
A group's curves lie in their per-sample range ``[glo, ghi]`` (a box in the curve space,
``N`` dimensions).  ``curve_box_lb = ||dist([L, U], [glo, ghi])||`` (per-sample gap between
the two intervals) is at most ``LB_Keogh(L, U, c)`` for every curve ``c`` of the group,
since each ``c_t`` lies in ``[glo_t, ghi_t]``; it is a second lower bound for the group
next to ``MINDIST`` (neither dominates), and the key of a group is the larger of the two.

Floating point
--------------
:func:`envelope_box` rounds the box outward by a bound on the rounding error of the dot
products (about ``4 N eps`` relative), so that a candidate lying inside the envelope
(``LB_Keogh == 0``) always gets ``Fourier_Dist == 0`` even when its coordinates come from
an FFT rather than from ``F @ c``; the box is wider than exact by ~1e-13 for
``N = 128`` curves of mean 1, which costs nothing in pruning.  Other comparisons in the
chain hold up to rounding of the last few ulps.

:func:`curve_box32` computes the curve-box bound in float32, which SIMD lanes do several
at a time, for the search's many group keys: the group's range (float32 curves' minima and
maxima, exact) against the envelope rounded outward to float32 (:func:`outward32`; a wider
envelope only lowers the bound). Each term ``fl(fl(a - b)^2)`` is within ``3u`` (relative)
of its exact value and a sum of ``N`` non-negative terms in any order within ``(N - 1) u``
(``u = 2^-24``, first order), so the float32 sum times ``1 - 2 (N + 4) u`` is at most the
exact bound; the scaled value is used.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
from numpy.typing import NDArray

from ..jit import njit

__all__ = [
    "cascade_dtw",
    "complex_to_coordinates",
    "curve_box32",
    "curve_box_lb_many",
    "dtw",
    "envelope",
    "envelope_box",
    "fourier_coordinates",
    "fourier_dist",
    "fourier_dist_many",
    "group_bounds",
    "lb_keogh",
    "lb_keogh_many",
    "lb_keogh_reverse",
    "lb_kim",
    "lb_paa",
    "mindist",
    "mindist_many",
    "mirror_box",
    "mirror_coordinates",
    "outward32",
    "paa_edges",
    "paa_envelope",
    "paa_means",
    "rounded32",
]

#: Segments of the LB_PAA bound (fewer when a curve has fewer samples).
PAA_SEGMENTS = 32


# ---------------------------------------------------------------------------------------
# numba kernels (private; inputs are validated float64 contiguous arrays)
# ---------------------------------------------------------------------------------------


@njit(cache=True, nogil=True)
def dtw_kernel(q, c, r, best_so_far):  # pragma: no cover - compiled
    return _dtw_rest_kernel(q, c, r, best_so_far, np.zeros(q.shape[0]))


@njit(cache=True, nogil=True)
def _dtw_rest_kernel(q, c, r, best_so_far, rest):  # pragma: no cover - compiled
    # DTW abandoned as soon as (the cheapest cell of row i) + rest[i] exceeds the limit,
    # ``rest[i]`` being a lower bound of what the rows after i add to any path (UCR
    # suite's cumulative bound; zeros for plain early abandoning).
    # Rows of the band only, indexed by w = j - i + r (0..2r), stored at w + 1 between two
    # infinite sentinels: cell (i, j) reads (i-1, j) at prev[w + 2], (i-1, j-1) at
    # prev[w + 1] and (i, j-1) at cur[w]; no branch per cell but the minimum.
    n = q.shape[0]
    width = 2 * r + 1
    thresh = best_so_far * best_so_far
    prev = np.full(width + 2, np.inf)
    cur = np.full(width + 2, np.inf)
    for i in range(n):
        w_lo = max(0, r - i)
        w_hi = min(width - 1, n - 1 - i + r)
        qi = q[i]
        rowmin = np.inf
        cur[w_lo] = np.inf
        for w in range(w_lo, w_hi + 1):
            best = prev[w + 2]
            v = prev[w + 1]
            if v < best:
                best = v
            v = cur[w]
            if v < best:
                best = v
            if i == 0 and w == r:  # cell (0, 0): the path starts here
                best = 0.0
            d = qi - c[i - r + w]
            v = d * d + best
            cur[w + 1] = v
            if v < rowmin:
                rowmin = v
        cur[w_hi + 2] = np.inf
        # every path crosses row i, then adds at least rest[i]: its cost is >= the sum
        # (summed in another order than the path's cost: a hair of slack for rounding)
        if rowmin + rest[i] * (1.0 - 1e-12) > thresh * (1.0 + 1e-12):
            return np.inf
        prev, cur = cur, prev
    return math.sqrt(prev[r + 1])


@njit(cache=True, nogil=True)
def _window_range(x, i, r):  # pragma: no cover - compiled
    # min and max of x over the band window [i - r, i + r] (clipped to the sequence)
    n = x.shape[0]
    a = max(0, i - r)
    b = min(n - 1, i + r)
    lo = x[a]
    hi = x[a]
    for t in range(a + 1, b + 1):
        v = x[t]
        if v < lo:
            lo = v
        if v > hi:
            hi = v
    return lo, hi


@njit(cache=True, nogil=True)
def _envelope_kernel(q, r):  # pragma: no cover - compiled
    n = q.shape[0]
    lower = np.empty(n)
    upper = np.empty(n)
    for i in range(n):
        lower[i], upper[i] = _window_range(q, i, r)
    return lower, upper


@njit(cache=True, nogil=True)
def fourier_dist2(coords, row, lo, hi):  # pragma: no cover - compiled
    # squared Fourier_Dist of point ``coords[row]`` to the box [lo, hi]
    s = 0.0
    for j in range(coords.shape[1]):
        p = coords[row, j]
        e = max(lo[j] - p, 0.0) + max(p - hi[j], 0.0)
        s += e * e
    return s


@njit(cache=True, nogil=True)
def lb_paa2(means, row, lo, hi, widths, limit2):  # pragma: no cover - compiled
    # squared LB_PAA of the segment means ``means[row]`` against the segment envelope
    # [lo, hi], abandoned (some value > limit2) as soon as it passes ``limit2``
    s = 0.0
    for j in range(means.shape[1]):
        x = means[row, j]
        if x > hi[j]:
            e = x - hi[j]
            s += widths[j] * e * e
        elif x < lo[j]:
            e = lo[j] - x
            s += widths[j] * e * e
        if s > limit2:
            return s
    return s


@njit(cache=True, nogil=True)
def lb_keogh2(curves, row, lower, upper, limit2):  # pragma: no cover - compiled
    # squared LB_Keogh of curve ``curves[row]`` against [lower, upper], abandoned (some
    # value > limit2) as soon as it passes ``limit2``
    s = 0.0
    for t in range(curves.shape[1]):
        x = curves[row, t]
        if x > upper[t]:
            e = x - upper[t]
            s += e * e
        elif x < lower[t]:
            e = lower[t] - x
            s += e * e
        if s > limit2:
            return s
    return s


#: float32's machine epsilon, 2u (a constant: a power in a kernel is computed on every call)
_EPS32 = 2.0**-23


@njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def _curve_box32_sum(lo, hi, g, wlo, whi):  # pragma: no cover - compiled
    # each gap clipped at zero by a comparison rather than max(), which LLVM vectorises
    # (max() keeps its NaN rule and stays scalar): about twice as fast
    zero = np.float32(0.0)
    s = np.float32(0.0)
    for t in range(lo.shape[1]):
        a = lo[g, t] - whi[t]
        b = wlo[t] - hi[g, t]
        e = (a if a > zero else zero) + (b if b > zero else zero)
        s += e * e
    return s


@njit(cache=True, nogil=True, inline="always")
def curve_box32(lo, hi, g, wlo, whi):  # pragma: no cover - compiled
    # squared curve-box bound of the float32 range [lo[g], hi[g]] against the float32
    # envelope [wlo, whi], summed in float32 in any order (SIMD) and scaled below its
    # rounding error (module doc, "Floating point")
    return float(_curve_box32_sum(lo, hi, g, wlo, whi)) * (1.0 - (lo.shape[1] + 4) * _EPS32)


@njit(cache=True, nogil=True)
def _lb_keogh_kernel(lower, upper, c):  # pragma: no cover - compiled
    return math.sqrt(lb_keogh2(c.reshape(1, c.shape[0]), 0, lower, upper, np.inf))


@njit(cache=True, nogil=True)
def _group_bounds_kernel(  # pragma: no cover - compiled
    lower, upper, mlower, mupper, blo, bhi, mblo, mbhi, coords, curves
):
    n = curves.shape[0]
    out = np.empty(2 * n)
    for i in range(n):
        out[i] = math.sqrt(max(fourier_dist2(coords, i, blo, bhi),
                               lb_keogh2(curves, i, lower, upper, np.inf)))
        out[n + i] = math.sqrt(max(fourier_dist2(coords, i, mblo, mbhi),
                                   lb_keogh2(curves, i, mlower, mupper, np.inf)))
    return out


@njit(cache=True, nogil=True)
def _group_keys_kernel(  # pragma: no cover - compiled
    blo, bhi, mblo, mbhi, lower, upper, mlower, mupper, lo, hi, clo, chi, at
):
    # per group g = at[i]: MINDIST of the nearer box to the MBR, and the key
    # max(MINDIST, curve-box bound of the nearer envelope)
    m = at.shape[0]
    d = lo.shape[1]
    n = clo.shape[1]
    mind = np.empty(m)
    keys = np.empty(m)
    for i in range(m):
        g = at[i]
        a = 0.0
        b = 0.0
        for j in range(d):
            e = max(blo[j] - hi[g, j], 0.0) + max(lo[g, j] - bhi[j], 0.0)
            a += e * e
            e = max(mblo[j] - hi[g, j], 0.0) + max(lo[g, j] - mbhi[j], 0.0)
            b += e * e
        md = math.sqrt(min(a, b))
        a = 0.0
        b = 0.0
        for t in range(n):
            e = max(clo[g, t] - upper[t], 0.0) + max(lower[t] - chi[g, t], 0.0)
            a += e * e
            e = max(clo[g, t] - mupper[t], 0.0) + max(mlower[t] - chi[g, t], 0.0)
            b += e * e
        mind[i] = md
        keys[i] = max(md, math.sqrt(min(a, b)))
    return mind, keys


@njit(cache=True, nogil=True)
def _cascade_dtw_kernel(q, c, r, best_so_far):  # pragma: no cover - compiled
    return cascade_env_kernel(q, c, r, best_so_far, q, q, False)


@njit(cache=True, nogil=True)
def cascade_env_kernel(q, c, r, best_so_far, lower, upper, with_envelope):  # pragma: no cover
    # LB_Keogh the other way round (the candidate's envelope against the query), then DTW
    # abandoned on the cumulative bound of that LB per row (and, given the query's
    # envelope, of the forward LB_Keogh per column: the columns after i + r are reached
    # in later rows only)
    n = q.shape[0]
    limit = best_so_far * best_so_far
    terms = np.empty(n)
    s = 0.0
    for i in range(n):
        lo, hi = _window_range(c, i, r)
        v = q[i]
        e = 0.0
        if v > hi:
            e = (v - hi) * (v - hi)
        elif v < lo:
            e = (lo - v) * (lo - v)
        terms[i] = e
        s += e
        if s > limit and math.sqrt(s) > best_so_far:
            return np.inf
    rest = np.empty(n)
    acc = 0.0
    for i in range(n - 1, -1, -1):
        rest[i] = acc  # rows after i
        acc += terms[i]
    if with_envelope:
        acc = 0.0
        for j in range(n - 1, r, -1):
            x = c[j]
            if x > upper[j]:
                acc += (x - upper[j]) * (x - upper[j])
            elif x < lower[j]:
                acc += (lower[j] - x) * (lower[j] - x)
            # acc = forward terms of the columns >= j, all reached after row j - r - 1
            i = j - r - 1
            if acc > rest[i]:
                rest[i] = acc
    return _dtw_rest_kernel(q, c, r, best_so_far, rest)


@njit(cache=True, nogil=True)
def _all_finite(a):  # pragma: no cover - compiled
    for i in range(a.shape[0]):
        if not math.isfinite(a[i]):
            return False
    return True


@njit(cache=True, nogil=True)
def _ordered(lo, hi):  # pragma: no cover - compiled
    for i in range(lo.shape[0]):
        if lo[i] > hi[i]:
            return False
    return True


# ---------------------------------------------------------------------------------------
# validation helpers
# ---------------------------------------------------------------------------------------


def _seq(x: object, name: str, *, ndim: int = 1) -> NDArray[np.float64]:
    a = np.ascontiguousarray(x, dtype=np.float64)
    if a.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {a.shape}")
    if a.size == 0 or (ndim == 2 and a.shape[1] == 0):
        raise ValueError(f"{name} must not be empty")
    if not _all_finite(a.reshape(-1)):
        raise ValueError(f"{name} must contain only finite values")
    return a


def _same_shape(*pairs: tuple[str, np.ndarray]) -> None:
    shape = pairs[0][1].shape
    for name, a in pairs[1:]:
        if a.shape != shape:
            raise ValueError(f"{pairs[0][0]} and {name} must have the same shape, got {shape} and {a.shape}")


def _band(r: object, n: int) -> int:
    if isinstance(r, bool) or not isinstance(r, numbers.Integral):
        raise TypeError(f"band r must be an integer, got {r!r}")
    r = int(r)
    if r < 0:
        raise ValueError(f"band r must be >= 0, got {r}")
    return min(r, n - 1)


def _box(lo: object, hi: object) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    lo_a = _seq(lo, "lo")
    hi_a = _seq(hi, "hi")
    _same_shape(("lo", lo_a), ("hi", hi_a))
    if not _ordered(lo_a, hi_a):
        raise ValueError("box must have lo <= hi in every coordinate")
    return lo_a, hi_a


# ---------------------------------------------------------------------------------------
# time domain
# ---------------------------------------------------------------------------------------


def dtw(q: np.ndarray, c: np.ndarray, r: int, best_so_far: float = math.inf) -> float:
    """DTW distance with a Sakoe-Chiba band, with early abandoning.

    Parameters
    ----------
    q, c : numpy.ndarray
        1-D finite sequences of the same length ``N`` (computed in float64).
    r : int
        Band half-width: only cells ``|i - j| <= r`` are used; ``r >= N - 1`` is
        unconstrained DTW and ``r = 0`` the Euclidean distance.
    best_so_far : float, optional
        Early-abandoning threshold (``>= 0``, may be ``inf``).  As soon as every cell of
        a row of the cost matrix costs more than ``best_so_far**2`` the path cost must
        too, and ``inf`` is returned (UCR suite; Keogh & Ratanamahatana 2005).

    Returns
    -------
    float
        ``sqrt`` of the least cost ``sum (q_i - c_j)^2`` over warping paths from
        ``(0, 0)`` to ``(N-1, N-1)`` in the band; ``inf`` only if that distance exceeds
        ``best_so_far`` (otherwise the exact distance, even if it equals it).

    Raises
    ------
    ValueError
        Shapes differ or are not 1-D, non-finite values, ``r < 0`` or a negative or NaN
        ``best_so_far``.
    TypeError
        ``r`` is not an integer.

    Notes
    -----
    O(N r) time, O(N) memory (two rows).
    """
    qa = _seq(q, "q")
    ca = _seq(c, "c")
    _same_shape(("q", qa), ("c", ca))
    rr = _band(r, qa.shape[0])
    bsf = float(best_so_far)
    if math.isnan(bsf) or bsf < 0:
        raise ValueError(f"best_so_far must be >= 0, got {best_so_far!r}")
    return float(dtw_kernel(qa, ca, rr, bsf))


def cascade_dtw(q: np.ndarray, c: np.ndarray, r: int, best_so_far: float = math.inf) -> float:
    """:func:`dtw` after the UCR suite's second filter: ``inf`` as soon as LB_Keogh of the
    query against the *candidate's* envelope exceeds ``best_so_far``, else :func:`dtw`
    with early abandoning. Equal to ``dtw(q, c, r)`` whenever that is ``<= best_so_far``."""
    qa = _seq(q, "q")
    ca = _seq(c, "c")
    _same_shape(("q", qa), ("c", ca))
    rr = _band(r, qa.shape[0])
    bsf = float(best_so_far)
    if math.isnan(bsf) or bsf < 0:
        raise ValueError(f"best_so_far must be >= 0, got {best_so_far!r}")
    return float(_cascade_dtw_kernel(qa, ca, rr, bsf))


def group_bounds(
    envelope: tuple[np.ndarray, np.ndarray], mirrored_envelope: tuple[np.ndarray, np.ndarray],
    box: tuple[np.ndarray, np.ndarray], mirrored_box: tuple[np.ndarray, np.ndarray],
    coords: np.ndarray, curves: np.ndarray,
) -> NDArray[np.float64]:
    """Keys of a group's curves and their mirrors, in one pass: ``(2n,)`` with
    ``max(Fourier_Dist(box, p_i), LB_Keogh(L, U, c_i))`` then the same for the mirrors
    (``mirrored_box``, and LB_Keogh against the mirrored envelope ``(P L, P U)``, ``P`` =
    :func:`viewdb.catalogue.features.mirror_curve`: see the module doc).

    Inputs are the query's envelopes ``(N,)``, its boxes in the indexed coordinates ``(d,)``,
    the curves' coordinates ``(n, d)`` and the curves ``(n, N)``, all float64, contiguous
    and finite (not re-validated: this is the search's inner loop).
    """
    return _group_bounds_kernel(
        envelope[0], envelope[1], mirrored_envelope[0], mirrored_envelope[1], box[0], box[1],
        mirrored_box[0], mirrored_box[1], coords, curves,
    )


def curve_box_lb_many(
    lower: np.ndarray, upper: np.ndarray, glo: np.ndarray, ghi: np.ndarray
) -> NDArray[np.float64]:
    """Lower bound of LB_Keogh(L, U, c) for every curve ``c`` in each box ``[glo_g, ghi_g]``
    (rows of ``(g, N)`` arrays): the per-sample gap between ``[L, U]`` and the box."""
    gap = np.maximum(glo - upper, 0.0) + np.maximum(lower - ghi, 0.0)
    return np.sqrt(np.einsum("ij,ij->i", gap, gap))


def envelope(q: np.ndarray, r: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """LB_Keogh envelope of a sequence (Keogh & Ratanamahatana 2005, eq. 7).

    Parameters
    ----------
    q : numpy.ndarray
        1-D finite sequence of length ``N``.
    r : int
        Band half-width, ``>= 0``.

    Returns
    -------
    (L, U) : tuple of numpy.ndarray
        float64 ``(N,)``: ``U_i = max(q[max(0, i-r) : i+r+1])`` and ``L_i`` the min
        (windows clipped at the ends, no wrap-around).
    """
    qa = _seq(q, "q")
    rr = _band(r, qa.shape[0])
    return _envelope_kernel(qa, rr)


def lb_keogh(L: np.ndarray, U: np.ndarray, c: np.ndarray) -> float:
    """LB_Keogh lower bound of ``DTW(q, c, r)`` from the envelope of ``q``.

    Parameters
    ----------
    L, U : numpy.ndarray
        Envelope of the query from :func:`envelope` (``L <= U``).
    c : numpy.ndarray
        Candidate sequence, same length.

    Returns
    -------
    float
        ``sqrt(sum_i d_i^2)`` with ``d_i = c_i - U_i`` if ``c_i > U_i``, ``L_i - c_i`` if
        ``c_i < L_i``, else 0: the Euclidean distance from ``c`` to the envelope
        (Keogh & Ratanamahatana 2005, eq. 8).
    """
    La = _seq(L, "L")
    Ua = _seq(U, "U")
    ca = _seq(c, "c")
    _same_shape(("L", La), ("U", Ua), ("c", ca))
    if not _ordered(La, Ua):
        raise ValueError("envelope must have L <= U")
    return float(_lb_keogh_kernel(La, Ua, ca))


def lb_keogh_many(L: np.ndarray, U: np.ndarray, C: np.ndarray) -> NDArray[np.float64]:
    """:func:`lb_keogh` of every row of ``C`` (shape ``(k, N)``); returns ``(k,)``."""
    La = _seq(L, "L")
    Ua = _seq(U, "U")
    _same_shape(("L", La), ("U", Ua))
    Ca = _seq(C, "C", ndim=2)
    if Ca.shape[1] != La.shape[0]:
        raise ValueError(f"rows of C must have length {La.shape[0]}, got {Ca.shape[1]}")
    if not _ordered(La, Ua):
        raise ValueError("envelope must have L <= U")
    d = np.maximum(Ca - Ua, 0.0) + np.maximum(La - Ca, 0.0)
    return np.sqrt(np.einsum("ij,ij->i", d, d))


def paa_edges(n: int, segments: int = PAA_SEGMENTS) -> NDArray[np.int64]:
    """Boundaries ``(S + 1,)`` of ``S = min(segments, n)`` near-equal consecutive segments
    of ``n`` samples (first 0, last ``n``)."""
    if n < 1 or segments < 1:
        raise ValueError(f"need n >= 1 and segments >= 1, got {n}, {segments}")
    s = min(segments, n)
    return np.round(np.linspace(0, n, s + 1)).astype(np.int64)


def paa_means(curves: np.ndarray, edges: np.ndarray) -> NDArray[np.float64]:
    """Each curve's mean over each segment: ``(V, N)`` (or ``(N,)``) → ``(V, S)`` float64."""
    c = np.asarray(curves, dtype=np.float64)
    flat = c.ndim == 1
    c = c[None, :] if flat else c
    e = np.asarray(edges, dtype=np.int64)
    out = np.add.reduceat(c, e[:-1], axis=1) / np.diff(e)
    return out[0] if flat else np.ascontiguousarray(out)


def paa_envelope(
    L: np.ndarray, U: np.ndarray, edges: np.ndarray
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The envelope's range over each segment and the segment widths: ``(lo, hi, widths)``,
    each ``(S,)`` (``lo_J = min L``, ``hi_J = max U`` over segment ``J``)."""
    La, Ua = _seq(L, "L"), _seq(U, "U")
    _same_shape(("L", La), ("U", Ua))
    e = np.asarray(edges, dtype=np.int64)
    if e[0] != 0 or e[-1] != len(La) or np.any(np.diff(e) < 1):
        raise ValueError(f"edges must rise from 0 to {len(La)}")
    return (np.minimum.reduceat(La, e[:-1]), np.maximum.reduceat(Ua, e[:-1]),
            np.diff(e).astype(np.float64))


def lb_paa(lo: np.ndarray, hi: np.ndarray, widths: np.ndarray, means: np.ndarray) -> float:
    """LB_PAA (module doc): a lower bound of ``LB_Keogh(L, U, c)`` from ``c``'s segment
    means and :func:`paa_envelope` ``(lo, hi, widths)``."""
    m = _seq(means, "means")
    lo_a, hi_a, w = _seq(lo, "lo"), _seq(hi, "hi"), _seq(widths, "widths")
    _same_shape(("lo", lo_a), ("hi", hi_a), ("widths", w), ("means", m))
    return math.sqrt(lb_paa2(m.reshape(1, -1), 0, lo_a, hi_a, w, np.inf))


def lb_keogh_reverse(q: np.ndarray, c: np.ndarray, r: int) -> float:
    """LB_Keogh with the envelope built around the candidate: ``lb_keogh(*envelope(c, r), q)``.

    Also a lower bound of ``DTW(q, c, r)`` because banded DTW is symmetric; the larger of
    the two is the UCR suite's "LB_Keogh EQ / EC" cascade.
    """
    qa = _seq(q, "q")
    ca = _seq(c, "c")
    _same_shape(("q", qa), ("c", ca))
    rr = _band(r, qa.shape[0])
    lower, upper = _envelope_kernel(ca, rr)
    return float(_lb_keogh_kernel(lower, upper, qa))


def lb_kim(q: np.ndarray, c: np.ndarray) -> float:
    """First/last-point lower bound of DTW (the UCR suite's cheap LB_Kim).

    Every warping path contains the cells ``(0, 0)`` and ``(N-1, N-1)`` (distinct cells for
    ``N >= 2``), so ``DTW >= sqrt((q_0 - c_0)^2 + (q_{N-1} - c_{N-1})^2)`` for any band.
    For ``N = 1`` it is ``|q_0 - c_0|``, the DTW itself.
    """
    qa = _seq(q, "q")
    ca = _seq(c, "c")
    _same_shape(("q", qa), ("c", ca))
    d0 = qa[0] - ca[0]
    if qa.shape[0] == 1:
        return float(abs(d0))
    d1 = qa[-1] - ca[-1]
    return float(math.sqrt(d0 * d0 + d1 * d1))


# ---------------------------------------------------------------------------------------
# Fourier coordinates and the query box
# ---------------------------------------------------------------------------------------


def fourier_coordinates(m: int, n: int) -> NDArray[np.float64]:
    """The linear map from a curve to its index coordinates.

    Parameters
    ----------
    m : int
        Number of DFT coefficients, ``1 <= m <= n``.
    n : int
        Curve length ``N >= 1``.

    Returns
    -------
    numpy.ndarray
        float64 ``(2m, n)`` matrix ``F`` with ``F[k, t] = cos(2 pi k t / n) / sqrt(n)`` and
        ``F[m + k, t] = -sin(2 pi k t / n) / sqrt(n)``, so that
        ``F @ x = [Re X_0..Re X_{m-1}, Im X_0..Im X_{m-1}]`` with
        ``X = np.fft.fft(x, norm="ortho")``.  Row ``m`` (``Im X_0``) is identically zero
        and kept.  ``||F v|| <= ||v||`` for every ``v`` (Parseval).
    """
    if isinstance(m, bool) or not isinstance(m, numbers.Integral):
        raise TypeError(f"m must be an integer, got {m!r}")
    if isinstance(n, bool) or not isinstance(n, numbers.Integral):
        raise TypeError(f"n must be an integer, got {n!r}")
    m, n = int(m), int(n)
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if not 1 <= m <= n:
        raise ValueError(f"m must be in [1, {n}], got {m}")
    k = np.arange(m)[:, None]
    t = np.arange(n)[None, :]
    angle = (2.0 * np.pi / n) * ((k * t) % n)  # exact phase reduction
    scale = 1.0 / math.sqrt(n)
    F = np.concatenate([np.cos(angle), -np.sin(angle)]) * scale
    F[m] = 0.0  # Im X_0: exactly zero
    if n % 2 == 0 and m > n // 2:
        F[m + n // 2] = 0.0  # Im X_{N/2}: exactly zero too
    return F


def complex_to_coordinates(points: np.ndarray) -> NDArray[np.float64]:
    """Index coordinates of Fourier points: ``[Re X, Im X]`` along the last axis.

    ``points`` is complex ``(m,)`` or ``(k, m)`` (e.g. from
    :func:`viewdb.catalogue.features.fourier_point`); returns float64 ``(2m,)`` or ``(k, 2m)``,
    equal to ``F @ c`` for :func:`fourier_coordinates`.
    """
    X = np.asarray(points)
    if X.ndim not in (1, 2) or X.shape[-1] == 0:
        raise ValueError(f"points must be 1-D or 2-D and non-empty, got shape {X.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError("points must contain only finite values")
    return np.concatenate([X.real, X.imag], axis=-1).astype(np.float64, copy=False)


def envelope_box(
    L: np.ndarray, U: np.ndarray, F: np.ndarray
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The query box: exact range of each coordinate over the envelope (Zhu & Shasha 2003).

    Parameters
    ----------
    L, U : numpy.ndarray
        Envelope ``(N,)`` with ``L <= U`` (from :func:`envelope`), or several envelopes
        as the rows of ``(T, N)`` arrays.
    F : numpy.ndarray
        ``(d, N)`` coordinate map (from :func:`fourier_coordinates`).

    Returns
    -------
    (lo, hi) : tuple of numpy.ndarray
        float64 ``(d,)`` (``(T, d)`` for several envelopes, one row each):
        ``lo_k = sum_t min(F_kt L_t, F_kt U_t)`` and
        ``hi_k = sum_t max(F_kt L_t, F_kt U_t)``, the min and max of ``F_k . x`` over
        ``L <= x <= U`` (a linear function on a box attains its extremes at a vertex,
        chosen per ``t`` by the sign of ``F_kt``), each rounded outward by
        ``4 N eps (sum_t |F_kt| M_t + max_t M_t)``, ``M_t = max(|L_t|, |U_t|)``, to absorb
        the rounding of the dot products here and of the FFT that gives the candidates'
        coordinates (the second term covers the all-zero rows, which an FFT only
        reproduces up to rounding).
    """
    La = _seq(L, "L", ndim=np.ndim(L) if np.ndim(L) in (1, 2) else 1)
    Ua = _seq(U, "U", ndim=La.ndim)
    _same_shape(("L", La), ("U", Ua))
    if not _ordered(La.reshape(-1), Ua.reshape(-1)):
        raise ValueError("envelope must have L <= U")
    Fa = _seq(F, "F", ndim=2)
    if Fa.shape[1] != La.shape[-1]:
        raise ValueError(f"F must have {La.shape[-1]} columns, got shape {Fa.shape}")
    pos = np.maximum(Fa, 0.0)
    neg = np.minimum(Fa, 0.0)
    lo = La @ pos.T + Ua @ neg.T
    hi = Ua @ pos.T + La @ neg.T
    size = np.maximum(np.abs(La), np.abs(Ua))
    # |error| of F_k . x (dot product or FFT) <= ~ N eps sum_t |F_kt| |x_t|, plus a floor
    # for rows that are exactly 0 in F (Im X_0, Im X_{N/2}) but not in an FFT result
    slack = (4.0 * La.shape[-1] * np.finfo(np.float64).eps) * (
        size @ np.abs(Fa).T + size.max(axis=-1, keepdims=True))
    return lo - slack, hi + slack


def mirror_box(lo: np.ndarray, hi: np.ndarray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The box ``S [lo, hi]`` for mirrored candidates, ``S = diag(I_m, -I_m)``.

    ``lo`` and ``hi`` have length ``2m`` in the layout of :func:`fourier_coordinates`;
    the ``Re`` half is unchanged and the ``Im`` half becomes ``[-hi_Im, -lo_Im]``.  Then
    ``fourier_dist(*mirror_box(lo, hi), F c) == fourier_dist(lo, hi, F mirror_curve(c))``
    and likewise for :func:`mindist` with the MBR of the stored (unmirrored) points.
    """
    lo_a, hi_a = _box(lo, hi)
    if lo_a.shape[0] % 2:
        raise ValueError(f"box must have even length 2m, got {lo_a.shape[0]}")
    m = lo_a.shape[0] // 2
    new_lo = np.concatenate([lo_a[:m], -hi_a[m:]])
    new_hi = np.concatenate([hi_a[:m], -lo_a[m:]])
    return new_lo, new_hi


def rounded32(x: np.ndarray, up: bool) -> NDArray[np.float32]:
    """``x`` as float32, each value rounded up (never below ``x``) or down (never above)."""
    x = np.asarray(x, dtype=np.float64)
    out = np.array(x, dtype=np.float32)
    off = out.astype(np.float64) < x if up else out.astype(np.float64) > x
    out[off] = np.nextafter(out[off], np.float32(np.inf if up else -np.inf))
    return np.ascontiguousarray(out)


def outward32(lo: np.ndarray, hi: np.ndarray) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """``lo`` and ``hi`` in float32, each value rounded outward (``lo`` down, ``hi`` up), so
    the float32 interval holds the float64 one."""
    return rounded32(lo, up=False), rounded32(hi, up=True)


def mirror_coordinates(p: np.ndarray) -> NDArray[np.float64]:
    """Coordinates of the mirrored curve: ``S p`` (``Im`` half negated), rows of a 2-D ``p``."""
    pa = np.asarray(p, dtype=np.float64)
    if pa.ndim not in (1, 2) or pa.shape[-1] % 2 or pa.shape[-1] == 0:
        raise ValueError(f"p must be 1-D or 2-D with even length 2m, got shape {pa.shape}")
    m = pa.shape[-1] // 2
    out = pa.copy()
    out[..., m:] *= -1.0
    return out


def fourier_dist(lo: np.ndarray, hi: np.ndarray, p: np.ndarray) -> float:
    """Fourier_Dist: Euclidean distance from the point ``p`` to the box ``[lo, hi]``.

    ``p = F @ c`` are the candidate's coordinates; 0 if ``p`` is inside the box.  A lower
    bound of ``LB_Keogh(L, U, c)`` when ``[lo, hi] = envelope_box(L, U, F)`` (module
    docstring; Zhu & Shasha 2003, Keogh & Ratanamahatana 2005).
    """
    lo_a, hi_a = _box(lo, hi)
    pa = _seq(p, "p")
    _same_shape(("lo", lo_a), ("p", pa))
    d = np.maximum(lo_a - pa, 0.0) + np.maximum(pa - hi_a, 0.0)
    return float(math.sqrt(float(d @ d)))


def fourier_dist_many(lo: np.ndarray, hi: np.ndarray, P: np.ndarray) -> NDArray[np.float64]:
    """:func:`fourier_dist` for every row of ``P`` (shape ``(k, d)``); returns ``(k,)``."""
    lo_a, hi_a = _box(lo, hi)
    Pa = _seq(P, "P", ndim=2)
    if Pa.shape[1] != lo_a.shape[0]:
        raise ValueError(f"rows of P must have length {lo_a.shape[0]}, got {Pa.shape[1]}")
    d = np.maximum(lo_a - Pa, 0.0) + np.maximum(Pa - hi_a, 0.0)
    return np.sqrt(np.einsum("ij,ij->i", d, d))


def mindist(lo: np.ndarray, hi: np.ndarray, mbr_lo: np.ndarray, mbr_hi: np.ndarray) -> float:
    """MINDIST: Euclidean distance between the query box and an MBR (0 if they meet).

    Per coordinate the gap is ``max(lo - mbr_hi, mbr_lo - hi, 0)`` (Keogh &
    Ratanamahatana 2005, eq. 12, with the query box in place of a point).
    """
    lo_a, hi_a = _box(lo, hi)
    blo, bhi = _box(mbr_lo, mbr_hi)
    _same_shape(("lo", lo_a), ("mbr_lo", blo))
    d = np.maximum(lo_a - bhi, 0.0) + np.maximum(blo - hi_a, 0.0)
    return float(math.sqrt(float(d @ d)))


def mindist_many(
    lo: np.ndarray, hi: np.ndarray, mbr_lo: np.ndarray, mbr_hi: np.ndarray
) -> NDArray[np.float64]:
    """:func:`mindist` to each of ``k`` MBRs given as rows of ``(k, d)`` arrays."""
    lo_a, hi_a = _box(lo, hi)
    blo = _seq(mbr_lo, "mbr_lo", ndim=2)
    bhi = _seq(mbr_hi, "mbr_hi", ndim=2)
    _same_shape(("mbr_lo", blo), ("mbr_hi", bhi))
    if blo.shape[1] != lo_a.shape[0]:
        raise ValueError(f"MBRs must have {lo_a.shape[0]} columns, got {blo.shape[1]}")
    if np.any(blo > bhi):
        raise ValueError("MBRs must have lo <= hi in every coordinate")
    d = np.maximum(lo_a - bhi, 0.0) + np.maximum(blo - hi_a, 0.0)
    return np.sqrt(np.einsum("ij,ij->i", d, d))
