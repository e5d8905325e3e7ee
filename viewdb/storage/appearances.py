"""How :class:`~viewdb.catalogue.appearance.Appearance` records are kept (schema revision
0005): each record packed into a few hundred bytes, an object's records concatenated into
one BLOB (``appearance_blobs``; SQLite fills its overflow pages whole, where a row per
record of one to three kB would leave most of each page empty), and a row per record in
``appearances`` saying where in it the record lies. A query reads only its records'
bytes (incremental BLOB I/O).

A packed record, little-endian::

    b"AR"  version:u8  flags:u8 (1: has a signature)
    x0 y0 x1 y1: u16      the silhouette's bounding box
    mask:u32 edges:u32 theta:u32      lengths of the three zlib streams that follow
    zlib(packbits(box XOR box shifted down a row))     the silhouette (rows as differences)
    zlib(packbits(edge pixels in the box))
    zlib(edge directions, uint8 levels, row-major)
    zlib(signature, uint16 BINS × BINS)       if flags & 1

Decoding checks what the record promises (its box inside the image, the stream lengths,
edge pixels inside the silhouette, one direction per edge pixel, the signature's size), so
``viewdb check`` and a query reject a damaged record alike.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Sequence

import numpy as np

from ..catalogue.appearance import BINS, THETA_LEVELS, Appearance
from ..errors import StorageError

__all__ = ["decode_record", "decode_signature", "encode_record", "pack_records"]

MAGIC = b"AR"
VERSION = 1
_HEADER = struct.Struct("<2sBB4H3I")


#: zlib level of the bit images: level 9 took 6x the time of 6 for 10 % fewer bytes.
BITS_LEVEL = 6


def _bits(box: np.ndarray) -> bytes:
    return zlib.compress(np.packbits(box, axis=None).tobytes(), BITS_LEVEL)


def encode_record(record: Appearance) -> bytes:
    """The packed bytes of one record (module doc)."""
    mask = np.asarray(record.mask, dtype=bool)
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    x0, y0, x1, y1 = ((int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1)
                      if len(rows) else (0, 0, 0, 0))
    box = mask[y0:y1, x0:x1]
    delta = box.copy()
    delta[1:] ^= box[:-1]
    edges = np.zeros(box.shape, dtype=bool)
    edges[record.edge_points[:, 1] - y0, record.edge_points[:, 0] - x0] = True
    theta = np.ascontiguousarray(record.edge_theta, np.uint8).tobytes()
    parts = [_bits(delta), _bits(edges), zlib.compress(theta, 9)]
    signature = b""
    if record.signature is not None:
        signature = zlib.compress(np.ascontiguousarray(record.signature, "<u2").tobytes(), 9)
    header = _HEADER.pack(MAGIC, VERSION, int(record.signature is not None), x0, y0, x1, y1,
                          *(len(p) for p in parts))
    return header + b"".join(parts) + signature


def _inflate(data: bytes, what: str) -> bytes:
    try:
        return zlib.decompress(data)
    except zlib.error as exc:
        raise StorageError(f"appearance: its {what} does not decompress: {exc}") from exc


def decode_record(data: bytes | memoryview, azimuth: float, elevation: float, image_size: int) -> Appearance:
    """The record packed in ``data`` of a view ``(azimuth, elevation)`` of a file whose views
    are ``image_size`` square.

    Raises
    ------
    StorageError
        The bytes are not a record, or the record breaks its promises.
    """
    buf = bytes(data)
    flags, x0, y0, x1, y1, n_mask, n_edges, n_theta = _header(buf)
    if not (x0 <= x1 <= image_size and y0 <= y1 <= image_size):
        raise StorageError(f"appearance: box {(x0, y0, x1, y1)} is not inside a {image_size}-pixel view")
    at = _HEADER.size
    ends = np.cumsum([at, n_mask, n_edges, n_theta])
    if ends[-1] > len(buf) or (not flags & 1 and ends[-1] != len(buf)):
        raise StorageError("appearance: record lengths do not add up")
    shape = (y1 - y0, x1 - x0)
    n = shape[0] * shape[1]

    def bits(raw: bytes, what: str) -> np.ndarray:
        packed = np.frombuffer(_inflate(raw, what), np.uint8)
        if len(packed) != (n + 7) // 8:
            raise StorageError(
                f"appearance: its {what} holds {len(packed)} bytes, its box needs {(n + 7) // 8}")
        return np.unpackbits(packed, count=n).reshape(shape).astype(bool)

    box = np.bitwise_xor.accumulate(bits(buf[ends[0]:ends[1]], "silhouette"), axis=0)
    edges = bits(buf[ends[1]:ends[2]], "edges")
    theta = np.frombuffer(_inflate(buf[ends[2]:ends[3]], "edge directions"), np.uint8)
    ys, xs = np.nonzero(edges)  # row-major, the directions' order
    if len(theta) != len(xs):
        raise StorageError(f"appearance: {len(xs)} edge pixels but {len(theta)} directions")
    if np.any(theta >= THETA_LEVELS):
        raise StorageError("appearance: an edge direction is out of range")
    if not box[ys, xs].all():
        raise StorageError("appearance: edge pixels outside the silhouette")
    signature = _signature(buf[ends[3]:]) if flags & 1 else None
    mask = np.zeros((image_size, image_size), dtype=bool)
    mask[y0:y1, x0:x1] = box
    points = np.stack([xs + x0, ys + y0], axis=1).astype(np.int32)
    return Appearance(float(azimuth), float(elevation), mask, points, theta.copy(), signature)


def decode_signature(data: bytes | memoryview) -> np.ndarray | None:
    """The colour signature (uint16, ``BINS × BINS``) of the record packed in ``data``
    without decoding its silhouette and edges, or None for a record without one.

    Raises
    ------
    StorageError
        The bytes are not a record, or its signature is damaged.
    """
    buf = bytes(data)
    flags, *_, n_mask, n_edges, n_theta = _header(buf)
    start = _HEADER.size + n_mask + n_edges + n_theta
    if start > len(buf) or (not flags & 1 and start != len(buf)):
        raise StorageError("appearance: record lengths do not add up")
    return _signature(buf[start:]) if flags & 1 else None


def _header(buf: bytes) -> tuple[int, ...]:
    """A record's header after its magic and version: flags, box, stream lengths."""
    if len(buf) < _HEADER.size:
        raise StorageError(f"appearance: record too short ({len(buf)} bytes)")
    magic, version, *rest = _HEADER.unpack_from(buf)
    if magic != MAGIC or version != VERSION:
        raise StorageError("appearance: record has a bad header")
    return tuple(rest)


def _signature(stream: bytes) -> np.ndarray:
    """A record's colour signature from its zlib stream (uint16, ``BINS × BINS``)."""
    raw = _inflate(stream, "colour signature")
    if len(raw) != 2 * BINS * BINS:
        raise StorageError(f"appearance: colour signature of {len(raw)} bytes, not {2 * BINS * BINS}")
    return np.frombuffer(raw, "<u2").reshape(BINS, BINS).astype(np.uint16)


def pack_records(records: Sequence[Appearance]) -> tuple[bytes, list[tuple[float, float, int, int]]]:
    """An object's records as one BLOB, and ``(azimuth, elevation, offset, size)`` of each."""
    parts, index, at = [], [], 0
    for record in records:
        data = encode_record(record)
        parts.append(data)
        index.append((float(record.azimuth), float(record.elevation), at, len(data)))
        at += len(data)
    return b"".join(parts), index
