"""Sharded catalogues on a local Ray: latency, memory per shard and pruning across shards.

    python benchmarks/scale.py [--objects 10000] [--views 24] [--shards 1,2,4] [--queries 100]

Builds a synthetic catalogue of curves only (no rendering): each object's views are real
distance curves of the sample models (ingested once at a 30° grid), each perturbed (a
smooth random scaling of up to ±8 %, a shift of up to 2 samples, renormalised to mean 1),
so objects are near-twins of real shapes, the hard case for pruning. It is written through
the library's own writer (``Store.write_object``: real rows, real R-trees) and split with
``viewdb.shards.layout.split_catalogue`` into 1, 2 and 4 shards. The same queries (a stored
curve plus noise, k = 5, band 6) are answered:

* ``single``: the single file in this process (``LocalServerTier.refine``): the baseline;
* ``N shards``: ``ShardedServerTier.refine`` over N Ray actors on this machine; every
  answer is checked equal to the baseline's.

Reported: p50/p95 latency and the ratio to the baseline's p50; DTWs computed (all shards)
against the sum of each shard searched alone without bounds (the pruning the first
round's bound buys); the full tier's bytes and the resident set of each shard's process.
"""

from __future__ import annotations

import argparse
import math
import shutil
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

import viewdb
from viewdb.catalogue.features import fourier_point
from viewdb.catalogue.sift import empty_features
from viewdb.config import BuildConfig, IndexConfig, RenderConfig, ShardConfig
from viewdb.search.plans import RefineRequest
from viewdb.storage.store import Store

SAMPLES = Path(__file__).resolve().parent.parent / "sample_models"


def real_curves(work: Path) -> list[np.ndarray]:
    path = work / "real.db"
    config = BuildConfig(gap=30, render=RenderConfig(image_size=128), index=IndexConfig(client_gap=90))
    with viewdb.open(path, config=config) as db:
        db.ingest(viewdb.describe_paths([SAMPLES]))
        arrays, _ = db.search_tier("full")
        return [arrays.curves[arrays.owner == o] for o in range(len(arrays.names))]


def perturbed(curve: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    n = len(curve)
    t = np.arange(n) / n
    field = 1 + sum(rng.uniform(-0.04, 0.04) * np.cos(2 * math.pi * (f * t + rng.random()))
                    for f in (1, 2, 3))
    out = np.roll(curve, int(rng.integers(-2, 3))) * field
    return (out / out.mean()).astype(np.float32)


def build(
    path: Path, objects: int, views: int, bases: list[np.ndarray], seed: int, first: int = 0,
) -> BuildConfig:
    """Write ``objects`` synthetic objects, numbered from ``first``, into the catalogue at
    ``path`` (created if new; an object of the same number is replaced)."""
    config = BuildConfig(gap=30, index=IndexConfig(client_gap=90)).resolved()
    rng = np.random.default_rng(seed)
    store = Store(path, initial=(config, "full"))
    grid = [(float(h), float(v)) for v in range(-60, 90, 30) for h in range(0, 360, 30)][:views]
    m = config.features.fourier_coefficients
    try:
        for i in range(first, first + objects):
            base = bases[i % len(bases)]
            vs = [SimpleNamespace(azimuth=h, elevation=v, curve=(c := perturbed(base[j % len(base)], rng)),
                                  fourier=fourier_point(c, m), sift=empty_features())
                  for j, (h, v) in enumerate(grid)]
            desc = SimpleNamespace(name=f"obj{i:07d}", source="synthetic",
                                   content_hash=f"{seed:016x}{i:048x}", n_faces=1, n_vertices=3,
                                   centre=np.zeros(3), scale=1.0, glb=b"",
                                   empty_views=[], seconds=0.0, views=vs)
            store.write_object(desc, config)
    finally:
        store.close()
    return config


def percentiles(ms: list[float]) -> tuple[float, float]:
    return float(np.percentile(ms, 50)), float(np.percentile(ms, 95))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=10000)
    ap.add_argument("--views", type=int, default=24)
    ap.add_argument("--shards", default="1,2,4")
    ap.add_argument("--queries", type=int, default=100)
    ap.add_argument("--k", type=int, default=5)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--keep", type=Path, help="folder to keep the catalogue and shards in")
    args = ap.parse_args()

    import ray

    from viewdb.shards.cluster import ShardedServerTier
    from viewdb.shards.layout import split_catalogue
    from viewdb.shards.shard import Shard

    work = args.keep or Path(tempfile.mkdtemp(prefix="viewdb-scale-"))
    work.mkdir(parents=True, exist_ok=True)
    full = work / f"synthetic-{args.objects}.viewdb"
    bases = real_curves(work)
    t = time.perf_counter()
    if not full.exists():
        build(full, args.objects, args.views, bases, args.seed)
    print(f"catalogue: {args.objects} objects x {args.views} views, {full.stat().st_size / 1e6:.0f} MB, "
          f"built in {time.perf_counter() - t:.0f} s")

    rng = np.random.default_rng(args.seed + 1)
    with viewdb.open(full, read_only=True) as db:
        arrays, _ = db.search_tier("full")
        picks = rng.integers(len(arrays.curves), size=args.queries)
        queries = [np.clip(arrays.curves[i] + rng.normal(0, 0.03, 128), 0, None) for i in picks]
        tier = db.server_tier()
        tier.refine(RefineRequest(queries[0], 6, args.k, []))  # warm: kernels compiled, rows read
        base_ms, answers, base_dtw = [], [], 0.0
        for q in queries:
            s = time.perf_counter()
            reply, _ = tier.refine(RefineRequest(q, 6, args.k, []))
            base_ms.append((time.perf_counter() - s) * 1e3)
            answers.append([c.to_dict() for c in reply.results])
            base_dtw += reply.stats["dtw"]
    p50, p95 = percentiles(base_ms)
    whole = Shard(full, 0, check=False)
    single_bytes = whole.memory()["tier_bytes"]
    whole.close()
    print(f"{'setup':>10} | {'p50 ms':>7} | {'p95 ms':>7} | {'p50/base':>8} | {'DTW/query':>9} | "
          f"{'unbounded':>9} | {'tier MB/shard':>13} | {'RSS MB/shard':>12}")
    print(f"{'single':>10} | {p50:7.1f} | {p95:7.1f} | {1.0:8.2f} | {base_dtw / len(queries):9.0f} | "
          f"{'':>9} | {single_bytes / 1e6:13.1f} | {'':>12}")

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    for n in (int(x) for x in args.shards.split(",")):
        folder = work / f"shards-{n}"
        if not folder.exists():
            split_catalogue(full, n, folder)
        # synthetic objects have no meshes, which check would report: skip it here
        sharded = ShardedServerTier(folder, config=ShardConfig(check_at_start=False))
        try:
            sharded.refine(RefineRequest(queries[0], 6, args.k, []))
            ms, dtw, alone = [], 0.0, 0.0
            for q, want in zip(queries, answers, strict=True):
                s = time.perf_counter()
                reply, _ = sharded.refine(RefineRequest(q, 6, args.k, []))
                ms.append((time.perf_counter() - s) * 1e3)
                assert [c.to_dict() for c in reply.results] == want, "sharded answer differs"
                dtw += reply.stats["dtw"]
            for q in queries:  # each shard alone, unbounded: what the cross-shard bound saves
                body = RefineRequest(q, 6, args.k, []).to_dict()
                refs = [a.call.remote("refine", body, math.inf) for a in sharded.actors]
                alone += sum(r["stats"]["dtw"] for r in ray.get(refs))
            memory = ray.get([a.call.remote("memory") for a in sharded.actors])
            p50n, p95n = percentiles(ms)
            tier_mb = np.mean([m["tier_bytes"] for m in memory]) / 1e6
            rss = [m["rss_bytes"] for m in memory if m["rss_bytes"]]
            print(f"{f'{n} shards':>10} | {p50n:7.1f} | {p95n:7.1f} | {p50n / p50:8.2f} | "
                  f"{dtw / len(queries):9.0f} | {alone / len(queries):9.0f} | {tier_mb:13.1f} | "
                  f"{(np.mean(rss) / 1e6 if rss else float('nan')):12.0f}")
        finally:
            sharded.close()
    ray.shutdown()
    if args.keep is None:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
