"""How well a box or a point prompt cuts an object out of a real photo.

    python benchmarks/prompts.py

On the 7 objects of the two YCB-Video frames (``../shared/real/ycb_video_2frames``, or
``$VIEWDB_SHARED/real/...``), whose label maps give the true visible masks, each way of
cutting an object out of a prompt (:mod:`viewdb.recognition.regions`) is scored by the IoU
of its cut-out with the label map's object (holes filled, as a cut-out's are; a refusal
scores 0), with the CPU time per object:

* boxes from the frames' box files: GrabCut from the box (``box_method="grabcut"``), each
  box alone and all of a frame's boxes together (overlapping claims to the smaller
  object, the default), with the other prompts' boxes painted over (the default) or
  learnt as background (``box_others_unknown``), at crop margins of 10, 20 and 30 %
  (the default), and with more iterations; the border colour model on a crop around the box
  (``box_method="border"``). The boxes as given, and ``--jitter`` copies with each side
  moved by up to ``--pixels``: one GrabCut can flip between keeping and losing a shaded
  face on a pixel's change, so a choice is made on the jittered mean;
* points: the pixel deepest inside each object (farthest from its outline).

This is how ``SegmentationConfig.box_method``, ``box_margin`` and ``box_others_unknown``
were chosen.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from viewdb.config import SegmentationConfig
from viewdb.errors import ImageError
from viewdb.recognition.image import load_image
from viewdb.recognition.regions import Box, Point, Prompts, find_regions, segment_box, segment_point
from viewdb.recognition.segmentation import largest_filled

ROOT = Path(__file__).resolve().parent.parent
YCB = Path(os.environ.get("VIEWDB_SHARED", ROOT.parent / "shared")) / "real" / "ycb_video_2frames"


def _iou(mask: np.ndarray, truth: np.ndarray) -> float:
    return float(np.count_nonzero(mask & truth) / np.count_nonzero(mask | truth))


def _frames() -> list[tuple[object, list[tuple[str, np.ndarray, Box]]]]:
    """Per frame: the photo, and per object its name, true mask and box."""
    gt = json.loads((YCB / "gt.json").read_text())
    out = []
    for frame_id, frame in gt["frames"].items():
        labels = cv2.imread(str(YCB / frame["label"]), cv2.IMREAD_UNCHANGED)
        boxes = {line.split()[0]: Box(*(float(v) for v in line.split()[1:]))
                 for line in (YCB / f"{frame_id}-box.txt").read_text().splitlines() if line.strip()}
        objects = [(o["name"], largest_filled(labels == int(o["class_index"])), boxes[o["name"]])
                   for o in frame["objects"]]
        out.append((load_image(YCB / frame["color"]), objects))
    return out


def _jittered(frames: list, count: int, pixels: float, seed: int = 7) -> list[list]:
    """The frames as given, then ``count`` copies with every box side moved by up to
    ``pixels`` (uniform; a detector's boxes are not exact)."""
    rng = np.random.default_rng(seed)
    out = [frames]
    for _ in range(count):
        out.append([(image, [(name, truth, Box(*(np.array([b.x1, b.y1, b.x2, b.y2])
                                                  + rng.uniform(-pixels, pixels, 4))))
                             for name, truth, b in objects]) for image, objects in frames])
    return out


def _score(name: str, variants: list[list], cut) -> None:  # type: ignore[no-untyped-def]
    """The IoU per object with the boxes as given, and its mean over the jittered boxes."""
    per, seconds, count = [], 0.0, 0
    for frames in variants:
        ious = []
        for image, objects in frames:
            start = time.process_time()
            masks = cut(image, objects)
            seconds += time.process_time() - start
            count += len(objects)
            ious += [_iou(m, truth) for m, (_, truth, _) in zip(masks, objects, strict=True)]
        per.append(ious)
    given, jittered = np.array(per[0]), np.array(per[1:]) if len(per) > 1 else np.array(per)
    print(f"{name:48s} mean IoU {given.mean():.3f} (jittered {jittered.mean():.3f})  min {given.min():.3f} "
          f"({jittered.mean(axis=0).min():.3f})  {seconds / count:.2f} s CPU per object  "
          f"[{' '.join(f'{v:.3f}' for v in given)}]", flush=True)


def _each(segment, cfg: SegmentationConfig):  # type: ignore[no-untyped-def]
    def cut(image, objects):  # type: ignore[no-untyped-def]
        out = []
        for _, truth, box in objects:
            try:
                out.append(segment(image, box, truth, cfg))
            except ImageError:
                out.append(np.zeros_like(truth))
        return out
    return cut


def _together(cfg: SegmentationConfig):  # type: ignore[no-untyped-def]
    def cut(image, objects):  # type: ignore[no-untyped-def]
        return [r.mask for r in find_regions(image, Prompts(tuple(b for _, _, b in objects)), config=cfg)]
    return cut


def _deepest(truth: np.ndarray) -> Point:
    d = cv2.distanceTransform(truth.astype(np.uint8), cv2.DIST_L2, 5)
    y, x = np.unravel_index(int(np.argmax(d)), d.shape)
    return Point(x + 0.5, y + 0.5)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jitter", type=int, default=8, help="jittered copies of the boxes (0: none)")
    parser.add_argument("--pixels", type=float, default=4.0, help="how far each box side moves at most")
    args = parser.parse_args()
    if not (YCB / "gt.json").is_file():
        raise SystemExit(f"prompts: {YCB} not found")
    frames = _jittered(_frames(), args.jitter, args.pixels)
    base = SegmentationConfig()
    box = lambda image, b, truth, cfg: segment_box(image, b, cfg).mask  # noqa: E731
    print(f"{sum(len(o) for _, o in frames[0])} YCB-Video objects; IoU with the label map's object, "
          "per object (gelatin box, mug, foam brick, master chef can, sugar box, potted meat can, "
          "pitcher); in brackets "
          f"the mean over {args.jitter} copies with each box side moved by up to {args.pixels:g} pixels")
    _score("box, GrabCut, each alone", frames, _each(box, base))
    _score("box, GrabCut, together (default)", frames, _together(base))
    _score("box, GrabCut, together, others as background", frames,
           _together(replace(base, box_others_unknown=False)))
    for margin in (0.1, 0.2):
        _score(f"box, GrabCut, together, crop margin {margin:.0%}", frames,
               _together(replace(base, box_margin=margin)))
        _score(f"box, GrabCut, together, others as background, margin {margin:.0%}", frames,
               _together(replace(base, box_margin=margin, box_others_unknown=False)))
    _score("box, GrabCut, together, 10 iterations", frames, _together(replace(base, box_iterations=10)))
    _score("box, border colour model on the crop", frames[:1], _each(box, replace(base, box_method="border")))
    point = lambda image, b, truth, cfg: segment_point(image, _deepest(truth), cfg).mask  # noqa: E731
    _score("point deepest inside, each alone", frames[:1], _each(point, base))


if __name__ == "__main__":
    main()
