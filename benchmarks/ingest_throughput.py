"""Ingest throughput (views/s, SIFT included) with 1 and with N jobs, in one run.

    python benchmarks/ingest_throughput.py ../shared/models --gap 30 [--limit 40] [--jobs 2]

Each configuration ingests the same files into a fresh database in a temporary folder,
without skimming (every grid view rendered, described and stored: the raw pipeline
rate); the ratio is against the 1-job run measured in the same invocation.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import viewdb


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", type=Path, nargs="?", default=Path("../shared/models"))
    parser.add_argument("--gap", type=float, default=30.0)
    parser.add_argument("--image-size", type=int, default=256)
    parser.add_argument("--limit", type=int, default=0, help="use only the first N files")
    parser.add_argument("--jobs", type=int, default=2, help="the parallel configuration")
    args = parser.parse_args()
    files = viewdb.describe_paths([args.models])
    if args.limit:
        files = files[: args.limit]
    if not files:
        raise SystemExit(f"no mesh files in {args.models}")
    print(f"{len(files)} files, gap {args.gap:g}°, {args.image_size} px")
    results = {}
    for jobs in (1, args.jobs):
        with tempfile.TemporaryDirectory() as tmp:
            with viewdb.open(Path(tmp) / "bench.db", gap=args.gap, image_size=args.image_size) as db:
                start = time.perf_counter()
                report = db.ingest(files, jobs=jobs, skim=False)
                wall = time.perf_counter() - start
                size = db.info().file_bytes
        rate = report.views_rendered / wall
        results[jobs] = rate
        print(
            f"jobs={jobs}: {report.views_rendered} views in {wall:.1f} s = {rate:.1f} views/s; "
            f"{report.counts()}; db {size / 1e6:.1f} MB"
        )
        for o in report.failed:
            print(f"  failed: {o.error}")
    print(f"ratio jobs={args.jobs} / jobs=1: {results[args.jobs] / results[1]:.2f}x")


if __name__ == "__main__":
    main()
