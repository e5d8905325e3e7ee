"""Why photos are not recognised: every miss of the synthetic photo benchmark, classified.

    python benchmarks/miss_analysis.py DB [--seeds 1-6] [--photos 40] [--plan fast]
                                          [--rotations 8] [--pool 5] [--shortlist 10]
                                          [--min-iou 0.9] [--twin-threshold 0.03]

The photos are those of ``benchmarks/photo_accuracy.py`` (:func:`viewdb.bench.photos.photo_series`:
same seed, same photos): a random object of DB seen off the grid through a perspective
camera, randomly lit, on a plain random background, with noise and JPEG compression. Each
is queried as a user would (automatic segmentation, ``rotations`` in-plane turns, colour and
shape re-rankings of the plan's best ``pool``, no pose). Each miss (the right object not
first) is classified (:mod:`viewdb.bench.misses`), the first that holds:

* twin: what won has a near-identical mesh (:mod:`viewdb.bench.twins`: symmetric chamfer
  distance of the normalised meshes in their best alignment, reflections allowed, at most
  ``--twin-threshold`` RMS radii);
* segmentation: the automatic mask's IoU with the true silhouette (rendered depth > 0, holes
  filled as the query fills them) is below ``--min-iou``;
* recall: the right object is not among the search's best ``--shortlist`` objects by outline
  alone (the same query with ``colour=False, verify=False``);
* re-ranking: it was, and the outline distance with the re-rankings put another first.

Printed: a line per photo, then per miss the right object, what won, the cause and the
numbers behind it (IoU, outline rank and distances, final scores, colour distances and shape
fits, twin distance, and the rank a query with the true silhouette gives), and the table of
causes per seed and in total (markdown). Query times are wall-clock on a shared machine:
compare them only within one run.
"""

from __future__ import annotations

import argparse
import math
import time
from collections import Counter
from dataclasses import replace

import numpy as np

import viewdb
from viewdb.bench.config import MissConfig, TwinConfig
from viewdb.bench.misses import CAUSES, Miss, cause_of, filled, iou, outline_rank
from viewdb.bench.photos import PhotoSpec, decoded_photo, parse_seeds, photo_series, true_silhouette
from viewdb.bench.twins import Twins
from viewdb.config import DEFAULT_PLAN, RecognitionConfig
from viewdb.recognition.options import QueryOptions
from viewdb.recognition.pipeline import segment_photo, segment_query
from viewdb.recognition.results import QueryMatch


def rank_of(name: str, matches: list[QueryMatch]) -> int | None:
    return next((m.rank for m in matches if m.object == name), None)


def nearest_distance(db: viewdb.ViewDB, name: str, photo: np.ndarray, rotations: int) -> float:
    """The right object's outline distance to the photo: its nearest stored view over the
    in-plane turns the query searches."""
    shape = segment_query(photo, db.config.features.curve_samples, rotations)
    return min(db.nearest_views(name, curve, 1)[0][2] for _, curve in shape.curves)


def analyse(
    db: viewdb.ViewDB, seed: int, index: int, spec: PhotoSpec, options: QueryOptions, config: MissConfig,
    twins: Twins,
) -> tuple[int | None, float, Miss | None]:
    """One photo: its object's rank, the query's seconds, and the miss if it is one."""
    name = spec.object
    mesh = db.mesh(name)
    photo = decoded_photo(mesh, spec)
    start = time.perf_counter()
    answer = db.query(photo, options=options).results
    seconds = time.perf_counter() - start
    rank = rank_of(name, answer)
    if rank == 1:
        return rank, seconds, None
    winner = answer[0]
    truth = true_silhouette(mesh, spec)
    mask_iou = iou(segment_photo(photo)[1].mask, filled(truth))
    outline = replace(options, k=config.shortlist, colour=False, verify=False)
    shortlist = db.query(photo, options=outline).results
    listed = outline_rank(name, shortlist)
    if listed is not None:
        distance = shortlist[listed - 1].distance
    else:
        distance = nearest_distance(db, name, photo, options.rotations)
    mask_rank = rank_of(name, db.query(photo, mask=truth, options=options).results)
    mine = next((m for m in answer if m.object == name), None)
    twin_d = twins.distance(name, winner.object)
    miss = Miss(
        seed=seed, index=index, object=name, winner=winner.object,
        cause=cause_of(twin_d <= config.twins.threshold, mask_iou, listed, config.min_iou),
        iou=mask_iou, rank=rank, outline_rank=listed, distance=distance, winner_distance=winner.distance,
        score=None if mine is None else mine.score, winner_score=winner.score,
        colour=None if mine is None else mine.colour, winner_colour=winner.colour,
        fit=None if mine is None else mine.shape_fit, winner_fit=winner.shape_fit,
        twin_distance=twin_d, mask_rank=mask_rank,
    )
    return rank, seconds, miss


def fmt(x: float | int | None, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return str(x) if isinstance(x, int) else f"{x:.{digits}f}"


def miss_table(misses: list[Miss], shortlist: int) -> list[str]:
    lines = [
        "| seed | photo | object | ranked first | cause | IoU | rank | outline rank "
        f"(of {shortlist}) | outline d: object / first | score: object / first | "
        "colour d: object / first | fit: object / first | twin d | rank, true mask |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for m in misses:
        lines.append(
            f"| {m.seed} | {m.index} | {m.object} | {m.winner} | {m.cause} | {m.iou:.3f} | {fmt(m.rank)} | "
            f"{fmt(m.outline_rank)} | {fmt(m.distance)} / {fmt(m.winner_distance)} | "
            f"{fmt(m.score)} / {fmt(m.winner_score)} | {fmt(m.colour, 2)} / {fmt(m.winner_colour, 2)} | "
            f"{fmt(m.fit, 2)} / {fmt(m.winner_fit, 2)} | {m.twin_distance:.3f} | {fmt(m.mask_rank)} |")
    return lines


def cause_table(rows: dict[int, tuple[list[int | None], list[float], list[Miss]]], pool: int) -> list[str]:
    """Counts per cause, per seed and in all; re-ranking misses whose object was on the
    shortlist but beyond the re-ranked ``pool`` are counted apart as well."""
    head = ("| seed | photos | rank-1 | rank-5 | misses | " + " | ".join(CAUSES)
            + f" | re-ranking, outline rank > {pool} | median query (ms) |")
    lines = [head, "|" + "---|" * (7 + len(CAUSES))]
    every: tuple[list[int | None], list[float], list[Miss]] = ([], [], [])

    def row(label: str, ranks: list[int | None], times: list[float], misses: list[Miss]) -> str:
        r = np.array([x or 0 for x in ranks])
        count = Counter(m.cause for m in misses)
        beyond = sum(m.cause == "re-ranking" and (m.outline_rank or 0) > pool for m in misses)
        return (f"| {label} | {len(r)} | {np.mean(r == 1) * 100:.1f} % | "
                f"{np.mean((r >= 1) & (r <= 5)) * 100:.1f} % | {len(misses)} | "
                + " | ".join(str(count[c]) for c in CAUSES) + f" | {beyond} | {np.median(times) * 1e3:.0f} |")

    for seed, (ranks, times, misses) in rows.items():
        lines.append(row(str(seed), ranks, times, misses))
        for total, part in zip(every, (ranks, times, misses), strict=True):
            total.extend(part)  # type: ignore[arg-type]
    lines.append(row("**all**", *every))
    count = Counter(m.cause for m in every[2])
    n = max(len(every[2]), 1)
    shares = " | ".join(f"{count[c] / n * 100:.0f} %" for c in CAUSES)
    lines.append(f"| share of misses | | | | 100 % | {shares} | | |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--seeds", default="1-6", help="photo seeds, e.g. 1-6 or 1,3 (default 1-6)")
    parser.add_argument("--photos", type=int, default=40, help="photos per seed")
    parser.add_argument("--plan", default=DEFAULT_PLAN)
    parser.add_argument("--rotations", type=int, default=viewdb.QueryOptions().rotations)
    parser.add_argument("--pool", type=int, default=RecognitionConfig().pool,
                        help="objects the plan finds for the colour and shape re-rankings")
    parser.add_argument("--shortlist", type=int, default=MissConfig().shortlist)
    parser.add_argument("--min-iou", type=float, default=MissConfig().min_iou)
    parser.add_argument("--twin-threshold", type=float, default=TwinConfig().threshold)
    args = parser.parse_args()
    config = MissConfig(min_iou=args.min_iou, shortlist=args.shortlist,
                        twins=TwinConfig(threshold=args.twin_threshold))
    options = QueryOptions(k=5, plan=args.plan, rotations=args.rotations, pose=False,
                           recognition=replace(RecognitionConfig(), pool=args.pool))
    db = viewdb.open(args.db, read_only=True)
    names = [o.name for o in db.objects()]
    twins = Twins(db.mesh, config.twins)
    rows: dict[int, tuple[list[int | None], list[float], list[Miss]]] = {}
    for seed in parse_seeds(args.seeds):
        ranks: list[int | None] = []
        times: list[float] = []
        misses: list[Miss] = []
        for i, spec in enumerate(photo_series(names, seed, args.photos)):
            rank, seconds, miss = analyse(db, seed, i, spec, options, config, twins)
            ranks.append(rank)
            times.append(seconds)
            note = "" if miss is None else f"  first {miss.winner}: {miss.cause}"
            print(f"seed {seed} {i:3d} {spec.object:32s} rank {fmt(rank)} {seconds * 1e3:6.0f} ms{note}",
                  flush=True)
            if miss is not None:
                misses.append(miss)
        rows[seed] = (ranks, times, misses)
    every = [m for _, _, ms in rows.values() for m in ms]
    print(f"\n{len(names)} objects, plan {args.plan}, {args.rotations} turns, pool {args.pool}, k = 5, "
          f"no pose; seeds {args.seeds}, {args.photos} photos each\n")
    print("\n".join(miss_table(every, config.shortlist)))
    print()
    print("\n".join(cause_table(rows, args.pool)))


if __name__ == "__main__":
    main()
