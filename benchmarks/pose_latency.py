"""Where the pose of the top result spends its time, and what rendering nothing saves:
the same photos' top matches posed three ways in one run, each from empty caches.

    python benchmarks/pose_latency.py DB [--seeds 1-6] [--photos 10]
                                         [--textured-seeds 1-4] [--textured-photos 40]

The photos are those of ``benchmarks/query_latency.py`` (``--seeds`` x ``--photos``) and,
with ``--textured-seeds``, the photos of textured asymmetric objects among
``benchmarks/photo_accuracy.py``'s (``--textured-photos`` per seed; their pose is unique,
so its viewing-direction error is meaningful). Each photo is queried once without pose
(``server`` plan, k = 5, default options); its top match, the segmented photo and the
curve at the turn that matched are then posed (:func:`viewdb.pose.matched.pose_matches`,
what a query's pose stage runs) three ways:

* ``renders``: the pruned candidates' SIFT features made from renders when the stored ones
  give no SIFT pose (``MatchedPoseConfig(regenerate="always")``), and every view without an
  appearance record of its own rendered (image twins off): the pose before this change;
* ``twins``: the same, but a symmetric uncoloured object's views take a recorded image
  twin's appearance (:func:`viewdb.catalogue.skimming.image_twins`);
* ``default``: the library's defaults (no pruned candidate rendered, image twins on).

Printed per way and photo set: the median and p95 wall and CPU time of the pose, renders
per pose, the SIFT and shape poses' shares, the median time of its parts (SIFT extraction of
the query, matching, RANSAC and refits, the shape pose, its off-grid refinement, reading
and decoding appearance, renders), and the median viewing-direction error of the poses of
right top matches (the angle between the estimated and the photo's viewing direction).
"""

from __future__ import annotations

import argparse
import functools
import math
import os
import statistics
import time
from collections import defaultdict

import numpy as np
from photo_accuracy import direction, textured  # this folder's: the same photos, the same test

import viewdb
import viewdb.pose.estimate as estimate_module
import viewdb.pose.matched as matched_module
import viewdb.pose.sift_pose as sift_module
from viewdb.bench.photos import decoded_photo, parse_seeds, photo_series, seed_photos
from viewdb.config import MatchedPoseConfig
from viewdb.pose.estimate import PoseConfig
from viewdb.pose.matched import pose_matches
from viewdb.pose.views import QueryView
from viewdb.recognition.pipeline import segment_query
from viewdb.search.plans import Candidate

WAYS = {
    "renders": (MatchedPoseConfig(regenerate="always"), False),
    "twins": (MatchedPoseConfig(regenerate="always"), True),
    "default": (MatchedPoseConfig(), True),
}
#: The pose's parts, timed by wrapping these functions: (label, module, name).
PARTS = (("sift extract", estimate_module, "extract_sift"), ("sift match", sift_module, "_match"),
         ("ransac", sift_module, "_hypothesis"), ("refit", sift_module, "_refine_pooled"),
         ("shape pose", estimate_module, "shape_pose"), ("refine", matched_module, "refine_shape"))
SPENT: dict[str, float] = defaultdict(float)


def timed(label: str, function):
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        start = time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            SPENT[label] += time.perf_counter() - start
    return wrapper


def view_error(pose, spec) -> float:
    cos = direction(pose.azimuth, pose.elevation) @ direction(spec.azimuth, spec.elevation)
    return math.degrees(math.acos(float(np.clip(cos, -1.0, 1.0))))


def photos_of(db, args) -> list[tuple[str, object, np.ndarray]]:
    names = [o.name for o in db.objects()]
    out = [("latency", spec, photo) for spec, photo in seed_photos(db, args.seeds, args.photos)]
    eligible: dict[str, bool] = {}
    for seed in parse_seeds(args.textured_seeds):
        for spec in photo_series(names, seed, args.textured_photos):
            if spec.object not in eligible:
                sym = db.symmetry(spec.object)
                eligible[spec.object] = bool(sym is not None and not sym.generators
                                             and textured(db.mesh(spec.object)))
            if eligible[spec.object]:
                out.append(("textured", spec, decoded_photo(db.mesh(spec.object), spec)))
    return out


def inputs_of(db, photos):
    """Each photo's top match (no pose), segmented photo and curve at the matched turn."""
    samples = db.config.features.curve_samples
    out = []
    for kind, spec, photo in photos:
        result = db.query(photo, k=5, pose=False)
        if not result.results:
            continue
        top = result.results[0]
        shape = segment_query(photo, samples, viewdb.QueryOptions().rotations)
        match = Candidate(top.object, top.distance, top.azimuth, top.elevation, top.mirrored)
        out.append((kind, spec, shape.view, match, shape.by_angle.get(top.inplane)))
    return out


def run_way(path: str, inputs, posing: MatchedPoseConfig, twins: bool) -> list[dict]:
    with viewdb.open(path, read_only=True) as db:
        catalogue = db._catalogue
        catalogue.image_twins = twins
        render, renders = catalogue.render, [0]

        def counted(*args, **kwargs):
            renders[0] += 1
            start = time.perf_counter()
            try:
                return render(*args, **kwargs)
            finally:
                SPENT["rendering"] += time.perf_counter() - start

        catalogue.render = counted
        appearance = catalogue.appearance
        catalogue.appearance = timed("appearance", appearance)
        _, _, segmented, match, curve = inputs[0]
        warm = QueryView(segmented.color, segmented.mask, segmented.ignore)
        pose_matches(catalogue, warm, [match], None, PoseConfig(), [curve], posing=posing)
        rows = []
        for kind, spec, segmented, match, curve in inputs:
            # a fresh query view: what a query derives from the photo (its SIFT, outline,
            # edges) is not carried over from another way
            view = QueryView(segmented.color, segmented.mask, segmented.ignore)
            SPENT.clear()
            renders[0] = 0
            wall, cpu = time.perf_counter(), time.process_time()
            pose, _ = pose_matches(catalogue, view, [match], None, PoseConfig(), [curve], posing=posing)[0]
            wall, cpu = (time.perf_counter() - wall) * 1e3, (time.process_time() - cpu) * 1e3
            right = match.object == spec.object and pose is not None
            rows.append({"kind": kind, "wall": wall, "cpu": cpu, "renders": renders[0],
                         "method": pose.method if pose is not None else None,
                         "error": view_error(pose, spec) if right else math.nan,
                         **{label: ms * 1e3 for label, ms in SPENT.items()}})
        return rows


def report(way: str, kind: str, rows: list[dict]) -> None:
    wall, cpu = [r["wall"] for r in rows], [r["cpu"] for r in rows]
    errors = [r["error"] for r in rows if not math.isnan(r["error"])]
    methods = [r["method"] for r in rows]
    renders = float(np.mean([r["renders"] for r in rows]))
    parts = [label for label, _, _ in PARTS] + ["appearance", "rendering"]
    split = ", ".join(f"{p} {statistics.median(r.get(p, 0.0) for r in rows):.1f}" for p in parts)
    print(f"{way:8s} {kind:9s} n={len(rows):3d}  wall median {statistics.median(wall):6.1f} ms, "
          f"p95 {np.percentile(wall, 95):6.1f}; CPU median {statistics.median(cpu):6.1f}, "
          f"p95 {np.percentile(cpu, 95):6.1f}; renders/pose mean {renders:5.1f}; "
          f"sift {methods.count('sift')}, shape {methods.count('shape')}; "
          f"view error median {statistics.median(errors) if errors else math.nan:5.2f} deg "
          f"(mean {np.mean(errors) if errors else math.nan:5.2f}, {len(errors)} right)\n"
          f"{'':18s} part medians (ms): {split}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("db")
    parser.add_argument("--seeds", default="1-6")
    parser.add_argument("--photos", type=int, default=10, help="photos per seed")
    parser.add_argument("--textured-seeds", default="1-4")
    parser.add_argument("--textured-photos", type=int, default=40)
    args = parser.parse_args()
    for label, module, name in PARTS:
        setattr(module, name, timed(label, getattr(module, name)))
    with viewdb.open(args.db, read_only=True) as db:
        inputs = inputs_of(db, photos_of(db, args))
    print(f"{args.db}: {len(inputs)} photos; load {os.getloadavg()[0]:.1f}", flush=True)
    for way, (posing, twins) in WAYS.items():
        rows = run_way(args.db, inputs, posing, twins)
        for kind in ("latency", "textured"):
            chosen = [r for r in rows if r["kind"] == kind]
            if chosen:
                report(way, kind, chosen)
    print(f"load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
