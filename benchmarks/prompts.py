"""How well a box or a point prompt cuts an object out of a real photo.

    python benchmarks/prompts.py

On the 7 objects of the two YCB-Video frames (``../shared/real/ycb_video_2frames``, or
``$VIEWDB_SHARED/real/...``), whose label maps give the true visible masks, each way of
cutting an object out of a prompt (:mod:`viewdb.recognition.regions`) is scored by the IoU
of its cut-out with the label map's object (holes filled, as a cut-out's are; a refusal
scores 0), with the CPU time per object:

* boxes from the frames' box files: GrabCut from the box (``box_method="grabcut"``), each
  box alone and all of a frame's boxes together (overlapping claims to the smaller
  object, the default); the border colour model on a crop around the box
  (``box_method="border"``); GrabCut with a wider crop margin, and with more iterations;
* points: the pixel deepest inside each object (farthest from its outline).

This is how ``SegmentationConfig.box_method`` was chosen.
"""

from __future__ import annotations

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


def _score(name: str, frames: list, cut) -> None:  # type: ignore[no-untyped-def]
    ious, seconds, count = [], 0.0, 0
    for image, objects in frames:
        start = time.process_time()
        masks = cut(image, objects)
        seconds += time.process_time() - start
        count += len(objects)
        ious += [_iou(m, truth) for m, (_, truth, _) in zip(masks, objects, strict=True)]
    print(f"{name:44s} mean IoU {np.mean(ious):.3f}  min {np.min(ious):.3f}  "
          f"{seconds / count:.2f} s CPU per object  [{' '.join(f'{v:.3f}' for v in ious)}]", flush=True)


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
    if not (YCB / "gt.json").is_file():
        raise SystemExit(f"prompts: {YCB} not found")
    frames = _frames()
    base = SegmentationConfig()
    box = lambda image, b, truth, cfg: segment_box(image, b, cfg).mask  # noqa: E731
    print(f"{sum(len(o) for _, o in frames)} YCB-Video objects; IoU with the label map's object, per object "
          "(gelatin box, mug, foam brick, master chef can, sugar box, potted meat can, pitcher)")
    _score("box, GrabCut, each alone", frames, _each(box, base))
    _score("box, GrabCut, together (default)", frames, _together(base))
    _score("box, border colour model on the crop", frames, _each(box, replace(base, box_method="border")))
    _score("box, GrabCut, together, crop margin 25 %", frames, _together(replace(base, box_margin=0.25)))
    _score("box, GrabCut, together, 10 iterations", frames, _together(replace(base, box_iterations=10)))
    point = lambda image, b, truth, cfg: segment_point(image, _deepest(truth), cfg).mask  # noqa: E731
    _score("point deepest inside, each alone", frames, _each(point, base))


if __name__ == "__main__":
    main()
