"""What the stored appearance saves: the colour, verification and pose stages with the
appearance records against rendering every view (the baseline), on the same photos and
the same file in one run, and the shape pose's off-grid step by interpolation against the
render walk.

    python benchmarks/appearance.py DB [--photos 40] [--seed 1] [-k 5]

Each photo is a synthetic photograph of a random object of DB (:mod:`viewdb.bench.photos`,
the generator of ``benchmarks/photo_accuracy.py``: same seed, same photos), segmented
automatically and queried with the default options (``server`` plan, 12 turns, the top
result posed) twice: reading the file's appearance records (``stored``) and ignoring them,
so that every view compared is rendered from the mesh as before revision 0005
(``rendered``). Both start from empty view caches for every photo (a server that kept them
would be faster still). Reported: rank-1 and rank-5 of each way (they agree), the median
of each stage's ``timing_ms`` and the ratio rendered / stored.

The top result's pose, when it is the right object of an asymmetric object (no symmetry
generator, so the pose is unique), is compared with the photo's camera: the angle between
the true and the estimated viewing directions. For shape poses (texture-less views) the
same match is also posed with the off-grid walk that renders (``MatchedPoseConfig(shape_refine=
"walk")``) and without leaving the grid, to compare their errors and times.
"""

from __future__ import annotations

import argparse
import math
import time

import cv2
import numpy as np

import viewdb
from viewdb.bench.photos import draw_photo_spec, encode_jpeg, render_photo
from viewdb.config import MatchedPoseConfig
from viewdb.pose.estimate import PoseConfig
from viewdb.pose.matched import pose_matches
from viewdb.recognition.pipeline import segment_query
from viewdb.search.plans import Candidate

STAGES = ("segment", "server", "colour", "verify", "pose", "total")


def direction(azimuth: float, elevation: float) -> np.ndarray:
    h, v = math.radians(azimuth), math.radians(elevation)
    return np.array([math.sin(h) * math.cos(v), math.sin(v), math.cos(h) * math.cos(v)])


def view_error(pose, spec) -> float:
    cos = float(direction(pose.azimuth, pose.elevation) @ direction(spec.azimuth, spec.elevation))
    return math.degrees(math.acos(np.clip(cos, -1.0, 1.0)))


def forget(db: viewdb.ViewDB) -> None:
    """Empty the file's view caches (renders, regenerated views, appearance records)."""
    catalogue = db._catalogue
    for cache in (catalogue._renders, catalogue._regenerated, *catalogue._derived.values()):
        cache.clear()


def together_of(stages: dict[str, list[float]], rows: list[int]) -> list[float]:
    return [stages["colour"][i] + stages["verify"][i] for i in rows]


def median(values) -> float:
    v = [x for x in values if not math.isnan(x)]
    return float(np.median(v)) if v else math.nan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--photos", type=int, default=40)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("-k", type=int, default=5)
    args = parser.parse_args()
    db = viewdb.open(args.db, read_only=True)
    catalogue = db._catalogue
    names = [o.name for o in db.objects()]
    lacking = sum(1 for o in db.objects() if o.appearances == 0)
    if lacking:
        print(f"note: {lacking} objects have no appearance records; they are rendered either way")
    rng = np.random.default_rng(args.seed)
    ranks: dict[str, list[int]] = {"stored": [], "rendered": []}
    times: dict[str, dict[str, list[float]]] = {w: {s: [] for s in STAGES} for w in ranks}
    poses: list[tuple[str, str, float, float, float, float, float, float]] = []
    asymmetric: list[bool] = []
    renders: dict[str, list[int]] = {"stored": [], "rendered": []}
    count = [0]
    render = catalogue.render

    def counted(*args, **kwargs):  # every render of a view, whatever asks for it
        count[0] += 1
        return render(*args, **kwargs)

    catalogue.render = counted
    samples = db.config.features.curve_samples
    for i in range(args.photos):
        name = names[rng.integers(len(names))]
        spec = draw_photo_spec(rng, name)
        mesh = db.mesh(name)
        jpeg = encode_jpeg(render_photo(mesh, spec), spec.jpeg_quality)
        photo = cv2.cvtColor(cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        line = [f"{i:3d} {name:28s}"]
        results = {}
        for way in ("rendered", "stored"):
            catalogue.stored_appearance = way == "stored"
            forget(db)
            count[0] = 0
            result = db.query(photo, k=args.k, pose_top=1)
            renders[way].append(count[0])
            found = [m.object for m in result.results]
            ranks[way].append(found.index(name) + 1 if name in found else 0)
            for stage in STAGES:
                times[way][stage].append(result.timing_ms.get(stage, 0.0))
            results[way] = result
            line.append(f"{way} {ranks[way][-1] or '-'} colour {result.timing_ms['colour']:.0f} "
                        f"verify {result.timing_ms['verify']:.0f} pose {result.timing_ms['pose']:.0f} ms "
                        f"({renders[way][-1]} renders)")
        catalogue.stored_appearance = True
        top = results["stored"].results[0] if results["stored"].results else None
        sym = db.symmetry(name)
        asymmetric.append(sym is not None and not sym.generators)
        if top is not None and top.object == name and top.pose is not None and sym is not None \
                and not sym.generators:
            error = view_error(top.pose, spec)
            rendered_top = results["rendered"].results[0]
            rendered_error = view_error(rendered_top.pose, spec) if rendered_top.pose else math.nan
            walk = grid = walk_ms = math.nan
            if top.pose.method == "shape":
                shape = segment_query(photo, samples, viewdb.QueryOptions().rotations)
                match = Candidate(top.object, top.distance, top.azimuth, top.elevation, top.mirrored)
                curve = shape.by_angle.get(top.inplane)
                forget(db)
                start = time.perf_counter()
                walked, why = pose_matches(catalogue, shape.view, [match], None, PoseConfig(), [curve],
                                           posing=MatchedPoseConfig(shape_refine="walk"))[0]
                walk_ms = (time.perf_counter() - start) * 1e3
                walk = view_error(walked, spec) if walked is not None else math.nan
                gridded, _ = pose_matches(catalogue, shape.view, [match], None, PoseConfig(), [curve],
                                          posing=MatchedPoseConfig(shape_refine="none"))[0]
                grid = view_error(gridded, spec) if gridded is not None else math.nan
            poses.append((name, top.pose.method, error, rendered_error, walk, grid,
                          results["stored"].timing_ms["pose"], walk_ms))
            line.append(f"pose {top.pose.method} {error:.1f} deg (rendered {rendered_error:.1f}"
                        + (f", walk {walk:.1f}, grid {grid:.1f}" if top.pose.method == "shape" else "") + ")")
        print("  ".join(line), flush=True)

    print(f"\n{args.photos} photos, {len(names)} objects, seed {args.seed}, k = {args.k}, default options "
          f"(server plan, 12 turns, top result posed); view caches emptied for every photo")
    for way in ("stored", "rendered"):
        r = np.array(ranks[way])
        top5 = np.mean((r >= 1) & (r <= 5)) * 100
        print(f"{way:9s} rank-1 {np.mean(r == 1) * 100:.1f}%  rank-5 {top5:.1f}%  "
              + "  ".join(f"{s} {median(times[way][s]):.0f}" for s in STAGES) + " ms (medians)")
    print("ratio rendered / stored (medians): " + "  ".join(
        f"{s} {median(times['rendered'][s]) / max(median(times['stored'][s]), 1e-9):.2f}x"
        for s in ("colour", "verify", "pose", "total")))
    together = [c + v for c, v in zip(times["stored"]["colour"], times["stored"]["verify"], strict=True)]
    print(f"stored: colour + verify median {median(together):.0f} ms; pose of the top result median "
          f"{median(times['stored']['pose']):.0f} ms; renders a query: median "
          f"{median(renders['stored']):.0f}, "
          f"none in {sum(n == 0 for n in renders['stored'])} of {args.photos} (rendered: median "
          f"{median(renders['rendered']):.0f})")
    for label, wanted in (("asymmetric", True), ("symmetric", False)):
        rows = [i for i, a in enumerate(asymmetric) if a == wanted]
        if rows:
            parts = [f"{way} colour + verify {median(together_of(times[way], rows)):.0f} ms, "
                     f"pose {median(times[way]['pose'][i] for i in rows):.0f} ms"
                     for way in ("stored", "rendered")]
            print(f"  photos of {label} objects ({len(rows)}): " + "; ".join(parts))
    for method in ("sift", "shape"):
        rows = [p for p in poses if p[1] == method]
        if not rows:
            continue
        text = (f"pose ({method}, asymmetric objects, top-1 right): {len(rows)} photos, median "
                f"viewing-direction error stored {median(p[2] for p in rows):.1f} deg, "
                f"rendered {median(p[3] for p in rows):.1f} deg")
        if method == "shape":
            text += (f"; render walk {median(p[4] for p in rows):.1f} deg "
                     f"({median(p[7] for p in rows):.0f} ms a pose, vs {median(p[6] for p in rows):.0f} ms "
                     f"the stored query's pose stage), on the grid {median(p[5] for p in rows):.1f} deg")
        print(text)


if __name__ == "__main__":
    main()
