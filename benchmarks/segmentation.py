"""Query-image segmentation: intersection over union per method and background type.

    python benchmarks/segmentation.py [--views 3] [--methods border,otsu,grabcut] [--worst 3]

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
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--views", type=int, default=3, help="random views per model (default 3)")
    parser.add_argument("--methods", default="border,otsu,grabcut",
                        help="any of border, otsu, grabcut, auto, and auto+plain (auto with "
                             "SegmentationConfig.plain_border on)")
    parser.add_argument("--worst", type=int, default=3, help="worst cases to list per method and background")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    sys.path.insert(0, str(ROOT))  # the scene generator lives with the tests
    from scipy.ndimage import binary_fill_holes

    import viewdb
    from tests.conftest import sample_files
    from tests.test_query_image import ALL_BACKGROUNDS, make_scene
    from viewdb.catalogue.features import distance_curve
    from viewdb.config import SegmentationConfig
    from viewdb.errors import ImageError
    from viewdb.recognition.image import load_image
    from viewdb.recognition.segmentation import segment

    methods = args.methods.split(",")
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
                        if method == "auto+plain":  # auto with the plain-background shortcut
                            mask = segment(image, config=SegmentationConfig(plain_border=True)).mask
                        else:
                            mask = segment(image, method=method).mask
                    except ImageError:
                        mask = np.zeros_like(truth)
                    spent = time.process_time() - start
                    seconds[method] += spent
                    times.setdefault((method, kind), []).append(spent)
                    iou = np.count_nonzero(mask & truth) / np.count_nonzero(mask | truth)
                    error = 1.0  # a refusal
                    if mask.any():
                        error = np.sqrt(np.mean((distance_curve(mask, 128) - true_curve) ** 2))
                    curve_errors.setdefault((method, kind), []).append(float(error))
                    label = f"{path.stem} ({azimuth}, {elevation}) seed {seed}"
                    scores.setdefault((method, kind), []).append((float(iou), label))

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


if __name__ == "__main__":
    main()
