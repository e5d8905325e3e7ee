"""The search of a photo's in-plane turns, this tree against another, on the same curves.

    python benchmarks/stack_search.py DB --baseline TREE [--seeds 2-3] [--photos 8] [-k 5]
                                         [--threads 1,2] [--rounds 2]

The photos are those of ``benchmarks/query_latency.py``
(:func:`viewdb.bench.photos.seed_photos`), segmented and turned as a query does; each photo's
stack of turned curves (the query's default count) is searched on the file's full tier
(:func:`viewdb.search.knn.knn_stack`, k objects, the query's block of one curve) by a fresh
process of each tree, the trees taking turns ``--rounds`` times. Printed per tree and thread
count: the median and mean wall time of a search over the photos (the fastest of its rounds
per photo), the median of the views bounded, and the median per-photo ratio against the
baseline tree; then whether both trees gave the same answers (objects, distances, views,
orientations and turns). ``TREE`` is a checkout of the project (e.g. ``git worktree add``).
Give the load average with the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

#: What each tree's process runs: the stacks of a .npz, searched once per thread count.
CHILD = r"""
import json, sys, time
import numpy as np
import viewdb
from viewdb.search.knn import knn_stack

db_path, stacks_path, k, threads = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
stacks = np.load(stacks_path)["stacks"]
db = viewdb.open(db_path, read_only=True)
reader = db._catalogue.tier_reader()
out = {}
with reader.snapshot():
    source = reader.tier("full")
    knn_stack(stacks[0], source, k, 6, block=1, threads=1)  # compile, map or read every group
    for t in (int(x) for x in threads.split(",")):
        rows = []
        for stack in stacks:
            start = time.perf_counter()
            found, stats = knn_stack(stack, source, k, 6, block=1, threads=t)
            rows.append([time.perf_counter() - start, stats.points_visited,
                         [[nb.object, nb.distance, nb.view, nb.mirrored, nb.shift] for nb in found]])
        out[t] = rows
json.dump(out, sys.stdout)
"""


def photo_stacks(db_path: str, seeds: str, count: int) -> np.ndarray:
    """Each photo's turned query curves (:func:`viewdb.bench.queries.turned_stacks`)."""
    import viewdb
    from viewdb.bench.photos import seed_photos
    from viewdb.bench.queries import turned_stacks

    db = viewdb.open(db_path, read_only=True)
    return np.stack(turned_stacks(db, [photo for _, photo in seed_photos(db, seeds, count)]))


def run_tree(tree: Path, db: str, stacks: str, k: int, threads: str) -> dict[int, list]:
    env = dict(os.environ, PYTHONPATH=str(tree))
    done = subprocess.run([sys.executable, "-c", CHILD, db, stacks, str(k), threads], env=env,
                          capture_output=True, text=True, check=True, cwd=tree)
    return {int(t): rows for t, rows in json.loads(done.stdout).items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("db")
    parser.add_argument("--baseline", required=True, type=Path, help="a checkout to compare with")
    parser.add_argument("--seeds", default="2-3")
    parser.add_argument("--photos", type=int, default=8, help="photos per seed")
    parser.add_argument("-k", type=int, default=5)
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    here = Path(__file__).resolve().parent.parent
    trees = {"baseline": args.baseline.resolve(), "this": here}
    with tempfile.TemporaryDirectory() as tmp:
        stacks = os.path.join(tmp, "stacks.npz")
        np.savez(stacks, stacks=photo_stacks(args.db, args.seeds, args.photos))
        runs: dict[str, list[dict[int, list]]] = {name: [] for name in trees}
        for i in range(args.rounds):
            for name in trees if i % 2 == 0 else list(trees)[::-1]:
                runs[name].append(run_tree(trees[name], args.db, stacks, args.k, args.threads))
    counts = [int(t) for t in args.threads.split(",")]
    best = {name: {t: np.min([[row[0] for row in r[t]] for r in rounds], axis=0) for t in counts}
            for name, rounds in runs.items()}
    for t in counts:
        for name, rounds in runs.items():
            wall = best[name][t]
            points = statistics.median(row[1] for row in rounds[0][t])
            ratio = statistics.median(best["baseline"][t] / wall)
            print(f"threads {t}, {name:8s}: median {np.median(wall) * 1e3:6.1f} ms, mean "
                  f"{np.mean(wall) * 1e3:6.1f} ms, views bounded (median) {points:9.0f}, "
                  f"{ratio:.2f}x vs baseline (median per photo)")
    same = all(a[2] == b[2] for t in counts for a, b in zip(runs["baseline"][0][t], runs["this"][0][t],
                                                             strict=True))
    print(f"same answers on every photo and thread count: {same}")


if __name__ == "__main__":
    main()
