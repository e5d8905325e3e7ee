"""Compact, typed BLOBs for numpy arrays.

Layout (little-endian)::

    b"VA"  version:u8  dtype:u8  ndim:u8  shape:u32*ndim  data

``dtype`` is a code from :data:`DTYPE_CODES`; ``data`` is the C-ordered array bytes. With
``compress=True`` the magic is ``b"VZ"`` and ``data`` is zlib-compressed. Bit images
(masks) have their own layout, the bits of their content's bounding box packed and
compressed::

    b"VB"  version:u8  height:u32  width:u32  x0:u32  y0:u32  x1:u32  y1:u32  zlib(packbits(box))

A blob that does not decode exactly (wrong magic, unknown dtype, length that does not match
the shape) raises :class:`~viewdb.errors.StorageError` instead of returning garbage.
"""

from __future__ import annotations

import math
import struct
import zlib

import numpy as np
from numpy.typing import NDArray

from ..errors import StorageError

__all__ = ["DTYPE_CODES", "decode_array", "decode_bits", "encode_array", "encode_bits"]

MAGIC = b"VA"
#: A zlib-compressed array.
ZMAGIC = b"VZ"
#: A bit image.
BMAGIC = b"VB"
VERSION = 1

#: dtype code ↔ numpy dtype. Codes are part of the file format: never renumber.
DTYPE_CODES: dict[int, np.dtype] = {
    1: np.dtype("<f4"),
    2: np.dtype("<f8"),
    3: np.dtype("|u1"),
    4: np.dtype("<f2"),
    5: np.dtype("<i4"),
    6: np.dtype("<i8"),
    7: np.dtype("<c8"),
    8: np.dtype("<c16"),
    9: np.dtype("<u2"),
    10: np.dtype("|b1"),
}
_CODE_OF = {dt: code for code, dt in DTYPE_CODES.items()}
_HEADER = struct.Struct("<2sBBB")


def encode_array(array: NDArray, *, compress: bool = False) -> bytes:
    """Encode ``array`` (any shape, a dtype of :data:`DTYPE_CODES`) as a BLOB, its data
    zlib-compressed if ``compress``."""
    arr = np.asarray(array)
    dtype = arr.dtype.newbyteorder("<") if arr.dtype.byteorder == ">" else arr.dtype
    code = _CODE_OF.get(np.dtype(dtype.str))
    if code is None:
        raise TypeError(f"cannot encode arrays of dtype {arr.dtype}")
    if arr.ndim > 255:
        raise ValueError("too many dimensions")
    data = np.ascontiguousarray(arr, dtype=DTYPE_CODES[code])
    header = _HEADER.pack(ZMAGIC if compress else MAGIC, VERSION, code, arr.ndim)
    shape = struct.pack(f"<{arr.ndim}I", *arr.shape)
    return header + shape + (zlib.compress(data.tobytes(), 9) if compress else data.tobytes())


def decode_array(
    blob: bytes | memoryview,
    dtype: np.dtype | type | str | None = None,
    shape: tuple[int | None, ...] | None = None,
) -> NDArray:
    """Decode a BLOB made by :func:`encode_array`.

    Parameters
    ----------
    dtype, shape
        If given, what the array must be (``None`` in ``shape`` matches any length).

    Raises
    ------
    StorageError
        The blob is malformed or not of the expected dtype/shape.
    """
    if not isinstance(blob, (bytes, bytearray, memoryview)):
        raise StorageError(f"array blob is missing (a {type(blob).__name__})")
    buf = bytes(blob)
    if len(buf) < _HEADER.size:
        raise StorageError(f"array blob too short ({len(buf)} bytes)")
    magic, version, code, ndim = _HEADER.unpack_from(buf)
    if magic not in (MAGIC, ZMAGIC) or version != VERSION:
        raise StorageError("array blob has a bad header")
    if code not in DTYPE_CODES:
        raise StorageError(f"array blob has unknown dtype code {code}")
    offset = _HEADER.size + 4 * ndim
    if len(buf) < offset:
        raise StorageError("array blob truncated in its shape")
    dims = struct.unpack_from(f"<{ndim}I", buf, _HEADER.size)
    dt = DTYPE_CODES[code]
    if magic == ZMAGIC:
        try:
            buf = buf[:offset] + zlib.decompress(buf[offset:])
        except zlib.error as exc:
            raise StorageError(f"array blob does not decompress: {exc}") from exc
    expected = math.prod(dims) * dt.itemsize  # exact; np.prod costs ~6 µs a call
    if len(buf) - offset != expected:
        raise StorageError(
            f"array blob holds {len(buf) - offset} data bytes, shape {dims} needs {expected}"
        )
    arr = np.frombuffer(buf, dtype=dt, offset=offset).reshape(dims)
    if dtype is not None and arr.dtype != np.dtype(dtype):
        raise StorageError(f"array blob has dtype {arr.dtype}, expected {np.dtype(dtype)}")
    if shape is not None and (
        len(shape) != arr.ndim or any(s is not None and s != d for s, d in zip(shape, dims, strict=False))
    ):
        raise StorageError(f"array blob has shape {dims}, expected {shape}")
    return arr


_BITS = struct.Struct("<2sB6I")


def encode_bits(bits: NDArray[np.bool_]) -> bytes:
    """Encode a 2-D bool image (a mask) as a BLOB: the bits of the bounding box of its set
    pixels, packed and compressed (module doc)."""
    arr = np.asarray(bits, dtype=bool)
    if arr.ndim != 2:
        raise ValueError(f"a bit image is 2-D, got shape {arr.shape}")
    rows, cols = np.flatnonzero(arr.any(axis=1)), np.flatnonzero(arr.any(axis=0))
    if len(rows) == 0:
        box = (0, 0, 0, 0)
    else:
        box = (int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1)
    x0, y0, x1, y1 = box
    packed = np.packbits(arr[y0:y1, x0:x1], axis=None).tobytes()
    return _BITS.pack(BMAGIC, VERSION, arr.shape[0], arr.shape[1], *box) + zlib.compress(packed, 9)


def decode_bits(blob: bytes | memoryview, shape: tuple[int, int] | None = None) -> NDArray[np.bool_]:
    """Decode a BLOB made by :func:`encode_bits`; ``shape``: what the image must be.

    Raises
    ------
    StorageError
        The blob is malformed or not of the expected shape.
    """
    if not isinstance(blob, (bytes, bytearray, memoryview)):
        raise StorageError(f"bit image blob is missing (a {type(blob).__name__})")
    buf = bytes(blob)
    if len(buf) < _BITS.size:
        raise StorageError(f"bit image blob too short ({len(buf)} bytes)")
    magic, version, height, width, x0, y0, x1, y1 = _BITS.unpack_from(buf)
    if magic != BMAGIC or version != VERSION:
        raise StorageError("bit image blob has a bad header")
    if shape is not None and (height, width) != tuple(shape):
        raise StorageError(f"bit image has shape {(height, width)}, expected {tuple(shape)}")
    if not (x0 <= x1 <= width and y0 <= y1 <= height):
        raise StorageError(f"bit image box {(x0, y0, x1, y1)} is not inside {(height, width)}")
    try:
        packed = zlib.decompress(buf[_BITS.size:])
    except zlib.error as exc:
        raise StorageError(f"bit image blob does not decompress: {exc}") from exc
    n = (x1 - x0) * (y1 - y0)
    if len(packed) != (n + 7) // 8:
        raise StorageError(f"bit image blob holds {len(packed)} bytes, its box needs {(n + 7) // 8}")
    out = np.zeros((height, width), dtype=bool)
    out[y0:y1, x0:x1] = np.unpackbits(np.frombuffer(packed, np.uint8), count=n).reshape(
        y1 - y0, x1 - x0).astype(bool)
    return out
