"""Load test of ``viewdb serve`` on loopback: throughput and latency with 1 and 2 workers.

    python benchmarks/http_load.py [DB] [--clients 4] [--requests 1000] [--plan cs1]
                                   [--pose-requests 0]

Without DB a small database is built from ``sample_models/`` (30° grid, 90° client
grid) in a temporary folder. The queries are the server half of real client work: the
distance curves of silhouettes of random objects rendered at random off-grid angles,
each first run through the client half on an exported client file (so the requests are
exactly what ``viewdb query --client ... --server ...`` sends). Then for 1 and for 2
worker processes a server is started on a free loopback port, ``--clients`` threads (each
with its own keep-alive connection) send ``--requests`` /refine (or /walk) requests in
all, and the run reports throughput, p50/p99 latency, errors, and the 2-vs-1 worker
throughput ratio. Every reply is checked against the local server half. ``--pose-requests``
adds that many /pose requests (rendering on the server) per run. Stops by itself.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

import viewdb
from support.serving import ServerProcess
from viewdb.catalogue.features import distance_curve
from viewdb.errors import FeatureError
from viewdb.pose.estimate import QueryView
from viewdb.search.plans import RefineRequest, WalkRequest

ROOT = Path(__file__).resolve().parents[1]


def build(folder: Path) -> Path:
    from viewdb.config import BuildConfig, IndexConfig

    path = folder / "full.db"
    models = viewdb.describe_paths([ROOT / "sample_models"])
    with viewdb.open(path, config=BuildConfig(gap=30, index=IndexConfig(client_gap=90))) as db:
        db.ingest(models, jobs=2)
    return path


def workload(db_path: Path, client_path: Path, plan: str, count: int, seed: int):
    """(request, expected results) pairs: client half on the client file, expected answer
    from the full file's own server half."""
    rng = np.random.default_rng(seed)
    out = []
    with viewdb.open(db_path, read_only=True) as db, viewdb.open(client_path, read_only=True) as client:
        names = [o.name for o in db.objects()]
        poses = []
        while len(out) < count:
            name = names[rng.integers(len(names))]
            h, v = rng.uniform(0, 360, 2)
            view = db.render(name, h, v)
            try:
                curve = distance_curve(view.mask, db.config.features.curve_samples)
            except FeatureError:
                continue
            mine, _ = client.client_candidates(curve, 5)
            if plan == "cs1":
                req = RefineRequest(curve, 6, 5, mine)
                expected = db.server_tier().refine(req)[0].results
            else:
                req = WalkRequest(curve, 6, 5, client.config.client_gap, mine)
                expected = db.server_tier().walk(req)[0].results
            out.append((req, expected))
            if len(poses) < 8:
                poses.append((QueryView(view.color, view.mask), expected[:2]))
    return out, poses


def run(url: str, token: str, plan: str, work, poses, clients: int, requests: int, pose_requests: int):
    latencies: list[float] = []
    errors: list[str] = []
    lock = threading.Lock()
    counter = iter(range(requests + pose_requests))

    def worker() -> None:
        with viewdb.RemoteServer(url, token=token) as remote:
            for i in counter:
                start = time.perf_counter()
                try:
                    if i >= requests:
                        query, matches = poses[i % len(poses)]
                        got, _ = remote.poses(query, [viewdb.Candidate(**c.to_dict()) for c in matches])
                        ok = len(got) == len(matches)
                    else:
                        req, expected = work[i % len(work)]
                        reply, _ = remote.refine(req) if plan == "cs1" else remote.walk(req)
                        ok = reply.results == expected
                    problem = None if ok else f"request {i}: reply differs from the local answer"
                except viewdb.ViewDBError as exc:
                    problem = str(exc)
                with lock:
                    latencies.append((time.perf_counter() - start) * 1e3)
                    if problem:
                        errors.append(problem)

    threads = [threading.Thread(target=worker) for _ in range(clients)]
    start = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    seconds = time.perf_counter() - start
    lat = np.array(latencies)
    return {"requests": len(lat), "seconds": seconds, "throughput": len(lat) / seconds,
            "p50": float(np.percentile(lat, 50)), "p99": float(np.percentile(lat, 99)),
            "errors": errors}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db", nargs="?")
    parser.add_argument("--clients", type=int, default=4)
    parser.add_argument("--requests", type=int, default=1000)
    parser.add_argument("--pose-requests", type=int, default=0)
    parser.add_argument("--plan", choices=("cs1", "cs2"), default="cs1")
    parser.add_argument("--distinct", type=int, default=60, help="distinct queries (cycled)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="viewdb-load-") as tmp:
        folder = Path(tmp)
        if args.db:
            db_path = Path(args.db)
        else:
            print("building a database from sample_models/ ...", flush=True)
            db_path = build(folder)
        client_path = folder / "client.db"
        with viewdb.open(db_path, read_only=True) as db:
            db.export_client(client_path)
            n_objects = len(db.objects())
        print(f"preparing {args.distinct} distinct {args.plan} requests ...", flush=True)
        work, poses = workload(db_path, client_path, args.plan, args.distinct, args.seed)
        token = os.urandom(8).hex()
        print(f"{db_path.name}: {n_objects} objects; {args.clients} concurrent clients, "
              f"{args.requests} /{'refine' if args.plan == 'cs1' else 'walk'} + {args.pose_requests} /pose "
              f"requests per run; {os.cpu_count()} CPUs")
        print(f"{'workers':>7} {'req/s':>8} {'p50 ms':>8} {'p99 ms':>8} {'errors':>6} {'seconds':>8}")
        results = {}
        for workers in (1, 2):
            with ServerProcess(db_path, workers=workers, token=token) as server:
                run(server.url, token, args.plan, work, poses, 2, len(work), 0)  # warm-up
                r = run(server.url, token, args.plan, work, poses, args.clients, args.requests,
                        args.pose_requests)
            results[workers] = r
            print(f"{workers:>7} {r['throughput']:>8.1f} {r['p50']:>8.2f} {r['p99']:>8.2f} "
                  f"{len(r['errors']):>6} {r['seconds']:>8.2f}", flush=True)
            for e in r["errors"][:5]:
                print(f"        error: {e}")
        ratio = results[2]["throughput"] / results[1]["throughput"]
        print(f"throughput 2 workers / 1 worker: {ratio:.2f}x")
        if any(r["errors"] for r in results.values()):
            sys.exit(1)


if __name__ == "__main__":
    main()
