"""The paper's experiments (Tak & Hwang, section IV): ``viewdb bench``.

:func:`run_bench` builds or reuses the databases (full files at the server grid with and
without skimming, client files at each client grid), draws the queries, measures S1–S6
(Table 1) and the time against the client gap, and writes JSON, CSV, markdown and PNGs.
"""

from .config import CONFIGURATIONS, PROTOCOLS, BenchConfig, Configuration
from .runner import BenchProgress, BenchRun, run_bench

__all__ = [
    "CONFIGURATIONS",
    "PROTOCOLS",
    "BenchConfig",
    "BenchProgress",
    "BenchRun",
    "Configuration",
    "run_bench",
]
