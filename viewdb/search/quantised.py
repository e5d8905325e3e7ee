"""How far a distance on a quantised curve can be from the distance on the exact curve.

A compact client file stores each curve ``c`` (float32) as codes that decode to ``c' =
c + e`` (:func:`viewdb.storage.codecs.encode_quantised`), and records ``||e||_2`` and
``||e||_inf`` rounded up. For every query ``q``, band ``r``, mirroring and shift::

    |DTW_r(q, c') - DTW_r(q, c)|  <=  B = sqrt(||e||_2^2 + (N - 1) ||e||_inf^2)   (r >= 1)
                                       B = ||e||_2                                 (r = 0)

Proof. For one warping path P, ``f_P(x) = sqrt(sum_{(i,j) in P} (q_i - x_j)^2)`` is the
Euclidean norm of a vector linear in ``x``, so by the triangle inequality ``|f_P(c') -
f_P(c)| <= sqrt(sum_{(i,j) in P} e_j^2)``. Every path visits each column ``j`` at least
once and has at most ``2N - 1`` cells (``N`` for ``r = 0``, the diagonal), so that sum is
at most ``||e||_2^2 + (N - 1) ||e||_inf^2``. DTW is the minimum of ``f_P`` over the
paths, and the minimum of functions each moved by at most ``B`` moves by at most ``B``.
Mirroring the stored curve permutes ``e`` (both norms unchanged); a shift moves the
query, not ``e``; the search's distance is a minimum over orientations and shifts, each
within ``B``. So ``d' + B`` bounds the exact distance from above, which is what a CS1
client may send (:func:`upper_distance`; the server's bounds stay valid and its answer
stays exactly ``server``'s).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["distance_bound", "round_up", "upper_distance"]

#: Relative and absolute slack for the floating-point rounding of the DTW sums (float64
#: sums of at most 2N-1 terms err by ~1e-13 relative; this is far beyond).
RELATIVE_SLACK = 1e-9
ABSOLUTE_SLACK = 1e-12
#: Significant digits of a raised distance (rounded up): shorter JSON, still a bound.
DIGITS = 7


def distance_bound(errors: NDArray[np.floating], samples: int, band: int) -> NDArray[np.float64]:
    """``B`` (module doc) for error norms ``errors`` ``(..., 2)`` (L2, L-infinity) of
    curves of ``samples`` samples searched with band ``band``."""
    e = np.asarray(errors, dtype=np.float64)
    l2, linf = e[..., 0], e[..., 1]
    if band <= 0:
        return l2.copy()
    return np.sqrt(l2 * l2 + (samples - 1) * linf * linf)


def round_up(x: float, digits: int = DIGITS) -> float:
    """The smallest float of ``digits`` significant decimal digits that is ``>= x``."""
    if not math.isfinite(x) or x <= 0:
        return x
    exponent = math.floor(math.log10(x)) - digits + 1
    y = float(f"{math.ceil(x / 10.0**exponent)}e{exponent}")
    while y < x:  # the division or the decimal parse rounded down
        y = float(f"{round(y / 10.0**exponent) + 1}e{exponent}")
    return y


def upper_distance(distance: float, bound: float) -> float:
    """An upper bound of the exact distance of a view whose quantised curve is at
    ``distance`` and whose error bound is ``bound`` (module doc), rounded up."""
    if bound <= 0:
        return distance
    raised = (distance + bound) * (1 + RELATIVE_SLACK) + ABSOLUTE_SLACK
    return round_up(raised)
