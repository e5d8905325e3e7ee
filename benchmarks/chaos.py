"""Chaos test of a sharded ``viewdb serve``: steady remote queries while shard actors are killed.

    python benchmarks/chaos.py [--duration 1200] [--kill-every 30] [--baseline 120]
                               [--clients 3] [--shards 3] [--seed 0] [--json out.json]

A full database is built from ``sample_models/`` (30° grid, 90° client grid, 96 px) in a
temporary folder, split into ``--shards`` shards, and its client file exported. This
process starts a private local Ray (2 CPUs); ``viewdb serve --shards DIR --ray ADDRESS``
(the real command, in a child process, on a free loopback port) joins it. ``--clients``
threads then send photo queries through the real remote client
(``client.query(photo, server=RemoteServer(url))``): the ``cs1`` and ``server`` plans,
each with and without pose, on photos of every object rendered off-grid, turned and
scaled. Every answer is compared, field by field, with the single file's answer to the
same query computed locally before the load starts.

The run has two phases: ``--baseline`` seconds with no faults, then ``--duration``
seconds during which a random shard actor is SIGKILLed every ``--kill-every`` seconds
(only when every shard is up). It reports, per phase: queries, wrong answers, partial
answers (fewer results than the single file's), 503s (their share) and any other error,
p50/p95 latency of the answered queries; the time each killed shard took to come back
(from the kill until ``/health`` shows every shard up again); and the resident set of
the server and of each shard actor at the start and at the end. Loopback only; stops by
itself (after baseline + duration + the time to build, about two minutes).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np

import viewdb
from support.samples import sample
from viewdb.bench.photos import composite_photo
from viewdb.errors import ServerError

MODELS = ("marked_cube", "car", "mug", "l_bracket", "chair", "arrow", "bottle", "torus", "table")
TOKEN = "chaos-token"


def build(folder: Path, shards: int) -> tuple[Path, Path, Path]:
    """The full file, its shards and its client file."""
    from viewdb.config import BuildConfig, IndexConfig, RenderConfig
    from viewdb.shards.layout import split_catalogue

    full = folder / "full.db"
    config = BuildConfig(gap=30, render=RenderConfig(image_size=96), index=IndexConfig(client_gap=90))
    with viewdb.open(full, config=config) as db:
        report = db.ingest([sample(m) for m in MODELS], jobs=2)
        assert not report.failed, report.failed
        db.export_client(folder / "client.db")
    split_catalogue(full, shards, folder / "shards")
    return full, folder / "shards", folder / "client.db"


def _key(result: viewdb.QueryResult) -> list[dict]:
    """What must match: every field of every result but timings."""
    return [m.to_dict() for m in result.results]


def workload(full: Path, seed: int) -> list[dict]:
    """The queries (photo, plan, pose) and the single file's answer to each."""
    rng = np.random.default_rng(seed)
    out = []
    with viewdb.open(full, read_only=True) as db:
        for name in MODELS:
            h, v = float(rng.uniform(0, 360)), float(rng.uniform(-40, 60))
            img, _ = composite_photo(db.render(name, h, v), turn=float(rng.uniform(0, 360)),
                                     scale=0.8, background=200)
            for plan in ("cs1", "server"):
                for pose in (False, True):
                    expected = db.query(img, k=3, plan=plan, pose=pose, pose_top=1)
                    out.append({"name": name, "image": img, "plan": plan, "pose": pose,
                                "expected": _key(expected)})
    return out


class Server:
    """``viewdb serve --shards DIR --ray ADDRESS`` in a child process."""

    def __init__(self, shards: Path, ray_address: str) -> None:
        cmd = [sys.executable, "-m", "viewdb_cli.main", "serve", "--shards", str(shards), "--ray",
               ray_address, "--port", "0", "--no-ui", "--token", TOKEN, "--log-level", "critical"]
        self.log = tempfile.TemporaryFile(mode="w+")
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self.log, text=True)
        line = self.proc.stdout.readline()
        found = re.search(r"http://[\d.]+:\d+", line)
        if found is None:
            self.stop()
            self.log.seek(0)
            raise RuntimeError(f"the server did not start: {line!r} {self.log.read()[-2000:]}")
        self.url = found.group(0)

    def health(self) -> dict:
        req = urllib.request.Request(self.url + "/health", headers={"Authorization": f"Bearer {TOKEN}"})
        with urllib.request.urlopen(req, timeout=10) as r:
            return json.loads(r.read())

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def actor_pids(ray) -> list[int]:
    """The pids of the live shard actors of the cluster."""
    from ray._private import state

    return sorted(int(a["Pid"]) for a in state.actors().values()
                  if a["ActorClassName"].endswith("_Host") and a["State"] == "ALIVE")


def rss_mb(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as f:
            return next(int(line.split()[1]) / 1024 for line in f if line.startswith("VmRSS:"))
    except (OSError, StopIteration):
        return None


class Load:
    """``clients`` threads sending the workload's queries until stopped; every outcome
    recorded with its phase."""

    def __init__(self, url: str, client_path: Path, work: list[dict], clients: int, seed: int) -> None:
        self.url, self.client_path, self.work = url, client_path, work
        self.phase = "baseline"
        self.records: list[dict] = []
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.threads = [threading.Thread(target=self._run, args=(seed + i,), daemon=True)
                        for i in range(clients)]

    def start(self) -> None:
        for t in self.threads:
            t.start()

    def join(self) -> None:
        self.stop.set()
        for t in self.threads:
            t.join(600)

    def _run(self, seed: int) -> None:
        rng = random.Random(seed)
        with viewdb.open(self.client_path, read_only=True) as client, \
                viewdb.RemoteServer(self.url, token=TOKEN) as remote:
            while not self.stop.is_set():
                q = self.work[rng.randrange(len(self.work))]
                started_in = self.phase
                start = time.perf_counter()
                try:
                    got = _key(client.query(q["image"], k=3, plan=q["plan"], pose=q["pose"],
                                            pose_top=1, server=remote))
                    exp = q["expected"]
                    if got == exp:
                        outcome = "ok"
                    elif len(got) < len(exp):
                        outcome = "partial"
                    else:
                        outcome = "wrong"
                    detail = "" if outcome == "ok" else json.dumps({"got": got, "expected": exp})[:2000]
                except ServerError as exc:
                    outcome = "503" if "HTTP 503" in str(exc) or "(503)" in str(exc) else "error"
                    detail = str(exc)[:500]
                except Exception as exc:  # noqa: BLE001 - every failure is counted, not raised
                    outcome, detail = "error", f"{type(exc).__name__}: {exc}"[:500]
                ms = (time.perf_counter() - start) * 1e3
                phase = "kills" if "kills" in (started_in, self.phase) else started_in
                with self.lock:
                    self.records.append({"phase": phase, "outcome": outcome, "ms": ms,
                                         "plan": q["plan"], "pose": q["pose"], "detail": detail})
                if outcome == "503":
                    time.sleep(0.2)


def summary(records: list[dict], phase: str) -> dict:
    rs = [r for r in records if r["phase"] == phase]
    count = {k: sum(r["outcome"] == k for r in rs) for k in ("ok", "wrong", "partial", "503", "error")}
    ok_ms = np.array([r["ms"] for r in rs if r["outcome"] == "ok"]) if count["ok"] else np.zeros(1)
    return {"queries": len(rs), **count, "share_503": count["503"] / max(len(rs), 1),
            "p50_ms": float(np.percentile(ok_ms, 50)), "p95_ms": float(np.percentile(ok_ms, 95)),
            "errors": sorted({r["detail"] for r in rs if r["outcome"] in ("error", "wrong", "partial")})[:5]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=1200, help="seconds of load with kills")
    parser.add_argument("--kill-every", type=float, default=30, help="seconds between two kills")
    parser.add_argument("--baseline", type=float, default=120, help="seconds of load without kills first")
    parser.add_argument("--clients", type=int, default=3)
    parser.add_argument("--shards", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, help="write the figures here too")
    args = parser.parse_args()
    if not (args.duration > 0 and args.kill_every > 0 and args.baseline >= 0 and 1 <= args.clients <= 64
            and 1 <= args.shards <= 64):
        parser.error("--duration and --kill-every must be positive, --baseline >= 0, "
                     "--clients and --shards in [1, 64]")
    import ray

    rng = random.Random(args.seed)
    with tempfile.TemporaryDirectory(prefix="viewdb-chaos-") as tmp:
        t0 = time.monotonic()
        print("building the catalogue and its shards ...", flush=True)
        full, shards, client_path = build(Path(tmp), args.shards)
        work = workload(full, args.seed)
        print(f"built in {time.monotonic() - t0:.0f} s: {len(work)} distinct queries", flush=True)
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
        server = None
        try:
            server = Server(shards, ray.get_runtime_context().gcs_address)
            health = server.health()
            start_rss = {"server": rss_mb(health["pid"]),
                         "actors": [rss_mb(p) for p in actor_pids(ray)]}
            load = Load(server.url, client_path, work, args.clients, args.seed)
            load.start()
            time.sleep(args.baseline)
            load.phase = "kills"
            comebacks: list[float | None] = []
            end = time.monotonic() + args.duration
            while time.monotonic() < end:
                next_kill = time.monotonic() + args.kill_every
                pids = actor_pids(ray)
                if pids and all(s["up"] for s in server.health()["shards"]):
                    before = sum(s["recoveries"] for s in server.health()["shards"])
                    os.kill(rng.choice(pids), signal.SIGKILL)
                    killed = time.monotonic()
                    back = None
                    while time.monotonic() < killed + 120:
                        h = server.health()["shards"]
                        if all(s["up"] for s in h) and sum(s["recoveries"] for s in h) > before:
                            back = time.monotonic() - killed
                            break
                        time.sleep(0.05)
                    comebacks.append(back)
                    print(f"kill {len(comebacks)}: back in "
                          f"{'never' if back is None else f'{back:.2f} s'}", flush=True)
                time.sleep(max(0.0, min(next_kill, end) - time.monotonic()))
            load.join()
            health = server.health()
            end_rss = {"server": rss_mb(health["pid"]), "actors": [rss_mb(p) for p in actor_pids(ray)]}
            backs = [b for b in comebacks if b is not None]
            figures = {
                "command": " ".join(["python", "benchmarks/chaos.py", *sys.argv[1:]]),
                "baseline": summary(load.records, "baseline"),
                "kills": summary(load.records, "kills"),
                "killed": len(comebacks), "never_back": sum(b is None for b in comebacks),
                "back_s": {"max": max(backs, default=None), "p50": float(np.median(backs)) if backs else None,
                           "all": [round(b, 2) for b in backs]},
                "rss_mb_start": start_rss, "rss_mb_end": end_rss,
                "shards": server.health()["shards"],
            }
        finally:
            if server is not None:
                server.stop()
            ray.shutdown()
    print(json.dumps(figures, indent=1))
    if args.json:
        args.json.write_text(json.dumps(figures, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
