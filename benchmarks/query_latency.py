"""Warm query latency and accuracy on the synthetic photos, per set of options, with each
stage's share and the search against a brute-force scan of the same features.

    python benchmarks/query_latency.py DB [--seeds 1-6] [--photos 40] [-k 5] [--plan fast]
                                          [--configs no-pose,default,upright-no-pose,upright]
                                          [--brute 3]

The photos are those of ``benchmarks/photo_accuracy.py`` (:func:`viewdb.bench.photos.photo_series`,
same seeds, same photos: a random object, off-grid perspective view, random light, plain
background, noise, JPEG), generated before any timing. One process; each
set of options opens the file afresh (empty caches), is warmed up on the first photo, then
every photo is queried with it:

* ``no-pose``: ``pose=False``;
* ``default``: the library's defaults (the top result posed);
* ``upright-no-pose``, ``upright``: the same with the gravity hint ``roll=0`` (the
  photos are upright, as a camera that knows gravity takes them);
* ``no-pose-separate``, ``default-separate``: ``no-pose`` and ``default`` with the 12
  in-plane turns searched one by one (``RecognitionConfig(turn_search="separate")``)
  instead of as one stack. With both a set and its ``-separate`` twin in the run, the
  two answers are compared photo by photo, and the search stages (``client`` + ``server``)
  paired; then each photo's 12 turns are searched both ways again, one right after the
  other (alternating which goes first), and the CPU time of each search is given: the
  steadier figure on a shared machine.

Printed per set: the median and p95 wall time of a whole query, the median of each stage
(``timing_ms``), rank-1 and rank-5 (the photo's own object). With ``--brute N`` the first N
photos' curves (the 12 turns) are also searched by a compiled DTW scan of every view of the
full tier (and its mirror, :func:`viewdb.search.refine.scan_all`), and the scan's time is
given against the same photos' search stages (``client`` + ``server``) without pose. Give
the load average with the figures: the machine's other work lengthens every stage.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from dataclasses import replace

import numpy as np

import viewdb
from viewdb.bench.photos import seed_photos
from viewdb.config import DEFAULT_PLAN, RecognitionConfig
from viewdb.recognition.client_tier import ClientTier
from viewdb.recognition.pipeline import segment_query
from viewdb.recognition.retrieval import merge, recognise_curve
from viewdb.search.refine import scan_all

CONFIGS = {
    "no-pose": {"pose": False},
    "default": {},
    "upright-no-pose": {"pose": False, "roll": 0.0},
    "upright": {"roll": 0.0},
    "no-pose-separate": {"pose": False, "recognition": RecognitionConfig(turn_search="separate")},
    "default-separate": {"recognition": RecognitionConfig(turn_search="separate")},
}


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q))


def run_config(db: viewdb.ViewDB, photos: list[tuple[str, np.ndarray]], options: dict, k: int,
               plan: str) -> dict:
    query = viewdb.QueryOptions(k=k, plan=plan, **options)
    db.query(photos[0][1], options=query)  # warm
    totals, ranks, stages, answers, searches, cpu = [], [], {}, [], [], []
    for name, photo in photos:
        start, cpu_start = time.perf_counter(), time.process_time()
        try:
            result = db.query(photo, options=query)
        except viewdb.ViewDBError as exc:
            totals.append((time.perf_counter() - start) * 1e3)
            ranks.append(None)
            answers.append(str(exc))
            searches.append(None)
            continue
        totals.append((time.perf_counter() - start) * 1e3)
        cpu.append((time.process_time() - cpu_start) * 1e3)
        objects = [r.object for r in result.results]
        ranks.append(objects.index(name) + 1 if name in objects else None)
        answers.append(result.to_dict()["results"])
        searches.append(result.timing_ms["client"] + result.timing_ms["server"])
        for stage, ms in result.timing_ms.items():
            stages.setdefault(stage, []).append(ms)
    return {"totals": totals, "ranks": ranks, "stages": stages, "answers": answers, "searches": searches,
            "cpu": cpu}


def compare(config: str, stack: dict, separate: dict) -> None:
    """The answers of a set and its ``-separate`` twin, photo by photo, and their search stages."""
    same = sum(a == b for a, b in zip(stack["answers"], separate["answers"], strict=True))
    pairs = [(a, b) for a, b in zip(stack["searches"], separate["searches"], strict=True)
             if a is not None and b is not None]
    new, old = statistics.median(a for a, _ in pairs), statistics.median(b for _, b in pairs)
    ratio = statistics.median(b / a for a, b in pairs if a > 0)
    cpu_new, cpu_old = statistics.median(stack["cpu"]), statistics.median(separate["cpu"])
    print(f"{config}: stack vs separate turns: answers identical on {same}/{len(stack['answers'])} photos; "
          f"search stage median {new:.0f} ms (stack) vs {old:.0f} ms (separate): {old / new:.2f}x; "
          f"median per-photo ratio {ratio:.2f}x; whole-query CPU median {cpu_new:.0f} vs {cpu_old:.0f} ms: "
          f"{cpu_old / cpu_new:.2f}x", flush=True)


def brute_force(db: viewdb.ViewDB, photos: list[tuple[str, np.ndarray]], band: int) -> list[float]:
    """Milliseconds of a compiled DTW scan of every full-tier view for each photo's 12 turns."""
    tier, _ = db.search_tier("full")
    samples = db.config.features.curve_samples
    out = []
    for _, photo in photos:
        shape = segment_query(photo, samples, viewdb.QueryOptions().rotations)
        start = time.perf_counter()
        for _, curve in shape.curves:
            scan_all(curve, tier.curves, band)
        out.append((time.perf_counter() - start) * 1e3)
    return out


def search_cpu(db: viewdb.ViewDB, photos: list[tuple[str, np.ndarray]], k: int, plan: str,
               band: int = 6) -> tuple[list[float], list[float], int]:
    """Per photo, the CPU milliseconds of searching its 12 turns as one stack and one by one
    (each bounded by the turns before, as the pipeline does), back to back; and on how many
    photos the two agree."""
    samples = db.config.features.curve_samples
    server, client = db.server_tier(), ClientTier(db._catalogue)  # the file's own sparse tier (cs1)

    def stack(curves):
        found = recognise_curve(np.stack([c for _, c in curves]), k, band, plan, server, client)
        return [(replace(c, curve_index=None), curves[c.curve_index][0]) for c in found.results]

    def separate(curves):
        per_curve = []
        for angle, curve in curves:
            prior = [c for c, _ in merge(per_curve, k)]
            per_curve.append((angle, recognise_curve(curve, k, band, plan, server, client, prior).results))
        return merge(per_curve, k)

    stacked, one_by_one, same = [], [], 0
    for i, (_, photo) in enumerate(photos):
        try:
            curves = segment_query(photo, samples, viewdb.QueryOptions().rotations).curves
        except viewdb.ViewDBError:
            continue
        answers = {}
        for how in ((stack, separate) if i % 2 else (separate, stack)):
            start = time.thread_time()
            answers[how] = how(curves)
            (stacked if how is stack else one_by_one).append((time.thread_time() - start) * 1e3)
        same += answers[stack] == answers[separate]
    return stacked, one_by_one, same


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("db")
    parser.add_argument("--seeds", default="1-6")
    parser.add_argument("--photos", type=int, default=40, help="photos per seed")
    parser.add_argument("-k", type=int, default=5)
    parser.add_argument("--plan", default=DEFAULT_PLAN)
    parser.add_argument("--configs", default="no-pose,default,upright-no-pose,upright")
    parser.add_argument("--brute", type=int, default=3, help="photos also searched by brute force")
    args = parser.parse_args()
    configs = args.configs.split(",")
    unknown = [c for c in configs if c not in CONFIGS]
    if unknown:
        raise SystemExit(f"unknown --configs {unknown}; known: {', '.join(CONFIGS)}")
    with viewdb.open(args.db, read_only=True) as db:
        photos = [(spec.object, photo) for spec, photo in seed_photos(db, args.seeds, args.photos)]
        print(f"{args.db}: {len(db.objects())} objects; {len(photos)} photos (seeds {args.seeds}); "
              f"plan {args.plan}, k={args.k}; load {os.getloadavg()[0]:.1f}", flush=True)
    runs = {}
    for config in configs:
        with viewdb.open(args.db, read_only=True) as db:  # each set starts with empty caches
            got = runs[config] = run_config(db, photos, CONFIGS[config], args.k, args.plan)
            ranks = got["ranks"]
            rank1 = sum(r == 1 for r in ranks) / len(ranks)
            rank5 = sum(r is not None and r <= 5 for r in ranks) / len(ranks)
            split = ", ".join(f"{s} {statistics.median(v):.0f}" for s, v in got["stages"].items()
                              if s != "total")
            print(f"{config:16s} median {statistics.median(got['totals']):6.0f} ms  "
                  f"p95 {percentile(got['totals'], 95):6.0f} ms  rank-1 {rank1:6.1%}  rank-5 {rank5:6.1%}  "
                  f"load {os.getloadavg()[0]:.1f}\n{'':16s} stage medians (ms): {split}", flush=True)
    for config in configs:
        if f"{config}-separate" in runs:
            compare(config, runs[config], runs[f"{config}-separate"])
    if any(f"{config}-separate" in runs for config in configs):
        with viewdb.open(args.db, read_only=True) as db:
            stacked, separate, same = search_cpu(db, photos, max(args.k, 5), args.plan)
        ratio = statistics.median(b / a for a, b in zip(stacked, separate, strict=True) if a > 0)
        new, old = statistics.median(stacked), statistics.median(separate)
        print(f"search alone, back to back: CPU median {new:.0f} ms (stack) vs {old:.0f} ms (separate): "
              f"{old / new:.2f}x; median per-photo ratio {ratio:.2f}x; p95 {percentile(stacked, 95):.0f} vs "
              f"{percentile(separate, 95):.0f} ms; the same pool on {same}/{len(stacked)} photos "
              f"(load {os.getloadavg()[0]:.1f})", flush=True)
    if args.brute > 0:
        with viewdb.open(args.db, read_only=True) as db:
            some = photos[:args.brute]
            brute = brute_force(db, some, 6)
            search = run_config(db, some, {"pose": False}, args.k, args.plan)["stages"]
            searched = [c + s for c, s in zip(search["client"], search["server"], strict=True)]
            scan, searching = statistics.median(brute), statistics.median(searched)
            print(f"brute force over {len(some)} photos: DTW scan of every view, 12 turns, median "
                  f"{scan:.0f} ms against the search stage's {searching:.0f} ms: {scan / searching:.1f}x "
                  f"(load {os.getloadavg()[0]:.1f})")


if __name__ == "__main__":
    main()
