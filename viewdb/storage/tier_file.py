"""A tier's arrays ready to map: a file next to the database holding every group's and
every view's arrays of one tier as a search reads them, so a fresh process maps them
instead of decoding the groups' BLOBs and computing their coordinates.

The file (``DB.tier-full``, ``DB.tier-sparse``) is a cache derived from the database, never
the only copy of anything: a file without one, or with a stale one, is searched as
before (its groups decoded on first use), with the same answers. It is written, whole and
then renamed into place (never half-written), by a writable :class:`~viewdb.storage.tiers.TierReader`
the first time it opens the tier without a valid file (an ingest, a query on a file
opened for writing), and only for tiers of exact curves (not a client file's quantised ones).

Why a file beside the database and not a table in it: a table would hold a second copy
of every curve (a sixth more of a 10° file) and each ingest would rewrite it; the file
costs the database nothing, and a fresh process maps it (``mmap``), reading from disk only
the pages a search touches.

Layout: ``MAGIC``, a little-endian u32 header length, a JSON header (``key``, ``tier``,
``arrays``: ``name -> [dtype, shape, offset]``), then each array at a 64-byte aligned offset.
The ``key`` (:func:`tier_key`) digests what identifies the tier's content in the
database: the schema revision, the *generation* of the index (a random token every writer
of groups renews in the same transaction, :func:`new_generation`), the tier's group
count, id sum and maximum (read from the tier's index alone), and every object's id, name
and content hash. Since schema revision 0009 every write transaction that renews the
generation also stamps each tier's key, computed from the generation alone (the revision
keeps writers that would not renew it out), in ``tier_stamps`` (:func:`stamp_tiers`): a
fresh open reads the stamp of the current generation, one read, and computes the key only
for a file without one. A database no writer with generations has changed has none; its key is
the tier's group count, id sum and maximum, the total length of its curve and view-id
BLOBs, and every object's id, name, content hash and time of writing, which cost a read of
every group row (0.1–0.3 s on the 212-model file with the pages cached) and, before schema
revision 0007 indexed it, of every stored mesh (an object's time lies after its mesh in the
row). A file whose key differs from the database's is not used.
"""

from __future__ import annotations

import hashlib
import json
import mmap
import os
import sqlite3
import struct
import tempfile
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

__all__ = ["ARRAYS", "generation", "map_tier_file", "new_generation", "stamp_tiers", "tier_file_path",
           "tier_key", "write_tier_file"]

MAGIC = b"VDBTIER2"
_LENGTH = struct.Struct("<I")
_ALIGN = 64

#: The arrays a file holds (:class:`~viewdb.storage.tiers.StoredTier`'s), with their dtypes.
ARRAYS = {
    "ids": "<i8", "object_ids": "<i8", "group_owner": "<i8", "group_count": "<i8",
    "views": "<i8", "lo": "<f8", "hi": "<f8", "curve_lo": "<f4", "curve_hi": "<f4",
    "curves": "<f4", "coords": "<f8", "means": "<f8",
}


def tier_file_path(db: str | Path, tier: str) -> Path:
    """Where the tier file of database ``db`` lies."""
    db = Path(db)
    return db.with_name(f"{db.name}.tier-{tier}")


#: The ``settings`` row a writer changes, in the same transaction, whenever it writes or
#: deletes index groups (:func:`new_generation`).
GENERATION_KEY = "index_generation"


def new_generation(conn: sqlite3.Connection, keep: bool = False) -> None:
    """Mark the index groups as changed (a fresh random token in ``settings``), in the
    caller's transaction; every writer of groups calls it. ``keep``: only if the database
    has no generation yet (so that its tier key is the quick one)."""
    on_conflict = "NOTHING" if keep else "UPDATE SET value = excluded.value"
    conn.execute(f"INSERT INTO settings (key, value) VALUES (?, ?) ON CONFLICT (key) DO {on_conflict}",
                 (GENERATION_KEY, json.dumps(uuid.uuid4().hex)))


def generation(conn: sqlite3.Connection) -> str | None:
    """The index's generation (None in a file without one, or without settings yet)."""
    try:
        row = conn.execute("SELECT value FROM settings WHERE key = ?", (GENERATION_KEY,)).fetchone()
    except sqlite3.OperationalError:  # a file being created: no tables yet
        return None
    return None if row is None else str(row[0])


def stamp_tiers(conn: sqlite3.Connection) -> None:
    """Stamp the key of every tier with groups (and of every tier stamped before) with the
    current generation, in the caller's write transaction, after its last write: a fresh
    open then reads the key (:func:`tier_key`) rather than computes it."""
    now = generation(conn)
    if now is None:
        return
    tiers = {str(r[0]) for r in conn.execute("SELECT DISTINCT tier FROM index_groups")}
    tiers |= {str(r[0]) for r in conn.execute("SELECT tier FROM tier_stamps")}
    for tier in sorted(tiers):
        conn.execute("INSERT INTO tier_stamps (tier, generation, key) VALUES (?, ?, ?) ON CONFLICT (tier)"
                     " DO UPDATE SET generation = excluded.generation, key = excluded.key",
                     (tier, now, _stamped_key(conn, tier, now)))


def _stamped_key(conn: sqlite3.Connection, tier: str, now: str) -> str:
    """A stamp's key: the generation (a fresh token in every transaction that changed any
    group, since revision 0009 by every writer) and the schema revision identify it."""
    digest = hashlib.sha256(f"{MAGIC!r} {tier} {now} stamped".encode())
    digest.update(repr(conn.execute("SELECT version_num FROM alembic_version").fetchall()).encode())
    return digest.hexdigest()


def tier_key(conn: sqlite3.Connection, tier: str) -> str:
    """The digest of what identifies tier ``tier``'s content in the open database (module
    doc); read inside the caller's read transaction."""
    try:
        stamp = conn.execute(
            "SELECT t.key FROM tier_stamps t JOIN settings s ON s.key = ? AND s.value = t.generation"
            " WHERE t.tier = ?", (GENERATION_KEY, tier)).fetchone()
    except sqlite3.OperationalError:  # a file from before revision 0009, read as it is
        stamp = None
    if stamp is not None:
        return str(stamp[0])
    token = conn.execute("SELECT value FROM settings WHERE key = ?", (GENERATION_KEY,)).fetchone()
    if token is None:
        return _unmarked_key(conn, tier)
    digest = hashlib.sha256(f"{MAGIC!r} {tier} {token[0]}".encode())
    digest.update(repr(conn.execute("SELECT version_num FROM alembic_version").fetchall()).encode())
    # the tier's index covers these: no group row is read
    groups = conn.execute("SELECT count(*), total(id), max(id) FROM index_groups WHERE tier = ?",
                          (tier,)).fetchone()
    digest.update(repr(tuple(groups)).encode())
    for row in conn.execute("SELECT id, name, content_hash FROM objects ORDER BY id"):
        digest.update(repr(tuple(row)).encode())
    return digest.hexdigest()


def _unmarked_key(conn: sqlite3.Connection, tier: str) -> str:
    """The key of a database without a generation (module doc)."""
    digest = hashlib.sha256(f"{MAGIC!r} {tier}".encode())
    groups = conn.execute(
        "SELECT count(*), total(id), max(id), total(length(curves)), total(length(view_ids))"
        " FROM index_groups WHERE tier = ?", (tier,),
    ).fetchone()
    digest.update(repr(tuple(groups)).encode())
    # sorted here, not by the query, which then reads the objects' index (revision 0007), not
    # their rows: a row's time of writing lies after its mesh
    for row in sorted(conn.execute("SELECT id, name, content_hash, created_at FROM objects")):
        digest.update(repr(tuple(row)).encode())
    return digest.hexdigest()


def write_tier_file(
    path: Path, key: str, tier: str, arrays: Mapping[str, NDArray], mode: int = 0o644
) -> None:
    """Write ``arrays`` (every name of :data:`ARRAYS`) to ``path`` with permissions ``mode``:
    to a temporary file in the same folder, then renamed over ``path``, so a reader sees
    the old file or the whole new one. Raises OSError if the folder is not writable."""
    layout: dict[str, list] = {}
    offset = 0
    for name, dtype in ARRAYS.items():
        a = arrays[name]
        layout[name] = [dtype, list(a.shape), offset]
        offset += -(-np.dtype(dtype).itemsize * a.size // _ALIGN) * _ALIGN
    header = json.dumps({"key": key, "tier": tier, "arrays": layout}).encode()
    start = -(-(len(MAGIC) + _LENGTH.size + len(header)) // _ALIGN) * _ALIGN
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as out:
            out.write(MAGIC + _LENGTH.pack(len(header)) + header)
            for name, dtype in ARRAYS.items():
                out.seek(start + layout[name][2])
                out.write(np.ascontiguousarray(arrays[name], dtype=dtype).tobytes())
            out.truncate(start + offset)
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def read_cache_header(f: BinaryIO, magic: bytes, key: str | None, tier: str) -> tuple[Any, int] | None:
    """The JSON header of a cache file beside a database (a tier file, a ``fast``
    index), read from ``f`` at its start: ``magic``, a little-endian u32 length, the
    header; and where its payload starts (aligned to 64 bytes). None when the file is
    not one, or was written for another ``tier`` or (unless ``key`` is None) ``key``;
    ValueError when its header is not JSON, AttributeError when it is not an object."""
    head = f.read(len(magic) + _LENGTH.size)
    if len(head) < len(magic) + _LENGTH.size or head[: len(magic)] != magic:
        return None
    (length,) = _LENGTH.unpack(head[len(magic):])
    header = json.loads(f.read(length))
    if (key is not None and header.get("key") != key) or header.get("tier") != tier:
        return None
    return header, -(-(len(magic) + _LENGTH.size + length) // _ALIGN) * _ALIGN


def map_tier_file(path: Path, key: str, tier: str) -> dict[str, NDArray] | None:
    """The arrays of the tier file at ``path`` if it exists, is whole and was written for
    ``key`` and ``tier``; else None. The arrays are a private (copy-on-write) mapping of
    the file: writable as NumPy arrays, never written back."""
    try:
        with open(path, "rb") as f:
            read = read_cache_header(f, MAGIC, key, tier)
            if read is None:
                return None
            header, start = read
            size = os.fstat(f.fileno()).st_size
            layout = header["arrays"]
            if set(layout) != set(ARRAYS):
                return None
            ends = [start + off + np.dtype(dt).itemsize * int(np.prod(shape))
                    for dt, shape, off in layout.values()]
            if max(ends, default=start) > size or size == 0:
                return None
            mapped = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_COPY)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    out = {}
    for name, (dtype, shape, off) in layout.items():
        if dtype != ARRAYS[name]:
            return None
        count = int(np.prod(shape))
        out[name] = np.frombuffer(mapped, dtype=dtype, count=count, offset=start + off).reshape(shape)
    return out
