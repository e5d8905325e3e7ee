"""Camera view skimming on a model folder: types, index size reduction, ingest time, accuracy.

    python benchmarks/skimming.py ../shared/models [--gap 10] [--ingest-limit 12] [--queries 200]

1. Classifies every model (silhouette-only renders) and tabulates the 16 types and the
   views stored against the full grid at ``--gap``.
2. Ingests the first ``--ingest-limit`` models twice in this run, with and without
   skimming (same machine, same jobs), and prints both times and the ratio.
3. No-loss audit: for every grid view of those models, the curve of a fresh silhouette
   render against the curve of the kept view it maps to (reversed when mirrored).
4. Retrieval check (the paper's claim that skimming keeps accuracy): random grid views
   of those models as queries (the paper's protocol), ranked by brute force (Euclidean
   distance to every stored curve and its reverse) over both databases; prints rank-1
   accuracy of each and how often the two disagree on the best object.
"""

from __future__ import annotations

import argparse
import collections
import tempfile
import time
from pathlib import Path

import numpy as np

import viewdb
from viewdb.camera import grid_views
from viewdb.catalogue.describe import classify_object
from viewdb.catalogue.features import distance_curve, mirror_curve
from viewdb.catalogue.mesh import load_mesh
from viewdb.catalogue.render import get_renderer
from viewdb.catalogue.skimming import skim_plan
from viewdb.config import BuildConfig


def curves_of(db: viewdb.ViewDB) -> dict[str, np.ndarray]:
    out = {}
    for o in db.objects():
        curves = [db.view(o.name, h, v).curve for h, v in db.views(o.name)]
        c = np.asarray(curves, dtype=np.float64)
        out[o.name] = np.vstack([c, [mirror_curve(x) for x in c]])  # stored + their mirrors
    return out


def audit(mesh, plan, renderer, config) -> np.ndarray:  # type: ignore[no-untyped-def]
    """RMS difference of every grid view's fresh curve to its kept view's (mirrored) curve."""
    n = config.features.curve_samples
    curves: dict[tuple[float, float], np.ndarray] = {}

    def curve(h: float, v: float) -> np.ndarray:
        if (h, v) not in curves:
            try:
                curves[(h, v)] = distance_curve(renderer.render(mesh, h, v, shaded=False).mask, n)
            except viewdb.FeatureError:
                curves[(h, v)] = np.zeros(n)
        return curves[(h, v)]

    return np.array([
        np.sqrt(np.mean((curve(*view) - (mirror_curve(curve(*kept)) if mirrored else curve(*kept))) ** 2))
        for view, (kept, mirrored) in plan.mapping.items()
    ])


def best_object(curves: dict[str, np.ndarray], query: np.ndarray) -> tuple[str, float]:
    best = {name: float(np.min(np.linalg.norm(c - query, axis=1))) for name, c in curves.items()}
    name = min(best, key=best.get)
    return name, best[name]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", type=Path, nargs="?", default=Path("../shared/models"))
    parser.add_argument("--gap", type=float, default=10.0)
    parser.add_argument("--image-size", type=int, default=256)
    parser.add_argument("--ingest-limit", type=int, default=12)
    parser.add_argument("--queries", type=int, default=200)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    files = viewdb.describe_paths([args.models])
    config = BuildConfig(gap=args.gap)
    grid = len(grid_views(args.gap))

    print(f"== 1. types of {len(files)} models at gap {args.gap:g} ({grid} views each)")
    types: collections.Counter[str] = collections.Counter()
    stored = 0
    start = time.perf_counter()
    for i, path in enumerate(files, 1):
        try:
            sym = classify_object(load_mesh(path), config)
        except viewdb.ViewDBError as exc:
            print(f"  skipped: {exc}")
            continue
        types[f"{sym.h_type}/{sym.v_type}"] += 1
        stored += skim_plan(sym, args.gap).views_stored
        if i % 25 == 0:
            print(f"  {i}/{len(files)} classified ({time.perf_counter() - start:.0f} s)")
    n = sum(types.values())
    print(f"  classification: {time.perf_counter() - start:.1f} s in all")
    print("  type     " + "  ".join(f"V{j}" for j in range(1, 5)))
    for hi in range(1, 5):
        row = [types.get(f"H{hi}/V{vj}", 0) for vj in range(1, 5)]
        print(f"  H{hi}      " + "  ".join(f"{c:2d}" for c in row))
    print(f"  views stored {stored} of {n * grid} ({stored / (n * grid):.1%}; "
          f"{n * grid / stored:.2f}x smaller index)")

    subset = files[: args.ingest_limit]
    print(f"== 2. ingest of {len(subset)} models, jobs={args.jobs}, with and without skimming")
    rng = np.random.default_rng(args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        dbs = {}
        for skim in (True, False):
            path = Path(tmp) / f"{'skim' if skim else 'full'}.db"
            with viewdb.open(path, gap=args.gap, image_size=args.image_size) as db:
                t = time.perf_counter()
                report = db.ingest(subset, jobs=args.jobs, skim=skim)
                wall = time.perf_counter() - t
                views = db.info().rows["views"]
            dbs[skim] = path
            print(f"  skim={skim}: {wall:.1f} s, {views} views stored, "
                  f"{path.stat().st_size / 1e6:.1f} MB, {report.counts()}")
            if skim:
                skim_time = wall
            else:
                print(f"  ingest time ratio skim/no-skim: {skim_time / wall:.2f}")

        print("== 3. no-loss audit: every grid view against its kept view (RMS)")
        renderer = get_renderer(config.render)
        for path in subset:
            mesh = load_mesh(path)
            plan = skim_plan(classify_object(mesh, config, renderer), args.gap)
            errors = audit(mesh, plan, renderer, config)
            print(f"  {path.stem:24s} max {errors.max():.4f}  p99 {np.percentile(errors, 99):.4f}  "
                  f"over sigma {(errors > config.skim.sigma).sum()} of {len(errors)}")

        print(f"== 4. retrieval: {args.queries} random grid views as queries")
        with viewdb.open(dbs[True]) as skim_db, viewdb.open(dbs[False]) as full_db:
            cs, cf = curves_of(skim_db), curves_of(full_db)
            names = sorted(cs)
            views = grid_views(args.gap)
            hits = {True: 0, False: 0}
            disagree = 0
            for _ in range(args.queries):
                name = names[rng.integers(len(names))]
                h, v = views[rng.integers(len(views))]
                try:
                    q = distance_curve(full_db.render(name, h, v).mask, config.features.curve_samples)
                except viewdb.FeatureError:
                    continue
                a, b = best_object(cs, q)[0], best_object(cf, q)[0]
                hits[True] += a == name
                hits[False] += b == name
                disagree += a != b
            print(f"  rank-1 skimmed {hits[True] / args.queries:.1%}, "
                  f"unskimmed {hits[False] / args.queries:.1%}, disagreements {disagree}")


if __name__ == "__main__":
    main()
