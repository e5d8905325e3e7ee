"""Would perspective views in the index help? Rank-1 on synthetic photos against indexes of
orthographic and of perspective silhouettes (an experiment for a future schema change).

    python benchmarks/perspective_views.py DB [--gap 20] [--distances 6,4,3] [--photos 40]
                                              [--seeds 1,3]

The stored views of a viewdb file are orthographic, as in the paper; the photos of
``benchmarks/photo_accuracy.py`` are taken through a 30–55° lens from 2.5–7 bounding
radii. For every object of DB, the silhouette of every view of a ``--gap`` grid (all of
them: no skimming, since a perspective view is not the mirror of its opposite) is rendered
orthographically and through a pinhole camera at each of ``--distances`` (bounding radii,
on the view's axis, the bounding sphere just in the frame); each projection, and unions of
them, make an in-memory index (:class:`viewdb.search.knn.TierArrays`, the exact k-NN of
the real tiers). The same photos as ``photo_accuracy.py`` (same seeds), segmented
automatically and turned through 12 in-plane angles, are searched in each, k = 5, by
outline alone (no colour). Prints rank-1 and rank-5 per index.

Rendering takes about 5 s per object for four projections at 20° (about 18 minutes for
the 212 models of ``../shared/models``); the searches a few minutes more.
"""

from __future__ import annotations

import argparse
import math
import time

import cv2
import numpy as np

import viewdb
from viewdb.bench.photos import draw_photo_spec, encode_jpeg, render_photo
from viewdb.camera import camera_pose, grid_views
from viewdb.catalogue.features import distance_curve
from viewdb.catalogue.gl import pyrender_module
from viewdb.catalogue.render import offscreen
from viewdb.errors import FeatureError
from viewdb.recognition.image import load_image
from viewdb.recognition.segmentation import segment
from viewdb.recognition.shapes import rotated_curves
from viewdb.search.knn import TierArrays, knn

SIZE = 256
SAMPLES = 128


def silhouette_curves(db, name: str, gap: int, distances: list[float | None]) -> dict[float | None, list]:
    """Curves of every grid view of ``name`` per projection (None: orthographic)."""
    pyrender = pyrender_module()
    scene = pyrender.Scene()
    scene.add(pyrender.Mesh.from_trimesh(db.mesh(name).geometry, smooth=False))
    pinhole = scene.add(pyrender.PerspectiveCamera(yfov=1.0, aspectRatio=1.0, znear=0.05, zfar=100.0))
    ortho = scene.add(pyrender.OrthographicCamera(xmag=1.0, ymag=1.0, znear=0.05, zfar=100.0))
    flags = pyrender.RenderFlags.DEPTH_ONLY | pyrender.RenderFlags.SKIP_CULL_FACES
    out: dict[float | None, list] = {}
    for d in distances:
        if d is None:
            node, away = ortho, 3.0
        else:
            pinhole.camera.yfov = 2.0 * math.asin(1.0 / d) * 1.05
            node, away = pinhole, d
        scene.main_camera_node = node
        curves = out[d] = []
        for h, v in grid_views(gap):
            scene.set_pose(node, camera_pose(h, v, away))
            depth = np.asarray(offscreen(SIZE).render(scene, flags=flags))
            try:
                curves.append(distance_curve(depth > 0, SAMPLES))
            except FeatureError:
                continue  # no silhouette from there
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--gap", type=int, default=20)
    parser.add_argument("--distances", default="6,4,3", help="pinhole camera distances, bounding radii")
    parser.add_argument("--photos", type=int, default=40)
    parser.add_argument("--seeds", default="1,3")
    args = parser.parse_args()
    pinholes = [float(x) for x in args.distances.split(",")]
    projections: list[float | None] = [None, *pinholes]
    db = viewdb.open(args.db, read_only=True)
    names = [o.name for o in db.objects()]
    curves: dict[float | None, list] = {d: [] for d in projections}
    owners: dict[float | None, list] = {d: [] for d in projections}
    start = time.perf_counter()
    for i, name in enumerate(names):
        for d, found in silhouette_curves(db, name, args.gap, projections).items():
            curves[d] += found
            owners[d] += [i] * len(found)
        if i % 20 == 0:
            print(f"rendered {i + 1}/{len(names)} objects, {time.perf_counter() - start:.0f} s", flush=True)

    def label(ds) -> str:
        return "+".join("ortho" if d is None else f"d{d:g}" for d in ds)

    indexes = {label([d]): [d] for d in projections}
    indexes[label(pinholes)] = pinholes
    indexes[label(projections)] = projections
    tiers = {key: TierArrays(names, np.concatenate([owners[d] for d in ds]),
                             np.concatenate([np.array(curves[d]) for d in ds]))
             for key, ds in indexes.items()}
    print(f"{len(names)} objects, {args.gap}° grid, views per index: "
          + ", ".join(f"{key} {len(t.curves)}" for key, t in tiers.items()))
    for seed in (int(s) for s in args.seeds.split(",")):
        rng = np.random.default_rng(seed)
        ranks: dict[str, list[int]] = {key: [] for key in tiers}
        for _ in range(args.photos):
            name = names[rng.integers(len(names))]
            spec = draw_photo_spec(rng, name)
            jpeg = encode_jpeg(render_photo(db.mesh(name), spec), spec.jpeg_quality)
            photo = cv2.cvtColor(cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR),
                                 cv2.COLOR_BGR2RGB)
            turns = rotated_curves(segment(load_image(photo), None).mask, SAMPLES,
                                   viewdb.QueryOptions().rotations)
            for key, tier in tiers.items():
                best: dict[str, float] = {}
                for _, q in turns:
                    for nb in knn(q, tier, 5, 6)[0]:
                        best[nb.object] = min(best.get(nb.object, math.inf), nb.distance)
                top = sorted(best, key=lambda o: (best[o], o))[:5]
                ranks[key].append(top.index(name) + 1 if name in top else 0)
        for key, r in ranks.items():
            a = np.array(r)
            print(f"seed {seed}  {key:24s} rank-1 {np.mean(a == 1) * 100:5.1f} %  "
                  f"rank-5 {np.mean(a >= 1) * 100:5.1f} %", flush=True)


if __name__ == "__main__":
    main()
