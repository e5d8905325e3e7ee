"""k-NN latency and pruning power through the stored R-trees, against two exact baselines.

    python benchmarks/knn_latency.py DB [DB ...] [--queries 50] [--r 6] [--tier full]

(several files, e.g. the skimmed and the unskimmed paper-scale catalogues, in one run)

Two query sets, same seed ⇒ same queries:

* ``noisy``: stored curves of random views with Gaussian noise (sd 0.02) and a random
  mirror flip, so the right object exists but no view matches exactly;
* ``render``: silhouettes of random objects rendered at random off-grid angles (the
  realistic case: the query falls between grid views).

Baselines, measured in the same run on the same queries (all three are exact and must
agree; the script checks it):

* ``brute``: the compiled DTW against every view and its mirror, in one compiled loop
  (:func:`viewdb.search.refine.scan_all`; no bounds, no Python per view);
* ``flat``: a numpy flat scan in the UCR-suite style: LB_Keogh of every curve (both
  orientations) in one vectorised pass, then DTW in bound order until the bound exceeds
  the k-th best distinct-object distance.

Also reported: time to open the file and answer a first query in a fresh process
(nothing is rebuilt at open: the R-tree pages are read as they are).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

import numpy as np

import viewdb
from viewdb.catalogue.features import FeatureError, distance_curve, mirror_curve
from viewdb.search.bounds import dtw, envelope, lb_keogh_many
from viewdb.search.knn import TierArrays
from viewdb.search.refine import scan_all


def flat_scan_knn(q: np.ndarray, tier: TierArrays, mirrored: np.ndarray, k: int, r: int):
    """Exact top-k distinct objects by a vectorised LB_Keogh pass then DTW in bound order."""
    lower, upper = envelope(q, r)
    n = len(tier.curves)
    bounds = np.concatenate([lb_keogh_many(lower, upper, tier.curves),
                             lb_keogh_many(lower, upper, mirrored)])
    best: dict[int, float] = {}
    dtws = 0
    for slot in np.argsort(bounds, kind="stable"):
        if len(best) >= k and bounds[slot] > sorted(best.values())[k - 1]:
            break
        view = slot % n
        owner = int(tier.owner[view])
        d = dtw(q, mirrored[view] if slot >= n else tier.curves[view], r)
        dtws += 1
        if d < best.get(owner, np.inf):
            best[owner] = d
    top = sorted(best.items(), key=lambda x: (x[1], tier.names[x[0]]))[:k]
    return [(tier.names[o], d) for o, d in top], dtws


def brute_force_top(q: np.ndarray, tier: TierArrays, k: int, r: int) -> list[tuple[str, float]]:
    """Exact top-k distinct objects by the compiled DTW on every view and its mirror."""
    distances = scan_all(q, tier.curves, r)
    best = np.full(len(tier.names), np.inf)
    np.minimum.at(best, tier.owner, distances)
    top = sorted((d, tier.names[o]) for o, d in enumerate(best.tolist()))[:k]
    return [(name, d) for d, name in top]


def queries(db: viewdb.ViewDB, tier: TierArrays, count: int, seed: int) -> dict[str, list[np.ndarray]]:
    rng = np.random.default_rng(seed)
    noisy = []
    for _ in range(count):
        c = tier.curves[rng.integers(len(tier.curves))] + rng.normal(0, 0.02, tier.curves.shape[1])
        noisy.append(mirror_curve(c) if rng.random() < 0.5 else c)
    rendered = []
    while len(rendered) < count:
        name = tier.names[rng.integers(len(tier.names))]
        h, v = rng.uniform(0, 360, 2)
        try:
            rendered.append(distance_curve(db.render(name, h, v).mask, tier.curves.shape[1]))
        except FeatureError:
            continue
    return {"noisy": noisy, "render": rendered}


def open_to_first_result(path: str, tier: str, r: int) -> str:
    code = (
        "import time, numpy as np; t0 = time.perf_counter(); import viewdb; "
        f"t1 = time.perf_counter(); db = viewdb.open({path!r}, create=False); "
        "t2 = time.perf_counter(); n = db.config.features.curve_samples; "
        f"db.search(1 + 0.1 * np.cos(np.linspace(0, 6.28, n)), k=5, band={r}, tier={tier!r}); "
        "t3 = time.perf_counter(); print(f'import {t1 - t0:.2f} s, open {(t2 - t1) * 1e3:.0f} ms, "
        "first search {(t3 - t2) * 1e3:.0f} ms (loads the tier and the compiled kernels)')"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.strip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db", nargs="+")
    parser.add_argument("--queries", type=int, default=50)
    parser.add_argument("--brute", type=int, default=3, help="queries per set also run by brute force")
    parser.add_argument("--r", type=int, default=6)
    parser.add_argument("--tier", default="full", choices=["full", "sparse"])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    for path in args.db:
        print(f"== {path}")
        run(path, args)


def run(path: str, args: argparse.Namespace) -> None:
    print("fresh process:", open_to_first_result(path, args.tier, args.r))
    with viewdb.open(path, read_only=True) as db:
        start = time.perf_counter()
        tier, _ = db.search_tier(args.tier)
        load = time.perf_counter() - start
        n = len(tier.curves)
        print(f"{args.tier} tier: {len(tier.names)} objects, {n} views, {tier.n_groups} groups "
              f"(in-memory copy for the baselines loaded in {load:.2f} s)")
        mirrored = mirror_curve(tier.curves)
        sets = queries(db, tier, args.queries, args.seed)
        db.search(sets["noisy"][0], k=1, band=args.r, tier=args.tier)  # warm up (compile)
        for label, qs in sets.items():
            flat_times = []
            for k in (1, 2, 3, 4, 5):
                times, dtws, groups = [], [], []
                for q in qs:
                    t = time.perf_counter()
                    hits, stats = db.search(q, k=k, band=args.r, tier=args.tier)
                    times.append(time.perf_counter() - t)
                    dtws.append(stats.dtw)
                    groups.append(stats.groups_visited)
                    if k == 5:
                        t = time.perf_counter()
                        flat, _ = flat_scan_knn(q, tier, mirrored, k, args.r)
                        flat_times.append(time.perf_counter() - t)
                        assert [h.object for h in hits] == [o for o, _ in flat], "flat scan disagrees"
                pruning = 1 - np.mean(dtws) / (2 * n)
                print(f"{label} k={k}: p50 {np.median(times) * 1e3:.1f} ms, "
                      f"p95 {np.percentile(times, 95) * 1e3:.1f} ms, DTWs {np.mean(dtws):.0f} "
                      f"(pruning power {pruning:.4f}), groups opened {np.mean(groups):.0f}/{tier.n_groups}")
            best_first = []
            for q in qs:
                t = time.perf_counter()
                db.search(q, k=5, band=args.r, tier=args.tier)
                best_first.append(time.perf_counter() - t)
            brute = []
            for q in qs[: args.brute]:
                t = time.perf_counter()
                expected = brute_force_top(q, tier, 5, args.r)
                brute.append(time.perf_counter() - t)
                hits, _ = db.search(q, k=5, band=args.r, tier=args.tier)
                assert [h.object for h in hits] == [o for o, _ in expected], "brute force disagrees"
            bf, fl, me = np.mean(brute), np.median(flat_times), np.median(best_first)
            print(f"{label} k=5 medians: R-tree best-first {me * 1e3:.1f} ms; numpy flat scan "
                  f"{fl * 1e3:.1f} ms ({fl / me:.1f}x slower); brute-force DTW {bf * 1e3:.0f} ms "
                  f"({bf / me:.0f}x slower)")


if __name__ == "__main__":
    main()
