"""Time per call of the compiled bound kernels (DTW, LB_Keogh, the envelope) on two
smooth 128-sample curves with a band of 6.

    python benchmarks/bound_kernels.py [--calls 20000] [--band 6] [--seed 0]

Each kernel is called once (compiling it, or loading it from numba's cache), then
``--calls`` times in a row; the mean per call is printed in microseconds.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from support.curves import smooth_curve
from viewdb.search import bounds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=20000)
    parser.add_argument("--band", type=int, default=6)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    q, c = smooth_curve(rng, 128), smooth_curve(rng, 128)
    lower, upper = bounds.envelope(q, args.band)
    for name, call in (
        ("dtw", lambda: bounds.dtw(q, c, args.band)),
        ("lb_keogh", lambda: bounds.lb_keogh(lower, upper, c)),
        ("envelope", lambda: bounds.envelope(q, args.band)),
    ):
        call()
        start = time.perf_counter()
        for _ in range(args.calls):
            call()
        print(f"{name}: {(time.perf_counter() - start) / args.calls * 1e6:.2f} us/call")


if __name__ == "__main__":
    main()
