"""numba's ``njit`` for every kernel module, imported without what viewdb's kernels never use.

A fresh process pays for numba's optional imports on the query path:

* its first call of any cached kernel loads numba's implementation registries, among them
  ``numba.np.arraymath``, which probes for BLAS by importing ``scipy.linalg.cython_blas``.
  That brings in all of ``scipy.linalg`` (and, through SciPy's array-API layer,
  ``numpy.f2py`` and ``numpy.testing``): about 0.2 s on this machine, on a path that needs
  no linear algebra (the client half of a query on a device). The probe decides only
  whether ``np.convolve`` and ``np.correlate`` inside *jitted* code call BLAS or an
  equivalent plain loop (none of viewdb's kernels use them); ``np.dot`` and ``np.linalg``
  in jitted code still find BLAS, as they import it themselves when a kernel using them
  is compiled.
* ``import numba`` imports ``colorama`` to colour its compile errors (about 25 ms), and
  ``yaml`` to read a ``.numba_config.yaml`` in the working folder (about 15 ms).

Importing this module (every kernel module takes ``njit`` from here) imports numba with
those imports failing: numba then compiles with plain error messages and without BLAS
for the two functions above. ``yaml`` is left alone when the working folder has a numba
configuration file, and anything already imported is used as it is. The modules stay
importable by other code afterwards.
"""

from __future__ import annotations

import os
import sys

_PROBE = "scipy.linalg.cython_blas"


def _numba_without_optional_imports() -> None:
    """Import ``numba`` and ``numba.np.arraymath`` with the optional imports above failing
    (module doc), unless numba is loaded already."""
    if "numba.np.arraymath" in sys.modules:
        return
    skipped = [_PROBE, "colorama"] + ([] if os.path.isfile(".numba_config.yaml") else ["yaml"])
    blocked = [name for name in skipped if name not in sys.modules]
    for name in blocked:
        sys.modules[name] = None  # type: ignore[assignment]  # "import" raises ImportError
    try:
        import numba.np.arraymath  # noqa: F401
    finally:
        for name in blocked:
            if sys.modules.get(name, 0) is None:
                del sys.modules[name]


_numba_without_optional_imports()

from numba import njit  # noqa: E402

__all__ = ["njit"]
