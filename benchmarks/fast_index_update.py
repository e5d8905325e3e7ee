"""What growing the ``fast`` index in place saves a change to a large catalogue.

    python benchmarks/fast_index_update.py [--objects 10000] [--views 24] [--queries 100]
                                           [--noise 0.01] [--keep DIR]

The synthetic catalogue of ``benchmarks/scale.py`` (N objects of ``--views`` perturbed real
curves each, written through the library's own writer; kept in ``--keep``), with its tier
files and ``fast`` index written as an ingest leaves them. Then one change, the same in
two copies of it: an object added and another replaced (written again with other curves,
so that its old views die in the index), through the same writer, and the files beside
the database written as an ingest does when it ends (``ViewDB.write_tier_files``: the
tier files, then the index):

* ``grown`` (what an ingest does): the stale index is grown in place
  (:mod:`viewdb.search.fast_update`);
* ``built`` (the baseline, as before growing): the index file removed first, so that it
  is built anew.

Reported for each: the wall time of writing the files, of the index step alone (the
changed file's stale index put back and grown, or removed and built, timed by itself),
the index's keys and dead keys; and, on scale.py's queries (a stored curve plus noise of
sd ``--noise``, k = 5), how often ``fast`` at the default shortlist agrees with
``server`` on each copy, so that the grown graph is seen to find what a new one finds.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from fast_plan import agreement, search
from scale import build, real_curves

import viewdb
from support.files import copy_catalogue
from viewdb.config import FastConfig, RecognitionConfig
from viewdb.storage.ann_file import ann_file_path, index_file_key, map_ann_file
from viewdb.storage.tiers import TierReader

#: the object the change writes again with other curves
REPLACED = 3


def change(db: Path, args: argparse.Namespace, bases: list[np.ndarray]) -> float:
    """Add an object to ``db``, write object ``REPLACED`` again with other curves, then the
    files beside it as an ingest ends; the seconds that last step took."""
    build(db, 1, args.views, bases, args.seed + 7, first=args.objects)
    build(db, 1, args.views, bases, args.seed + 8, first=REPLACED)
    start = time.perf_counter()
    with viewdb.open(db, create=False) as vdb:
        vdb.write_tier_files()
    return time.perf_counter() - start


def index_step(db: Path, stale: bytes | None) -> float:
    """The index step of an ingest alone: ``stale`` put back as the index file (grown) or
    the file removed (built); the tier itself mapped first, untimed."""
    path = ann_file_path(db, "full")
    if stale is None:
        path.unlink(missing_ok=True)
    else:
        path.write_bytes(stale)
    reader = TierReader(db, write_files=True)
    try:
        with reader.snapshot():
            reader.tier("full")
            start = time.perf_counter()
            reader.fast_index("full")
            return time.perf_counter() - start
    finally:
        reader.close()


def key_counts(db: Path) -> tuple[int, int]:
    """The ``fast`` index file's keys and dead keys."""
    reader = TierReader(db)
    try:
        with reader.snapshot():
            tier = reader.tier("full")
            found = map_ann_file(ann_file_path(db, "full"), index_file_key(tier.key, FastConfig()), "full",
                                 len(tier.row_owner))
    finally:
        reader.close()
    if found is None:
        raise SystemExit(f"{db}: no valid fast index after the ingest")
    return found[1].keys, found[1].dead


def agreement_of(db: Path, queries: list[np.ndarray], k: int) -> dict[str, float]:
    shortlist = RecognitionConfig().fast_shortlist
    with viewdb.open(db, read_only=True) as vdb:
        tier = vdb.server_tier()
        exact = [search(tier, q, k, None)[0] for q in queries]
        fast = [search(tier, q, k, shortlist)[0] for q in queries]
    return agreement(exact, fast, k)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--objects", type=int, default=10000)
    parser.add_argument("--views", type=int, default=24)
    parser.add_argument("--queries", type=int, default=100)
    parser.add_argument("--noise", type=float, default=0.01)
    parser.add_argument("-k", type=int, default=5)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--keep", type=Path, help="folder for the synthetic catalogue")
    args = parser.parse_args()

    work = args.keep or Path(f"/tmp/viewdb-fast-{args.objects}")
    work.mkdir(parents=True, exist_ok=True)
    full = work / f"synthetic-{args.objects}.viewdb"
    bases = real_curves(work)
    if not full.exists():
        build(full, args.objects, args.views, bases, args.seed)
    with viewdb.open(full) as db:  # the tier files and the index, as an ingest leaves them
        db.write_tier_files()
    rng = np.random.default_rng(args.seed + 1)
    with viewdb.open(full, read_only=True) as db:
        arrays, _ = db.search_tier("full")
        picks = rng.integers(len(arrays.curves), size=args.queries)
        queries = [np.clip(arrays.curves[i] + rng.normal(0, args.noise, arrays.curves.shape[1]), 0, None)
                   for i in picks]
        views = len(arrays.curves)
        del arrays
    stale = ann_file_path(full, "full").read_bytes()

    with tempfile.TemporaryDirectory(prefix="viewdb-grow-", dir=work) as tmp:
        print(f"{full.name}: {args.objects:,} objects, {views:,} views; the change: one object added, "
              f"one replaced", flush=True)
        rows = {}
        for how in ("built", "grown"):
            db = copy_catalogue(full, Path(tmp) / f"{how}.viewdb", fast_index=how == "grown")
            took = change(db, args, bases)
            keys, dead = key_counts(db)
            step = index_step(copy_catalogue(db, Path(tmp) / f"{how}-step.viewdb", fast_index=False),
                              stale if how == "grown" else None)
            rows[how] = (took, step, keys, dead, agreement_of(db, queries, args.k))
        base_ingest, base_step = rows["built"][0], rows["built"][1]
        print(f"{'index':>6} | {'files s':>8} | {'vs built':>8} | {'index step s':>12} | {'vs built':>8} | "
              f"{'keys':>9} | {'dead':>5} | {'top-1 = server':>14} | {f'top-{args.k} found':>11}")
        for how, (took, step, keys, dead, agree) in rows.items():
            print(f"{how:>6} | {took:8.1f} | {took / base_ingest:7.2f}x | {step:12.2f} | "
                  f"{step / base_step:7.3f}x | {keys:9,} | {dead:5,} | {agree['top1']:14.1%} | "
                  f"{agree['found']:11.1%}")
    print(f"(load average {os.getloadavg()[0]:.1f})")


if __name__ == "__main__":
    main()
