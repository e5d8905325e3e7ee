"""What a large photo costs a box query: the same photos at their size and enlarged.

    python benchmarks/large_photo.py --db CATALOGUE [--scale 6] [--frames 4] [--repeat 3]

A phone takes 12-megapixel photos; the benchmarks' real photos are 640 × 480. Each photo
of a real set (``../shared/real/ycb_video_2frames`` and the first ``--frames`` of
``lmo_dev``) is queried with the boxes of its annotated objects and its intrinsics, default
options, warm (each query repeated ``--repeat`` times in one process, the best kept), once
as it is and once enlarged ``--scale`` times (bicubic; boxes and intrinsics scaled with
it). Printed: the median seconds per object at each size, their ratio, and how many
objects get the same first answer at both sizes (an enlarged photo holds no more detail,
so a query that only reads the object's part of it should answer alike).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np

import viewdb
from support.real import REAL
from viewdb.bench.groundtruth import read_frames


def _query(db: viewdb.ViewDB, rgb: np.ndarray, boxes: list[list[float]], intrinsics, repeat: int
           ) -> tuple[float, list[str | None]]:
    best = float("inf")
    answer: list[str | None] = []
    for _ in range(repeat):
        start = time.perf_counter()
        reply = db.query(rgb, boxes=boxes, intrinsics=intrinsics)
        best = min(best, time.perf_counter() - start)
        answer = [o.results[0].object if o.results else None for o in reply.objects]
    return best / len(boxes), answer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, required=True)
    parser.add_argument("--scale", type=float, default=6.0,
                        help="enlargement (6: 3840 x 2880 from 640 x 480)")
    parser.add_argument("--frames", type=int, default=4, help="LM-O photos to use")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    frames = [*read_frames(REAL / "ycb_video_2frames"), *read_frames(REAL / "lmo_dev")[: args.frames]]
    small_s, large_s, same, total = [], [], 0, 0
    with viewdb.open(args.db, create=False, read_only=True) as db:
        for frame in frames:
            rgb = cv2.cvtColor(cv2.imread(str(frame.photo)), cv2.COLOR_BGR2RGB)
            boxes = [list(map(float, i.box)) for i in frame.instances
                     if min(i.box[2] - i.box[0], i.box[3] - i.box[1]) >= 4]
            k = frame.intrinsics
            s = args.scale
            big = cv2.resize(rgb, None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC)
            big_k = (k[0] * s, k[1] * s, (k[2] + 0.5) * s - 0.5, (k[3] + 0.5) * s - 0.5)
            db.query(rgb, boxes=boxes[:1], intrinsics=k)  # warm: kernels, tiers, meshes
            one, first = _query(db, rgb, boxes, k, args.repeat)
            many, second = _query(db, big, [[v * s for v in b] for b in boxes], big_k, args.repeat)
            small_s.append(one)
            large_s.append(many)
            same += sum(a == b for a, b in zip(first, second, strict=True))
            total += len(boxes)
            print(f"{frame.photo.parent.name} {frame.name}: {one:.2f} s per object at {rgb.shape[1]} x "
                  f"{rgb.shape[0]}, {many:.2f} s at {big.shape[1]} x {big.shape[0]}", flush=True)
    a, b = float(np.median(small_s)), float(np.median(large_s))
    print(f"{len(frames)} photos, {total} objects: {a:.2f} s per object as taken, {b:.2f} s enlarged "
          f"{args.scale:g}x ({b / a:.2f}x); the same first answer for {same} of {total}")


if __name__ == "__main__":
    main()
