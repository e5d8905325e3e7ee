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
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..errors import StorageError

__all__ = ["DTYPE_CODES", "decode_array", "decode_many", "encode_array"]

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


def decode_many(
    blobs: Sequence[bytes], dtype: np.dtype | type | str, ndim: int
) -> tuple[NDArray, NDArray[np.int64]]:
    """Decode many BLOBs of one dtype and number of dimensions at once: their data end to
    end (1-D) and each one's shape (``(len(blobs), ndim)``).

    Exactly what :func:`decode_array` on each would give (the tests hold it to that), but
    with one copy for the lot instead of a call per blob: a tier's 10,000 groups decode
    in milliseconds rather than a good part of a second.

    Raises
    ------
    StorageError
        Any blob is malformed or not of ``dtype`` and ``ndim`` (the message is the one
        :func:`decode_array` gives for the first such blob).
    """
    dt = np.dtype(dtype)
    head = _HEADER.size + 4 * ndim
    code = _CODE_OF.get(np.dtype(dt.str))
    if code is None:
        raise TypeError(f"cannot decode arrays of dtype {dt}")
    n = len(blobs)
    if n == 0:
        return np.zeros(0, dt), np.zeros((0, ndim), np.int64)
    try:
        sizes = np.fromiter(map(len, blobs), np.int64, n)
        heads = np.frombuffer(b"".join(memoryview(b)[:head] for b in blobs), np.uint8)
    except TypeError:  # something that is not a blob (NULL)
        sizes = heads = np.zeros(0, np.int64)
    if len(heads) == n * head:
        heads = heads.reshape(n, head)
        expected = np.frombuffer(_HEADER.pack(MAGIC, VERSION, code, ndim), np.uint8)
        shapes = np.ascontiguousarray(heads[:, _HEADER.size:]).view("<u4").astype(np.int64)
        ok = (heads[:, : _HEADER.size] == expected).all(axis=1)
        ok &= sizes - head == shapes.prod(axis=1) * dt.itemsize
        if ok.all():
            data = b"".join(memoryview(b)[head:] for b in blobs)
            return np.frombuffer(data, dt), shapes.reshape(n, ndim)
        bad = int(np.argmin(ok))
    else:
        bad = next(i for i, b in enumerate(blobs)
                   if not isinstance(b, (bytes, bytearray, memoryview)) or len(b) < head)
    decode_array(blobs[bad], dt, (None,) * ndim)  # raises the precise error
    raise StorageError(f"array blob {bad} does not decode as {ndim}-D {dt}")  # pragma: no cover
