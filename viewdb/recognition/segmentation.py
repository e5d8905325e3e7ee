"""Segmentation: cut the one object a query photo shows out of its background.

:func:`segment` finds the object's silhouette in a :class:`~viewdb.recognition.image.LoadedImage`;
:func:`query_curve` reduces it to the centroid distance curve the database is searched with;
:func:`label_mask` picks one object out of a label image (a prompt for a photo of several).
Photos of several objects (box and point prompts, every object) are cut out by
:mod:`viewdb.recognition.regions`, which builds on :func:`colour_foreground` (what stands
out from the border's colours, every region of it) and :func:`grabcut_from`.
Every tunable named below is a field of :class:`~viewdb.config.SegmentationConfig`.

>>> seg = segment(load_image("photo.jpg"))                # doctest: +SKIP
>>> curve = query_curve(seg, 128)                         # doctest: +SKIP

An explicit mask wins; else an alpha channel that makes at least 2 % of the image
transparent (alpha <= 127) defines the object as ``alpha > 127``; else the object is
separated from its background by colour.  Every colour method assumes that the image
border shows background (the object may touch the border, but most of the border should
be background) and starts from a model of it:

* **border** (the border model): the pixels of a strip along the image border
  (``border_strip`` of the shorter side), in CIE Lab, are described by a few colour
  clusters (deterministic k-means; clusters of under ``min_cluster_share`` of the
  strip, such as an object touching the border, are dropped) and, for gradients and
  vignetting, by a quadratic colour surface over the image.  A pixel's distance to the
  background is the smaller of its Lab distance to the nearest cluster and to the
  surface.  Pixels farther than ``max(min_threshold, threshold_factor x the 99th
  percentile of the strip's own distances)`` are object, less isolated specks (a 3 x 3
  majority vote that may only remove pixels).  The outline is then moved to
  where a pixel is half object (a pixel near the outer background is object when its
  distance exceeds half the local contrast of the object next to it), and one- or
  two-pixel cracks are bridged (a closing that adds only pixels tinted by the object,
  not clean background, so real narrow gaps stay open).
* **otsu**: the same, with the threshold chosen by Otsu's method on the distance image
  (never below the strip's noise).
* **grabcut**: OpenCV's GrabCut on a crop around the border-model result, initialised
  from it: object well inside it, probably object in the rest of it, probably background
  in a band around it, background beyond.  It re-learns both colour models and so drops
  background patches the border model let in (clutter next to the object); where it only
  shaves a thin rim off that result, the border model's outline is kept.  GrabCut's start
  (a k-means of each colour model's samples, as costly as an iteration) runs on a copy of
  the crop scaled by ``grabcut_start_scale`` (a half), and ``grabcut_iterations`` (one)
  iteration at the working scale begins from those models: it re-learns them from every
  pixel of the crop, then cuts.  From the border model's mask that gives the masks of a
  start and four iterations at the working scale (mean IoU with them 0.999; with the
  true silhouettes 0.985 either way on the synthetic photos of the 212 catalogue models)
  in 0.43 of the time of :func:`segment` (``python benchmarks/segmentation.py
  --catalogue-photos 1-6``).  The start uses OpenCV's random generator, which is seeded
  (``cv2.setRNGSeed``) before each run so that the same photo always gives the same
  mask; this resets the calling thread's OpenCV RNG.  It falls back to the border-model
  result ("border") when it cannot run.

The colour methods run on a copy scaled down to at most ``work_max_side`` pixels on
the longer side; the mask is scaled back up.  ``method="auto"`` uses ``default_method``,
GrabCut; with ``SegmentationConfig.plain_border`` it uses the border model alone on a
plain background (off by default: the outline differs from GrabCut's by a few pixels,
enough to change the matched view of a nearly symmetric object).  A background
is plain when the border strip's Lab colours lie within ``plain_spread`` of their median
(99th percentile), or within twice that and vary from pixel to pixel as sensor noise
does (their variance at most ``plain_noise_ratio`` times half the mean squared step
between neighbouring pixels; a gradient or blobs vary smoothly).  There GrabCut refines
nothing (mean IoU 0.997 / 0.995 with or without it on the benchmark's plain
backgrounds, 0.985 / 0.984 on the synthetic photos of the 212 catalogue models) and takes
about 2.7 times the time (20 against 7.4 ms of CPU for a 256 x 256 photo).  GrabCut was
chosen by measurement: ``python
benchmarks/segmentation.py`` scores each method by intersection over union (IoU) with
the true silhouette, and by the RMS difference of the distance curves, on renders of all
15 sample models (3 views each) composited over plain, gradient and cluttered
backgrounds.  Border model and GrabCut tie on IoU (mean 0.997 / 0.995-0.996 on plain
backgrounds, 0.96 on gradients, 0.99 on mild clutter), but GrabCut keeps more distance
curves within 0.05 RMS of the truth (gradients 93 % of cases against 89 %, mild clutter
98 % against 89 %), for about two and a half times the CPU time (24 against 10 ms for a
320 x 240 photo, 0.17-0.36 against 0.1 s at the full working size).  Otsu's threshold
often cuts low-contrast parts of the object off (mean IoU 0.82-0.96).  Thin parts (the
arrow's shaft) as pale as a gradient behind them are lost by every method, and strong
clutter (blobs of twice the contrast) defeats them in about one case in five.

Whatever the method, only the largest 8-connected region is kept and its holes are
filled (the shape feature uses the outer contour anyway), and the result is refused
(``ImageError``, "no object found") when it is empty, smaller than
``min_object_fraction`` of the image or ``min_object_pixels`` pixels, or
larger than ``max_object_fraction`` of it (no background found).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray
from PIL import Image, UnidentifiedImageError

from ..catalogue.features import distance_curve, mask_box
from ..config import SegmentationConfig
from ..errors import FeatureError, ImageError
from ..paths import open_regular
from .image import DEFAULTS as IMAGE_DEFAULTS
from .image import LoadedImage, check_size, describe_error, load_image

__all__ = [
    "METHODS", "Foreground", "Segmentation", "check_object", "colour_foreground", "grabcut_from",
    "grabcut_labels", "label_mask", "largest_filled", "query_curve", "read_label_map", "segment",
]

#: Every ``method`` :func:`segment` accepts; the last three are the colour methods.
METHODS = ("auto", "mask", "alpha", "border", "otsu", "grabcut")
#: Gaussians in each of OpenCV GrabCut's colour models (each needs a sample to start).
_GMM_COMPONENTS = 5


@dataclass(frozen=True, eq=False)
class Segmentation:
    """The silhouette of the one object of a query image."""

    #: bool (H, W): the kept object, one 8-connected region without holes.
    mask: NDArray[np.bool_] = field(repr=False)
    #: The method actually used: "mask", "alpha", "border", "otsu" or "grabcut".
    method: str
    #: Share of the image the object covers.
    area_fraction: float
    #: The image file it was cut from, or None.
    path: str | None = None




def segment(
    image: LoadedImage,
    mask: np.ndarray | str | os.PathLike[str] | None = None,
    *,
    method: str = "auto",
    config: SegmentationConfig | None = None,
) -> Segmentation:
    """The silhouette of the one object of a query image.

    Parameters
    ----------
    image : LoadedImage
        From :func:`load_image`.
    mask : numpy.ndarray, str or os.PathLike, optional
        An explicit mask (non-zero = object): a 2-D array, an (H, W, C) array (any of its
        first three channels non-zero), or an image file (any colour channel non-zero;
        pixels its alpha makes transparent are background).  It must have the image's size.
        When given it is used, and ``method`` must be "auto" or "mask".
    method : str
        "auto" (mask, else a transparent alpha channel, else ``config.default_method``),
        "mask", "alpha", "border", "otsu" or "grabcut"; see the module docstring.
    config : SegmentationConfig, optional
        The tunables (the defaults when not given).

    Returns
    -------
    Segmentation
        ``method`` is the method actually used ("grabcut" falls back to "border" when
        GrabCut cannot run, e.g. no background left around the object).

    Raises
    ------
    ImageError
        No object found (nothing stands out, too small, or no background), a mask of
        the wrong size or unreadable, or ``method="alpha"`` without transparent pixels.
    ValueError
        An unknown ``method``, ``method="mask"`` without a mask, or a mask with another
        ``method``.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    cfg = SegmentationConfig() if config is None else config
    name = image.path
    if mask is not None:
        if method not in ("auto", "mask"):
            raise ValueError(f"a mask is used as given: method must be 'auto' or 'mask', not {method!r}")
        raw, used = _explicit_mask(mask, image), "mask"
    elif method == "mask":
        raise ValueError("method='mask' needs a mask")
    elif method == "alpha" or (method == "auto" and _alpha_has_background(image.alpha, cfg)):
        if image.alpha is None or not (image.alpha <= 127).any():
            raise ImageError("cannot segment by alpha: the image has no transparent pixels", name)
        raw, used = image.alpha > 127, "alpha"
    else:
        used = cfg.default_method if method == "auto" else method
        raw, used = _colour_segmentation(image.rgb, used, cfg,
                                          plain_as_border=method == "auto" and cfg.plain_border)
    final = largest_filled(raw)
    # a mask says where the object is: how small a share of the photo it covers does not
    # matter (a far object in a large photo), only that it has pixels enough for a curve
    checks = replace(cfg, min_object_fraction=0.0) if used == "mask" else cfg
    fraction = check_object(final, used, name, checks)
    return Segmentation(final, used, fraction, name)


def query_curve(seg: Segmentation, samples: int) -> NDArray[np.float64]:
    """The centroid distance curve (:func:`viewdb.catalogue.features.distance_curve`) of a segmentation.

    Raises
    ------
    ImageError
        The silhouette has no usable contour.
    """
    try:
        return distance_curve(seg.mask, samples)
    except FeatureError as exc:
        raise ImageError(exc.message, seg.path) from exc


def _alpha_has_background(alpha: NDArray[np.uint8] | None, cfg: SegmentationConfig) -> bool:
    if alpha is None:
        return False
    transparent = int(np.count_nonzero(alpha <= 127))
    return transparent >= (1.0 - cfg.max_object_fraction) * alpha.size


def _explicit_mask(mask: np.ndarray | str | os.PathLike[str], image: LoadedImage) -> NDArray[np.bool_]:
    h, w = image.rgb.shape[:2]
    where = image.path
    if isinstance(mask, (str, os.PathLike)):
        where = str(mask)
        loaded = load_image(mask, max_pixels=max(IMAGE_DEFAULTS.max_pixels, h * w))
        fg = (loaded.rgb != 0).any(axis=2)
        if loaded.alpha is not None:
            fg &= loaded.alpha > 127
    else:
        arr = np.asarray(mask)
        if arr.ndim == 2:
            fg = arr != 0
        elif arr.ndim == 3 and arr.shape[2] in (1, 3, 4):
            fg = (arr[:, :, :3] != 0).any(axis=2)
        else:
            raise ImageError(f"mask array has shape {arr.shape}; expected (H, W) or (H, W, C)", where)
    if fg.shape != (h, w):
        raise ImageError(
            f"mask is {fg.shape[1]}x{fg.shape[0]} pixels but the image is {w}x{h}", where
        )
    return fg


def read_label_map(label_map: np.ndarray | str | os.PathLike[str], image: LoadedImage | None = None
                   ) -> NDArray[np.integer]:
    """A label image as a 2-D integer array (see :func:`label_mask`), checked against
    ``image``'s size."""
    where = str(label_map) if isinstance(label_map, (str, os.PathLike)) else (image.path if image else None)
    if isinstance(label_map, (str, os.PathLike)):
        path = Path(label_map)
        if not path.is_file():
            raise ImageError("label map not found", path)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # DecompressionBombWarning: the size is checked here
                with open_regular(path) as f, Image.open(f) as im:
                    check_size(im.width, im.height, IMAGE_DEFAULTS.max_pixels, str(path))
                    arr = np.asarray(im)
        except Image.DecompressionBombError as exc:
            raise ImageError(f"label map too large ({describe_error(exc)}; refused as a possible "
                             "decompression bomb)", path) from exc
        except (OSError, UnidentifiedImageError, ValueError) as exc:
            raise ImageError(f"cannot read the label map: {describe_error(exc)}", path) from exc
    else:
        arr = np.asarray(label_map)
    if arr.ndim == 3 and arr.shape[2] >= 3 and (arr[:, :, :3] == arr[:, :, :1]).all():
        arr = arr[:, :, 0]  # a grey image saved as RGB
    if arr.ndim != 2 or not (np.issubdtype(arr.dtype, np.integer) or arr.dtype == np.bool_):
        raise ImageError(f"a label map must be one channel of integer labels, got {arr.dtype} "
                         f"{arr.shape}", where)
    if image is not None and arr.shape != (image.height, image.width):
        raise ImageError(f"label map is {arr.shape[1]}x{arr.shape[0]} pixels but the image is "
                         f"{image.width}x{image.height}", where)
    return arr


def label_mask(
    label_map: np.ndarray | str | os.PathLike[str], label: int, image: LoadedImage | None = None
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Pick one object out of a label image: ``(pixels == label, other labelled pixels)``.

    ``label_map`` is a single-channel image file (8- or 16-bit PNG/TIFF, or a palette PNG,
    whose indices are the labels) or a 2-D integer array; 0 is background. The second mask
    holds the pixels of every other non-zero label (objects that may hide this one).

    Raises
    ------
    ImageError
        Unreadable file, not single-channel, a size other than ``image``'s, or ``label``
        absent from the map (the message lists the labels present).
    """
    where = str(label_map) if isinstance(label_map, (str, os.PathLike)) else (image.path if image else None)
    arr = read_label_map(label_map, image)
    if int(label) <= 0:
        raise ImageError(f"label must be a positive integer (0 is background), got {label}", where)
    chosen = arr == int(label)
    if not chosen.any():
        present = [int(v) for v in np.unique(arr) if v != 0]
        listed = ", ".join(str(v) for v in present[:20]) or "none"
        raise ImageError(f"label {label} is not in the label map (labels present: {listed})", where)
    return chosen, (arr != 0) & ~chosen


def largest_filled(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The largest 8-connected region of ``mask`` with its holes filled."""
    out = np.zeros(mask.shape, dtype=bool)
    box = mask_box(mask)  # the regions lie within it
    if box is None:
        return out
    top, left = box[0].start, box[1].start
    _, labels, stats, _ = cv2.connectedComponentsWithStats(mask[box].astype(np.uint8), connectivity=8)
    k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    x, y, bw, bh = (int(v) for v in stats[k, :4])
    region = labels[y : y + bh, x : x + bw] == k
    out[top + y : top + y + bh, left + x : left + x + bw] = ~_outside(region)  # the region and its holes
    return out


def check_object(mask: NDArray[np.bool_], method: str, name: str | None, cfg: SegmentationConfig) -> float:
    total = mask.size
    area = int(np.count_nonzero(mask))
    fraction = area / total
    if area == 0:
        raise ImageError(f"no object found: nothing stands out from the background (method {method})", name)
    if area < cfg.min_object_pixels or fraction < cfg.min_object_fraction:
        raise ImageError(
            f"no object found: the largest region has only {area} pixels ({fraction:.2%} of the image; "
            f"at least {cfg.min_object_fraction:.1%} and {cfg.min_object_pixels} pixels needed; "
            f"method {method})",
            name,
        )
    if fraction > cfg.max_object_fraction:
        raise ImageError(
            f"no object found: the object would cover {fraction:.1%} of the image, so there is no "
            f"background (at most {cfg.max_object_fraction:.0%}; method {method})",
            name,
        )
    return fraction


# ------------------------------------------------------------------ colour methods


@dataclass(frozen=True, eq=False)
class Foreground:
    """What stands out from the border's background model, at the working scale."""

    #: The photo scaled to at most ``work_max_side`` on the longer side (RGB).
    small: NDArray[np.uint8] = field(repr=False)
    #: Each pixel's Lab distance to the background model.
    dist: NDArray[np.float32] = field(repr=False)
    #: Pixels that stand out (every region, not only the largest).
    found: NDArray[np.bool_] = field(repr=False)
    #: ``small``'s size over the photo's.
    scale: float

    def full_size(self, mask: NDArray[np.bool_], shape: tuple[int, ...]) -> NDArray[np.bool_]:
        """A working-scale mask at the photo's size ``shape`` (H, W, ...)."""
        if self.scale >= 1.0:
            return mask
        h, w = int(shape[0]), int(shape[1])
        up = cv2.resize(mask.astype(np.uint8) * 255, (w, h), interpolation=cv2.INTER_LINEAR)
        return up > 127


def colour_foreground(rgb: NDArray[np.uint8], method: str, cfg: SegmentationConfig) -> Foreground:
    """Every pixel that stands out from the background model of the image border, by the
    border model's threshold (``method`` "border" or "grabcut") or Otsu's ("otsu")."""
    h, w = rgb.shape[:2]
    scale = min(1.0, cfg.work_max_side / max(h, w))
    if scale < 1.0:
        size = (max(1, round(w * scale)), max(1, round(h * scale)))
        small = np.asarray(cv2.resize(rgb, size, interpolation=cv2.INTER_AREA), np.uint8)
    else:
        small = rgb
    lab = np.asarray(cv2.cvtColor(small.astype(np.float32) / 255.0, cv2.COLOR_RGB2Lab), np.float32)
    dist, border = _background_distance(lab, cfg)
    noise = float(np.quantile(border, cfg.border_quantile))
    if method == "otsu":
        threshold = max(_otsu(dist), noise)
    else:
        threshold = max(cfg.min_threshold, cfg.threshold_factor * noise)
    # a 3 x 3 majority vote drops specks (texture, noise, JPEG) at the threshold; it may
    # only remove pixels (filling narrow gaps is left to _bridge, which looks first)
    found = dist > threshold
    found &= cv2.medianBlur(found.astype(np.uint8) * 255, 3) > 127
    found = _bridge(_half_contrast(dist, found, threshold), dist, cfg)
    return Foreground(small, dist, found, scale)


def _colour_segmentation(
    rgb: NDArray[np.uint8], method: str, cfg: SegmentationConfig, plain_as_border: bool = False
) -> tuple[NDArray[np.bool_], str]:
    """The object's mask by a colour method, at the image's size, and the method used
    (with ``plain_as_border``, the border model on a plain background, :func:`_plain`)."""
    fg = colour_foreground(rgb, method, cfg)
    found = fg.found
    if plain_as_border and method == "grabcut":
        lab = np.asarray(cv2.cvtColor(fg.small.astype(np.float32) / 255.0, cv2.COLOR_RGB2Lab), np.float32)
        if _plain(lab, cfg):
            method = "border"
    if method == "grabcut":
        found, method = grabcut_from(fg, largest_filled(found), cfg)
    return fg.full_size(found, rgb.shape), method


def _plain(lab: NDArray[np.float32], cfg: SegmentationConfig) -> bool:
    """Whether the image border shows a plain background: its Lab colours within
    ``cfg.plain_spread`` of their median (99th percentile), or within twice that and
    spatially white (their variance at most ``cfg.plain_noise_ratio`` times half the mean
    squared difference of neighbouring pixels along the strip, as for sensor noise)."""
    h, w = lab.shape[:2]
    b = max(2, round(cfg.border_strip * min(h, w)))
    # the strips along the border, each running lengthwise: (b, length, 3)
    strips = [lab[:b], lab[-b:], lab[:, :b].transpose(1, 0, 2), lab[:, -b:].transpose(1, 0, 2)]
    values = np.concatenate([s.reshape(-1, 3) for s in strips]).astype(np.float64)
    deviation = values - np.median(values, axis=0)
    spread = float(np.quantile(np.sqrt((deviation * deviation).sum(axis=1)), 0.99))
    if spread <= cfg.plain_spread:
        return True
    if spread > 2.0 * cfg.plain_spread:
        return False
    steps = np.concatenate([np.diff(s, axis=1).reshape(-1, 3) for s in strips]).astype(np.float64)
    variance = float((deviation * deviation).sum(axis=1).mean())
    noise = 0.5 * float((steps * steps).sum(axis=1).mean())
    return variance <= cfg.plain_noise_ratio * noise


def _half_contrast(
    dist: NDArray[np.float32], found: NDArray[np.bool_], threshold: float
) -> NDArray[np.bool_]:
    """Move the outline to where a pixel is half object, half background.

    A pixel on the object's outline mixes the two: its distance to the background is
    about the object's share of it times the local contrast (the mean distance of the
    object's pixels a little further in).  Pixels within two pixels of the outer
    background (the background connected to the image border; holes do not count, so
    inner lines between faces are left alone) are object when their distance exceeds
    half the local contrast, and ``threshold``: a 50 % coverage rule.
    """
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    outside = _outside(found)
    near_outside = cv2.dilate(outside.astype(np.uint8), disk).astype(bool)
    band = near_outside & cv2.dilate(found.astype(np.uint8), disk).astype(bool)
    interior = (found & ~near_outside).astype(np.float32)
    contrast = _local_contrast(dist, interior)
    # parts too thin to have an interior: their most distinct pixel nearby
    thin = cv2.dilate(dist * found.astype(np.float32), disk)
    contrast = np.where(contrast > 0, contrast, thin)
    local = np.maximum(threshold, 0.5 * contrast)
    out = found.copy()
    out[band] = dist[band] > local[band]
    return out


def _local_contrast(dist: NDArray[np.float32], weights: NDArray[np.float32]) -> NDArray[np.float32]:
    """Mean of ``dist`` over the pixels with weight 1 in a 9 x 9 window (0 where none)."""
    weight = cv2.boxFilter(weights, -1, (9, 9), normalize=False)
    total = cv2.boxFilter(dist * weights, -1, (9, 9), normalize=False)
    return np.divide(total, weight, out=np.zeros_like(total), where=weight > 0.5)


def _outside(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The pixels off ``mask`` that are 4-connected to the image border (not in holes)."""
    h, w = mask.shape
    pad = np.zeros((h + 2, w + 2), np.uint8)
    pad[1:-1, 1:-1] = mask
    cv2.floodFill(pad, np.zeros((h + 4, w + 4), np.uint8), (0, 0), 2)
    return pad[1:-1, 1:-1] == 2


def _border_pixels(shape: tuple[int, int], share: float) -> NDArray[np.bool_]:
    h, w = shape
    b = max(2, round(share * min(h, w)))
    strip = np.zeros((h, w), dtype=bool)
    strip[:b] = strip[-b:] = True
    strip[:, :b] = strip[:, -b:] = True
    return strip


def _background_distance(
    lab: NDArray[np.float32], cfg: SegmentationConfig
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Each pixel's Lab distance to the background model, and the border pixels' distances."""
    h, w = lab.shape[:2]
    strip = _border_pixels((h, w), cfg.border_strip)
    rows, cols = np.nonzero(strip)
    if len(rows) > cfg.border_samples:  # an even, deterministic subsample
        pick = np.linspace(0, len(rows) - 1, cfg.border_samples).astype(np.int64)
        rows, cols = rows[pick], cols[pick]
    samples = lab[rows, cols].astype(np.float64)
    channels = [lab[:, :, i] for i in range(3)]

    def distance_to(values: list[np.ndarray | float]) -> NDArray[np.float32]:
        d2 = np.zeros((h, w), np.float32)
        for channel, value in zip(channels, values, strict=True):
            diff = channel - value if isinstance(value, np.ndarray) else channel - np.float32(value)
            d2 += diff * diff
        return d2

    # a few colour clusters: plain backgrounds, two-tone backdrops, blobs on the border
    d2 = np.full((h, w), np.inf, np.float32)
    for centre in _kmeans(samples, cfg.background_clusters, cfg.min_cluster_share):
        np.minimum(d2, distance_to(list(centre)), out=d2)
    # a quadratic colour surface through the border: gradients, vignetting
    ys = rows / max(h - 1, 1) - 0.5
    xs = cols / max(w - 1, 1) - 0.5
    design = np.stack([np.ones_like(xs), xs, ys, xs * xs, xs * ys, ys * ys], axis=1)
    # normal equations (well conditioned: coordinates in [-1/2, 1/2]); much cheaper than lstsq
    gram = design.T @ design + 1e-9 * np.eye(design.shape[1])
    coef = np.linalg.solve(gram, design.T @ samples)
    y = (np.arange(h, dtype=np.float32) / max(h - 1, 1) - 0.5)[:, None]
    x = (np.arange(w, dtype=np.float32) / max(w - 1, 1) - 0.5)[None, :]
    c = coef.astype(np.float32)
    surface = [c[0, i] + c[1, i] * x + c[2, i] * y + c[3, i] * x * x + c[4, i] * x * y + c[5, i] * y * y
               for i in range(3)]
    np.minimum(d2, distance_to(surface), out=d2)
    dist = np.sqrt(d2)
    return dist, dist[strip]


def _kmeans(x: NDArray[np.float64], k: int, min_share: float, iterations: int = 10) -> NDArray[np.float64]:
    """Deterministic k-means (farthest-point start, at most ``iterations`` updates, fewer
    once no sample changes cluster); drops clusters of < ``min_share``."""
    centres = [np.median(x, axis=0)]
    d = ((x - centres[0]) ** 2).sum(axis=1)
    for _ in range(1, k):
        centres.append(x[int(np.argmax(d))])
        d = np.minimum(d, ((x - centres[-1]) ** 2).sum(axis=1))
    c = np.array(centres)

    def assign(c: np.ndarray) -> np.ndarray:
        return np.argmin((c * c).sum(axis=1)[None, :] - 2.0 * x @ c.T, axis=1)

    previous = None
    for _ in range(iterations):
        labels = assign(c)
        if previous is not None and np.array_equal(labels, previous):
            break  # converged: the centres would not move again
        previous = labels
        counts = np.bincount(labels, minlength=len(c))
        for i in range(x.shape[1]):
            sums = np.bincount(labels, weights=x[:, i], minlength=len(c))
            c[:, i] = np.where(counts > 0, sums / np.maximum(counts, 1), c[:, i])
    share = np.bincount(assign(c), minlength=len(c)) / len(x)
    keep = share >= min_share
    return c[keep] if keep.any() else c[[int(np.argmax(share))]]


def _otsu(dist: NDArray[np.float32]) -> float:
    top = float(np.quantile(dist, 0.995))
    if top <= 0.0:
        return 0.0
    u8 = np.clip(dist * (255.0 / top), 0, 255).astype(np.uint8)
    t, _ = cv2.threshold(u8, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    return float(t) * top / 255.0


def _bridge(
    found: NDArray[np.bool_], dist: NDArray[np.float32], cfg: SegmentationConfig
) -> NDArray[np.bool_]:
    """Close one- or two-pixel cracks in the object, but not real gaps.

    A 3 x 3 closing bridges cracks (an inner edge as pale as the background reaching the
    outline), which would otherwise cut deep into the contour; but it would also bridge
    a narrow real gap, e.g. between a chair's legs.  The pixels of a crack are tinted by
    the object around them, those of a gap are clean background: the closing adds only
    pixels whose distance to the background is at least ``cfg.bridge_share`` of the
    local contrast (the mean distance of the object's pixels nearby).
    """
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
    closed = cv2.morphologyEx(found.astype(np.uint8), cv2.MORPH_CLOSE, kernel).astype(bool)
    added = closed & ~found
    if not added.any():
        return found
    contrast = _local_contrast(dist, found.astype(np.float32))
    return found | (added & (dist >= cfg.bridge_share * contrast))


def grabcut_from(
    fg: Foreground, seed: NDArray[np.bool_], cfg: SegmentationConfig
) -> tuple[NDArray[np.bool_], str]:
    """GrabCut (working scale) from ``seed``, one region of the border-model result
    ``fg.found``; falls back to the seed ("border") when GrabCut cannot run."""
    rgb, dist = fg.small, fg.dist
    area = int(np.count_nonzero(seed))
    if area == 0:
        return seed, "border"
    h, w = seed.shape
    r_in = max(2, round(0.04 * np.sqrt(area)))
    r_out = 2 * r_in + 2
    disk = lambda r: cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))  # noqa: E731
    seed8 = seed.astype(np.uint8)
    outer = cv2.dilate(seed8, disk(r_out)).astype(bool)
    inner = cv2.erode(seed8, disk(r_in)).astype(bool)
    gc = np.full((h, w), cv2.GC_BGD, np.uint8)
    gc[outer] = cv2.GC_PR_BGD
    gc[seed] = cv2.GC_PR_FGD
    gc[inner] = cv2.GC_FGD
    ys, xs = np.nonzero(outer)
    margin = r_out + 8
    y0, y1 = max(0, int(ys.min()) - margin), min(h, int(ys.max()) + margin + 1)
    x0, x1 = max(0, int(xs.min()) - margin), min(w, int(xs.max()) + margin + 1)
    crop = np.ascontiguousarray(gc[y0:y1, x0:x1])
    background = (crop == cv2.GC_BGD) | (crop == cv2.GC_PR_BGD)
    if background.all() or not background.any():  # GrabCut needs samples of both
        return seed, "border"
    bgr = np.ascontiguousarray(rgb[y0:y1, x0:x1, ::-1])
    try:
        _grabcut(bgr, crop, cfg)
    except cv2.error:
        return seed, "border"
    out = np.zeros((h, w), dtype=bool)
    out[y0:y1, x0:x1] = (crop == cv2.GC_FGD) | (crop == cv2.GC_PR_FGD)
    # GrabCut decides which regions are object; where it only shaves a thin rim (no
    # 5 x 5 disk fits in what it removed) off the border-model result, that outline stays
    removed = seed & ~out
    n, labels = cv2.connectedComponents(removed.astype(np.uint8), connectivity=8)
    if n > 1:
        core = cv2.morphologyEx(removed.astype(np.uint8), cv2.MORPH_OPEN, disk(2)).astype(bool)
        thick = np.isin(labels, np.unique(labels[core & (labels > 0)]))
        out = (seed & ~thick) | (out & ~seed)
    return _bridge(out, dist, cfg), "grabcut"


def _grabcut(bgr: NDArray[np.uint8], labels: NDArray[np.uint8], cfg: SegmentationConfig) -> None:
    """GrabCut on ``bgr`` from the ``GC_*`` ``labels``, which it overwrites with its result.

    OpenCV's GrabCut starts each colour model by a k-means of its samples (every pixel of
    the crop), which costs as much as an iteration; with ``cfg.grabcut_start_scale`` below
    1 the models are started on a scaled-down copy instead (:func:`_started_models`) and
    the ``cfg.grabcut_iterations`` iterations at this scale begin from them (``GC_EVAL``:
    each iteration assigns every pixel to a Gaussian, re-learns both models from this
    scale's pixels, then cuts). Without a usable copy (too few pixels of either kind on
    it) the models are started at this scale. Raises ``cv2.error`` when GrabCut cannot run.
    """
    models = _started_models(bgr, labels, cfg) if cfg.grabcut_start_scale < 1.0 else None
    if models is None:
        cv2.setRNGSeed(0x5EED)  # GrabCut's GMM start uses OpenCV's RNG: make it repeatable
        grabcut_labels(bgr, labels, (np.zeros((1, 65)), np.zeros((1, 65))), cfg.grabcut_iterations,
                       cv2.GC_INIT_WITH_MASK)
    else:
        grabcut_labels(bgr, labels, models, cfg.grabcut_iterations, cv2.GC_EVAL)


def grabcut_labels(
    bgr: NDArray[np.uint8], labels: NDArray[np.uint8],
    models: tuple[NDArray[np.float64], NDArray[np.float64]], iterations: int, mode: int,
) -> None:
    """``cv2.grabCut`` from the ``GC_*`` ``labels`` (no rectangle), which it overwrites, with
    the background and object colour ``models`` (OpenCV's 1 x 65 arrays, updated too)."""
    # OpenCV's stubs type `rect` as Sequence[int]; its binding takes None (no rectangle)
    cv2.grabCut(bgr, labels, None, *models, iterations, mode)  # type: ignore[call-overload]


def _started_models(
    bgr: NDArray[np.uint8], labels: NDArray[np.uint8], cfg: SegmentationConfig
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """GrabCut's background and object colour models (OpenCV's 1 x 65 arrays) as its
    start makes them (no iteration), on a copy of ``bgr`` and ``labels`` scaled by
    ``cfg.grabcut_start_scale`` (colours averaged, labels nearest); None when the copy
    holds fewer pixels of either kind than a model has Gaussians, or GrabCut fails on it."""
    h, w = labels.shape
    size = (max(1, round(w * cfg.grabcut_start_scale)), max(1, round(h * cfg.grabcut_start_scale)))
    small = np.asarray(cv2.resize(bgr, size, interpolation=cv2.INTER_AREA), np.uint8)
    coarse = np.asarray(cv2.resize(labels, size, interpolation=cv2.INTER_NEAREST), np.uint8)
    background = np.count_nonzero((coarse == cv2.GC_BGD) | (coarse == cv2.GC_PR_BGD))
    if min(background, coarse.size - background) < _GMM_COMPONENTS:
        return None
    bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
    try:
        cv2.setRNGSeed(0x5EED)  # GrabCut's GMM start uses OpenCV's RNG: make it repeatable
        grabcut_labels(small, coarse, (bgd, fgd), 0, cv2.GC_INIT_WITH_MASK)
    except cv2.error:
        return None
    return bgd, fgd
