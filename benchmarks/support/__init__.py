"""What the benchmarks share, and the tests with them: a real ``viewdb serve`` in a
subprocess (``serving``), Debian's headless Chromium (``browser``), the bundled sample
models (``samples``), synthetic scenes behind a rendered object (``scenes``), synthetic
distance curves (``curves``) and the real photo sets with 6-D ground truth: their options,
bands and pose errors, twins' poses carried between mesh frames (``real``).

A benchmark, run as ``python benchmarks/NAME.py``, imports it as ``support`` (its own
folder is first on ``sys.path``); the tests import it as ``benchmarks.support``.
"""
