"""The key of a tier file on a fresh open: read from its stamp, or computed from every object.

    python benchmarks/tier_stamp.py [--objects 20000] [--runs 30]

A file is built from two sample models; ``--objects`` more object rows (a name, a hash and
a small mesh each, no views: the key reads only the objects' id, name and hash and the
tier's group count) are added by SQL, and an ingest of one more model stamps the tiers'
keys (schema revision 0009). For each tier, the median of ``--runs`` fresh connections'
``tier_key`` is timed with the stamp and with the stamp removed (a file not written since
the revision: the key computed). The two keys differ (they are digests of different
things) but each matches its own tier file. Stops by itself in a minute or two.
"""

from __future__ import annotations

import argparse
import hashlib
import shutil
import sqlite3
import statistics
import tempfile
import time
from pathlib import Path

import viewdb
from support.samples import sample
from viewdb.storage.tier_file import tier_key
from viewdb.storage.tiers import TIERS


def timed_key(path: Path, tier: str, runs: int) -> tuple[float, int]:
    """Median ms of a fresh connection's ``tier_key`` (in its read transaction), and the
    statements it ran."""
    times, statements = [], 0
    for _ in range(runs):
        conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        ran: list[str] = []
        conn.set_trace_callback(ran.append)
        conn.execute("BEGIN")
        start = time.perf_counter()
        tier_key(conn, tier)
        times.append((time.perf_counter() - start) * 1e3)
        conn.execute("ROLLBACK")
        conn.close()
        statements = len(ran) - 2  # but BEGIN and ROLLBACK
    return statistics.median(times), statements


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", type=int, default=20_000)
    parser.add_argument("--runs", type=int, default=30)
    args = parser.parse_args()
    if not (0 <= args.objects <= 10_000_000 and 1 <= args.runs <= 10_000):
        parser.error("--objects must be in [0, 1e7] and --runs in [1, 1e4]")
    with tempfile.TemporaryDirectory(prefix="viewdb-stamp-") as tmp:
        path = Path(tmp) / "many.db"
        with viewdb.open(path, gap=90, image_size=64) as db:
            db.ingest([sample("cone"), sample("pyramid")])
        with sqlite3.connect(path) as conn:
            row = conn.execute("SELECT * FROM objects LIMIT 1").fetchone()
            columns = [r[1] for r in conn.execute("PRAGMA table_info(objects)")]
            rows = []
            for i in range(args.objects):
                values = dict(zip(columns, row, strict=True))
                values.update(id=None, name=f"synthetic-{i:07d}",
                              content_hash=hashlib.sha256(str(i).encode()).hexdigest(), mesh_glb=b"\0" * 2048)
                rows.append(tuple(values.values()))
            conn.executemany(f"INSERT INTO objects VALUES ({', '.join('?' * len(columns))})", rows)
        with viewdb.open(path) as db:  # a write: the generation renewed and the keys stamped
            db.ingest([sample("torus")])
        unstamped = Path(tmp) / "unstamped.db"
        shutil.copy(path, unstamped)
        with sqlite3.connect(unstamped) as conn:
            conn.execute("DELETE FROM tier_stamps")
        print(f"{args.objects + 3:,} objects, median of {args.runs} fresh connections")
        print("| tier | stamped ms | statements | computed ms | statements |")
        print("|---|---|---|---|---|")
        for tier in TIERS:
            a, na = timed_key(path, tier, args.runs)
            b, nb = timed_key(unstamped, tier, args.runs)
            print(f"| {tier} | {a:.3f} | {na} | {b:.3f} | {nb} |")


if __name__ == "__main__":
    main()
