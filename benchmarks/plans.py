"""The three plans side by side: accuracy, agreement with the exact answer, time, bytes.

    python benchmarks/plans.py DB [--client CLIENT_DB] [--queries 100] [--k 5] [--seed 0]

Queries are silhouettes of random objects rendered at random off-grid angles (upright; the
in-plane turns of a photo query only repeat the same search), so the right object is
known. For each plan: top-1 and top-k accuracy (the rendered object is first / among the
k), agreement of the top-k with the ``server`` answer, client and server milliseconds
(medians) and the bytes a client would send and receive. Without ``--client`` the client
half runs on the db's own sparse tier; the client file's size is reported when given.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import viewdb
from viewdb.errors import FeatureError
from viewdb.features import distance_curve


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--client")
    parser.add_argument("--queries", type=int, default=100)
    parser.add_argument("--k", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with viewdb.open(args.db, create=False) as db:
        client = viewdb.open(args.client, create=False) if args.client else None
        names = [o.name for o in db.objects()]
        rng = np.random.default_rng(args.seed)
        queries = []
        while len(queries) < args.queries:
            name = names[rng.integers(len(names))]
            h, v = rng.uniform(0, 360, 2)
            try:
                queries.append((name, distance_curve(db.render(name, h, v).mask, 128)))
            except FeatureError:
                continue
        db.recognise(queries[0][1], 1)  # warm up
        info = db.info()
        side = client or db
        print(f"{len(names)} objects; full tier {info.tiers['full']['views']} views at "
              f"{db.config.gap:g}°; client tier {side.info().tiers['sparse']['views']} views at "
              f"{side.config.client_gap:g}°")
        if client is not None:
            size = client.info().file_bytes
            print(f"client file {size / 1e6:.2f} MB = {size / info.file_bytes:.2%} of the full "
                  f"db ({info.file_bytes / 1e6:.1f} MB)")
        exact = {}
        for plan in ("server", "cs1", "cs2"):
            top1 = topk = agree = 0
            client_ms, server_ms, sent, received, wall = [], [], [], [], []
            for i, (name, q) in enumerate(queries):
                t = time.perf_counter()
                found = db.recognise(q, args.k, plan=plan, client=client)
                wall.append((time.perf_counter() - t) * 1e3)
                objects = [c.object for c in found.results]
                if plan == "server":
                    exact[i] = objects
                top1 += bool(objects) and objects[0] == name
                topk += name in objects
                agree += objects == exact[i]
                client_ms.append(found.client_ms)
                server_ms.append(found.server_ms)
                sent.append(found.bytes_sent)
                received.append(found.bytes_received)
            n = len(queries)
            print(f"{plan:6s}: top-1 {top1 / n:.1%}, top-{args.k} {topk / n:.1%}, same top-{args.k} as "
                  f"server {agree / n:.1%}; client {np.median(client_ms):.1f} ms, server "
                  f"{np.median(server_ms):.1f} ms, total {np.median(wall):.1f} ms (medians); "
                  f"sent {np.mean(sent):.0f} B, received {np.mean(received):.0f} B per query")
        if client is not None:
            client.close()


if __name__ == "__main__":
    main()
