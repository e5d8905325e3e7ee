"""The client file that ships to a device: the float32 format against the compact one, in
the same run.

    python benchmarks/device_file.py FULL_DB [--gaps 20 30 40 50] [--out DIR]
        [--queries 100] [--fresh 5] [--exact-gap 30]
    python benchmarks/device_file.py --cold CLIENT_DB [--baseline TREE] [--fresh 9]

For each client gap both files are exported from FULL_DB (read-only): ``float32`` (curve
bits 0 and 4 kB pages: the layout ``export-client`` wrote before compact files) and
``compact`` (the default). Printed per gap: file size, bytes per view, the ratio; the
fresh-process cost (a new Python that imports viewdb, opens the file read-only and runs
the client half of one query at k = 5, timed inside the child, median of ``--fresh``);
the warm client half (median over the grid queries, k = 5); the JSON bytes a remote CS1
query sends (median). At ``--exact-gap`` it also runs CS1 with the compact client against
``server`` on ``--queries`` grid queries and ``--queries`` synthetic photos (``viewdb
bench``'s two protocols: :mod:`viewdb.bench.queries`) and counts the answers that differ
(must be 0).

``--cold CLIENT_DB`` measures only the fresh-process cost of that client file, in
``--fresh`` new Pythons per source tree (this one, and ``--baseline TREE``, e.g. a worktree
of another commit, alternating so both see the same machine load; each tree's kernels are
loaded into its numba cache by one uncounted run first). Printed per tree, medians:
``import`` (NumPy, ``import viewdb`` and the client tier's modules), ``open + 1st half``
(``viewdb.open(read_only=True)``, which imports the rest of the facade, and one client half
at k = 5: the issue's figure), their sum, and the process's wall time from launch to exit
as the parent sees it; then the same as CPU time (user + system; what the machine's other
jobs disturb least).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import viewdb
from viewdb.bench.queries import grid_queries, photo_queries
from viewdb.config import ClientFileConfig
from viewdb.recognition.client_tier import ClientTier
from viewdb.search.plans import RefineRequest

ROOT = Path(__file__).resolve().parents[1]

FORMATS = {"float32": ClientFileConfig(curve_bits=0, page_size=4096), "compact": ClientFileConfig()}

CHILD = """
import sys, time, json
t0, c0 = time.perf_counter(), time.process_time()
import numpy as np
import viewdb
from viewdb.recognition.client_tier import ClientTier
t1, c1 = time.perf_counter(), time.process_time()
db = viewdb.open(sys.argv[1], read_only=True)
q = np.array(json.loads(sys.argv[2]))
ClientTier(db._catalogue).candidates(q, 5)
t2, c2 = time.perf_counter(), time.process_time()
print(json.dumps({"import_ms": (t1 - t0) * 1e3, "open_search_ms": (t2 - t1) * 1e3,
                  "import_cpu_ms": (c1 - c0) * 1e3, "open_search_cpu_ms": (c2 - c1) * 1e3}))
"""


def child(path: Path, curve: np.ndarray, tree: Path = ROOT) -> dict[str, float]:
    """One fresh Python importing viewdb from ``tree``: its timings (ms) and wall time."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    used = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CHILD, str(path), json.dumps(curve.tolist())],
                          capture_output=True, text=True, check=True, cwd=tree, env=env)
    wall = (time.perf_counter() - start) * 1e3
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime - used.ru_utime - used.ru_stime) * 1e3
    out = json.loads(done.stdout.strip().splitlines()[-1])
    return {**out, "total_ms": out["import_ms"] + out["open_search_ms"], "process_ms": wall,
            "process_cpu_ms": cpu}


def fresh(path: Path, curve: np.ndarray, runs: int) -> dict[str, float]:
    out = [child(path, curve) for _ in range(runs)]
    return {key: statistics.median(o[key] for o in out) for key in out[0]}


def cold_start(path: Path, runs: int, baseline: Path | None) -> None:
    """The fresh-process figures of client file ``path``, this tree against ``baseline``."""
    with viewdb.open(path, read_only=True) as db:
        arrays, _ = db.search_tier("sparse")
    rng = np.random.default_rng(0)
    stored = arrays.curves[rng.integers(len(arrays.curves))]
    curve = np.clip(stored + rng.normal(0, 0.02, len(stored)), 0, None)
    trees = {"this": ROOT} | ({"baseline": baseline.resolve()} if baseline else {})
    for tree in trees.values():
        child(path, curve, tree)  # loads (or compiles) the tree's kernels into its cache
    runs_of: dict[str, list[dict[str, float]]] = {name: [] for name in trees}
    for _ in range(runs):
        for name, tree in trees.items():
            runs_of[name].append(child(path, curve, tree))
    print(f"{path}: {path.stat().st_size / 1e6:.2f} MB; median of {runs} fresh processes per tree")
    print("tree      import_ms  open+1st_ms  sum_ms  process_ms   CPU: import  open+1st  process")
    for name, out in runs_of.items():
        med = {key: statistics.median(o[key] for o in out) for key in out[0]}
        print(f"{name:<9} {med['import_ms']:9.0f} {med['open_search_ms']:12.0f} {med['total_ms']:7.0f} "
              f"{med['process_ms']:11.0f} {med['import_cpu_ms']:13.0f} {med['open_search_cpu_ms']:9.0f} "
              f"{med['process_cpu_ms']:8.0f}   ({trees[name]})")


def warm(path: Path, curves: list[np.ndarray]) -> tuple[float, float]:
    """Median client half (ms) and median CS1 request bytes, k = 5."""
    times, sent = [], []
    with viewdb.open(path, read_only=True) as db:
        tier = ClientTier(db._catalogue)
        tier.candidates(curves[0], 5)
        for q in curves:
            start = time.perf_counter()
            found = tier.candidates(q, 5)
            times.append((time.perf_counter() - start) * 1e3)
            sent.append(len(json.dumps(RefineRequest(q, 6, 5, found).to_dict())))
    return statistics.median(times), statistics.median(sent)


def exactness(full: viewdb.ViewDB, client_path: Path, grid: list, photos: list) -> tuple[int, int]:
    """Answers of CS1 with the client that differ from ``server``'s (grid, photos)."""
    wrong = [0, 0]
    with viewdb.open(client_path, read_only=True) as client:
        for q in grid:
            a = full.recognise(q.curve, 5, plan="server").results
            b = full.recognise(q.curve, 5, plan="cs1", client=client).results
            wrong[0] += [c.to_dict() for c in a] != [c.to_dict() for c in b]
        for p in photos:
            a = full.query(p.path, k=5, plan="server", pose=False).results
            b = full.query(p.path, k=5, plan="cs1", client=client, pose=False).results
            wrong[1] += [(r.object, r.distance) for r in a] != [(r.object, r.distance) for r in b]
    return wrong[0], wrong[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("db", type=Path, nargs="?")
    parser.add_argument("--cold", type=Path, default=None, metavar="CLIENT_DB")
    parser.add_argument("--baseline", type=Path, default=None, metavar="TREE")
    parser.add_argument("--gaps", type=float, nargs="+", default=[20, 30, 40, 50])
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--queries", type=int, default=100)
    parser.add_argument("--fresh", type=int, default=5)
    parser.add_argument("--exact-gap", type=float, default=30)
    args = parser.parse_args()
    if args.cold is not None:
        cold_start(args.cold, args.fresh, args.baseline)
        return
    if args.db is None:
        parser.error("FULL_DB is required (or --cold CLIENT_DB)")
    out = args.out or Path(tempfile.mkdtemp(prefix="device_file_"))
    out.mkdir(parents=True, exist_ok=True)
    with viewdb.open(args.db, read_only=True) as full:
        names = sorted(o.name for o in full.objects())
        grid = grid_queries(full, names, args.queries, 0, out / "queries")
        photos = photo_queries(full, names, args.queries, 0, out / "queries") if args.queries else []
        curves = [q.curve for q in grid]
        full_bytes = full.info().file_bytes
        print(f"{args.db}: {full_bytes / 1e6:.1f} MB, {len(names)} objects; {len(curves)} grid queries")
        print("gap  format    MB     B/view  ratio  import_ms  open+1st_ms  warm_ms  sent_B")
        for gap in args.gaps:
            row = {}
            for fmt, file in FORMATS.items():
                path = out / f"client_{gap:g}_{fmt}.db"
                if not path.exists():
                    full.export_client(path, client_gap=gap, file=file)
                with viewdb.open(path, read_only=True) as c:
                    info = c.info()
                cold = fresh(path, curves[0], args.fresh)
                warm_ms, sent = warm(path, curves)
                row[fmt] = info.file_bytes
                ratio = info.file_bytes / row["float32"]
                print(f"{gap:<4g} {fmt:<8} {info.file_bytes / 1e6:6.2f} {info.bytes_per_view:8.0f} "
                      f"{ratio:6.3f} {cold['import_ms']:10.0f} {cold['open_search_ms']:12.0f} "
                      f"{warm_ms:8.2f} {sent:7.0f}")
            if gap == args.exact_gap:
                g, p = exactness(full, out / f"client_{gap:g}_compact.db", grid, photos)
                print(f"     CS1 (compact, {gap:g}°) != server: {g}/{len(grid)} grid, "
                      f"{p}/{len(photos)} photos")


if __name__ == "__main__":
    main()
