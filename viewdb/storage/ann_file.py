"""The ``fast`` plan's index in a file next to the database (``DB.fast-full``), ready to map.

Like a tier file (:mod:`viewdb.storage.tier_file`) it is a cache derived from the
database, never the only copy of anything, and it is never trusted when stale: its
header carries the tier's key (:func:`~viewdb.storage.tier_file.tier_key`: the schema
revision, the index generation every write of groups renews, the tier's group count, id
sum and maximum, every object's id, name and content hash) and the index's settings
(:meth:`~viewdb.config.FastConfig.index_key`); a file whose key differs from the
database's, or that is truncated or foreign, is not used for a search. The index's keys
name the tier's views as its key table says (:class:`~viewdb.search.fast_update.KeyTable`:
per group, its curves' digest and its run of keys), which is how a writer grows a stale
index of the same settings instead of building it anew (:func:`open_fast_index`).

Layout: ``MAGIC``, a little-endian u32 header length, a JSON header (``key``, ``tier``,
``rows``, ``keys``: the index's keys, ``groups``: the key table's rows, ``bytes``: the
length of the serialised index), then at 64-byte aligned offsets the key table (``groups``
× 3 little-endian int64) and the serialised USearch index
(:meth:`~viewdb.search.ann.ViewIndex.to_bytes`). Written to a temporary file and renamed
into place, with the database's permissions.
"""

from __future__ import annotations

import json
import mmap
import os
import struct
import tempfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..config import FastConfig
from ..search.ann import ViewIndex
from ..search.fast import FastIndex, build_fast_index
from ..search.fast_update import KeyTable, group_digests, update_fast_index
from ..search.knn import TierSource
from .tier_file import read_cache_header

__all__ = ["ann_file_path", "index_file_key", "map_ann_file", "open_fast_index", "write_ann_file"]

MAGIC = b"VDBFAST2"
_LENGTH = struct.Struct("<I")
_ALIGN = 64
_TABLE = np.dtype("<i8")


def ann_file_path(db: str | Path, tier: str) -> Path:
    """Where the ``fast`` index of tier ``tier`` of database ``db`` lies."""
    db = Path(db)
    return db.with_name(f"{db.name}.fast-{tier}")


def index_file_key(tier_key: str, config: FastConfig) -> str:
    """The key an index file of the tier whose key is ``tier_key``, made with ``config``'s
    settings, is written under (and used only under)."""
    return f"{tier_key} {config.index_key()}"


def _aligned(offset: int) -> int:
    return -(-offset // _ALIGN) * _ALIGN


def write_ann_file(
    path: Path, key: str, tier: str, index: ViewIndex, table: KeyTable, mode: int = 0o644,
) -> int:
    """Write ``index`` and its key ``table`` under ``key`` to ``path`` with permissions
    ``mode``, whole or not at all (a temporary file renamed over ``path``); the bytes
    written. Raises OSError if the folder is not writable."""
    blob = index.to_bytes()
    rows = table.to_array().astype(_TABLE).tobytes()
    header = json.dumps({"key": key, "tier": tier, "rows": table.rows, "keys": table.keys,
                         "groups": len(table.counts), "bytes": len(blob)}).encode()
    table_at = _aligned(len(MAGIC) + _LENGTH.size + len(header))
    index_at = _aligned(table_at + len(rows))
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as out:
            out.write(MAGIC + _LENGTH.pack(len(header)) + header)
            out.seek(table_at)
            out.write(rows)
            out.seek(index_at)
            out.write(blob)
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return index_at + len(blob)


def _read(path: Path, key: str | None, tier: str) -> tuple[str, KeyTable, mmap.mmap, int, int] | None:
    """The key and key table of the file at ``path``, its mapping and where and how long
    its index is, if the file is whole and was written for ``tier`` (and ``key``, unless
    None); else None."""
    try:
        with open(path, "rb") as f:
            read = read_cache_header(f, MAGIC, key, tier)
            if read is None:
                return None
            header, table_at = read
            groups, keys, size = int(header["groups"]), int(header["keys"]), int(header["bytes"])
            index_at = _aligned(table_at + groups * 3 * _TABLE.itemsize)
            if groups < 0 or size <= 0 or os.fstat(f.fileno()).st_size != index_at + size:
                return None
            mapped = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        table = KeyTable.from_array(np.frombuffer(mapped, _TABLE, groups * 3, table_at), keys)
        if table.rows != header.get("rows"):
            return None
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    return str(header["key"]), table, mapped, index_at, size


def map_ann_file(path: Path, key: str, tier: str, rows: int) -> tuple[ViewIndex, KeyTable] | None:
    """The index in the file at ``path`` and its key table if the file exists, is whole and
    was written for ``key``, ``tier`` and a tier of ``rows`` rows; else None. The index is
    used in place (a read-only mapping of the file)."""
    read = _read(path, key, tier)
    if read is None:
        return None
    _, table, mapped, at, size = read
    if table.rows != rows:
        return None
    try:
        index = ViewIndex.view(memoryview(mapped)[at : at + size], keep=mapped)
    except ValueError:
        return None
    return (index, table) if index.size == table.keys else None


def _grown(path: Path, tier: str, source: TierSource, config: FastConfig,
           digests: NDArray[np.uint64]) -> tuple[FastIndex, KeyTable] | None:
    """The index of ``source`` grown from the (stale) one in the file at ``path``, if that
    was written with ``config``'s settings (:meth:`~viewdb.config.FastConfig.index_key`)
    and growing it is due (:func:`~viewdb.search.fast_update.update_fast_index`); else None."""
    read = _read(path, None, tier)
    if read is None:
        return None
    stored, table, mapped, at, size = read
    with mapped:
        if not stored.endswith(index_file_key("", config)):  # another tier's key, the same settings
            return None
        try:
            old = ViewIndex.load(memoryview(mapped)[at : at + size], config.expansion_add)
        except ValueError:
            return None
    if old.size != table.keys or old.ndim != config.coefficients + config.quantiles:
        return None
    return update_fast_index(old, table, source, config, digests)


def open_fast_index(
    source: TierSource, db: Path, tier: str, tier_key: str, config: FastConfig, write: bool,
    mode: int = 0o644,
) -> FastIndex | None:
    """The ``fast`` index of ``source`` (tier ``tier`` of database ``db``, whose tier key is
    ``tier_key``): mapped from its file if that is valid; else, if ``write``, grown from a
    stale file of the same settings where that is due, or built, and written (a folder
    that refuses the file leaves the index in memory); else None."""
    key = index_file_key(tier_key, config)
    path = ann_file_path(db, tier)
    found = map_ann_file(path, key, tier, len(source.row_owner))
    if found is not None:
        index, table = found
        return FastIndex.of(index, source, config, table.row_of_key())
    if not write:
        return None
    digests = group_digests(source)
    grown = _grown(path, tier, source, config, digests)
    if grown is None:
        built = build_fast_index(source, config)
        grown = built, KeyTable.fresh(digests, source.group_count)
    fast, table = grown
    try:
        write_ann_file(path, key, tier, fast.index, table, mode)
    except OSError:
        pass  # a folder this process may not write: the index serves this process alone
    return fast
