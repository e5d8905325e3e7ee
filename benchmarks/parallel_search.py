"""One search on one thread against the same search split over threads, on the synthetic photos.

    python benchmarks/parallel_search.py DB [--seeds 1-6] [--photos 10] [-k 5] [--threads 1,2]
                                            [--whole [--roll DEG]]

The photos are those of ``benchmarks/query_latency.py`` (:func:`viewdb.bench.photos.photo_series`),
segmented and turned as a query does (its default in-plane turns); each photo's stack of turned curves is
then searched on the file's full tier (:func:`viewdb.search.knn.knn_stack`, k objects) once per
thread count, one right after the other (the order alternating from photo to photo). Printed per
thread count: the median and p95 wall time of a search, the CPU time it took (all threads),
and the median per-photo ratio of wall times against the first count; then on how many photos
every count gave the same answer (objects, distances, views, orientations, turns). With
``--whole`` each photo is also queried whole (``ViewDB.query``, k objects, no pose, ``server``
plan; ``--roll``: with that gravity hint) once per thread count (``VIEWDB_SEARCH_THREADS``),
alternately, and the median of each stage (``timing_ms``) and of the whole query is given per
count. Give the load average with the figures: threads only help on idle cores.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

import viewdb
from viewdb.bench.photos import seed_photos
from viewdb.bench.queries import turned_stacks
from viewdb.config import SearchConfig
from viewdb.search.knn import knn_stack


def whole_queries(db: viewdb.ViewDB, photos: list[np.ndarray], counts: list[int], k: int,
                  roll: float | None) -> None:
    """Each photo queried once per thread count, alternately; the stages' medians per count."""
    stages: dict[int, dict[str, list[float]]] = {t: {} for t in counts}
    for t in counts:  # warm
        os.environ["VIEWDB_SEARCH_THREADS"] = str(t)
        db.query(photos[0], k=k, pose=False, roll=roll)
    for i, photo in enumerate(photos):
        for t in counts if i % 2 == 0 else counts[::-1]:
            os.environ["VIEWDB_SEARCH_THREADS"] = str(t)
            try:
                result = db.query(photo, k=k, pose=False, roll=roll)
            except viewdb.ViewDBError:
                continue
            for stage, ms in result.timing_ms.items():
                stages[t].setdefault(stage, []).append(ms)
    os.environ.pop("VIEWDB_SEARCH_THREADS")
    base = np.asarray(stages[counts[0]]["total"])
    for t in counts:
        split = ", ".join(f"{s} {statistics.median(v):.0f}" for s, v in stages[t].items() if s != "total")
        ratio = statistics.median(base / np.asarray(stages[t]["total"]))
        print(f"whole query, threads {t}: median {statistics.median(stages[t]['total']):.0f} ms "
              f"({ratio:.2f}x vs {counts[0]}, median per photo); stage medians (ms): {split}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("db")
    parser.add_argument("--seeds", default="1-6")
    parser.add_argument("--photos", type=int, default=10, help="photos per seed")
    parser.add_argument("-k", type=int, default=5)
    parser.add_argument("--threads", default="1,2", help="thread counts to compare, the first the baseline")
    parser.add_argument("--whole", action="store_true", help="also time whole queries per thread count")
    parser.add_argument("--roll", type=float, default=None, help="the whole queries' gravity hint (degrees)")
    args = parser.parse_args()
    counts = [int(t) for t in args.threads.split(",")]
    with viewdb.open(args.db, read_only=True) as db:
        photos = [photo for _, photo in seed_photos(db, args.seeds, args.photos)]
        queries = turned_stacks(db, photos)
        catalogue = db._catalogue
        band = 6
        block = SearchConfig().stack_block
        with catalogue.tier_reader().snapshot() as reader:
            source = reader.tier("full")
            curves = [np.stack([catalogue.query_curve(c, args.k, "full") for c in q]) for q in queries]
            print(f"{args.db}: {len(curves)} photos (seeds {args.seeds}), {source.n_groups} groups, "
                  f"k={args.k}; {os.cpu_count()} CPUs; load {os.getloadavg()[0]:.1f}", flush=True)
            for t in counts:  # compile and read every row once
                knn_stack(curves[0], source, args.k, band, block=block, threads=t)
            wall = {t: [] for t in counts}
            cpu = {t: [] for t in counts}
            same = 0
            for i, q in enumerate(curves):
                answers = {}
                for t in counts if i % 2 == 0 else counts[::-1]:
                    start, cpu_start = time.perf_counter(), time.process_time()
                    found, _ = knn_stack(q, source, args.k, band, block=block, threads=t)
                    wall[t].append((time.perf_counter() - start) * 1e3)
                    cpu[t].append((time.process_time() - cpu_start) * 1e3)
                    answers[t] = found
                same += all(answers[t] == answers[counts[0]] for t in counts)
    base = np.asarray(wall[counts[0]])
    for t in counts:
        ratio = statistics.median(base / np.asarray(wall[t]))
        print(f"threads {t}: wall median {statistics.median(wall[t]):6.0f} ms  p95 "
              f"{np.percentile(wall[t], 95):6.0f} ms  CPU median {statistics.median(cpu[t]):6.0f} ms  "
              f"speed-up vs {counts[0]} thread(s): {ratio:.2f}x (median per photo)", flush=True)
    print(f"the same answer on {same}/{len(curves)} photos; load {os.getloadavg()[0]:.1f}", flush=True)
    if args.whole:
        with viewdb.open(args.db, read_only=True) as db:  # afresh: empty caches
            whole_queries(db, photos, counts, args.k, args.roll)
        print(f"load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
