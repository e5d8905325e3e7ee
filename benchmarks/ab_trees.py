"""Whole queries by two source trees of viewdb, alternately, on the same photos: did a change
keep the answers and the time?

    python benchmarks/ab_trees.py DB --base TREE [--new TREE] [--photos 12] [--seed 5]
                                  [--rounds 2] [--no-pose]

``TREE`` is a checkout of viewdb (e.g. ``git worktree add /tmp/base <commit>``); ``--new``
defaults to this checkout. Each round starts one fresh process per tree on the same synthetic photos
(:mod:`viewdb.bench.photos`, ``--seed``); each warms up on the first photo, then the two
answer photo by photo, taking turns to go first, so that a change in the machine's load
falls on both (``pose_top=1``, or ``--no-pose``). Printed per round: both medians, their
ratio and the median of the per-photo ratios, how many photos got the same top object and
the same pose from both, and the load average.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

CHILD = r"""
import json, sys, time
import cv2, numpy as np
import viewdb
from viewdb.bench.photos import draw_photo_spec, encode_jpeg, render_photo

db_path, n, seed, no_pose = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4] == "1"
with viewdb.open(db_path, read_only=True) as db:
    names = sorted(o.name for o in db.objects())
    rng = np.random.default_rng(seed)
    photos = []
    for _ in range(n):
        name = names[int(rng.integers(len(names)))]
        spec = draw_photo_spec(rng, name)
        jpeg = np.frombuffer(encode_jpeg(render_photo(db.mesh(name), spec), spec.jpeg_quality), np.uint8)
        photos.append((name, cv2.cvtColor(cv2.imdecode(jpeg, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)))
    options = {"pose": False} if no_pose else {"pose_top": 1}
    db.query(photos[0][1], k=5, **options)
    print("ready", flush=True)
    for line in sys.stdin:
        name, image = photos[int(line)]
        start = time.perf_counter()
        top = (db.query(image, k=5, **options).results or [None])[0]
        pose = None if top is None or top.pose is None else [round(top.pose.azimuth, 3),
                                                              round(top.pose.elevation, 3)]
        print(json.dumps({"truth": name, "top": None if top is None else top.object, "pose": pose,
                          "ms": (time.perf_counter() - start) * 1e3}), flush=True)
"""


class Tree:
    """One tree's child process, answering one photo at a time."""

    def __init__(self, tree: Path, args: argparse.Namespace):
        env = {**os.environ, "PYTHONPATH": str(tree)}
        self.tree = tree
        self.child = subprocess.Popen(
            [sys.executable, "-c", CHILD, args.db, str(args.photos), str(args.seed), str(int(args.no_pose))],
            env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        if self.child.stdout.readline().strip() != "ready":
            raise SystemExit(f"{tree}: the child process failed (its error is above)")

    def query(self, index: int) -> dict:
        self.child.stdin.write(f"{index}\n")
        self.child.stdin.flush()
        line = self.child.stdout.readline()
        if not line:
            raise SystemExit(f"{self.tree}: the child process died (its error is above)")
        return json.loads(line)

    def close(self) -> None:
        self.child.stdin.close()
        self.child.wait()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("db")
    parser.add_argument("--base", type=Path, required=True, help="the tree compared against")
    parser.add_argument("--new", type=Path, default=Path(__file__).resolve().parents[1])
    parser.add_argument("--photos", type=int, default=12)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--no-pose", action="store_true")
    args = parser.parse_args()
    for r in range(1, args.rounds + 1):
        base, new = Tree(args.base, args), Tree(args.new, args)
        a, b = [], []
        for i in range(args.photos):
            first, second = (base, new) if (i + r) % 2 else (new, base)  # alternate who goes first
            got = {first: first.query(i), second: second.query(i)}
            a.append(got[base])
            b.append(got[new])
        base.close()
        new.close()
        ma, mb = (statistics.median(x["ms"] for x in side) for side in (a, b))
        paired = statistics.median(y["ms"] / x["ms"] for x, y in zip(a, b, strict=True))
        same = sum(x["top"] == y["top"] for x, y in zip(a, b, strict=True))
        same_pose = sum(x["pose"] == y["pose"] for x, y in zip(a, b, strict=True))
        right = [sum(x["top"] == x["truth"] for x in side) for side in (a, b)]
        print(f"round {r}: base {ma:.0f} ms, new {mb:.0f} ms, new/base {mb / ma:.2f} "
              f"(paired median {paired:.2f}); same top object {same}/{len(a)}, same pose "
              f"{same_pose}/{len(a)}; right first: base {right[0]}, new {right[1]}; "
              f"load {os.getloadavg()[0]:.1f}", flush=True)


if __name__ == "__main__":
    main()
