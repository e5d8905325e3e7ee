"""One search over many query curves: every circular shift of the curve, or any set.

A silhouette turned in the image plane gives the same contour walked from another start
point, so its distance curve is (up to resampling) a **circular shift** of the upright
one: ``shifted(q, s)[i] = q[(i + s) mod N]`` starts at sample ``s``. The distance of a
view ``c`` under a :class:`ShiftWindow` ``W`` is

    ``D_W(q, c) = min over s in W of min(DTW_r(shifted(q, s), c), DTW_r(shifted(q, s), P c))``

(``P c`` the mirrored curve, :func:`viewdb.catalogue.features.mirror_curve`), and the
search returns the k distinct objects with the smallest ``D_W`` exactly
(:func:`viewdb.search.knn.knn` with ``shifts=``). More generally the search takes any
stack of ``T`` query curves ``q_1 .. q_T`` (e.g. the 12 in-plane turns of the silhouette,
each resampled) and the distance ``min_t min(DTW(q_t, c), DTW(q_t, P c))``
(:class:`CurveQuery`); a window is the stack of the shifted curves.

Bounds valid for a set of curves
--------------------------------
Every bound of :mod:`viewdb.search.bounds` is a lower bound of ``DTW_r(q_t, c)`` derived
from one fact: the point ``x* = clip(c, L_t, U_t)`` of q_t's envelope ``E_t = [L_t, U_t]``
nearest to ``c`` has ``||x* - c|| = LB_Keogh(E_t, c) <= DTW_r(q_t, c)``. For a **set** ``B``
of curves take the **wedge** ``W_B = [min_t L_t, max_t U_t]`` (Keogh, Wei, Xi, Lee &
Vlachos, "LB_Keogh supports exact indexing of shapes under rotation invariance with
arbitrary representations and distance measures", VLDB 2006): every ``E_t`` with ``t`` in
``B`` lies inside it, so ``LB_Keogh(W_B, c) <= LB_Keogh(E_t, c)`` for each ``t`` (the
distance to a larger set is smaller) and hence ``<= min_t DTW_r(q_t, c)``. Each bound of
the chain then applies to the wedge unchanged: LB_PAA over the wedge's segment ranges
(the union of the curves' segment ranges), the curve-box bound of a group against the
wedge, and Fourier_Dist / MINDIST against the **union of the curves' boxes**
``[min_t lo_t, max_t hi_t]``, which holds ``F x`` for every ``x`` in any ``E_t``.

Rings: a bound for all shifts at once
-------------------------------------
The union of the boxes of all 128 shifts is nearly the whole disc ``|X_k| <= max``, so the
group level adds a bound that uses what shifting leaves alone: shifting a curve by ``s``
multiplies ``X_k`` by ``exp(2 pi i k s / N)`` and leaves ``|X_k|`` unchanged. For each
curve ``t`` and indexed coefficient ``k``, every ``x`` in ``E_t`` has ``X_k(x)`` in the
rectangle ``box_t,k`` (Re, Im), hence ``near_t,k <= |X_k(x)| <= far_t,k`` (the
rectangle's nearest and farthest points from 0). The **ring**
``A_k = {z : min_t near_t,k <= |z| <= max_t far_t,k}`` therefore holds ``X_k(x)`` for every
``x`` in every ``E_t``, and since ``F x*`` lies in the product of the rings,
``dist(F c, A) <= ||F x* - F c|| <= ||x* - c||`` (``F`` a contraction, as in
:mod:`viewdb.search.bounds`) with ``dist(F c, A)^2 = sum_k dist(X_k(c), A_k)^2``. For a
group, the distance from its MBR's rectangle to each ring bounds that of every point in
it. A ring is its own mirror (``P`` conjugates ``X_k``), so one ring serves both
orientations. The group key is the largest of the box MINDIST, the ring distance and the
curve-box bound, all against the whole stack.

Levels of the search
--------------------
The stack is cut into **blocks** of ``block`` consecutive curves
(:class:`~viewdb.config.SearchConfig`). A search entry is a (group, block), a (view,
block) or a (view, curve), each keyed by its bounds against the block's wedge or the
curve's own envelope, always at least its parent's key; :mod:`viewdb.search.multirefine`
refines them best first (its module doc says why the result is exact). A block of one
curve skips the (view, block) level; a stack of one curve with ``block = 1`` is the
ordinary fixed-start search.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import QueryError
from ..jit import njit
from .bounds import envelope_box, fourier_coordinates, outward32, paa_edges
from .grouping import INDEXED_COEFFICIENTS, indexed_rows

__all__ = ["CurveQuery", "ShiftWindow", "shift_turn", "shifted", "shifted_curves", "turn_window"]


@dataclass(frozen=True)
class ShiftWindow:
    """The circular shifts a search tries: every ``step``-th shift from ``centre -
    half_width`` to ``centre + half_width`` (mod N) through ``centre``, or round the
    whole curve (``half_width`` None, or at least ``N // 2``).

    ``ShiftWindow()`` is every shift; ``ShiftWindow(0, 0)`` the curve as given (the
    fixed-start search); ``ShiftWindow(c, h)`` the shifts within ``h`` samples of ``c``
    (e.g. around the start sample a gravity hint predicts, :func:`turn_window`);
    ``ShiftWindow(step=8)`` every 8th start round the curve (16 of 128).
    """

    centre: int = 0
    half_width: int | None = None
    step: int = 1

    def __post_init__(self) -> None:
        for name, value in (("centre", self.centre), ("half_width", self.half_width),
                            ("step", self.step)):
            if value is None and name == "half_width":
                continue
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise QueryError(f"shift window {name} must be an integer, got {value!r}")
        if self.half_width is not None and self.half_width < 0:
            raise QueryError(f"shift window half_width must be >= 0, got {self.half_width}")
        if self.step < 1:
            raise QueryError(f"shift window step must be at least 1, got {self.step}")

    def shifts(self, n: int) -> NDArray[np.int64]:
        """The shifts of a curve of ``n`` samples, in window order (from its start, or
        from ``centre`` round the curve), each once."""
        if self.half_width is None or 2 * self.half_width + 1 >= n:
            return (self.centre + np.arange(0, n, self.step, dtype=np.int64)) % n
        reach = self.half_width // self.step * self.step
        return (self.centre + np.arange(-reach, reach + 1, self.step, dtype=np.int64)) % n

    def to_dict(self) -> dict[str, Any]:
        return {"centre": int(self.centre), "half_width": self.half_width, "step": int(self.step)}

    @classmethod
    def from_dict(cls, data: Any) -> ShiftWindow:
        if not isinstance(data, dict) or set(data) - {"centre", "half_width", "step"}:
            raise QueryError("shifts must be an object with centre, half_width and step")
        return cls(data.get("centre", 0), data.get("half_width"), data.get("step", 1))


def shifted(curve: NDArray[np.floating], s: int) -> NDArray[np.float64]:
    """The curve started at sample ``s``: ``out[i] = curve[(i + s) mod N]``."""
    return np.roll(np.asarray(curve, dtype=np.float64), -int(s))


def shifted_curves(curve: NDArray[np.floating], shifts: NDArray[np.integer]) -> NDArray[np.float64]:
    """:func:`shifted` for each of ``shifts``, as the rows of a ``(T, N)`` array."""
    q = np.asarray(curve, dtype=np.float64)
    idx = (np.arange(len(q))[None, :] + np.asarray(shifts, dtype=np.int64)[:, None]) % len(q)
    return np.ascontiguousarray(q[idx])


def shift_turn(bearings: NDArray[np.floating], shift: int) -> float:
    """The in-plane turn a shift stands for: the silhouette turned back (clockwise on
    screen) by this many degrees starts its curve at sample ``shift`` (see
    :func:`turn_window`), in ``[0, 360)``."""
    return float((-float(bearings[shift])) % 360.0)


def turn_window(bearings: NDArray[np.floating], turn: float, tolerance: float) -> ShiftWindow:
    """The shifts that stand for the in-plane turns within ``tolerance`` degrees of
    ``turn``.

    ``bearings[i]`` is the direction of sample ``i`` seen from the centroid, in degrees
    clockwise from up on screen (:func:`viewdb.catalogue.features.sample_bearings`): the
    silhouette turned back by ``turn`` degrees (clockwise on screen, as
    :func:`viewdb.recognition.shapes.rotated_curves` turns it) starts its curve where the
    contour crosses the ray of bearing ``-turn`` (the topmost crossing once turned). The
    window is centred on the sample nearest that bearing (sample 0 for turn 0) and reaches
    as far along the contour either way as the samples stay within the tolerance: the
    start moves along the contour as the turn changes (a jump across a concavity, where
    the ray grazes the contour, is left to the DTW band).
    """
    b = np.asarray(bearings, dtype=np.float64)
    if b.ndim != 1 or len(b) == 0 or not np.all(np.isfinite(b)):
        raise QueryError("bearings must be a non-empty 1-D array of finite angles")
    if not (math.isfinite(turn) and math.isfinite(tolerance) and tolerance >= 0):
        raise QueryError(f"turn and tolerance must be finite, tolerance >= 0; got {turn}, {tolerance}")
    n = len(b)
    off = np.abs((b + turn + 180.0) % 360.0 - 180.0)  # angle between bearing and -turn
    centre = int(np.argmin(off))
    reach = [0, 0]
    for side, sign in enumerate((-1, 1)):
        while reach[side] < n // 2 and off[(centre + sign * (reach[side] + 1)) % n] <= tolerance:
            reach[side] += 1
    return ShiftWindow(centre, max(reach))


# ---------------------------------------------------------------------------------------
# the query side: envelopes, boxes, wedges and rings of a stack of curves
# ---------------------------------------------------------------------------------------


@njit(cache=True, nogil=True)
def _envelopes_kernel(Q, r):  # pragma: no cover - compiled
    # the clipped LB_Keogh envelope of each row (bounds.envelope, row by row)
    t_count, n = Q.shape
    lower = np.empty((t_count, n))
    upper = np.empty((t_count, n))
    for t in range(t_count):
        for i in range(n):
            a = max(0, i - r)
            b = min(n - 1, i + r)
            lo = Q[t, a]
            hi = Q[t, a]
            for j in range(a + 1, b + 1):
                v = Q[t, j]
                if v < lo:
                    lo = v
                if v > hi:
                    hi = v
            lower[t, i] = lo
            upper[t, i] = hi
    return lower, upper


@njit(cache=True, nogil=True)
def _rect_gap2(re_lo, re_hi, im_lo, im_hi, ring_lo, ring_hi):  # pragma: no cover - compiled
    # squared distance from the rectangle [re_lo, re_hi] x [im_lo, im_hi] to the ring
    # ring_lo <= |z| <= ring_hi (0 if they meet)
    gx = max(re_lo, 0.0, -re_hi)
    gy = max(im_lo, 0.0, -im_hi)
    near = math.sqrt(gx * gx + gy * gy)
    fx = max(abs(re_lo), abs(re_hi))
    fy = max(abs(im_lo), abs(im_hi))
    far = math.sqrt(fx * fx + fy * fy)
    e = max(near - ring_hi, ring_lo - far, 0.0)
    return e * e


@njit(cache=True, nogil=True)
def _stack_group_keys_kernel(  # pragma: no cover - compiled
    blo, bhi, ring_lo, ring_hi, wlo, whi, lo, hi, clo, chi, at
):
    # per group g = at[i]: the Fourier bound (the larger of MINDIST of the nearer union box
    # and the distance of the MBR to the rings) and the key (the larger of that and the
    # curve-box bound of the nearer whole-stack wedge); index 0 unmirrored, 1 mirrored
    m = at.shape[0]
    d = lo.shape[1]
    half = d // 2
    n = clo.shape[1]
    mind = np.empty(m)
    keys = np.empty(m)
    for i in range(m):
        g = at[i]
        a = 0.0
        b = 0.0
        for j in range(d):
            e = max(blo[0, j] - hi[g, j], 0.0) + max(lo[g, j] - bhi[0, j], 0.0)
            a += e * e
            e = max(blo[1, j] - hi[g, j], 0.0) + max(lo[g, j] - bhi[1, j], 0.0)
            b += e * e
        ring = 0.0
        for j in range(half):
            ring += _rect_gap2(lo[g, j], hi[g, j], lo[g, half + j], hi[g, half + j],
                               ring_lo[j], ring_hi[j])
        md = math.sqrt(max(min(a, b), ring))
        a = 0.0
        b = 0.0
        for t in range(n):
            e = max(clo[g, t] - whi[0, t], 0.0) + max(wlo[0, t] - chi[g, t], 0.0)
            a += e * e
            e = max(clo[g, t] - whi[1, t], 0.0) + max(wlo[1, t] - chi[g, t], 0.0)
            b += e * e
        mind[i] = md
        keys[i] = max(md, math.sqrt(min(a, b)))
    return mind, keys


def _mirrored(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`~viewdb.catalogue.features.mirror_curve` of each row."""
    return np.ascontiguousarray(np.roll(x[:, ::-1], 1, axis=1))


def _mirrored_boxes(lo: NDArray[np.float64], hi: NDArray[np.float64]):
    """:func:`~viewdb.search.bounds.mirror_box` of each row (``[Re.., Im..]`` layout)."""
    h = lo.shape[1] // 2
    return (np.concatenate([lo[:, :h], -hi[:, h:]], axis=1),
            np.concatenate([hi[:, :h], -lo[:, h:]], axis=1))


def _pair(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.ascontiguousarray(np.stack([a, b]))


@dataclass(frozen=True)
class CurveQuery:
    """A stack of query curves with everything the search bounds them by (module doc).

    Arrays with a leading axis of 2 hold the curves' own value at ``[0]`` and the value for
    mirrored views at ``[1]`` (the mirrored envelope, the mirrored box).
    """

    #: The curves, ``(T, N)``, and the DTW band.
    curves: NDArray[np.float64]
    band: int
    #: Each curve's envelope, ``(2, T, N)``.
    env_lo: NDArray[np.float64]
    env_hi: NDArray[np.float64]
    #: Each envelope's box in the indexed coordinates, ``(2, T, d)``.
    box_lo: NDArray[np.float64]
    box_hi: NDArray[np.float64]
    #: Each envelope's range per PAA segment, ``(2, T, S)``, and the segment widths ``(S,)``.
    seg_lo: NDArray[np.float64]
    seg_hi: NDArray[np.float64]
    widths: NDArray[np.float64]
    #: Blocks: curves ``block_start[b] .. block_end[b] - 1``; their wedges ``(2, B, N)``,
    #: union boxes ``(2, B, d)`` and segment ranges ``(2, B, S)``.
    block_start: NDArray[np.int64]
    block_end: NDArray[np.int64]
    wedge_lo: NDArray[np.float64]
    wedge_hi: NDArray[np.float64]
    wbox_lo: NDArray[np.float64]
    wbox_hi: NDArray[np.float64]
    wseg_lo: NDArray[np.float64]
    wseg_hi: NDArray[np.float64]
    #: The wedges in float32, rounded outward (:func:`~viewdb.search.bounds.outward32`), for
    #: the float32 curve-box bound of a group (:func:`~viewdb.search.bounds.curve_box32`).
    wedge32_lo: NDArray[np.float32]
    wedge32_hi: NDArray[np.float32]
    #: The whole stack: wedge ``(2, N)``, union box ``(2, d)`` and rings ``(d / 2,)``.
    all_lo: NDArray[np.float64]
    all_hi: NDArray[np.float64]
    all_box_lo: NDArray[np.float64]
    all_box_hi: NDArray[np.float64]
    ring_lo: NDArray[np.float64]
    ring_hi: NDArray[np.float64]

    @classmethod
    def of(cls, curves: NDArray[np.floating], band: int, block: int = 1) -> CurveQuery:
        """The bounds of a ``(T, N)`` stack (rows finite; not re-validated), ``block``
        curves per block."""
        Q = np.ascontiguousarray(curves, dtype=np.float64)
        if Q.ndim != 2 or not len(Q):
            raise QueryError(f"a stack of query curves must be (T, N) with T >= 1, got {Q.shape}")
        if isinstance(block, bool) or not isinstance(block, numbers.Integral) or block < 1:
            raise QueryError(f"block must be a positive integer, got {block!r}")
        t_count, n = Q.shape
        r = min(int(band), n - 1)
        lower, upper = _envelopes_kernel(Q, r)
        env_lo, env_hi = _pair(lower, _mirrored(lower)), _pair(upper, _mirrored(upper))
        m = max(INDEXED_COEFFICIENTS) + 1
        F = fourier_coordinates(m, n)[indexed_rows(m)]
        lo, hi = envelope_box(lower, upper, F)
        mlo, mhi = _mirrored_boxes(lo, hi)
        box_lo, box_hi = _pair(lo, mlo), _pair(hi, mhi)
        edges = paa_edges(n)
        seg_lo = np.ascontiguousarray(np.minimum.reduceat(env_lo, edges[:-1], axis=2))
        seg_hi = np.ascontiguousarray(np.maximum.reduceat(env_hi, edges[:-1], axis=2))
        starts = np.arange(0, t_count, block, dtype=np.int64)
        ends = np.minimum(starts + block, t_count)

        def lows(a: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.ascontiguousarray(np.minimum.reduceat(a, starts, axis=1))

        def highs(a: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.ascontiguousarray(np.maximum.reduceat(a, starts, axis=1))

        half = lo.shape[1] // 2
        gx = np.maximum.reduce([lo[:, :half], np.zeros_like(lo[:, :half]), -hi[:, :half]])
        gy = np.maximum.reduce([lo[:, half:], np.zeros_like(lo[:, half:]), -hi[:, half:]])
        fx = np.maximum(np.abs(lo[:, :half]), np.abs(hi[:, :half]))
        fy = np.maximum(np.abs(lo[:, half:]), np.abs(hi[:, half:]))
        return cls(
            Q, r, env_lo, env_hi, box_lo, box_hi, seg_lo, seg_hi,
            np.diff(edges).astype(np.float64), starts, ends,
            lows(env_lo), highs(env_hi), lows(box_lo), highs(box_hi), lows(seg_lo), highs(seg_hi),
            *outward32(lows(env_lo), highs(env_hi)),
            np.ascontiguousarray(env_lo.min(axis=1)), np.ascontiguousarray(env_hi.max(axis=1)),
            np.ascontiguousarray(box_lo.min(axis=1)), np.ascontiguousarray(box_hi.max(axis=1)),
            np.hypot(gx, gy).min(axis=0), np.hypot(fx, fy).max(axis=0),
        )

    @property
    def box(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The union of the curves' boxes (what an R-tree is asked for)."""
        return self.all_box_lo[0], self.all_box_hi[0]

    @property
    def mirrored_box(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return self.all_box_lo[1], self.all_box_hi[1]

    def group_keys(
        self, lo: NDArray[np.float64], hi: NDArray[np.float64],
        curve_lo: NDArray[np.floating], curve_hi: NDArray[np.floating],
        at: NDArray[np.int64] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The Fourier bound (box MINDIST or rings, whichever is larger) and the key of
        groups given by their MBRs and curve ranges, for the rows ``at`` (default all):
        lower bounds of the distance of every view of the group to every curve of the
        stack, either orientation (module doc). Inputs are trusted."""
        rows = np.arange(len(lo), dtype=np.int64) if at is None else at
        return _stack_group_keys_kernel(
            self.all_box_lo, self.all_box_hi, self.ring_lo, self.ring_hi, self.all_lo,
            self.all_hi, lo, hi, curve_lo, curve_hi, rows,
        )
