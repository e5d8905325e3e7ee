"""Photos of several objects: cut each out from a prompt, or find every one.

A prompt says where one object is: a :class:`Box` (``x1,y1,x2,y2``, as a detector gives
it) or a :class:`Point` (``x,y``, as a tap on a screen gives it), in the photo's pixels
(x right, y down; the top-left pixel covers ``[0, 1) x [0, 1)``). :func:`find_regions`
turns the prompts, or ``every`` object, or every label of a label map, into one
:class:`Region` per object. Every tunable named below is a field of
:class:`~viewdb.config.SegmentationConfig`.

* **box**: GrabCut initialised from the box (``box_method="grabcut"``): pixels outside
  the box are background, pixels inside probably object; it runs on a crop reaching
  ``box_margin`` of the box's longer side beyond it (at least ``box_min_margin``
  pixels), scaled to at most ``box_work_side`` pixels, for ``box_iterations``
  iterations. When several objects are prompted, the other prompts' boxes, where they
  reach into the crop outside this box, are painted over from their surroundings
  (``box_others_unknown``): the object behind or beside is not background to be learnt
  (a red foam brick in front of a red mug kept its shaded face only so). A box that
  holds this one whole (a book under a mug) is not painted over, nor any when that
  would leave less than a tenth of the crop's background. The
  alternative ``box_method="border"`` cuts the crop's object out with the colour model
  of its border (:func:`~viewdb.recognition.segmentation.segment`'s way), then keeps
  what lies in the box. ``python benchmarks/prompts.py`` measures both on the YCB-Video
  frames against their label maps: GrabCut from the box, mean IoU 0.93; the border
  model fails in clutter (the crop's border crosses other objects). A box is taken to be
  drawn tight around its object: when the colour cut leaves more than
  ``box_texture_gap`` of the box's width or height between the object and a side, the
  box is cut again on :func:`texture_image` (a white printed face on a white table), and
  that cut is kept if it reaches the sides more nearly. In clutter GrabCut can give the
  whole box to the background: a cut that still fails (covers less than
  ``box_min_cover`` of the box, or stops short of a side) is made again with a centred
  ellipse of ``box_core`` of the box surely object. A box is never refused for its
  object's size in the photo; a box whose colours hardly vary (``box_min_spread``) holds
  no object. The region's curve
  is that of the cut-out with its holes filled; its pose is fitted to the cut-out with
  the holes the cut left in it (:attr:`Region.pose_mask`: the background seen through
  a handle, which the mesh's silhouette shows too).
* **point**: a square of ``point_start`` of the photo's shorter side around the point is
  cut as a box (crop margin ``point_margin``); while the object reaches a side of the
  square that is not the photo's edge, that side moves out by ``point_growth`` of the
  square's side (at most ``point_steps`` times). The object is the region that holds
  the point (or the nearest within ``point_reach`` of the square's side).
* **every object** (``every``): the pixels that stand out from the image border's colour
  model (:func:`~viewdb.recognition.segmentation.colour_foreground`), split into
  8-connected regions; the largest ``max_objects`` that are large enough
  (``min_object_fraction``, ``min_object_pixels``) are each refined by GrabCut
  (:func:`~viewdb.recognition.segmentation.grabcut_from`). Objects that touch are one
  region: the background must show between them. A photo where nothing stands out has
  no region: asking for every object is answered with none, not refused.
* **label map** with ``every``: one region per label present.

Where the objects of several prompts overlap, a pixel claimed by two goes to the one
whose mask is smaller (an object in front of another is usually seen whole, the one
behind only in part), and each region knows the pixels of the others
(:attr:`Region.others`): what may hide it, for the completed outline and the pose.

A prompt outside the photo, a box narrower or lower than ``min_box_side`` pixels, more
than ``max_prompts`` prompts, or a prompt (a box, a point) that finds no object raise
:class:`~viewdb.errors.ImageError`, one line naming the photo, the prompt and the
problem.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..config import SegmentationConfig
from ..errors import ImageError, QueryError
from .image import LoadedImage
from .segmentation import (
    Segmentation,
    check_object,
    colour_foreground,
    grabcut_from,
    grabcut_labels,
    label_mask,
    largest_filled,
    read_label_map,
    segment,
)

__all__ = ["Box", "Point", "Prompts", "Region", "find_regions", "parse_box", "parse_point", "surround_spread"]

_NUMBER = r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*"


@dataclass(frozen=True)
class Box:
    """A box prompt: ``x1 < x2``, ``y1 < y2`` in pixels (the pixel ``(i, j)`` covers
    ``[i, i + 1) x [j, j + 1)``)."""

    x1: float
    y1: float
    x2: float
    y2: float

    def __str__(self) -> str:
        return f"box {self.x1:g},{self.y1:g},{self.x2:g},{self.y2:g}"

    def to_dict(self) -> dict[str, Any]:
        return {"box": [self.x1, self.y1, self.x2, self.y2]}


@dataclass(frozen=True)
class Point:
    """A point prompt: a pixel position on the object."""

    x: float
    y: float

    def __str__(self) -> str:
        return f"point {self.x:g},{self.y:g}"

    def to_dict(self) -> dict[str, Any]:
        return {"point": [self.x, self.y]}


Prompt = Box | Point


def _numbers(text: str, count: int, what: str) -> list[float]:
    match = re.fullmatch(",".join([_NUMBER] * count), text)
    if match is None:
        raise QueryError(f"{what} must be {count} numbers separated by commas, got {text!r}")
    values = [float(v) for v in match.groups()]
    if not all(math.isfinite(v) for v in values):
        raise QueryError(f"{what} must be finite numbers, got {text!r}")
    return values


def parse_box(value: str | Sequence[float] | Box) -> Box:
    """A box from ``"x1,y1,x2,y2"``, four numbers or a :class:`Box`."""
    if isinstance(value, Box):
        return value
    if isinstance(value, str):
        return Box(*_numbers(value, 4, "a box"))
    values = _sequence(value, 4, "a box (x1, y1, x2, y2)")
    return Box(*values)


def parse_point(value: str | Sequence[float] | Point) -> Point:
    """A point from ``"x,y"``, two numbers or a :class:`Point`."""
    if isinstance(value, Point):
        return value
    if isinstance(value, str):
        return Point(*_numbers(value, 2, "a point"))
    return Point(*_sequence(value, 2, "a point (x, y)"))


def _sequence(value: Any, count: int, what: str) -> list[float]:
    try:
        values = [float(v) for v in value]
    except (TypeError, ValueError):
        raise QueryError(f"{what} must be {count} numbers, got {value!r}") from None
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise QueryError(f"{what} must be {count} finite numbers, got {value!r}")
    return values


@dataclass(frozen=True)
class Prompts:
    """What to cut out of a photo of several objects: one object per box and per point,
    or ``every`` object (up to ``max_objects``; with a label map, every label)."""

    boxes: tuple[Box, ...] = ()
    points: tuple[Point, ...] = ()
    every: bool = False
    #: With ``every``: at most this many objects, the largest (None: the configured default).
    max_objects: int | None = None

    @classmethod
    def of(cls, boxes: Sequence[Any] | None = None, points: Sequence[Any] | None = None,
           every: bool = False, max_objects: int | None = None) -> Prompts | None:
        """The prompts of a query, parsed (None when it has none: a single-object query)."""
        if isinstance(boxes, (str, Box)) or isinstance(points, (str, Point)):
            raise QueryError("boxes and points are lists: pass [box] for one box, [point] for one point")
        parsed = cls(tuple(parse_box(b) for b in boxes or ()), tuple(parse_point(p) for p in points or ()),
                     bool(every), max_objects)
        if max_objects is not None and (isinstance(max_objects, bool) or max_objects < 1):
            raise QueryError(f"max_objects must be at least 1, got {max_objects}")
        if parsed.every and (parsed.boxes or parsed.points):
            raise QueryError("give prompts (boxes, points) or ask for every object, not both")
        return parsed if parsed.every or parsed.boxes or parsed.points else None

    @property
    def prompts(self) -> list[Prompt]:
        return [*self.boxes, *self.points]


@dataclass(frozen=True, eq=False)
class Region:
    """One object of a photo of several."""

    segmentation: Segmentation
    #: What it was cut from: a :class:`Box`, a :class:`Point`, or None (every object).
    prompt: Box | Point | None = None
    #: Its label, when cut from a label map.
    label: int | None = None
    #: bool (H, W): the other objects' pixels (what may hide this one), or None.
    others: NDArray[np.bool_] | None = field(default=None, repr=False)
    #: The pixels the pose is fitted to (a label's or a box's cut-out keeps its holes);
    #: None: the segmentation's.
    pose_mask: NDArray[np.bool_] | None = field(default=None, repr=False)

    @property
    def mask(self) -> NDArray[np.bool_]:
        return self.segmentation.mask

    @property
    def box(self) -> tuple[int, int, int, int]:
        """The object's bounding box ``(x1, y1, x2, y2)``, ``x2``/``y2`` exclusive."""
        ys, xs = np.nonzero(self.mask)
        return int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1

    @property
    def area(self) -> int:
        """The object's pixels."""
        return int(np.count_nonzero(self.mask))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"box": list(self.box), "area": self.area}
        if self.prompt is not None:
            out["prompt"] = self.prompt.to_dict()
        if self.label is not None:
            out["label"] = self.label
        return out


# ---------------------------------------------------------------------- checks
def check_prompts(image: LoadedImage, prompts: Prompts, cfg: SegmentationConfig) -> None:
    """Refuse prompts outside the photo, degenerate boxes and too many prompts. A box that
    reaches past the photo's edge (an object the frame cuts, a tracker's box) is cut
    where the photo ends; only its part inside must be wide and high enough."""
    w, h = image.width, image.height
    name = image.path
    if len(prompts.prompts) > cfg.max_prompts:
        raise ImageError(f"{len(prompts.prompts)} prompts: at most {cfg.max_prompts} in one query", name)
    for box in prompts.boxes:
        if not (box.x1 < box.x2 and box.y1 < box.y2):
            raise ImageError(f"{box} is degenerate: need x1 < x2 and y1 < y2", name)
        inside_w = min(box.x2, w) - max(box.x1, 0)
        inside_h = min(box.y2, h) - max(box.y1, 0)
        if inside_w <= 0 or inside_h <= 0:
            raise ImageError(f"{box} lies outside the {w}x{h} image (x in [0, {w}], y in [0, {h}])", name)
        if min(inside_w, inside_h) < cfg.min_box_side:
            inside = "" if (inside_w, inside_h) == (box.x2 - box.x1, box.y2 - box.y1) else " inside the image"
            raise ImageError(f"{box} is degenerate: {inside_w:g}x{inside_h:g} pixels{inside}, "
                             f"at least {cfg.min_box_side:g} needed on each side", name)
    for point in prompts.points:
        if not (0 <= point.x < w and 0 <= point.y < h):
            raise ImageError(f"{point} lies outside the {w}x{h} image (x in [0, {w}), y in [0, {h}))",
                             name)


# ---------------------------------------------------------------------- one box
def _box_pixels(box: Box, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """The pixels a box covers at least half of: ``(x1, y1, x2, y2)``, end exclusive."""
    h, w = shape
    x1, y1 = min(w - 1, max(0, math.floor(box.x1 + 0.5))), min(h - 1, max(0, math.floor(box.y1 + 0.5)))
    x2, y2 = max(x1 + 1, min(w, math.floor(box.x2 + 0.5))), max(y1 + 1, min(h, math.floor(box.y2 + 0.5)))
    return x1, y1, x2, y2


def _grown(box: tuple[int, int, int, int], margin: int, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """``box`` grown by ``margin`` pixels on every side, clipped to a photo of ``shape``."""
    x1, y1, x2, y2 = box
    h, w = shape
    return max(0, x1 - margin), max(0, y1 - margin), min(w, x2 + margin), min(h, y2 + margin)


def _lab_spread(lab: NDArray[Any]) -> float:
    """The root of the trace of the covariance of Lab colours ``(n, 3)``; 0 for fewer than 2."""
    if len(lab) < 2:
        return 0.0
    return float(np.sqrt(max(0.0, float(np.trace(np.cov(np.asarray(lab).T))))))


def _grabcut_box(rgb: NDArray[np.uint8], box: Box, cfg: SegmentationConfig,
                 seed: tuple[int, int] | None = None, others: Sequence[Box] = (),
                 margin: float | None = None, texture: bool = False, core: float = 0.0) -> NDArray[np.bool_]:
    """GrabCut from a box: outside background, inside probably object (module doc), and
    a disc around ``seed`` (x, y) surely object; the pixels of the ``others`` boxes
    outside it painted over from their surroundings (``box_others_unknown``); the object
    pixels inside the box, at the photo's size; ``margin``: the crop's (default
    ``box_margin``); ``texture``: cut on :func:`texture_image` of the crop, not its
    colours; ``core``: a centred ellipse spanning this share of the box's width and
    height surely object too (``box_core``)."""
    h, w = rgb.shape[:2]
    x1, y1, x2, y2 = _box_pixels(box, (h, w))
    share = cfg.box_margin if margin is None else margin
    margin = max(cfg.box_min_margin, round(share * max(x2 - x1, y2 - y1)))
    cx1, cy1, cx2, cy2 = _grown((x1, y1, x2, y2), margin, (h, w))
    crop = rgb[cy1:cy2, cx1:cx2]
    init: NDArray[np.uint8] = np.full(crop.shape[:2], cv2.GC_BGD, np.uint8)
    init[y1 - cy1:y2 - cy1, x1 - cx1:x2 - cx1] = cv2.GC_PR_FGD
    if seed is not None:
        radius = max(2, round(cfg.point_seed * min(x2 - x1, y2 - y1)))
        cv2.circle(init, (seed[0] - cx1, seed[1] - cy1), radius, cv2.GC_FGD, -1)
    if core > 0:
        axes = (max(1, round(core * (x2 - x1) / 2)), max(1, round(core * (y2 - y1) / 2)))
        cv2.ellipse(init, (round((x1 + x2 - 1) / 2) - cx1, round((y1 + y2 - 1) / 2) - cy1), axes, 0, 0, 360,
                    cv2.GC_FGD, -1)
    unknown = None
    if cfg.box_others_unknown:
        unknown = _others_outside(others, (x1, y1, x2, y2), (h, w), (cx1, cy1, cx2, cy2), init)
    scale = min(1.0, cfg.box_work_side / max(crop.shape[:2]))
    if scale < 1.0:
        size = (max(1, round(crop.shape[1] * scale)), max(1, round(crop.shape[0] * scale)))
        crop = np.asarray(cv2.resize(crop, size, interpolation=cv2.INTER_AREA), np.uint8)
        init = np.asarray(cv2.resize(init, size, interpolation=cv2.INTER_NEAREST), np.uint8)
        if unknown is not None:
            unknown = np.asarray(cv2.resize(unknown, size, interpolation=cv2.INTER_NEAREST), np.uint8)
    out = np.zeros((h, w), dtype=bool)
    if not (init == cv2.GC_BGD).any():  # the box is the whole photo: nothing to learn background from
        out[y1:y2, x1:x2] = True
        return out
    bgr = np.ascontiguousarray(crop[:, :, ::-1])
    if unknown is not None and unknown.any():
        bgr = np.asarray(cv2.inpaint(bgr, unknown, 3, cv2.INPAINT_TELEA), np.uint8)
    if texture:
        bgr = texture_image(bgr)
    try:
        cv2.setRNGSeed(0x5EED)  # GrabCut's GMM start uses OpenCV's RNG: make it repeatable
        grabcut_labels(bgr, init, (np.zeros((1, 65)), np.zeros((1, 65))), cfg.box_iterations,
                       cv2.GC_INIT_WITH_MASK)
    except cv2.error:
        return out
    found = ((init == cv2.GC_FGD) | (init == cv2.GC_PR_FGD)).astype(np.uint8) * 255
    if scale < 1.0:
        found = cv2.resize(found, (cx2 - cx1, cy2 - cy1), interpolation=cv2.INTER_LINEAR)
    out[cy1:cy2, cx1:cx2] = found > 127
    inside = np.zeros((h, w), dtype=bool)
    inside[y1:y2, x1:x2] = True
    return out & inside


def texture_image(bgr: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """A picture of texture to cut where colour does not tell object from background:
    per pixel its grey level, its local contrast (standard deviation over 15 × 15 pixels)
    and its edge energy (gradient magnitude blurred over about 8 pixels), each scaled to
    0–255 by its 99th percentile in the picture. The scales span the gaps between the
    lines of print on a label (the ViSP tea box: 9 × 9 and 4 left the blank margin of its
    white face out, a notch in a box's outline)."""
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    mean = cv2.blur(grey, (15, 15))
    contrast = np.sqrt(np.maximum(cv2.blur(grey * grey, (15, 15)) - mean * mean, 0.0))
    gradient = np.hypot(cv2.Sobel(grey, cv2.CV_32F, 1, 0), cv2.Sobel(grey, cv2.CV_32F, 0, 1))
    energy = np.asarray(cv2.GaussianBlur(gradient, (0, 0), 8.0), np.float32)

    def byte(a: NDArray[np.float32]) -> NDArray[np.uint8]:
        return np.clip(a * (255.0 / (float(np.percentile(a, 99)) + 1e-6)), 0, 255).astype(np.uint8)

    return np.ascontiguousarray(np.dstack([grey.astype(np.uint8), byte(contrast), byte(energy)]))


def box_gap(mask: NDArray[np.bool_], box: tuple[int, int, int, int]) -> float:
    """The widest gap between a non-empty ``mask`` and a side of ``box`` (its pixels,
    :func:`_box_pixels`), as a share of the box's width (left, right) or height (top,
    bottom)."""
    x1, y1, x2, y2 = box
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    w, h = x2 - x1, y2 - y1
    return max((cols[0] - x1) / w, (x2 - 1 - cols[-1]) / w, (rows[0] - y1) / h, (y2 - 1 - rows[-1]) / h)


def _others_outside(others: Sequence[Box], box: tuple[int, int, int, int], shape: tuple[int, int],
                    crop: tuple[int, int, int, int], init: NDArray[np.uint8]) -> NDArray[np.uint8] | None:
    """The crop's background pixels (``init``) that lie in one of the ``others`` boxes,
    as an inpainting mask (1: unknown); None when there are none, or when they would
    leave less than a tenth of the background to paint from and learn. A box that
    holds ``box`` (its pixels, :func:`_box_pixels`) whole is left out: the object it
    prompts is what this one stands on or in front of, its colours this one's background."""
    if not others:
        return None
    cx1, cy1, cx2, cy2 = crop
    x1, y1, x2, y2 = box
    unknown = np.zeros(init.shape, dtype=np.uint8)
    for other in others:
        ox1, oy1, ox2, oy2 = _box_pixels(other, shape)
        if ox1 <= x1 and oy1 <= y1 and ox2 >= x2 and oy2 >= y2:
            continue
        unknown[max(0, oy1 - cy1):max(0, oy2 - cy1), max(0, ox1 - cx1):max(0, ox2 - cx1)] = 1
    background = init == cv2.GC_BGD
    unknown[~background] = 0
    if not unknown.any() or np.count_nonzero(unknown) > 0.9 * np.count_nonzero(background):
        return None
    return unknown


def _border_box(rgb: NDArray[np.uint8], box: Box, cfg: SegmentationConfig) -> NDArray[np.bool_]:
    """The colour model of the crop's border (the automatic segmentation's) on a crop
    around the box; the object pixels inside the box."""
    h, w = rgb.shape[:2]
    x1, y1, x2, y2 = _box_pixels(box, (h, w))
    margin = max(cfg.box_min_margin, round(cfg.box_margin * max(x2 - x1, y2 - y1)))
    cx1, cy1, cx2, cy2 = _grown((x1, y1, x2, y2), margin, (h, w))
    crop = np.ascontiguousarray(rgb[cy1:cy2, cx1:cx2])
    fg = colour_foreground(crop, "grabcut", cfg)
    inside = np.zeros(fg.found.shape, dtype=bool)
    s = fg.scale
    inside[round((y1 - cy1) * s):round((y2 - cy1) * s), round((x1 - cx1) * s):round((x2 - cx1) * s)] = True
    found, _ = grabcut_from(fg, largest_filled(fg.found & inside), cfg)
    out = np.zeros((h, w), dtype=bool)
    out[cy1:cy2, cx1:cx2] = fg.full_size(found, crop.shape)
    out[:, :x1] = out[:, x2:] = False
    out[:y1] = out[y2:] = False
    return out


def segment_box(image: LoadedImage, box: Box, cfg: SegmentationConfig, others: Sequence[Box] = ()
                ) -> Segmentation:
    """The object in a box (module doc): its largest region, holes filled; ``others``:
    the boxes of the other objects prompted in the same photo."""
    return _cut_box(image, box, cfg, others)[0]


def _cut_box(image: LoadedImage, box: Box, cfg: SegmentationConfig, others: Sequence[Box] = ()
             ) -> tuple[Segmentation, NDArray[np.bool_]]:
    """:func:`segment_box`, and the same region with the holes the cut left in it (the
    background seen through a handle), which the pose is fitted to. A box whose colours
    hardly vary (``box_min_spread``) holds no object."""
    spread = colour_spread(image.rgb, _box_pixels(box, image.rgb.shape[:2]))
    if spread < cfg.box_min_spread:
        raise ImageError(f"{box}: no object found: the box is uniform (colour spread {spread:.1f}, "
                         f"an object needs {cfg.box_min_spread:g})", image.path)
    if cfg.box_method == "grabcut":
        raw, whole = _tight_cut(image, box, cfg, others)
    else:
        raw = _border_box(image.rgb, box, cfg)
        whole = largest_filled(raw)
    seg = _checked(whole, "box", box, image, cfg)
    return seg, seg.mask & raw


def _tight_cut(image: LoadedImage, box: Box, cfg: SegmentationConfig, others: Sequence[Box]
               ) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """GrabCut's cut of a box and its largest region filled: on colour, or on texture when
    the colour cut stops more than ``box_texture_gap`` short of a side of the box and the
    texture cut comes nearer; when the cut kept still fails (:func:`_failed`), cut again
    with the box's middle surely object (``box_core``; module doc)."""
    raw = _grabcut_box(image.rgb, box, cfg, others=others)
    whole = largest_filled(raw)
    pixels = _box_pixels(box, image.rgb.shape[:2])
    if cfg.box_texture_gap < 1.0:
        gap = box_gap(whole, pixels) if whole.any() else 1.0
        if gap > cfg.box_texture_gap:
            raw_texture = _grabcut_box(image.rgb, box, cfg, others=others, texture=True)
            whole_texture = largest_filled(raw_texture)
            if whole_texture.any() and box_gap(whole_texture, pixels) < gap:
                raw, whole = raw_texture, whole_texture
    if cfg.box_core > 0 and _failed(whole, pixels, cfg):
        raw = _grabcut_box(image.rgb, box, cfg, others=others, core=cfg.box_core)
        whole = largest_filled(raw)
    return raw, whole


def _failed(whole: NDArray[np.bool_], box: tuple[int, int, int, int], cfg: SegmentationConfig) -> bool:
    """Whether a box's cut failed: it covers less than ``box_min_cover`` of the box, or
    stops more than ``box_texture_gap`` short of one of its sides."""
    x1, y1, x2, y2 = box
    area = int(np.count_nonzero(whole))
    return (area == 0 or area < cfg.box_min_cover * (x2 - x1) * (y2 - y1)
            or box_gap(whole, box) > cfg.box_texture_gap)


def colour_spread(rgb: NDArray[np.uint8], box: tuple[int, int, int, int]) -> float:
    """The spread of a box's colours (its pixels, :func:`_box_pixels`): the root of the
    trace of their CIE Lab covariance after a blur of one pixel (``box_min_spread``)."""
    x1, y1, x2, y2 = box
    h, w = rgb.shape[:2]
    top, left = max(0, y1 - 3), max(0, x1 - 3)  # a margin for the blur
    crop = rgb[top:min(h, y2 + 3), left:min(w, x2 + 3)]
    lab = cv2.GaussianBlur(cv2.cvtColor(np.ascontiguousarray(crop), cv2.COLOR_RGB2LAB).astype(np.float32),
                           (0, 0), 1.0)
    return _lab_spread(lab[y1 - top:y2 - top, x1 - left:x2 - left].reshape(-1, 3))


def surround_spread(rgb: NDArray[np.uint8], box: tuple[int, int, int, int], share: float = 0.3) -> float:
    """How busy an object's surroundings are: the root of the trace of the CIE Lab
    covariance of the pixels in a ring around ``box`` (reaching ``share`` of its longer
    side beyond it, at least 4 pixels; clipped to the photo). A plain table or wall gives
    about 10, a cluttered desk 20 to 50; 0 when the ring has fewer than 3 pixels."""
    h, w = rgb.shape[:2]
    x1, y1, x2, y2 = box
    margin = max(4, round(share * max(x2 - x1, y2 - y1)))
    cx1, cy1, cx2, cy2 = _grown((x1, y1, x2, y2), margin, (h, w))
    crop = np.ascontiguousarray(rgb[cy1:cy2, cx1:cx2, :3])
    ring = np.ones(crop.shape[:2], dtype=bool)
    ring[max(0, y1 - cy1):max(0, y2 - cy1), max(0, x1 - cx1):max(0, x2 - cx1)] = False
    if np.count_nonzero(ring) < 3:
        return 0.0
    return _lab_spread(cv2.cvtColor(crop.astype(np.float32) / 255.0, cv2.COLOR_RGB2Lab)[ring])


def _checked(mask: NDArray[np.bool_], method: str, prompt: Prompt | None, image: LoadedImage,
             cfg: SegmentationConfig) -> Segmentation:
    """A region's segmentation, or a one-line error naming its prompt. A box says where
    its object is, so how small it is in the photo does not matter; only an empty cut is
    refused."""
    if isinstance(prompt, Box):
        cfg = replace(cfg, min_object_fraction=0.0, min_object_pixels=1)
    try:
        fraction = check_object(mask, method, image.path, cfg)
    except ImageError as exc:
        if prompt is None:
            raise
        raise ImageError(f"{prompt}: {exc.message}", image.path) from None
    return Segmentation(mask, method, fraction, image.path)


# ---------------------------------------------------------------------- one point
def _holding(mask: NDArray[np.bool_], x: int, y: int, reach: float) -> NDArray[np.bool_]:
    """The 8-connected region of ``mask`` that holds pixel (x, y), or the nearest one
    within ``reach`` pixels; empty when there is none."""
    n, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    label = int(labels[y, x])
    if label == 0 and n > 1:
        ys, xs = np.nonzero(labels)
        d2 = (xs - x) ** 2 + (ys - y) ** 2
        nearest = int(np.argmin(d2))
        if d2[nearest] <= reach * reach:
            label = int(labels[ys[nearest], xs[nearest]])
    return labels == label if label else np.zeros_like(mask)


def segment_point(image: LoadedImage, point: Point, cfg: SegmentationConfig, others: Sequence[Box] = ()
                  ) -> Segmentation:
    """The object at a point (module doc): a box grown around it until the object fits;
    ``others``: the boxes of the other objects prompted in the same photo."""
    h, w = image.height, image.width
    x, y = min(w - 1, int(point.x)), min(h - 1, int(point.y))
    half = cfg.point_start * min(h, w) / 2.0
    x1, y1, x2, y2 = max(0.0, x - half), max(0.0, y - half), min(w, x + 1 + half), min(h, y + 1 + half)
    found = np.zeros((h, w), dtype=bool)
    for _ in range(cfg.point_steps):
        box = Box(x1, y1, x2, y2)
        reach = cfg.point_reach * min(x2 - x1, y2 - y1)
        found = _holding(_grabcut_box(image.rgb, box, cfg, (x, y), others, cfg.point_margin), x, y, reach)
        if not found.any():
            break
        ys, xs = np.nonzero(found)
        grow = cfg.point_growth * max(x2 - x1, y2 - y1)
        moved = [x1 > 0 and xs.min() <= x1 + 1, y1 > 0 and ys.min() <= y1 + 1,
                 x2 < w and xs.max() >= x2 - 2, y2 < h and ys.max() >= y2 - 2]
        if not any(moved):
            break
        x1 = max(0.0, x1 - grow) if moved[0] else x1
        y1 = max(0.0, y1 - grow) if moved[1] else y1
        x2 = min(float(w), x2 + grow) if moved[2] else x2
        y2 = min(float(h), y2 + grow) if moved[3] else y2
    return _checked(largest_filled(found), "point", point, image, cfg)


# ---------------------------------------------------------------------- every object
def segment_every(image: LoadedImage, max_objects: int, cfg: SegmentationConfig) -> list[Segmentation]:
    """Every separate object that stands out from the border's colours (module doc), the
    largest first; none (an empty list) when nothing does."""
    fg = colour_foreground(image.rgb, "grabcut", cfg)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(fg.found.astype(np.uint8), connectivity=8)
    small_area = fg.found.size
    least = max(cfg.min_object_fraction * small_area, cfg.min_object_pixels * fg.scale * fg.scale)
    order = sorted((int(i) for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= least),
                   key=lambda i: -int(stats[i, cv2.CC_STAT_AREA]))
    out: list[Segmentation] = []
    for i in order[:max_objects]:
        found, method = grabcut_from(fg, largest_filled(labels == i), cfg)
        mask = largest_filled(fg.full_size(found, image.rgb.shape))
        try:
            out.append(Segmentation(mask, method, check_object(mask, method, image.path, cfg), image.path))
        except ImageError:
            continue  # GrabCut shrank it below the minimum
    return out


# ---------------------------------------------------------------------- all together
def _separate(masks: list[NDArray[np.bool_]]) -> list[NDArray[np.bool_]]:
    """Give each pixel claimed by several masks to the smallest of them (module doc)."""
    if len(masks) < 2:
        return masks
    order = sorted(range(len(masks)), key=lambda i: int(np.count_nonzero(masks[i])))
    taken = np.zeros(masks[0].shape, dtype=bool)
    out: list[NDArray[np.bool_]] = [masks[0]] * len(masks)
    for i in order:
        out[i] = masks[i] & ~taken
        taken |= masks[i]
    return out


def _with_others(image: LoadedImage, found: list[tuple[Segmentation, Prompt | None]],
                 cfg: SegmentationConfig, holed: Sequence[NDArray[np.bool_] | None] = ()) -> list[Region]:
    """The regions of ``found``, overlapping claims settled (:func:`_separate`), each
    knowing the others' pixels; ``holed``: per region, its cut-out with the holes kept
    (None: none), the pose mask where it has any."""
    separated = _separate([s.mask for s, _ in found])
    union = np.zeros((image.height, image.width), dtype=bool)
    for mask in separated:
        union |= mask
    regions = []
    for i, ((seg, prompt), mask) in enumerate(zip(found, separated, strict=True)):
        if mask is not seg.mask and np.count_nonzero(mask) != np.count_nonzero(seg.mask) and (
                mask.any() or not isinstance(prompt, Box)):  # a box's object is never given away whole
            kept = largest_filled(mask)
            seg = _checked(kept, seg.method, prompt, image, cfg)
        others = union & ~seg.mask
        with_holes = holed[i] if i < len(holed) else None
        pose = None if with_holes is None else seg.mask & with_holes
        if pose is not None and np.count_nonzero(pose) == np.count_nonzero(seg.mask):
            pose = None
        regions.append(Region(seg, prompt, None, others if others.any() else None, pose))
    return regions


def _label_regions(image: LoadedImage, label_map: Any, max_objects: int) -> list[Region]:
    """One region per label of a label map (the largest ``max_objects``)."""
    labels = read_label_map(label_map, image)
    regions = []
    for value in (int(v) for v in np.unique(labels) if v != 0):
        chosen, others = label_mask(labels, value, image)
        try:
            seg = segment(image, chosen)
        except ImageError:
            continue  # too small to be an object
        regions.append(Region(seg, None, value, others if others.any() else None, seg.mask & chosen))
    if not regions:
        raise ImageError("no object found: no label of the label map covers enough pixels", image.path)
    regions.sort(key=lambda r: -r.area)
    return regions[:max_objects]


def find_regions(
    image: LoadedImage, prompts: Prompts, *, label_map: Any = None, config: SegmentationConfig | None = None,
) -> list[Region]:
    """One :class:`Region` per object the prompts ask for (module doc), in the prompts'
    order (boxes, then points), or every object's, the largest first."""
    cfg = config or SegmentationConfig()
    limit = prompts.max_objects or cfg.max_objects
    if label_map is not None:
        if not prompts.every:
            raise QueryError("a label map with prompts: give a label, or ask for every object")
        return _label_regions(image, label_map, limit)
    if prompts.every:
        return _with_others(image, [(s, None) for s in segment_every(image, limit, cfg)], cfg)
    check_prompts(image, prompts, cfg)
    boxes = prompts.boxes
    cut = [_cut_box(image, b, cfg, boxes[:i] + boxes[i + 1:]) for i, b in enumerate(boxes)]
    found: list[tuple[Segmentation, Prompt | None]] = [
        (seg, b) for (seg, _), b in zip(cut, boxes, strict=True)]
    found += [(segment_point(image, p, cfg, boxes), p) for p in prompts.points]
    return _with_others(image, found, cfg, [holed for _, holed in cut])
