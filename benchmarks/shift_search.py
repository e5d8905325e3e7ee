"""One search over the circular shifts of the query curve, against today's 12 in-plane turns.

    python benchmarks/shift_search.py DB [--photos 40] [--seed 1] [-k 5] [--band 6]
                                         [--blocks 4,8] [--grids 8,4] [--tolerance 5,15]
                                         [--brute 2] [--turned]

The queries are real: synthetic photos (:mod:`viewdb.bench.photos`, the generator of
``benchmarks/photo_accuracy.py``; same seed, same photos), segmented automatically as a
user's would be, then turned into distance curves; ``--turned`` also turns each photo by
a random angle in the image plane (a camera held at a random roll). Every design is
exact for its own distance and is timed on the same curves in the same run, on the
file's full tier through its R-tree (k distinct objects, Sakoe-Chiba band ``--band``):

* ``turns12``: today's search: the silhouette turned by 12 angles (each turn rendered and
  its curve resampled), one search per turn, each bounded by the turns before (``prior``);
* ``stack12``: the same 12 curves in one best-first search
  (:func:`viewdb.search.knn.knn_stack`, each turn keyed by its own bounds);
* ``shifts-bB``: every circular shift of the upright curve in one search
  (``knn(..., shifts=ShiftWindow())``), ``B`` shifts per wedge;
* ``gridT``: ``T`` evenly spaced shifts of the upright curve in one search
  (``ShiftWindow(step=S)``, ``--grids`` gives the steps);
* ``upright``: the upright curve alone (today's ``rotations=1``, a fixed start);
* ``roll±D-bB``: a gravity hint (the photo's true roll: 0, or its random turn): the shifts
  within ``--tolerance`` degrees of it (:func:`viewdb.search.shifts.turn_window`).

Printed per design: p50 and p95 of the search's wall time and its ratio to ``turns12``'s,
the median CPU time and its ratio (steadier on a shared machine), the DTWs and groups,
and the rank-1 / rank-5 of the photo's object by the search alone (the outline, before
any re-ranking). Brute force, on the first ``--brute`` queries (one for the 128-shift
stack): every view's exact distance for the design's stack of curves by a compiled scan
with no index (each view's DTWs abandon only past that view's own best,
:func:`viewdb.search.multirefine.scan_stack`); the script checks that each design finds
the same objects and distances and prints the scan's CPU time against the search's.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import cv2
import numpy as np

import viewdb
from viewdb.bench.photos import draw_photo_spec, encode_jpeg, render_photo
from viewdb.catalogue.features import distance_curve, sample_bearings
from viewdb.recognition.image import load_image
from viewdb.recognition.segmentation import segment
from viewdb.recognition.shapes import rotated_curves
from viewdb.search.knn import Neighbour, SearchStats, TierSource, knn, knn_stack
from viewdb.search.multirefine import scan_stack
from viewdb.search.shifts import CurveQuery, ShiftWindow, shifted_curves, turn_window


def photo_queries(db: viewdb.ViewDB, count: int, seed: int, turned: bool) -> list[dict]:
    """Seeded synthetic photos, segmented: the object's name, the upright curve, the 12
    turned curves, the samples' bearings and the roll a gravity sensor would report (the
    in-plane turn that makes the photo upright: 0, or the random turn of ``turned``)."""
    names = [o.name for o in db.objects()]
    n = db.config.features.curve_samples
    rng = np.random.default_rng(seed)
    turns = np.random.default_rng(seed + 1000)
    out = []
    for _ in range(count):
        name = names[rng.integers(len(names))]
        spec = draw_photo_spec(rng, name)
        jpeg = encode_jpeg(render_photo(db.mesh(name), spec), spec.jpeg_quality)
        rgb = cv2.cvtColor(cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR),
                           cv2.COLOR_BGR2RGB)
        roll = float(turns.uniform(0.0, 360.0)) if turned else 0.0
        if roll:  # the camera rolled: the photo turned anticlockwise on screen by `roll`
            size = rgb.shape[1], rgb.shape[0]
            m = cv2.getRotationMatrix2D(((size[0] - 1) / 2, (size[1] - 1) / 2), roll, 1.0)
            rgb = cv2.warpAffine(rgb, m, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        mask = segment(load_image(rgb)).mask
        out.append({"name": name, "curve": distance_curve(mask, n), "bearings": sample_bearings(mask, n),
                    "turns": np.stack([c for _, c in rotated_curves(mask, n, 12)]), "roll": roll})
    return out


def turns_with_prior(
    curves: np.ndarray, source: TierSource, k: int, band: int
) -> tuple[list[Neighbour], SearchStats]:
    """Today's search: one search per turn, each bounded by the merged results so far
    (what ``ViewDB.recognise(..., prior=)`` does)."""
    best: dict[int, Neighbour] = {}
    total = SearchStats()
    for curve in curves:
        merged = sorted(best.values(), key=lambda nb: (nb.distance, nb.object))[:k]
        upper = merged[k - 1].distance if len(merged) >= k else np.inf
        known = {source.object_index(nb.object): nb.distance for nb in merged}
        found, stats = knn(curve, source, k, band, upper=upper, known=known)
        for key in ("groups_visited", "points_visited", "lb_keogh", "dtw"):
            setattr(total, key, getattr(total, key) + getattr(stats, key))
        for nb in found:
            o = source.object_index(nb.object)
            if o not in best or nb.distance < best[o].distance:
                best[o] = nb
    return sorted(best.values(), key=lambda nb: (nb.distance, nb.object))[:k], total


def brute_top(query: CurveQuery, curves: np.ndarray, owner: np.ndarray, names: list[str], k: int):
    distances = scan_stack(query, curves)
    best = np.full(len(names), np.inf)
    np.minimum.at(best, owner, distances)
    return sorted((d, names[o]) for o, d in enumerate(best.tolist()))[:k]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--photos", type=int, default=40)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("-k", type=int, default=5)
    parser.add_argument("--band", type=int, default=6)
    parser.add_argument("--blocks", default="4,8", help="shifts per wedge to try (all shifts)")
    parser.add_argument("--grids", default="8,4", help="steps of the shift grids to try")
    parser.add_argument("--brute", type=int, default=2, help="queries also scanned by brute force")
    parser.add_argument("--tolerance", default="5,15", help="degrees around a roll hint (a comma list)")
    parser.add_argument("--turned", action="store_true",
                        help="turn each photo by a random in-plane angle (the roll hint then gives it)")
    args = parser.parse_args()
    k, band = args.k, args.band
    db = viewdb.open(args.db, read_only=True)
    start = time.perf_counter()
    queries = photo_queries(db, args.photos, args.seed, args.turned)
    print(f"{len(queries)} photos (seed {args.seed}) segmented in {time.perf_counter() - start:.1f} s")

    n = db.config.features.curve_samples
    every = np.arange(n)
    # label -> (stack of curves of a query, search); each search is exact for its stack
    designs: dict[str, tuple[Callable[[dict], np.ndarray], Callable[[dict, TierSource], tuple]]] = {
        "turns12": (lambda q: q["turns"], lambda q, s: turns_with_prior(q["turns"], s, k, band)),
        "stack12": (lambda q: q["turns"], lambda q, s: knn_stack(q["turns"], s, k, band, block=1)),
    }
    for b in (int(x) for x in args.blocks.split(",")):
        designs[f"shifts-b{b}"] = (
            lambda q: shifted_curves(q["curve"], every),
            lambda q, s, b=b: knn(q["curve"], s, k, band, shifts=ShiftWindow(), block=b))
    for step in (int(x) for x in args.grids.split(",")):
        window = ShiftWindow(step=step)
        designs[f"grid{len(window.shifts(n))}"] = (
            lambda q, w=window: shifted_curves(q["curve"], w.shifts(n)),
            lambda q, s, w=window: knn(q["curve"], s, k, band, shifts=w, block=1))
    designs["upright"] = (lambda q: q["curve"][None], lambda q, s: knn(q["curve"], s, k, band))
    def hinted(q: dict, tolerance: float) -> ShiftWindow:
        return turn_window(q["bearings"], q["roll"], tolerance)

    for tol in (float(x) for x in args.tolerance.split(",")):
        for b in (1, 8):
            designs[f"roll±{tol:g}-b{b}"] = (
                lambda q, t=tol: shifted_curves(q["curve"], hinted(q, t).shifts(n)),
                lambda q, s, b=b, t=tol: knn(q["curve"], s, k, band, block=b, shifts=hinted(q, t)))

    reader = db._catalogue.tier_reader()  # the file's R-tree, as ViewDB.search reads it
    with reader.snapshot():
        source = reader.tier("full")
        print(f"full tier: {source.n_objects} objects, {int(source.group_count.sum())} views, "
              f"{source.n_groups} groups")
        for _, run in designs.values():  # compile, and load every group once
            run(queries[0], source)
        results: dict[str, list] = {}
        for label, (_, run) in designs.items():
            rows = []
            for q in queries:
                wall, cpu = time.perf_counter(), time.process_time()
                found, stats = run(q, source)
                rows.append((time.perf_counter() - wall, time.process_time() - cpu, found, stats))
            results[label] = rows

    base_wall = np.median([r[0] for r in results["turns12"]])
    base_cpu = np.median([r[1] for r in results["turns12"]])
    print(f"\n{'design':12s} {'p50 ms':>7s} {'p95 ms':>7s} {'vs turns12':>10s} {'CPU p50':>8s} "
          f"{'vs turns12':>10s} {'DTWs':>6s} {'groups':>6s} {'rank-1':>7s} {'rank-5':>7s}")
    for label, rows in results.items():
        wall = np.array([r[0] for r in rows])
        cpu = np.array([r[1] for r in rows])
        ranks = []
        for q, row in zip(queries, rows, strict=True):
            names = [nb.object for nb in row[2]]
            ranks.append(names.index(q["name"]) + 1 if q["name"] in names else 0)
        r = np.array(ranks)
        print(f"{label:12s} {np.median(wall) * 1e3:7.1f} {np.percentile(wall, 95) * 1e3:7.1f} "
              f"{base_wall / np.median(wall):9.2f}x {np.median(cpu) * 1e3:8.1f} "
              f"{base_cpu / np.median(cpu):9.2f}x "
              f"{np.mean([x[3].dtw for x in rows]):6.0f} {np.mean([x[3].groups_visited for x in rows]):6.0f} "
              f"{np.mean(r == 1) * 100:6.1f}% {np.mean((r >= 1) & (r <= 5)) * 100:6.1f}%")

    if args.brute:
        tier, _ = db.search_tier("full")
        print(f"\nbrute force (every view's exact distance, no index), first {args.brute} queries "
              "(1 for the 128-shift designs):")
        first_shifts = next((x for x in designs if x.startswith("shifts")), None)
        for label, (stack_of, _) in designs.items():
            if label.startswith("shifts") and label != first_shifts:
                continue  # the same stack as the first block size
            count = 1 if label.startswith("shifts") else args.brute
            times = []
            for i, q in enumerate(queries[:count]):
                cpu = time.process_time()
                expected = brute_top(CurveQuery.of(stack_of(q), band), tier.curves, tier.owner, tier.names, k)
                times.append(time.process_time() - cpu)
                found = results[label][i][2]
                assert [nb.object for nb in found] == [name for _, name in expected], label
                assert np.allclose([nb.distance for nb in found], [d for d, _ in expected], rtol=0, atol=1e-9)
            searched = np.mean([r[1] for r in results[label][:count]])
            print(f"  {label:12s} {np.mean(times) * 1e3:9.0f} ms CPU a query, same answers; "
                  f"{np.mean(times) / searched:6.0f}x the search")


if __name__ == "__main__":
    main()
