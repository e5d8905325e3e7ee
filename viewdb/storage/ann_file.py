"""The ``fast`` plan's index in a file next to the database (``DB.fast-full``), ready to map.

Like a tier file (:mod:`viewdb.storage.tier_file`) it is a cache derived from the
database, never the only copy of anything, and it is never trusted when stale: its
header carries the tier's key (:func:`~viewdb.storage.tier_file.tier_key`: the schema
revision, the index generation every write of groups renews, the tier's group count, id
sum and maximum, every object's id, name and content hash) and the index's settings
(:meth:`~viewdb.config.FastConfig.index_key`); a file whose key differs from the
database's, or that is truncated or foreign, is not used. The index's keys are the rows of
the tier as :class:`~viewdb.storage.tiers.StoredTier` numbers them, which the tier's key
fixes.

Layout: ``MAGIC``, a little-endian u32 header length, a JSON header (``key``, ``tier``,
``rows``, ``bytes``: the length of the serialised index), then the serialised USearch index
at a 64-byte aligned offset (:meth:`~viewdb.search.ann.ViewIndex.to_bytes`). Written to a
temporary file and renamed into place, with the database's permissions.
"""

from __future__ import annotations

import json
import mmap
import os
import struct
import tempfile
from pathlib import Path

from ..config import FastConfig
from ..search.ann import ViewIndex
from ..search.fast import FastIndex, build_fast_index
from ..search.knn import TierSource
from .tier_file import read_cache_header

__all__ = ["ann_file_path", "map_ann_file", "open_fast_index", "write_ann_file"]

MAGIC = b"VDBFAST1"
_LENGTH = struct.Struct("<I")
_ALIGN = 64


def ann_file_path(db: str | Path, tier: str) -> Path:
    """Where the ``fast`` index of tier ``tier`` of database ``db`` lies."""
    db = Path(db)
    return db.with_name(f"{db.name}.fast-{tier}")


def _start(header_length: int) -> int:
    return -(-(len(MAGIC) + _LENGTH.size + header_length) // _ALIGN) * _ALIGN


def write_ann_file(path: Path, key: str, tier: str, index: ViewIndex, mode: int = 0o644) -> int:
    """Write ``index`` (of ``index.size`` rows) under ``key`` to ``path`` with permissions
    ``mode``, whole or not at all (a temporary file renamed over ``path``); the bytes
    written. Raises OSError if the folder is not writable."""
    blob = index.to_bytes()
    header = json.dumps({"key": key, "tier": tier, "rows": index.size, "bytes": len(blob)}).encode()
    start = _start(len(header))
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as out:
            out.write(MAGIC + _LENGTH.pack(len(header)) + header)
            out.seek(start)
            out.write(blob)
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return start + len(blob)


def map_ann_file(path: Path, key: str, tier: str, rows: int) -> ViewIndex | None:
    """The index in the file at ``path`` if it exists, is whole and was written for
    ``key``, ``tier`` and a tier of ``rows`` rows; else None. The index is used in place
    (a read-only mapping of the file)."""
    try:
        with open(path, "rb") as f:
            read = read_cache_header(f, MAGIC, key, tier)
            if read is None:
                return None
            header, start = read
            if header.get("rows") != rows or not isinstance(header.get("bytes"), int):
                return None
            size = int(header["bytes"])
            if size <= 0 or os.fstat(f.fileno()).st_size != start + size:
                return None
            mapped = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    try:
        index = ViewIndex.view(memoryview(mapped)[start : start + size], keep=mapped)
    except ValueError:
        return None
    return index if index.size == rows else None


def open_fast_index(
    source: TierSource, db: Path, tier: str, tier_key: str, config: FastConfig, write: bool,
    mode: int = 0o644,
) -> FastIndex | None:
    """The ``fast`` index of ``source`` (tier ``tier`` of database ``db``, whose tier key is
    ``tier_key``): mapped from its file if that is valid; else, if ``write``, built and
    written (a folder that refuses the file leaves the index in memory); else None."""
    key = f"{tier_key} {config.index_key()}"
    path = ann_file_path(db, tier)
    rows = len(source.row_owner)
    index = map_ann_file(path, key, tier, rows)
    if index is not None:
        return FastIndex.of(index, source, config)
    if not write:
        return None
    built = build_fast_index(source, config)
    try:
        write_ann_file(path, key, tier, built.index, mode)
    except OSError:
        pass  # a folder this process may not write: the index serves this process alone
    return built
