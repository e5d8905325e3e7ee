"""Ingest throughput on Ray (1 and 2 workers) against the plain local ingest, in one run.

    python benchmarks/ray_ingest.py [../shared/models] [--limit 12] [--gap 30] [--image-size 128]

The same files are ingested into a fresh database in a temporary folder by each setup:

* ``jobs=1``: the plain local ingest in this process: the baseline;
* ``jobs=2``: two local worker processes (``--jobs 2``);
* ``ray 1`` and ``ray 2``: a private local Ray of 1 and of 2 CPUs (``--ray``), each object
  one Ray task, written by this process.

The views are described without skimming (every grid view rendered, described and stored:
the raw pipeline rate). Each wall time includes starting the workers (processes, or Ray's
workers importing viewdb and creating their GL context) but not starting Ray itself
(``ray.init``, reported apart). Ratios are objects per second against ``jobs=1``
measured in the same run; every setup's file is checked to hold the same curves as the
baseline's. ``writer s`` is the time this process spent committing objects
(``Store.write_object``): the single writer's share of the wall time.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import viewdb
from viewdb.storage.store import Store

#: Seconds the writer spent committing objects (Store.write_object), per setup.
WRITING = {"seconds": 0.0}


def _timed(write):
    def timed(*args, **kwargs):
        start = time.perf_counter()
        try:
            return write(*args, **kwargs)
        finally:
            WRITING["seconds"] += time.perf_counter() - start

    return timed


def ingest(files: list[Path], folder: Path, name: str, gap: float, size: int, **how) -> tuple:
    path = folder / f"{name}.db"
    WRITING["seconds"] = 0.0
    with viewdb.open(path, gap=gap, image_size=size) as db:
        start = time.perf_counter()
        report = db.ingest(files, skim=False, **how)
        wall = time.perf_counter() - start
    if report.failed:
        print(f"  {name}: {len(report.failed)} failed, e.g. {report.failed[0].error}")
    return wall, WRITING["seconds"], path


def curves(path: Path) -> dict[str, list[bytes]]:
    with viewdb.open(path, read_only=True) as db:
        arrays, _ = db.search_tier("full")
        return {n: sorted(r.tobytes() for r in arrays.curves[arrays.owner == i])
                for i, n in enumerate(arrays.names)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", type=Path, nargs="?", default=Path("../shared/models"))
    parser.add_argument("--limit", type=int, default=12, help="use only the first N files")
    parser.add_argument("--gap", type=float, default=30.0)
    parser.add_argument("--image-size", type=int, default=128)
    args = parser.parse_args()
    import ray

    Store.write_object = _timed(Store.write_object)  # the one writer's share of the wall time
    files = viewdb.describe_paths([args.models])[: args.limit]
    if not files:
        raise SystemExit(f"no mesh files in {args.models}")
    print(f"{len(files)} files, gap {args.gap:g}°, {args.image_size} px, no skimming")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for jobs in (1, 2):
            wall, writing, path = ingest(files, folder, f"jobs{jobs}", args.gap, args.image_size, jobs=jobs)
            rows.append((f"jobs={jobs}", wall, writing, path, 0.0))
        for cpus in (1, 2):
            start = time.perf_counter()
            ray.init(num_cpus=cpus, include_dashboard=False, log_to_driver=False, configure_logging=False)
            started = time.perf_counter() - start
            try:
                wall, writing, path = ingest(files, folder, f"ray{cpus}", args.gap, args.image_size,
                                             ray="auto")
            finally:
                ray.shutdown()
            rows.append((f"ray {cpus} worker{'s' if cpus > 1 else ''}", wall, writing, path, started))
        baseline = curves(rows[0][3])
        base_rate = len(files) / rows[0][1]
        print(f"{'setup':<16}{'wall s':>9}{'objects/s':>11}{'vs jobs=1':>11}{'writer s':>10}"
              f"{'ray.init s':>12}  same curves")
        for label, wall, writing, path, started in rows:
            rate = len(files) / wall
            same = curves(path) == baseline
            print(f"{label:<16}{wall:>9.1f}{rate:>11.3f}{rate / base_rate:>10.2f}x{writing:>10.2f}"
                  f"{(f'{started:.1f}' if started else ''):>12}  {same}")


if __name__ == "__main__":
    main()
