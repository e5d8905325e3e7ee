"""Depth images: read one aligned with the photo, in the meshes' units.

A depth image (RGB-D cameras, robots, many phones) gives each pixel's distance along the
camera's viewing axis. viewdb takes it aligned with the photo (the same size, pixel for
pixel, as RGB-D drivers deliver it) and uses it to fix how far away a posed object is
(:mod:`viewdb.pose.depth_distance`).

* Files: a one-channel 16-bit PNG or TIFF (the usual millimetres of RGB-D drivers), a
  32-bit float TIFF, or a NumPy ``.npy`` file; arrays: 2-D, of any integer or float dtype.
* ``scale``: the length of one depth unit **in the meshes' own units** (the units poses are
  reported in). The default 0.001 reads a 16-bit image in millimetres against meshes in
  metres; a depth image in metres with meshes in millimetres takes 1000.
* Zero, negative and non-finite values are pixels without a reading (NaN).

>>> depth = load_depth("depth.png", (480, 640), 0.001)     # doctest: +SKIP
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..config import DEFAULT_DEPTH_SCALE, LIMITS, finite
from ..errors import ImageError
from ..paths import open_regular
from .image import describe_error

__all__ = ["decode_depth", "load_depth"]


def load_depth(source: str | os.PathLike[str] | NDArray[Any], shape: tuple[int, int],
               scale: float = DEFAULT_DEPTH_SCALE) -> NDArray[np.float64]:
    """The depth image ``source`` (a file or an array) as float64 ``(H, W)`` in the meshes'
    units (depth × ``scale``; NaN where there is no reading), checked to be the size of
    the photo (``shape``, its ``(height, width)``). ``ImageError`` naming the file for an
    unreadable file, a colour image, another size, or no reading at all; ``ValueError``
    for a ``scale`` outside ``LIMITS``' depth scales."""
    scale = finite(scale, "`depth_scale`", LIMITS.min_depth_scale, LIMITS.max_depth_scale)
    name = None if isinstance(source, np.ndarray) else str(source)
    raw = source if isinstance(source, np.ndarray) else _read(Path(source))
    if raw.ndim == 3 and raw.shape[2] == 1:
        raw = raw[:, :, 0]
    if raw.ndim != 2:
        raise ImageError(f"a depth image has one channel; this one has shape {raw.shape}", name)
    if not (np.issubdtype(raw.dtype, np.integer) or np.issubdtype(raw.dtype, np.floating)):
        raise ImageError(f"a depth image holds numbers, not {raw.dtype}", name)
    if raw.shape != tuple(shape):
        raise ImageError(f"the depth image is {raw.shape[1]}x{raw.shape[0]} pixels but the photo is "
                         f"{shape[1]}x{shape[0]}: give them aligned, pixel for pixel", name)
    depth = raw.astype(np.float64) * float(scale)
    depth[~(np.isfinite(depth) & (depth > 0))] = np.nan
    if np.isnan(depth).all():
        raise ImageError("the depth image has no reading (every pixel is zero or not a number)", name)
    return depth


def _read(path: Path) -> NDArray[Any]:
    """A depth file's values (:func:`decode_depth`)."""
    try:
        with open_regular(path) as f:
            data = f.read()
    except OSError as exc:
        raise ImageError(f"cannot read the depth image ({exc.strerror or describe_error(exc)})",
                         str(path)) from exc
    return decode_depth(data, str(path))


def decode_depth(data: bytes, name: str | None = None) -> NDArray[Any]:
    """The values of a depth file's bytes (``name``: the file, for errors): a NumPy
    ``.npy`` array (no pickles) by its magic bytes, anything else by OpenCV with its bit
    depth kept; not yet scaled nor checked (:func:`load_depth` does both)."""
    if not data:
        raise ImageError("empty file, not a depth image", name)
    if data.startswith(b"\x93NUMPY"):
        try:
            return np.asarray(np.load(io.BytesIO(data), allow_pickle=False))
        except Exception as exc:  # NumPy's ways of saying the file is not an array
            raise ImageError(f"not a NumPy array file ({describe_error(exc)})", name) from exc
    arr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if arr is None or arr.size == 0:
        raise ImageError("cannot decode the depth image (a 16-bit PNG or TIFF, a float TIFF or "
                         "a .npy file is needed)", name)
    return np.asarray(arr)
