"""What the benchmarks share, and the tests with them: a real ``viewdb serve`` in a
subprocess (``serving``), Debian's headless Chromium (``browser``), the bundled sample
models (``samples``) and synthetic scenes behind a rendered object (``scenes``).

A benchmark, run as ``python benchmarks/NAME.py``, imports it as ``support`` (its own
folder is first on ``sys.path``); the tests import it as ``benchmarks.support``.
"""
