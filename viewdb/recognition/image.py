"""Query images: load a photo (or an array) and cut out the one object it shows.

A query is a single photo of one object.  :func:`load_image` turns a file or an array into
8-bit RGB (plus alpha, if any), refusing anything that is not a usable image with an
:class:`~viewdb.errors.ImageError`; :func:`segment` finds the object's silhouette;
:func:`query_curve` reduces it to the centroid distance curve the database is searched with.

>>> image = load_image("photo.jpg")                       # doctest: +SKIP
>>> seg = segment(image)                                  # doctest: +SKIP
>>> curve = query_curve(seg, 128)                         # doctest: +SKIP

Loading
-------
* Files are decoded by OpenCV (``cv2.imdecode(..., IMREAD_UNCHANGED)`` on the file's
  bytes, so any path works, non-ASCII included), or by Pillow when OpenCV cannot decode
  them.  Any format either reads (PNG, JPEG, BMP, TIFF, WebP, GIF, ...) is accepted if
  Pillow can read its header (see below).
* Grey images are replicated to RGB; an alpha channel is kept as :attr:`LoadedImage.alpha`.
* 16-bit images are scaled to 8 bits (``round(v / 257)``, so 65535 → 255); float images
  (arrays, float TIFFs) must lie in [0, 1] and are scaled by 255.
* CMYK JPEGs are converted to RGB (by OpenCV's JPEG decoder).
* Animated images (APNG, GIF, multi-page TIFF): only the first frame is used.
* The EXIF orientation of a photo is applied (OpenCV's ``IMREAD_UNCHANGED`` ignores it),
  so the image is upright as a viewer shows it; the silhouette's distance curve starts
  from the image's vertical, so orientation matters.
* Before anything is decoded, the header is read (lazily, by Pillow) and an image of more
  than ``max_pixels`` pixels is refused, as is one narrower or lower than
  :data:`MIN_SIDE` pixels: a decompression bomb never gets decoded.  Pillow's own
  decompression-bomb guard also applies to the header (it refuses images of more than
  about 179 million pixels whatever ``max_pixels`` says).
* Arrays are taken as RGB(A), not OpenCV's BGR(A): (H, W), (H, W, 1), (H, W, 3) or
  (H, W, 4), of dtype uint8, uint16, bool or float in [0, 1].

Segmentation
------------
An explicit mask wins; else an alpha channel that makes at least 2 % of the image
transparent (alpha <= 127) defines the object as ``alpha > 127``; else the object is
separated from its background by colour.  Every colour method assumes that the image
border shows background (the object may touch the border, but most of the border should
be background) and starts from a model of it:

* **border** (the border model): the pixels of a strip along the image border
  (:data:`BORDER_STRIP` of the shorter side), in CIE Lab, are described by a few colour
  clusters (deterministic k-means; clusters of under :data:`MIN_CLUSTER_SHARE` of the
  strip, such as an object touching the border, are dropped) and, for gradients and
  vignetting, by a quadratic colour surface over the image.  A pixel's distance to the
  background is the smaller of its Lab distance to the nearest cluster and to the
  surface.  Pixels farther than ``max(MIN_THRESHOLD, THRESHOLD_FACTOR x the 99th
  percentile of the strip's own distances)`` are object, less isolated specks (a 3 x 3
  majority vote that may only remove pixels).  The outline is then moved to
  where a pixel is half object (a pixel near the outer background is object when its
  distance exceeds half the local contrast of the object next to it), and one- or
  two-pixel cracks are bridged (a closing that adds only pixels tinted by the object,
  not clean background, so real narrow gaps stay open).
* **otsu**: the same, with the threshold chosen by Otsu's method on the distance image
  (never below the strip's noise).
* **grabcut**: OpenCV's GrabCut (:data:`GRABCUT_ITERATIONS` iterations) on a crop around
  the border-model result, initialised from it: object well inside it, probably object
  in the rest of it, probably background in a band around it, background beyond.  It
  re-learns both colour models and so drops background patches the border model let in
  (clutter next to the object); where it only shaves a thin rim off that result, the
  border model's outline is kept.  GrabCut starts its colour models from OpenCV's random
  generator, which is seeded (``cv2.setRNGSeed``) before each run so that the same
  photo always gives the same mask; this resets the calling thread's OpenCV RNG.  It
  falls back to the border-model result ("border") when it cannot run.

The colour methods run on a copy scaled down to at most :data:`WORK_MAX_SIDE` pixels on
the longer side; the mask is scaled back up.  ``method="auto"`` uses
:data:`DEFAULT_METHOD`, GrabCut, chosen by measurement: ``python
benchmarks/segmentation.py`` scores each method by intersection over union (IoU) with
the true silhouette, and by the RMS difference of the distance curves, on renders of all
15 sample models (3 views each) composited over plain, gradient and cluttered
backgrounds.  Border model and GrabCut tie on IoU (mean 0.997 / 0.995-0.996 on plain
backgrounds, 0.96 on gradients, 0.99 on mild clutter), but GrabCut keeps more distance
curves within 0.05 RMS of the truth (gradients 93 % of cases against 89 %, mild clutter
98 % against 89 %), for about five times the CPU time (44 against 9 ms for a 320 x 240
photo, 0.3-0.8 against 0.1 s at the full working size).  Otsu's threshold
often cuts low-contrast parts of the object off (mean IoU 0.82-0.96).  Thin parts (the
arrow's shaft) as pale as a gradient behind them are lost by every method, and strong
clutter (blobs of twice the contrast) defeats them in about one case in five.

Whatever the method, only the largest 8-connected region is kept and its holes are
filled (the shape feature uses the outer contour anyway), and the result is refused
(``ImageError``, "no object found") when it is empty, smaller than
:data:`MIN_OBJECT_FRACTION` of the image or :data:`MIN_OBJECT_PIXELS` pixels, or
larger than :data:`MAX_OBJECT_FRACTION` of it (no background found).
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray
from PIL import Image, UnidentifiedImageError

from ..catalogue.features import distance_curve
from ..config import LIMITS
from ..errors import FeatureError, ImageError
from ..paths import open_regular

__all__ = [
    "DEFAULT_METHOD",
    "METHODS",
    "LoadedImage",
    "Segmentation",
    "label_mask",
    "load_image",
    "query_curve",
    "segment",
]

#: Default ``max_pixels`` of :func:`load_image`: larger images are refused undecoded.
MAX_PIXELS = LIMITS.max_pixels
#: Smallest accepted width and height, in pixels.
MIN_SIDE = 16
#: A kept object must cover at least this share of the image ...
MIN_OBJECT_FRACTION = 0.005
#: ... and at least this many pixels ...
MIN_OBJECT_PIXELS = 64
#: ... and at most this share (else no background was found).
MAX_OBJECT_FRACTION = 0.98
#: The colour methods work on a copy scaled to at most this many pixels on the longer side.
WORK_MAX_SIDE = 1024

#: Every ``method`` :func:`segment` accepts; the last three are the colour methods.
METHODS = ("auto", "mask", "alpha", "border", "otsu", "grabcut")
#: The colour method ``method="auto"`` uses (see ``benchmarks/segmentation.py``).
DEFAULT_METHOD = "grabcut"

#: Width of the border strip that samples the background, as a share of the shorter side.
BORDER_STRIP = 0.02
#: Colour clusters of the background model; clusters holding less than
#: ``MIN_CLUSTER_SHARE`` of the border samples are dropped (object pixels on the border).
BACKGROUND_CLUSTERS = 4
#: At most this many border pixels (evenly spaced along the strip) fit the model.
BORDER_SAMPLES = 4000
MIN_CLUSTER_SHARE = 0.01
#: A pixel is object when its Lab distance to the background model exceeds
#: ``max(MIN_THRESHOLD, THRESHOLD_FACTOR · the BORDER_QUANTILE quantile of the border's
#: own distances)``.
MIN_THRESHOLD = 8.0
THRESHOLD_FACTOR = 2.0
BORDER_QUANTILE = 0.99
#: The closing that bridges cracks adds only pixels at least this share of the local
#: object contrast away from the background (see ``_bridge``).
BRIDGE_SHARE = 0.1
#: GrabCut iterations.
GRABCUT_ITERATIONS = 4

_ORIENTATION_TAG = 0x0112


@dataclass(frozen=True, eq=False)
class LoadedImage:
    """A query image as 8-bit RGB, with its alpha channel if it has one."""

    #: uint8 (H, W, 3), RGB order.
    rgb: NDArray[np.uint8] = field(repr=False)
    #: uint8 (H, W) alpha (255 = opaque), or None for an image without alpha.
    alpha: NDArray[np.uint8] | None = field(repr=False)
    #: The file it was loaded from, or None for an array.
    path: str | None = None

    @property
    def width(self) -> int:
        return int(self.rgb.shape[1])

    @property
    def height(self) -> int:
        return int(self.rgb.shape[0])


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


# --------------------------------------------------------------------------- loading


def load_image(source: str | os.PathLike[str] | np.ndarray, *, max_pixels: int = MAX_PIXELS) -> LoadedImage:
    """Load a query image from a file or an array (see the module docstring for the rules).

    Parameters
    ----------
    source : str, os.PathLike or numpy.ndarray
        An image file, or an RGB(A) / grey array (H, W), (H, W, 3) or (H, W, 4) of dtype
        uint8, uint16 (scaled by 1/257), bool or float in [0, 1].
    max_pixels : int
        Images with more pixels are refused before they are decoded.

    Returns
    -------
    LoadedImage

    Raises
    ------
    ImageError
        A missing, empty, unreadable or unrecognised file, a directory, an image too
        large or too small, an array of an unsupported shape, dtype or range.  ``str`` of
        the error is one line naming the file and the problem.
    TypeError
        ``source`` is neither a path nor an array.
    """
    if isinstance(source, np.ndarray):
        rgb, alpha = _from_array(source, max_pixels)
        return LoadedImage(rgb, alpha, None)
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        rgb, alpha = _from_file(path, max_pixels)
        return LoadedImage(rgb, alpha, str(path))
    raise TypeError(f"source must be a path or a numpy array, got {type(source).__name__}")


def _check_size(width: int, height: int, max_pixels: int, name: str | None) -> None:
    if width * height > max_pixels:
        raise ImageError(
            f"image too large: {width}x{height} = {width * height:,} pixels, "
            f"more than the {max_pixels:,} accepted",
            name,
        )
    if min(width, height) < MIN_SIDE:
        raise ImageError(
            f"image too small: {width}x{height} pixels, at least {MIN_SIDE} needed on each side", name
        )


def _from_array(arr: np.ndarray, max_pixels: int) -> tuple[NDArray[np.uint8], NDArray[np.uint8] | None]:
    if arr.ndim == 3 and arr.shape[2] in (1, 2, 3, 4):
        channels = arr.shape[2]
    elif arr.ndim == 2:
        channels = 1
    else:
        raise ImageError(
            f"image array has shape {arr.shape}; expected (H, W), (H, W, 3) or (H, W, 4)"
        )
    _check_size(int(arr.shape[1]), int(arr.shape[0]), max_pixels, None)
    arr = _to_uint8(arr, None)
    if channels == 1:
        grey = arr.reshape(arr.shape[0], arr.shape[1])
        return np.repeat(grey[:, :, None], 3, axis=2), None
    if channels == 2:
        return np.repeat(arr[:, :, :1], 3, axis=2), arr[:, :, 1].copy()
    rgb = arr[:, :, :3].copy()  # never a view of the caller's array
    alpha = arr[:, :, 3].copy() if channels == 4 else None
    return rgb, alpha


def _to_uint8(arr: np.ndarray, name: str | None) -> NDArray[np.uint8]:
    """Pixel values as uint8: uint16 / 257, bool × 255, float in [0, 1] × 255."""
    if arr.dtype == np.uint8:
        return arr
    if arr.dtype == np.uint16:
        return ((arr.astype(np.uint32) + 128) // 257).astype(np.uint8)
    if arr.dtype == np.bool_:
        return arr.astype(np.uint8) * np.uint8(255)
    if np.issubdtype(arr.dtype, np.floating):
        if arr.size and not np.isfinite(arr).all():
            raise ImageError("image has NaN or infinite pixel values", name)
        lo, hi = (float(arr.min()), float(arr.max())) if arr.size else (0.0, 0.0)
        if lo < -1e-6 or hi > 1.0 + 1e-6:
            raise ImageError(
                f"float pixel values must lie in [0, 1], these span [{lo:.4g}, {hi:.4g}]", name
            )
        return np.rint(np.clip(arr, 0.0, 1.0) * 255.0).astype(np.uint8)
    raise ImageError(
        f"unsupported pixel type {arr.dtype}; expected uint8, uint16, bool or float in [0, 1]", name
    )


def _from_file(path: Path, max_pixels: int) -> tuple[NDArray[np.uint8], NDArray[np.uint8] | None]:
    name = str(path)
    try:
        if path.is_dir():
            raise ImageError("is a directory, not an image file", name)
        if not path.exists():
            raise ImageError("no such file", name)
        if not path.is_file():
            raise ImageError("not a regular file", name)
        with open_regular(path) as f:
            width, height, orientation = _read_header(f, name)
            _check_size(width, height, max_pixels, name)
            f.seek(0)
            data = f.read()
    except OSError as exc:
        raise ImageError(f"cannot read the file: {exc.strerror or exc}", name) from exc
    arr, order = _decode(data, name)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    height, width = arr.shape[:2]
    _check_size(int(width), int(height), max_pixels, name)  # in case the decoder disagrees
    arr = _to_uint8(arr, name)
    if arr.ndim == 2:
        rgb, alpha = np.repeat(arr[:, :, None], 3, axis=2), None
    elif arr.shape[2] == 2:
        rgb, alpha = np.repeat(arr[:, :, :1], 3, axis=2), arr[:, :, 1]
    elif arr.shape[2] in (3, 4):
        rgb = arr[:, :, 2::-1] if order == "bgr" else arr[:, :, :3]
        alpha = arr[:, :, 3] if arr.shape[2] == 4 else None
    else:
        raise ImageError(f"unsupported image with {arr.shape[2]} channels", name)
    rgb = _orient(rgb, orientation)
    alpha = None if alpha is None else np.ascontiguousarray(_orient(alpha, orientation))
    return np.ascontiguousarray(rgb), alpha


def _read_header(f: io.BufferedReader, name: str) -> tuple[int, int, int]:
    """``(width, height, EXIF orientation)`` from the header, without decoding pixels."""
    if os.fstat(f.fileno()).st_size == 0:
        raise ImageError("empty file, not an image", name)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(f) as im:
                width, height = (int(v) for v in im.size)
                orientation = _exif_orientation(im)
    except Image.DecompressionBombError as exc:
        pixels = re.search(r"\((\d+) pixels\)", str(exc))
        what = f"{int(pixels.group(1)):,} pixels" if pixels else "too many pixels"
        raise ImageError(f"image too large: {what} (refused as a possible decompression bomb)", name) from exc
    except UnidentifiedImageError as exc:
        raise ImageError("not an image file (unrecognised format)", name) from exc
    except Exception as exc:  # Pillow raises many types on garbage: all mean "not an image"
        raise ImageError(f"not a readable image file ({_describe(exc)})", name) from exc
    return width, height, orientation


def _exif_orientation(im: Image.Image) -> int:
    try:
        if im.format == "PNG" and "exif" not in im.info:
            return 1  # Pillow would decode the whole PNG looking for a late eXIf chunk
        value = int(im.getexif().get(_ORIENTATION_TAG, 1))
    except Exception:  # a broken EXIF block only loses the orientation
        return 1
    return value if 1 <= value <= 8 else 1


def _orient(arr: np.ndarray, orientation: int) -> np.ndarray:
    """Apply an EXIF orientation (as ``PIL.ImageOps.exif_transpose``) to (H, W[, C])."""
    if orientation == 2:
        return arr[:, ::-1]
    if orientation == 3:
        return arr[::-1, ::-1]
    if orientation == 4:
        return arr[::-1]
    if orientation == 5:
        return arr.swapaxes(0, 1)
    if orientation == 6:
        return np.rot90(arr, -1)
    if orientation == 7:
        return arr[::-1, ::-1].swapaxes(0, 1)
    if orientation == 8:
        return np.rot90(arr, 1)
    return arr


def _describe(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _decode(data: bytes, name: str) -> tuple[np.ndarray, str]:
    """Pixels of the first frame and their channel order ("bgr" from OpenCV, else "rgb")."""
    try:
        with _quiet_opencv():
            arr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    except Exception:  # whatever OpenCV's decoders raise, Pillow gets a go
        arr = None
    if arr is not None and arr.size > 0:
        return arr, "bgr"
    # OpenCV could not decode it (or a format only Pillow reads): try Pillow
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(io.BytesIO(data)) as im:
                im.seek(0)
                im.load()
                return _pil_pixels(im, name), "rgb"
    except ImageError:
        raise
    except Exception as exc:  # truncated or corrupt data, in any of Pillow's ways
        raise ImageError(f"cannot decode the image ({_describe(exc)})", name) from exc


@contextlib.contextmanager
def _quiet_opencv() -> Iterator[None]:
    """Keep OpenCV's decoders from logging warnings about damaged files to stderr (the
    damage is reported as an ImageError instead); restores the log level after."""
    log = getattr(getattr(cv2, "utils", None), "logging", None)
    if log is None:
        yield
        return
    level = log.getLogLevel()
    log.setLogLevel(min(level, log.LOG_LEVEL_ERROR))
    try:
        yield
    finally:
        log.setLogLevel(level)


def _pil_pixels(im: Image.Image, name: str) -> np.ndarray:
    mode = im.mode
    if mode.startswith("I") or mode == "F":
        arr = np.asarray(im)
        if arr.dtype.kind in "iu":
            if arr.size and (int(arr.min()) < 0 or int(arr.max()) > 65535):
                raise ImageError(f"unsupported {mode} image with values beyond 16 bits", name)
            arr = arr.astype(np.uint16) if arr.dtype != np.uint8 else arr
        return arr
    alpha = mode in ("RGBA", "LA", "PA", "RGBa", "La") or "transparency" in im.info
    return np.asarray(im.convert("RGBA" if alpha else "RGB"))


# ---------------------------------------------------------------------- segmentation


def segment(
    image: LoadedImage,
    mask: np.ndarray | str | os.PathLike[str] | None = None,
    *,
    method: str = "auto",
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
        "auto" (mask, else a transparent alpha channel, else :data:`DEFAULT_METHOD`),
        "mask", "alpha", "border", "otsu" or "grabcut"; see the module docstring.

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
    name = image.path
    if mask is not None:
        if method not in ("auto", "mask"):
            raise ValueError(f"a mask is used as given: method must be 'auto' or 'mask', not {method!r}")
        raw, used = _explicit_mask(mask, image), "mask"
    elif method == "mask":
        raise ValueError("method='mask' needs a mask")
    elif method == "alpha" or (method == "auto" and _alpha_has_background(image.alpha)):
        if image.alpha is None or not (image.alpha <= 127).any():
            raise ImageError("cannot segment by alpha: the image has no transparent pixels", name)
        raw, used = image.alpha > 127, "alpha"
    else:
        used = DEFAULT_METHOD if method == "auto" else method
        raw, used = _colour_segmentation(image.rgb, used)
    final = _largest_filled(raw)
    fraction = _check_object(final, used, name)
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


def _alpha_has_background(alpha: NDArray[np.uint8] | None) -> bool:
    if alpha is None:
        return False
    transparent = np.count_nonzero(alpha <= 127)
    return transparent >= (1.0 - MAX_OBJECT_FRACTION) * alpha.size


def _explicit_mask(mask: np.ndarray | str | os.PathLike[str], image: LoadedImage) -> NDArray[np.bool_]:
    h, w = image.rgb.shape[:2]
    where = image.path
    if isinstance(mask, (str, os.PathLike)):
        where = str(mask)
        loaded = load_image(mask, max_pixels=max(MAX_PIXELS, h * w))
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
    if isinstance(label_map, (str, os.PathLike)):
        path = Path(label_map)
        if not path.is_file():
            raise ImageError("label map not found", path)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # DecompressionBombWarning: the size is checked here
                with open_regular(path) as f, Image.open(f) as im:
                    _check_size(im.width, im.height, MAX_PIXELS, str(path))
                    arr = np.asarray(im)
        except Image.DecompressionBombError as exc:
            raise ImageError(f"label map too large ({_describe(exc)}; refused as a possible "
                             "decompression bomb)", path) from exc
        except (OSError, UnidentifiedImageError, ValueError) as exc:
            raise ImageError(f"cannot read the label map: {_describe(exc)}", path) from exc
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
    if int(label) <= 0:
        raise ImageError(f"label must be a positive integer (0 is background), got {label}", where)
    chosen = arr == int(label)
    if not chosen.any():
        present = [int(v) for v in np.unique(arr) if v != 0]
        listed = ", ".join(str(v) for v in present[:20]) or "none"
        raise ImageError(f"label {label} is not in the label map (labels present: {listed})", where)
    return chosen, (arr != 0) & ~chosen


def _largest_filled(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The largest 8-connected region of ``mask`` with its holes filled."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    out = np.zeros(mask.shape, dtype=bool)
    if n <= 1:
        return out
    k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    x, y, bw, bh = (int(v) for v in stats[k, :4])
    region = labels[y : y + bh, x : x + bw] == k
    out[y : y + bh, x : x + bw] = ~_outside(region)  # the region and its holes
    return out


def _check_object(mask: NDArray[np.bool_], method: str, name: str | None) -> float:
    total = mask.size
    area = int(np.count_nonzero(mask))
    fraction = area / total
    if area == 0:
        raise ImageError(f"no object found: nothing stands out from the background (method {method})", name)
    if area < MIN_OBJECT_PIXELS or fraction < MIN_OBJECT_FRACTION:
        raise ImageError(
            f"no object found: the largest region has only {area} pixels ({fraction:.2%} of the image; "
            f"at least {MIN_OBJECT_FRACTION:.1%} and {MIN_OBJECT_PIXELS} pixels needed; method {method})",
            name,
        )
    if fraction > MAX_OBJECT_FRACTION:
        raise ImageError(
            f"no object found: the object would cover {fraction:.1%} of the image, so there is no "
            f"background (at most {MAX_OBJECT_FRACTION:.0%}; method {method})",
            name,
        )
    return fraction


# ------------------------------------------------------------------ colour methods


def _colour_segmentation(rgb: NDArray[np.uint8], method: str) -> tuple[NDArray[np.bool_], str]:
    """The object's mask by a colour method, at the image's size, and the method used."""
    h, w = rgb.shape[:2]
    scale = min(1.0, WORK_MAX_SIDE / max(h, w))
    if scale < 1.0:
        size = (max(1, round(w * scale)), max(1, round(h * scale)))
        small = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
    else:
        small = rgb
    lab = cv2.cvtColor(small.astype(np.float32) / 255.0, cv2.COLOR_RGB2Lab)
    dist, border = _background_distance(lab)
    noise = float(np.quantile(border, BORDER_QUANTILE))
    if method == "otsu":
        threshold = max(_otsu(dist), noise)
    else:
        threshold = max(MIN_THRESHOLD, THRESHOLD_FACTOR * noise)
    # a 3 x 3 majority vote drops specks (texture, noise, JPEG) at the threshold; it may
    # only remove pixels (filling narrow gaps is left to _bridge, which looks first)
    found = dist > threshold
    found &= cv2.medianBlur(found.astype(np.uint8) * 255, 3) > 127
    found = _bridge(_half_contrast(dist, found, threshold), dist)
    if method == "grabcut":
        found, method = _grabcut(small, found, dist)
    if scale < 1.0:
        up = cv2.resize(found.astype(np.uint8) * 255, (w, h), interpolation=cv2.INTER_LINEAR)
        found = up > 127
    return found, method


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


def _border_pixels(shape: tuple[int, int]) -> NDArray[np.bool_]:
    h, w = shape
    b = max(2, round(BORDER_STRIP * min(h, w)))
    strip = np.zeros((h, w), dtype=bool)
    strip[:b] = strip[-b:] = True
    strip[:, :b] = strip[:, -b:] = True
    return strip


def _background_distance(lab: NDArray[np.float32]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Each pixel's Lab distance to the background model, and the border pixels' distances."""
    h, w = lab.shape[:2]
    strip = _border_pixels((h, w))
    rows, cols = np.nonzero(strip)
    if len(rows) > BORDER_SAMPLES:  # an even, deterministic subsample
        pick = np.linspace(0, len(rows) - 1, BORDER_SAMPLES).astype(np.int64)
        rows, cols = rows[pick], cols[pick]
    samples = lab[rows, cols].astype(np.float64)
    channels = [lab[:, :, i] for i in range(3)]

    def distance_to(values: list[np.ndarray | float]) -> NDArray[np.float32]:
        d2 = np.zeros((h, w), np.float32)
        for channel, value in zip(channels, values, strict=True):
            diff = channel - np.float32(value) if np.isscalar(value) else channel - value
            d2 += diff * diff
        return d2

    # a few colour clusters: plain backgrounds, two-tone backdrops, blobs on the border
    d2 = np.full((h, w), np.inf, np.float32)
    for centre in _kmeans(samples, BACKGROUND_CLUSTERS):
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


def _kmeans(x: NDArray[np.float64], k: int, iterations: int = 10) -> NDArray[np.float64]:
    """Deterministic k-means (farthest-point start); drops clusters of < MIN_CLUSTER_SHARE."""
    centres = [np.median(x, axis=0)]
    d = ((x - centres[0]) ** 2).sum(axis=1)
    for _ in range(1, k):
        centres.append(x[int(np.argmax(d))])
        d = np.minimum(d, ((x - centres[-1]) ** 2).sum(axis=1))
    c = np.array(centres)

    def assign(c: np.ndarray) -> np.ndarray:
        return np.argmin((c * c).sum(axis=1)[None, :] - 2.0 * x @ c.T, axis=1)

    for _ in range(iterations):
        labels = assign(c)
        counts = np.bincount(labels, minlength=len(c))
        for i in range(x.shape[1]):
            sums = np.bincount(labels, weights=x[:, i], minlength=len(c))
            c[:, i] = np.where(counts > 0, sums / np.maximum(counts, 1), c[:, i])
    share = np.bincount(assign(c), minlength=len(c)) / len(x)
    keep = share >= MIN_CLUSTER_SHARE
    return c[keep] if keep.any() else c[[int(np.argmax(share))]]


def _otsu(dist: NDArray[np.float32]) -> float:
    top = float(np.quantile(dist, 0.995))
    if top <= 0.0:
        return 0.0
    u8 = np.clip(dist * (255.0 / top), 0, 255).astype(np.uint8)
    t, _ = cv2.threshold(u8, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    return float(t) * top / 255.0


def _bridge(found: NDArray[np.bool_], dist: NDArray[np.float32]) -> NDArray[np.bool_]:
    """Close one- or two-pixel cracks in the object, but not real gaps.

    A 3 x 3 closing bridges cracks (an inner edge as pale as the background reaching the
    outline), which would otherwise cut deep into the contour; but it would also bridge
    a narrow real gap, e.g. between a chair's legs.  The pixels of a crack are tinted by
    the object around them, those of a gap are clean background: the closing adds only
    pixels whose distance to the background is at least :data:`BRIDGE_SHARE` of the
    local contrast (the mean distance of the object's pixels nearby).
    """
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
    closed = cv2.morphologyEx(found.astype(np.uint8), cv2.MORPH_CLOSE, kernel).astype(bool)
    added = closed & ~found
    if not added.any():
        return found
    contrast = _local_contrast(dist, found.astype(np.float32))
    return found | (added & (dist >= BRIDGE_SHARE * contrast))


def _grabcut(
    rgb: NDArray[np.uint8], init: NDArray[np.bool_], dist: NDArray[np.float32]
) -> tuple[NDArray[np.bool_], str]:
    """GrabCut from the border-model result; falls back to it when GrabCut cannot run."""
    seed = _largest_filled(init)
    area = int(np.count_nonzero(seed))
    if area == 0:
        return init, "border"
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
        cv2.setRNGSeed(0x5EED)  # GrabCut's GMM start uses OpenCV's RNG: make it repeatable
        cv2.grabCut(bgr, crop, None, np.zeros((1, 65)), np.zeros((1, 65)), GRABCUT_ITERATIONS,
                    cv2.GC_INIT_WITH_MASK)
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
    return _bridge(out, dist), "grabcut"
