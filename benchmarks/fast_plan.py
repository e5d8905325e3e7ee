"""The ``fast`` plan against ``server`` in the same run: search time, whole-query time, and
how often its answer is the ``server`` answer, per shortlist size; the index's build time
and file size.

    python benchmarks/fast_plan.py DB [--seeds 1-6] [--photos 40] [--shortlists 5,10,20,40]
                                      [--whole 20] [-k 5]
    python benchmarks/fast_plan.py --synthetic 10000 [--views 24] [--queries 100] [--keep DIR]
                                   [--noise 0.03] [--build-only]

**Photos** (a catalogue file ``DB``, opened read-only): the synthetic photos of
``benchmarks/photo_accuracy.py`` (:func:`viewdb.bench.photos.seed_photos`, same seeds, same
photos), each segmented once into its in-plane turned curves (the query's default
``rotations``), as a query's search receives them. Each photo's stack is searched by
``server`` and by ``fast`` at each shortlist size, one right after the other in turn
(the order rotating from photo to photo), through the file's server tier
(``LocalServerTier.refine``, k = the query's pool of 5): the wall time of each search, and per shortlist size

* ``top-1 = server``: photos whose best object (and its distance) is the ``server`` one;
* ``top-5 found``: of the ``server`` top 5 objects, the share in ``fast``'s top 5
  (photo by photo, then over all); ``top-5 same``: photos whose top 5 are the same set.

Then ``--whole N`` shortlist sizes' whole queries (``ViewDB.query`` with the default
options: colour and shape re-ranking, the top result posed), ``server`` and ``fast`` in
turn on every photo: median and p95 wall time, the search stage's median, rank-1 and
rank-5 of the photo's own object. The index: a valid ``DB.fast-full`` is used; else it is
built (timed: what an ingest adds) and written next to ``DB`` (the database itself is not
written), and its size is given per view.

**Synthetic** (``--synthetic N``): the catalogue of ``benchmarks/scale.py`` (N objects of
``--views`` perturbed real curves each, written through the library's own writer; kept in
``--keep``), its tier files and ``fast`` index written as an ingest writes them (timed),
and scale.py's queries (a stored curve plus noise of sd ``--noise``, 0.03 as there; k = 5,
band 6) answered by ``server``
and by ``fast`` per shortlist size, alternately: p50/p95 of each, the agreement figures
above, the index's bytes per view and the process's resident set.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

import viewdb
from viewdb.bench.photos import seed_photos
from viewdb.bench.queries import turned_stacks
from viewdb.config import FastConfig
from viewdb.search.plans import RefineRequest
from viewdb.storage.ann_file import ann_file_path, open_fast_index

BAND = 6


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q))


def rss_mb() -> float:
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            return next(int(line.split()[1]) / 1024 for line in f if line.startswith("VmRSS:"))
    except (OSError, StopIteration):
        return float("nan")


def ensure_index(db: viewdb.ViewDB) -> dict[str, float]:
    """The ``fast`` index of ``db``'s full tier: its valid file's, else built (timed) and
    written next to the database (never into it); its size."""
    catalogue = db.server_tier().catalogue
    with catalogue.tier_reader().snapshot() as reader:
        tier = reader.tier("full")
        rows = len(tier.row_owner)
        start = time.perf_counter()
        found = open_fast_index(tier, catalogue.path, "full", tier.key, FastConfig(), write=False)
        built = found is None
        if built:
            start = time.perf_counter()
            open_fast_index(tier, catalogue.path, "full", tier.key, FastConfig(), write=True)
        seconds = time.perf_counter() - start
    size = ann_file_path(catalogue.path, "full").stat().st_size
    return {"views": rows, "built": built, "seconds": seconds, "bytes": size}


def describe(index: dict[str, float]) -> str:
    how = "built" if index["built"] else "mapped"
    return (f"fast index {how} in {index['seconds']:.1f} s, {index['bytes'] / 1e6:.1f} MB "
            f"({index['bytes'] / index['views']:.0f} bytes per view)")


def search(tier, stack: np.ndarray, k: int, fast: int | None) -> tuple[list, float]:
    request = (RefineRequest.of_stack(stack, BAND, k, [], fast=fast) if stack.ndim == 2
               else RefineRequest(stack, BAND, k, [], fast=fast))
    start = time.perf_counter()
    reply, _ = tier.refine(request)
    return reply.results, (time.perf_counter() - start) * 1e3


def compare(stacks: list[np.ndarray], tier, k: int, shortlists: list[int]) -> dict:
    """Every stack searched by ``server`` and ``fast`` per shortlist, in rotating order."""
    setups: list[int | None] = [None, *shortlists]
    for setup in setups:  # warm: kernels loaded, tier and index mapped
        search(tier, stacks[0], k, setup)
    ms: dict[int | None, list[float]] = {s: [] for s in setups}
    answers: dict[int | None, list[list]] = {s: [] for s in setups}
    for i, stack in enumerate(stacks):
        order = setups[i % len(setups):] + setups[: i % len(setups)]
        for setup in order:
            found, took = search(tier, stack, k, setup)
            ms[setup].append(took)
            answers[setup].append(found)
    return {"ms": ms, "answers": answers}


def agreement(server: list[list], fast: list[list], k: int) -> dict[str, float]:
    pairs = list(zip(server, fast, strict=True))
    top1 = sum(bool(s) and bool(f) and s[0].object == f[0].object
               and abs(s[0].distance - f[0].distance) < 1e-9 for s, f in pairs)
    tops = [({c.object for c in s[:k]}, {c.object for c in f[:k]}) for s, f in pairs]
    found = [len(a & b) / max(len(a), 1) for a, b in tops]
    same = sum(a == b for a, b in tops)
    n = len(server)
    return {"top1": top1 / n, "found": float(np.mean(found)), "same": same / n}


def print_table(result: dict, k: int, shortlists: list[int], unit: str) -> None:
    ms, answers = result["ms"], result["answers"]
    base = statistics.median(ms[None])
    print(f"{'plan':>12} | {'p50 ms':>7} | {'p95 ms':>7} | {'p50 vs server':>13} | {'top-1 = server':>14} | "
          f"{f'top-{k} found':>11} | {f'top-{k} same':>10}")
    blank = f"{'':>14} | {'':>11} | {'':>10}"
    print(f"{'server':>12} | {base:7.1f} | {pct(ms[None], 95):7.1f} | {1.0:12.2f}x | {blank}")
    for s in shortlists:
        a = agreement(answers[None], answers[s], k)
        p50 = statistics.median(ms[s])
        print(f"{f'fast {s}':>12} | {p50:7.1f} | {pct(ms[s], 95):7.1f} | {p50 / base:12.3f}x | "
              f"{a['top1']:14.1%} | {a['found']:11.1%} | {a['same']:10.1%}")
    load = os.getloadavg()[0]
    print(f"({len(answers[None])} {unit}; search alone, wall time; load {load:.1f})", flush=True)


def whole_queries(db: viewdb.ViewDB, photos: list, shortlist: int) -> None:
    """Whole queries (default options, the top result posed), server and fast in turn."""
    runs: dict[str, dict[str, list]] = {p: {"total": [], "search": [], "rank": []}
                                        for p in ("server", "fast")}
    for plan in runs:
        db.query(photos[0][1], plan=plan, fast_shortlist=shortlist)  # warm
    for i, (spec, photo) in enumerate(photos):
        for plan in (("server", "fast") if i % 2 else ("fast", "server")):
            start = time.perf_counter()
            try:
                result = db.query(photo, plan=plan, fast_shortlist=shortlist)
            except viewdb.ViewDBError:
                continue
            runs[plan]["total"].append((time.perf_counter() - start) * 1e3)
            runs[plan]["search"].append(result.timing_ms["client"] + result.timing_ms["server"])
            objects = [r.object for r in result.results]
            runs[plan]["rank"].append(objects.index(spec.object) + 1 if spec.object in objects else None)
    base = statistics.median(runs["server"]["total"])
    for plan, run in runs.items():
        ranks = run["rank"]
        total = statistics.median(run["total"])
        rank1 = sum(r == 1 for r in ranks) / len(ranks)
        rank5 = sum(r is not None and r <= 5 for r in ranks) / len(ranks)
        name = f"{plan} {shortlist}" if plan == "fast" else plan
        searched = statistics.median(run["search"])
        print(f"whole query, {name:8s}: median {total:6.0f} ms ({total / base:.2f}x server), p95 "
              f"{pct(run['total'], 95):6.0f} ms, search stage median {searched:6.1f} ms; "
              f"rank-1 {rank1:6.1%}, rank-5 {rank5:6.1%} ({len(ranks)} photos)", flush=True)
    print(f"(load {os.getloadavg()[0]:.1f})", flush=True)


def photos_run(args: argparse.Namespace, shortlists: list[int]) -> None:
    with viewdb.open(args.db, read_only=True) as db:
        index = ensure_index(db)
        print(f"{args.db}: {len(db.objects())} objects, {index['views']:,} views in the full tier; "
              f"{describe(index)}; load {os.getloadavg()[0]:.1f}", flush=True)
        photos = [(spec, photo) for spec, photo in seed_photos(db, args.seeds, args.photos)]
        stacks = turned_stacks(db, [p for _, p in photos])
        print(f"{len(photos)} photos (seeds {args.seeds}), {len(stacks)} segmented", flush=True)
        print_table(compare(stacks, db.server_tier(), args.k, shortlists), args.k, shortlists, "photos")
        for shortlist in args.whole:
            whole_queries(db, photos, shortlist)
        print(f"resident set {rss_mb():.0f} MB")


def synthetic_run(args: argparse.Namespace, shortlists: list[int]) -> None:
    from scale import build, real_curves

    work = args.keep or Path(f"/tmp/viewdb-fast-{args.synthetic}")
    work.mkdir(parents=True, exist_ok=True)
    full = work / f"synthetic-{args.synthetic}.viewdb"
    if not full.exists():
        start = time.perf_counter()
        build(full, args.synthetic, args.views, real_curves(work), args.seed)
        print(f"catalogue built in {time.perf_counter() - start:.0f} s", flush=True)
    with viewdb.open(full) as db:  # writable: the tier files and the index, as an ingest ends
        start = time.perf_counter()
        db.write_tier_files()
        print(f"tier files and fast index written in {time.perf_counter() - start:.1f} s", flush=True)
    if args.build_only:
        return
    rng = np.random.default_rng(args.seed + 1)
    with viewdb.open(full, read_only=True) as db:
        index = ensure_index(db)
        arrays, _ = db.search_tier("full")
        picks = rng.integers(len(arrays.curves), size=args.queries)
        samples = arrays.curves.shape[1]
        queries = [np.clip(arrays.curves[i] + rng.normal(0, args.noise, samples), 0, None) for i in picks]
        del arrays
        print(f"{full.name}: {args.synthetic:,} objects x {args.views} views = {index['views']:,} views; "
              f"{describe(index)}; database {full.stat().st_size / 1e6:.0f} MB", flush=True)
        print_table(compare(queries, db.server_tier(), args.k, shortlists), args.k, shortlists,
                    f"queries: a stored curve plus noise of sd {args.noise:g}")
        print(f"resident set {rss_mb():.0f} MB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("db", nargs="?")
    parser.add_argument("--seeds", default="1-6")
    parser.add_argument("--photos", type=int, default=40, help="photos per seed")
    parser.add_argument("--shortlists", default="5,10,20,40")
    parser.add_argument("--whole", default="20", help="shortlist sizes of the whole-query runs ('' for none)")
    parser.add_argument("-k", type=int, default=5)
    parser.add_argument("--synthetic", type=int, help="objects of a synthetic catalogue (scale.py's)")
    parser.add_argument("--views", type=int, default=24)
    parser.add_argument("--queries", type=int, default=100)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--keep", type=Path, help="folder for the synthetic catalogue")
    parser.add_argument("--noise", type=float, default=0.03, help="synthetic queries' noise (scale.py: 0.03)")
    parser.add_argument("--build-only", action="store_true", help="build the synthetic catalogue and stop")
    args = parser.parse_args()
    shortlists = [int(s) for s in args.shortlists.split(",") if s]
    args.whole = [int(s) for s in args.whole.split(",") if s]
    if args.synthetic:
        synthetic_run(args, shortlists)
    elif args.db:
        photos_run(args, shortlists)
    else:
        parser.error("give DB or --synthetic N")


if __name__ == "__main__":
    main()
