"""Compact, typed BLOBs for numpy arrays.

Layout (little-endian)::

    b"VA"  version:u8  dtype:u8  ndim:u8  shape:u32*ndim  data

``dtype`` is a code from :data:`DTYPE_CODES`; ``data`` is the C-ordered array bytes. A
blob that does not decode exactly (wrong magic, unknown dtype, length that does not match
the shape) raises :class:`~viewdb.errors.StorageError` instead of returning garbage.
"""

from __future__ import annotations

import math
import struct

import numpy as np
from numpy.typing import NDArray

from ..errors import StorageError

__all__ = ["DTYPE_CODES", "decode_array", "encode_array"]

MAGIC = b"VA"
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


def encode_array(array: NDArray) -> bytes:
    """Encode ``array`` (any shape, a dtype of :data:`DTYPE_CODES`) as a BLOB."""
    arr = np.asarray(array)
    dtype = arr.dtype.newbyteorder("<") if arr.dtype.byteorder == ">" else arr.dtype
    code = _CODE_OF.get(np.dtype(dtype.str))
    if code is None:
        raise TypeError(f"cannot encode arrays of dtype {arr.dtype}")
    if arr.ndim > 255:
        raise ValueError("too many dimensions")
    data = np.ascontiguousarray(arr, dtype=DTYPE_CODES[code])
    header = _HEADER.pack(MAGIC, VERSION, code, arr.ndim)
    shape = struct.pack(f"<{arr.ndim}I", *arr.shape)
    return header + shape + data.tobytes()


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
    if magic != MAGIC or version != VERSION:
        raise StorageError("array blob has a bad header")
    if code not in DTYPE_CODES:
        raise StorageError(f"array blob has unknown dtype code {code}")
    offset = _HEADER.size + 4 * ndim
    if len(buf) < offset:
        raise StorageError("array blob truncated in its shape")
    dims = struct.unpack_from(f"<{ndim}I", buf, _HEADER.size)
    dt = DTYPE_CODES[code]
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
