"""k-NN latency and pruning power over a database's stored curves, against brute force.

    python benchmarks/knn_latency.py DB [--queries 50] [--r 6]

Queries are stored curves of random views with Gaussian noise (sd 0.02) and a random
mirror flip, so the right object exists but no view matches exactly. Brute force is the
same compiled DTW on every view and its mirror, measured in the same run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import viewdb
from viewdb.features import mirror_curve
from viewdb.search.knn import brute_force_knn, knn


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--queries", type=int, default=50)
    parser.add_argument("--brute", type=int, default=5, help="queries also run by brute force")
    parser.add_argument("--r", type=int, default=6)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with viewdb.open(args.db, create=False) as db:
        start = time.perf_counter()
        tier, _ = db.search_tier()
        load = time.perf_counter() - start
    curves = tier.curves
    print(f"{len(tier.names)} objects, {len(curves)} views (loaded in {load:.2f} s)")
    rng = np.random.default_rng(args.seed)
    queries = []
    for _ in range(args.queries):
        c = tier.curves[rng.integers(len(curves))] + rng.normal(0, 0.02, tier.curves.shape[1])
        queries.append(mirror_curve(c) if rng.random() < 0.5 else c)
    knn(queries[0], tier, 1, args.r)  # compile
    for k in (1, 3, 5):
        times, pruned = [], []
        for q in queries:
            t = time.perf_counter()
            _, stats = knn(q, tier, k, args.r)
            times.append(time.perf_counter() - t)
            pruned.append(1 - stats.dtw / (2 * len(curves)))
        print(f"k={k}: p50 {np.median(times) * 1e3:.1f} ms, p95 {np.percentile(times, 95) * 1e3:.1f} ms, "
              f"pruning power {np.mean(pruned):.4f}")
    t = time.perf_counter()
    for q in queries[: args.brute]:
        brute_force_knn(q, tier, 5, args.r)
    brute = (time.perf_counter() - t) / args.brute
    t = time.perf_counter()
    for q in queries[: args.brute]:
        knn(q, tier, 5, args.r)
    fast = (time.perf_counter() - t) / args.brute
    print(f"brute force DTW scan: {brute * 1e3:.0f} ms/query; best-first k=5: {fast * 1e3:.1f} ms; "
          f"ratio {brute / fast:.0f}x")


if __name__ == "__main__":
    main()
