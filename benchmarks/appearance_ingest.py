"""What recording every grid direction's appearance costs an ingest, in one run.

    python benchmarks/appearance_ingest.py ../shared/models [--limit 12] [--names a,b,...]

Each model is ingested into two fresh files at the default 10° grid, one job: first with
``AppearanceConfig(every_view=False)`` (the stored views and their opposites, as files
before schema revision 0008), then with the default ``every_view=True``; the two sides
alternate model by model so that the machine's load falls on both alike. Prints each
model's seconds (wall and this process's CPU), records and the two files' sizes, then the
ratios after / before.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import viewdb
from viewdb.config import AppearanceConfig, BuildConfig


def _ingest(path: Path, config: BuildConfig, model: str) -> tuple[float, float, int]:
    """Wall and CPU seconds of ingesting ``model`` into the file, and its records."""
    with viewdb.open(path, config=config) as db:
        wall, cpu = time.perf_counter(), time.process_time()
        report = db.ingest([model], jobs=1)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        if report.failed:
            raise SystemExit(report.failed[0].error)
        return wall, cpu, db.object(Path(model).stem).appearances


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", type=Path, nargs="?", default=Path("../shared/models"))
    parser.add_argument("--limit", type=int, default=12, help="the first N files")
    parser.add_argument("--names", default="", help="comma-separated model names instead")
    args = parser.parse_args()
    files = viewdb.describe_paths([args.models])
    if args.names:
        wanted = set(args.names.split(","))
        files = [f for f in files if Path(f).stem in wanted]
    elif args.limit:
        files = files[: args.limit]
    if not files:
        raise SystemExit(f"no mesh files in {args.models}")
    after = BuildConfig()
    before = replace(after, appearance=AppearanceConfig(every_view=False))
    totals = {"before": [0.0, 0.0, 0], "after": [0.0, 0.0, 0]}
    with tempfile.TemporaryDirectory() as tmp:
        paths = {"before": Path(tmp) / "before.db", "after": Path(tmp) / "after.db"}
        print(f"{len(files)} models, 10° grid, 1 job")
        print(f"{'model':28s} {'wall before':>11s} {'wall after':>10s} {'CPU before':>10s} {'CPU after':>9s} "
              f"{'records':>15s}")
        for model in files:
            row = {}
            for side, config in (("before", before), ("after", after)):
                row[side] = wall, cpu, records = _ingest(paths[side], config, model)
                for i, x in enumerate((wall, cpu, records)):
                    totals[side][i] += x
            (wb, cb, rb), (wa, ca, ra) = row["before"], row["after"]
            print(f"{Path(model).stem:28s} {wb:11.1f} {wa:10.1f} {cb:10.1f} {ca:9.1f} {rb:7d} → {ra:5d}")
        sizes = {side: path.stat().st_size for side, path in paths.items()}
    (wb, cb, rb), (wa, ca, ra) = totals["before"], totals["after"]
    print(f"{'total':28s} {wb:11.1f} {wa:10.1f} {cb:10.1f} {ca:9.1f} {rb:7d} → {ra:5d}")
    print(f"after / before: wall {wa / wb:.2f}x, CPU {ca / cb:.2f}x, records {ra / rb:.2f}x, "
          f"file {sizes['after'] / 1e6:.1f} MB / {sizes['before'] / 1e6:.1f} MB = "
          f"{sizes['after'] / sizes['before']:.2f}x")


if __name__ == "__main__":
    main()
