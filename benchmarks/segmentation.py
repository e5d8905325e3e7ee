"""Query-image segmentation: intersection over union per method and background type.

    python benchmarks/segmentation.py [--views 3] [--methods border,otsu,grabcut] [--worst 3]
    python benchmarks/segmentation.py --catalogue-photos 1-6 [--photos 40] [--models DIR]
                                      [--methods grabcut+full,grabcut]

Every sample model (``sample_models/``) is rendered from ``--views`` random viewpoints
(seeded), and each render is composited over every background of
``tests/test_query_image.py`` (plain light, plain dark, gradient, mild clutter, and
``clutter_strong``, which is beyond "mild" and only measured): scaled, off-centre,
anti-aliased, with sensor noise.  Each colour method of
:func:`viewdb.recognition.segmentation.segment` cuts the object out and is scored by IoU against the
render's silhouette with its holes filled (a refusal scores 0), and by the RMS
difference between the distance curves of its mask and of the truth (what a query is
searched with; a refusal scores 1).  Prints IoU mean, minimum, 10th percentile and the
share of cases at IoU >= 0.95 and >= 0.90, the curve error's median, 90th percentile and
share below 0.05, the median CPU time per photo and background and the mean over all
(process time: all threads), and the
worst cases (model, azimuth, elevation, seed).  This is how ``SegmentationConfig.default_method`` was
chosen.  About 3 minutes on 2 cores with the defaults.

A method is one of border, otsu, grabcut and auto, optionally with a suffix that changes
the configuration: ``+plain`` (``SegmentationConfig.plain_border`` on) or ``+full``
(GrabCut's colour models started at the working scale, and 4 iterations:
``grabcut_start_scale=1, grabcut_iterations=4``), e.g. ``grabcut+full,grabcut`` compares
the default GrabCut with that costlier one.

With ``--catalogue-photos SEEDS`` (``"1-6"`` or ``"1,3"``) the photos are instead the
synthetic query photos of the realistic protocol (:func:`viewdb.bench.photos.photo_series`,
``--photos`` per seed, the same as ``benchmarks/photo_accuracy.py`` and
``benchmarks/miss_analysis.py`` on a file of the meshes of ``--models``; 256 x 256 px,
perspective, random light and plain background, noise, JPEG), scored against the true
silhouette (holes filled).  Every method segments each photo in turn (their order rotating
from photo to photo) in a process held to one CPU with OpenCV on one thread; printed per
method: IoU with the truth, the curve error, the median wall and CPU time of ``segment()``
per photo and its ratio to the first method's, and the IoU of its masks with the first
method's (mean, minimum, photos below 0.98).  About 1 minute for 240 photos.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
#: The shared data: ``../shared`` beside the checkout, or ``$VIEWDB_SHARED``.
SHARED = Path(os.environ.get("VIEWDB_SHARED", ROOT.parent / "shared"))


def segmenter(method: str) -> Callable[[object], np.ndarray]:
    """``image -> mask`` for a method name with its optional configuration suffix."""
    from viewdb.config import SegmentationConfig
    from viewdb.recognition.segmentation import segment

    name, _, suffix = method.partition("+")
    options = {"": {}, "plain": {"plain_border": True},
               "full": {"grabcut_start_scale": 1.0, "grabcut_iterations": 4}}
    if suffix not in options:
        raise SystemExit(f"unknown method suffix +{suffix} (use +plain or +full)")
    config = SegmentationConfig(**options[suffix])
    return lambda image: segment(image, method=name, config=config).mask


def iou(mask: np.ndarray, truth: np.ndarray) -> float:
    return float(np.count_nonzero(mask & truth) / max(1, np.count_nonzero(mask | truth)))


def curve_error(mask: np.ndarray, true_curve: np.ndarray) -> float:
    """RMS difference of the distance curves (1 for a refusal)."""
    from viewdb.catalogue.features import distance_curve

    if not mask.any():
        return 1.0
    return float(np.sqrt(np.mean((distance_curve(mask, 128) - true_curve) ** 2)))


def composited(args: argparse.Namespace, methods: list[str]) -> None:
    """The sample models over the test backgrounds: IoU, curve error and CPU time per background."""
    from scipy.ndimage import binary_fill_holes

    import viewdb
    from support.samples import sample_files
    from support.scenes import ALL_BACKGROUNDS, make_scene
    from viewdb.catalogue.features import distance_curve
    from viewdb.config import SegmentationConfig
    from viewdb.errors import ImageError
    from viewdb.recognition.image import load_image

    cut = {method: segmenter(method) for method in methods}
    scores: dict[tuple[str, str], list[tuple[float, str]]] = {}
    curve_errors: dict[tuple[str, str], list[float]] = {}
    seconds: dict[str, float] = dict.fromkeys(methods, 0.0)
    times: dict[tuple[str, str], list[float]] = {}
    photos = 0
    for m_index, path in enumerate(sample_files()):
        rng = np.random.default_rng([args.seed, m_index])
        for v_index in range(args.views):
            azimuth, elevation = int(rng.integers(0, 360)), int(rng.integers(-60, 61)) % 360
            view = viewdb.render_model(path, azimuth, elevation, image_size=192)
            for b_index, kind in enumerate(ALL_BACKGROUNDS):
                seed = (args.seed, m_index, v_index, b_index)
                photo, truth = make_scene(view.color, view.mask, kind, np.random.default_rng(seed))
                truth = binary_fill_holes(truth)
                true_curve = distance_curve(truth, 128)
                image = load_image(photo)
                photos += 1
                for method in methods:
                    start = time.process_time()
                    try:
                        mask = cut[method](image)
                    except ImageError:
                        mask = np.zeros_like(truth)
                    spent = time.process_time() - start
                    seconds[method] += spent
                    times.setdefault((method, kind), []).append(spent)
                    curve_errors.setdefault((method, kind), []).append(curve_error(mask, true_curve))
                    label = f"{path.stem} ({azimuth}, {elevation}) seed {seed}"
                    scores.setdefault((method, kind), []).append((iou(mask, truth), label))

    per_background = photos // len(ALL_BACKGROUNDS)
    print(f"{per_background} photos per background ({len(sample_files())} models x {args.views} views), "
          f"240 x 320 pixels; auto default: {SegmentationConfig().default_method}")
    print(f"{'':24} {'IoU':-^34}  {'curve RMS':-^20}  {'CPU ms':-^6}")
    print(f"{'method':8} {'background':15} {'mean':>6} {'min':>6} {'p10':>6} {'>=.95':>6} {'>=.90':>6}"
          f"  {'median':>6} {'p90':>6} {'<.05':>6}  {'median':>6}")
    for method in methods:
        for kind in ALL_BACKGROUNDS:
            v = np.array([s for s, _ in scores[(method, kind)]])
            e = np.array(curve_errors[(method, kind)])
            print(f"{method:8} {kind:15} {v.mean():6.3f} {v.min():6.3f} {np.quantile(v, 0.1):6.3f} "
                  f"{np.mean(v >= 0.95):6.2f} {np.mean(v >= 0.90):6.2f}"
                  f"  {np.median(e):6.3f} {np.quantile(e, 0.9):6.3f} {np.mean(e < 0.05):6.2f}"
                  f"  {1000 * np.median(times[(method, kind)]):6.1f}")
        print(f"{method:8} {'CPU per photo':15} {1000 * seconds[method] / photos:6.1f} ms")
    if args.worst:
        print("\nworst cases")
        for method in methods:
            for kind in ALL_BACKGROUNDS:
                worst = sorted(scores[(method, kind)])[: args.worst]
                print(f"{method:8} {kind:15} " + "; ".join(f"{s:.3f} {label}" for s, label in worst))


def catalogue_photos(args: argparse.Namespace, methods: list[str]) -> None:
    """The realistic protocol's synthetic photos: IoU, curve error, wall and CPU time per photo."""
    import cv2
    from scipy.ndimage import binary_fill_holes

    import viewdb
    from viewdb.bench.photos import decoded_photo, parse_seeds, photo_series, true_silhouette
    from viewdb.catalogue.features import distance_curve
    from viewdb.catalogue.mesh import load_mesh
    from viewdb.errors import ImageError
    from viewdb.recognition.image import load_image

    paths = {p.stem: p for p in viewdb.describe_paths([args.models])}
    if not paths:
        raise SystemExit(f"no meshes in {args.models} (give --models or set VIEWDB_SHARED)")
    names = sorted(paths)  # the catalogue's order: by name
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core ...
    cv2.setNumThreads(1)  # ... and OpenCV on one thread
    cut = {method: segmenter(method) for method in methods}
    meshes: dict[str, object] = {}
    wall: dict[str, list[float]] = {m: [] for m in methods}
    cpu: dict[str, list[float]] = {m: [] for m in methods}
    ious: dict[str, list[float]] = {m: [] for m in methods}
    errors: dict[str, list[float]] = {m: [] for m in methods}
    agree: dict[str, list[float]] = {m: [] for m in methods}
    count = 0
    for seed in parse_seeds(args.catalogue_photos):
        for spec in photo_series(names, seed, args.photos):
            if spec.object not in meshes:
                meshes[spec.object] = load_mesh(paths[spec.object])
            mesh = meshes[spec.object]
            image = load_image(decoded_photo(mesh, spec))
            truth = binary_fill_holes(true_silhouette(mesh, spec))
            true_curve = distance_curve(truth, 128)
            masks: dict[str, np.ndarray] = {}
            for i in range(len(methods)):  # the order rotates from photo to photo
                method = methods[(count + i) % len(methods)]
                start, start_cpu = time.perf_counter(), time.process_time()
                try:
                    masks[method] = cut[method](image)
                except ImageError:
                    masks[method] = np.zeros_like(truth)
                wall[method].append(time.perf_counter() - start)
                cpu[method].append(time.process_time() - start_cpu)
            count += 1
            for method in methods:
                ious[method].append(iou(masks[method], truth))
                errors[method].append(curve_error(masks[method], true_curve))
                agree[method].append(iou(masks[method], masks[methods[0]]))

    print(f"{count} synthetic photos (seeds {args.catalogue_photos}, {args.photos} each, "
          f"{len(names)} meshes of {args.models}), 256 x 256 pixels; one core; load average "
          f"{os.getloadavg()[0]:.1f}")
    print(f"{'':14} {'IoU with the truth':-^27}  {'curve RMS':-^13}  {'segment() ms':-^27}  "
          f"{'IoU with ' + methods[0]:-^20}")
    print(f"{'method':14} {'mean':>6} {'min':>6} {'p10':>6} {'>=.95':>6}  {'median':>6} {'<.05':>6}  "
          f"{'wall':>6} {'ratio':>6} {'CPU':>6} {'ratio':>6}  {'mean':>6} {'min':>6} {'<.98':>6}")
    base_wall, base_cpu = np.median(wall[methods[0]]), np.median(cpu[methods[0]])
    for method in methods:
        v, e, a = np.array(ious[method]), np.array(errors[method]), np.array(agree[method])
        w, c = np.median(wall[method]), np.median(cpu[method])
        print(f"{method:14} {v.mean():6.4f} {v.min():6.3f} {np.quantile(v, 0.1):6.3f} "
              f"{np.mean(v >= 0.95):6.2f}  {np.median(e):6.3f} {np.mean(e < 0.05):6.2f}  "
              f"{1000 * w:6.1f} {w / base_wall:6.2f} "
              f"{1000 * c:6.1f} {c / base_cpu:6.2f}  {a.mean():6.4f} {a.min():6.3f} {np.sum(a < 0.98):6d}")


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--views", type=int, default=3, help="random views per model (default 3)")
    parser.add_argument("--methods", default=None,
                        help="any of border, otsu, grabcut and auto, each optionally with +plain "
                             "(plain_border on) or +full (GrabCut started at the working scale, 4 "
                             "iterations); default "
                             "border,otsu,grabcut (with --catalogue-photos: grabcut+full,grabcut)")
    parser.add_argument("--worst", type=int, default=3, help="worst cases to list per method and background")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--catalogue-photos", metavar="SEEDS", default=None,
                        help="segment the synthetic query photos of these seeds instead (e.g. 1-6)")
    parser.add_argument("--photos", type=int, default=40, help="photos per seed (default 40)")
    parser.add_argument("--models", type=Path, default=SHARED / "models",
                        help="the meshes the photos show (default ../shared/models)")
    args = parser.parse_args()
    if args.catalogue_photos:
        catalogue_photos(args, (args.methods or "grabcut+full,grabcut").split(","))
    else:
        composited(args, (args.methods or "border,otsu,grabcut").split(","))


if __name__ == "__main__":
    main()
