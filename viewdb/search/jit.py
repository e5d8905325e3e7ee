"""numba's ``njit`` for every kernel module, without the BLAS probe on a process's first call.

A fresh process's first call of any cached kernel makes numba load its implementation
registries, among them ``numba.np.arraymath``, which probes for BLAS by importing
``scipy.linalg.cython_blas``. That import brings in all of ``scipy.linalg`` (and, through
SciPy's array-API layer, ``numpy.f2py`` and ``numpy.testing``): about 0.2 s on this machine,
more than the rest of the first call, on a path that needs no linear algebra (the client
half of a query on a device). Importing this module (every kernel module takes ``njit``
from here) imports ``numba.np.arraymath`` with that probe failing, unless SciPy's BLAS is
already loaded. The one thing the probe decides is whether ``np.convolve`` and
``np.correlate`` inside *jitted* code call BLAS or an equivalent plain loop (none of
viewdb's kernels use them); ``np.dot`` and ``np.linalg`` in jitted code still find BLAS,
as they import it themselves when a kernel using them is compiled.
"""

from __future__ import annotations

import sys

_PROBE = "scipy.linalg.cython_blas"


def _registries_without_blas_probe() -> None:
    """Import ``numba.np.arraymath`` with its BLAS probe failing, if neither is loaded yet."""
    if "numba.np.arraymath" in sys.modules or _PROBE in sys.modules:
        return
    sys.modules[_PROBE] = None  # type: ignore[assignment]  # "import" raises ImportError
    try:
        import numba.np.arraymath  # noqa: F401
    finally:
        if sys.modules.get(_PROBE, 0) is None:
            del sys.modules[_PROBE]


_registries_without_blas_probe()

from numba import njit  # noqa: E402

__all__ = ["njit"]
