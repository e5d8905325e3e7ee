"""A distance curve's embedding that no in-plane turn or mirror changes: the magnitudes of
its discrete Fourier coefficients.

A photo's object turned in the image plane starts its distance curve at another sample: a
circular shift, which multiplies each DFT coefficient by a unit phase and leaves its
magnitude alone. The mirrored silhouette's curve (:func:`~viewdb.catalogue.features.mirror_curve`)
has the conjugate coefficients, of the same magnitudes. So one embedding stands for a view,
its mirror and every turn of each, and the ``fast`` plan (:mod:`viewdb.search.fast`) asks its
approximate index once per query curve instead of per turn and orientation.

The coefficients are ``np.fft.rfft(curve) / N`` (the mean of a curve is 1, coefficient 0,
and is left out), ``1 .. coefficients``. The Euclidean distance between two embeddings is at
most that between the two curves' coefficients at the best turn (the triangle inequality
per coefficient), i.e. what a turn-free Fourier distance would be; it is not a bound of DTW,
which is why the ``fast`` plan uses it only to shortlist objects and computes every distance
it reports exactly.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["embed_curves"]


def embed_curves(curves: NDArray[np.floating], coefficients: int) -> NDArray[np.float32]:
    """The embeddings ``(V, coefficients)`` (float32) of curves ``(V, N)`` (a single curve
    ``(N,)`` gives ``(1, coefficients)``): the magnitudes of DFT coefficients ``1 ..
    coefficients`` over ``N`` (module doc). Raises ValueError for fewer samples than
    ``2 * coefficients + 1`` (coefficients past the Nyquist frequency do not exist)."""
    x = np.asarray(curves, dtype=np.float64)
    if x.ndim == 1:
        x = x[None, :]
    if x.ndim != 2:
        raise ValueError(f"curves must be (V, N), got shape {x.shape}")
    n = x.shape[1]
    if not 1 <= coefficients or n < 2 * coefficients + 1:
        raise ValueError(f"{coefficients} coefficients need curves of at least {2 * coefficients + 1} "
                         f"samples, got {n}")
    spectrum = np.fft.rfft(x, axis=1)[:, 1 : coefficients + 1]
    return np.ascontiguousarray(np.abs(spectrum) / n, dtype=np.float32)
