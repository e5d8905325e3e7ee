"""A sharded catalogue on disk: N normal viewdb files and a small manifest.

``DIR/manifest.json`` names the shard files (``shard-000.viewdb`` …), how many objects
each holds, and the placement rule: an object lives in shard ``blake2b(name) mod N``
(:func:`shard_of`; a stable hash, the same in every process and on every machine, unlike
Python's ``hash()``). Each shard is an ordinary full viewdb file (``info``, ``check``,
``query --db`` work on it) holding every row of its objects: meshes, views, curves,
features, appearance and both tiers' groups, whose R-trees are rebuilt for the objects
kept.

:func:`split_catalogue` writes a sharded catalogue from a single file; it builds it in
a hidden folder beside ``DIR`` and renames it into place when complete, so a failed or
interrupted split leaves nothing behind. :func:`read_manifest` reads one back and
refuses (one line naming the file) a missing manifest or shard file.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sqlite3
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import StorageError, ViewDBError
from ..search.grouping import DIMENSION
from ..storage.codecs import decode_array
from ..storage.spatial import FourierIndex
from ..storage.tier_file import new_generation, stamp_tiers
from ..storage.tiers import TIERS

__all__ = ["MANIFEST", "Manifest", "check_new_folder", "read_manifest", "shard_file", "shard_of",
           "split_catalogue", "write_manifest"]

#: The manifest's file name inside a shard folder.
MANIFEST = "manifest.json"
FORMAT = "viewdb-shards"
VERSION = 1
#: Most shards a catalogue may be split into.
MAX_SHARDS = 4096


def shard_file(index: int) -> str:
    """The file name of shard ``index`` in its folder."""
    return f"shard-{index:03d}.viewdb"


def shard_of(name: str, shards: int) -> int:
    """The shard holding object ``name`` among ``shards``: a stable hash of the name (the
    first 8 bytes of its BLAKE2b digest, big-endian) modulo the shard count."""
    digest = hashlib.blake2b(name.encode("utf-8"), digest_size=8).digest()
    return int.from_bytes(digest, "big") % shards


@dataclass(frozen=True)
class Manifest:
    """A sharded catalogue: its folder, shard files (in shard order) and object counts."""

    folder: Path
    files: list[Path]
    objects: list[int]

    @property
    def shards(self) -> int:
        return len(self.files)

    def to_dict(self) -> dict[str, object]:
        return {"format": FORMAT, "version": VERSION, "placement": "blake2b-64-mod",
                "shards": [{"file": f.name, "objects": n} for f, n in zip(self.files, self.objects,
                                                                          strict=True)]}


def read_manifest(folder: str | Path) -> Manifest:
    """The manifest of the sharded catalogue in ``folder``; every shard file must exist."""
    folder = Path(folder)
    path = folder / MANIFEST
    if not folder.is_dir():
        raise StorageError("is not a folder of shards (as split_catalogue's `out`)", folder)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise StorageError("has no manifest.json: not a sharded catalogue (as split_catalogue's `out`)",
                           folder) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise StorageError(f"is unreadable: {exc}", path) from None
    try:
        if data["format"] != FORMAT or data["version"] != VERSION:
            raise StorageError(f"is not a version-{VERSION} shard manifest", path)
        entries = data["shards"]
        if not isinstance(entries, list) or not 1 <= len(entries) <= MAX_SHARDS:
            raise StorageError(f"must list 1 to {MAX_SHARDS} shards", path)
        files = [folder / str(e["file"]) for e in entries]
        objects = [int(e["objects"]) for e in entries]
    except (KeyError, TypeError, ValueError) as exc:
        raise StorageError(f"is not a valid shard manifest ({exc!r})", path) from None
    for f in files:
        if f.parent != folder or not f.is_file():
            raise StorageError(f"is missing (shard {files.index(f)} of {folder})", f)
    return Manifest(folder, files, objects)


def write_manifest(manifest: Manifest, folder: Path | None = None) -> None:
    """Write ``manifest`` into ``folder`` (default its own), atomically: a reader sees the
    old manifest or the new one, never half of one."""
    folder = manifest.folder if folder is None else folder
    partial = folder / f".{MANIFEST}.partial"
    partial.write_text(json.dumps(manifest.to_dict(), indent=1) + "\n", encoding="utf-8")
    os.replace(partial, folder / MANIFEST)


def check_new_folder(out: Path, option: str = "`out`") -> None:
    """Refuse ``out`` as the folder of a new sharded catalogue unless it is missing or
    empty and its parent exists; ``option``: the caller's parameter that gave it, in
    backticks, as library errors name parameters (the CLI shows its flag)."""
    if out.exists() and not out.is_dir():
        raise ViewDBError(f"exists and is not a folder; choose another {option}", out)
    if out.is_dir() and any(out.iterdir()):
        raise ViewDBError(f"exists and is not empty; remove it or choose another {option}", out)
    if not out.parent.is_dir():
        raise ViewDBError("its parent folder does not exist", out)


def split_catalogue(
    source: str | Path, shards: int, out: str | Path,
    progress: Callable[[int, int], None] | None = None,
) -> Manifest:
    """Split the full viewdb file ``source`` by object into ``shards`` files under ``out``
    (which must not exist or be empty), with a manifest, each with its tier files and
    ``fast`` index; ``progress(done, shards)``."""
    source, out = Path(source), Path(out)
    if not 1 <= shards <= MAX_SHARDS:
        raise ViewDBError(f"`shards` must be in [1, {MAX_SHARDS}], got {shards}")
    check_new_folder(out)
    names = _object_names(source)
    partial = out.with_name(f".{out.name}.partial")
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir()
    try:
        files, counts = [], []
        for i in range(shards):
            keep = [n for n in names if shard_of(n, shards) == i]
            target = partial / shard_file(i)
            _write_shard(source, target, set(keep))
            _write_derived(target, source)
            files.append(out / target.name)
            counts.append(len(keep))
            if progress is not None:
                progress(i + 1, shards)
        manifest = Manifest(out, files, counts)
        write_manifest(manifest, partial)
        if out.is_dir():
            out.rmdir()
        os.replace(partial, out)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    return manifest


def _object_names(source: Path) -> list[str]:
    """The object names of a full viewdb file (opened read-only: never written)."""
    from ..api import open as open_db

    with open_db(source, create=False, read_only=True) as db:
        if db.role != "full":
            raise ViewDBError("is a client file (export-client); shard the full database", source)
        return sorted(o.name for o in db.objects())


def _write_shard(source: Path, target: Path, keep: set[str]) -> None:
    """``source`` copied to ``target`` (SQLite's online backup: a consistent snapshot),
    then every object not in ``keep`` deleted (its rows follow by cascade) and both
    tiers' R-trees rebuilt from the groups left, in one transaction; then compacted."""
    with sqlite3.connect(f"file:{source}?mode=ro", uri=True) as src, sqlite3.connect(target) as dst:
        src.backup(dst)
    conn = sqlite3.connect(target, isolation_level=None)
    try:
        conn.execute("PRAGMA foreign_keys = ON")
        conn.execute("BEGIN IMMEDIATE")
        drop = [(i,) for i, name in conn.execute("SELECT id, name FROM objects") if name not in keep]
        conn.executemany("DELETE FROM index_groups WHERE object_id = ?", drop)
        new_generation(conn)
        conn.executemany("DELETE FROM objects WHERE id = ?", drop)
        conn.execute("DELETE FROM rtree_meta")
        conn.execute("DELETE FROM rtree_pages")
        for tier in TIERS:
            _rebuild_tier(conn, tier)
        stamp_tiers(conn)
        conn.execute("COMMIT")
        conn.execute("PRAGMA journal_mode = DELETE")
        conn.execute("VACUUM")
    except BaseException:
        if conn.in_transaction:
            conn.execute("ROLLBACK")
        raise
    finally:
        conn.close()


def _write_derived(target: Path, source: Path) -> None:
    """The shard's tier files and its ``fast`` index, next to it, as an ingest ends
    (a shard is opened read-only, and never writes them itself), and the look model of
    ``source`` (it serves every shard)."""
    from ..api import open as open_db
    from ..api import share_looks

    with open_db(target, create=False) as db, open_db(source, create=False, read_only=True) as whole:
        db.write_tier_files()
        share_looks(whole, [db])


def _rebuild_tier(conn: sqlite3.Connection, tier: str) -> None:
    index = FourierIndex.create(conn, tier, DIMENSION)
    try:
        for gid, lo, hi in conn.execute(
            "SELECT id, lo, hi FROM index_groups WHERE tier = ? ORDER BY id", (tier,)
        ).fetchall():
            index.insert_box(int(gid), decode_array(lo, np.float64, (DIMENSION,)),
                             decode_array(hi, np.float64, (DIMENSION,)))
        index.close()
    except BaseException:
        index.discard()
        raise
