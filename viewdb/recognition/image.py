"""Query images: load a photo (or an array) as 8-bit RGB.

A query is a single photo of one object.  :func:`load_image` turns a file or an array into
8-bit RGB (plus alpha, if any), refusing anything that is not a usable image with an
:class:`~viewdb.errors.ImageError`; :mod:`viewdb.recognition.segmentation` then cuts out
the object it shows.

>>> image = load_image("photo.jpg")                       # doctest: +SKIP

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
  than ``max_pixels`` pixels is refused, as is one narrower or lower than ``min_side``
  pixels (both in :class:`~viewdb.config.ImageConfig`): a decompression bomb never gets
  decoded.  Pillow's own decompression-bomb guard also applies to the header (it refuses
  images of more than about 179 million pixels whatever ``max_pixels`` says).
* Arrays are taken as RGB(A), not OpenCV's BGR(A): (H, W), (H, W, 1), (H, W, 3) or
  (H, W, 4), of dtype uint8, uint16, bool or float in [0, 1].
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
from typing import IO

import cv2
import numpy as np
from numpy.typing import NDArray
from PIL import Image, UnidentifiedImageError

from ..config import ImageConfig
from ..errors import ImageError
from ..paths import open_regular

__all__ = ["LoadedImage", "check_size", "describe_error", "load_image"]

#: The limits used where no other :class:`~viewdb.config.ImageConfig` is given.
DEFAULTS = ImageConfig()

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
    #: Its depth image, aligned pixel for pixel, in the meshes' units (NaN: no reading),
    #: or None (:func:`viewdb.recognition.depth_image.load_depth`).
    depth: NDArray[np.float64] | None = field(default=None, repr=False)

    @property
    def width(self) -> int:
        return int(self.rgb.shape[1])

    @property
    def height(self) -> int:
        return int(self.rgb.shape[0])


# --------------------------------------------------------------------------- loading


def load_image(
    source: str | os.PathLike[str] | np.ndarray, *, max_pixels: int = DEFAULTS.max_pixels
) -> LoadedImage:
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


def check_size(width: int, height: int, max_pixels: int, name: str | None) -> None:
    """Refuse (``ImageError`` naming ``name``) an image of more than ``max_pixels`` pixels
    or narrower or lower than ``min_side``."""
    if width * height > max_pixels:
        raise ImageError(
            f"image too large: {width}x{height} = {width * height:,} pixels, "
            f"more than the {max_pixels:,} accepted",
            name,
        )
    if min(width, height) < DEFAULTS.min_side:
        raise ImageError(
            f"image too small: {width}x{height} pixels, at least {DEFAULTS.min_side} needed on each side",
            name,
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
    check_size(int(arr.shape[1]), int(arr.shape[0]), max_pixels, None)
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
            check_size(width, height, max_pixels, name)
            f.seek(0)
            data = f.read()
    except OSError as exc:
        raise ImageError(f"cannot read the file: {exc.strerror or exc}", name) from exc
    arr, order = _decode(data, name)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    height, width = arr.shape[:2]
    check_size(int(width), int(height), max_pixels, name)  # in case the decoder disagrees
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


def _read_header(f: IO[bytes], name: str) -> tuple[int, int, int]:
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
        raise ImageError(f"not a readable image file ({describe_error(exc)})", name) from exc
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


def describe_error(exc: BaseException) -> str:
    """An exception in one line: its type and its message, white space folded."""
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
        raise ImageError(f"cannot decode the image ({describe_error(exc)})", name) from exc


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
