"""Writing a sharded catalogue: an ingest straight into its shard files, and the one
client file of all of them.

:func:`open_shards` opens every shard file of a folder for writing, creating the folder
(``count`` empty shard files and the manifest, under a hidden name renamed into place
when complete) if it is new. :meth:`ShardFiles.ingest` is the single file's ingest
(:func:`~viewdb.catalogue.ingest.run_ingest`, local workers or Ray tasks) with each
object written to its shard by the placement rule of :func:`~viewdb.shards.layout.shard_of`,
in one transaction of that shard's file. The manifest's object counts are rewritten
(atomically) after each new object, whenever the shards are opened and when an ingest
ends, each time from what the shard files hold (never from the manifest's own counts), so
a kill between an object's commit and its count is repaired by the next ingest. One
writer at a time: the folder's lock (:mod:`viewdb.shards.lock`) is held from the open to
the close, and a second ingest into the same folder is refused in one line.

:func:`export_client_from_shards` writes the client file of a sharded catalogue: the same
file the single file it was split from exports (:mod:`viewdb.storage.export`).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..api import ViewDB, fit_shared_looks
from ..api import open as open_db
from ..catalogue.describe import ObjectDescription
from ..catalogue.ingest import (
    IngestProgress,
    IngestReport,
    IngestTarget,
    Upgrade,
    checked_options,
    run_ingest,
)
from ..catalogue.mesh import DEFAULT_MAX_FACES
from ..config import BuildConfig, ClientFileConfig, RayIngestConfig
from ..errors import StorageError, ViewDBError
from ..storage.export import export_client
from ..storage.store import Store
from .layout import (
    MANIFEST,
    MAX_SHARDS,
    Manifest,
    check_new_folder,
    read_manifest,
    shard_file,
    shard_of,
    write_manifest,
)
from .lock import FolderLock

__all__ = ["ShardFiles", "export_client_from_shards", "open_shards"]


def open_shards(folder: str | Path, *, count: int | None = None, wait: float = 0.0,
                **settings: Any) -> ShardFiles:
    """The shard files of the sharded catalogue in ``folder``, open for writing. A folder
    without a manifest (missing or empty) becomes a new catalogue of ``count`` shards,
    built with ``settings`` (:func:`viewdb.open`'s ``gap``, ``image_size``,
    ``client_gap``, ``perspective``, ``config``); an existing one must hold ``count``
    shards (if given) built with those settings. The folder's writer lock
    (:class:`~viewdb.shards.lock.FolderLock`) is held until the files are closed: a
    second writer is refused in one line naming the first (or waits ``wait`` seconds
    for it)."""
    folder = Path(folder)
    if count is None and not (folder / MANIFEST).exists():
        raise ViewDBError("is not a sharded catalogue yet: give the number of shards to create "
                          "one (`count` N)", folder)
    if not folder.parent.is_dir():
        raise ViewDBError("its parent folder does not exist", folder)
    lock = FolderLock(folder, wait)
    dbs: list[ViewDB] = []
    try:
        if not (folder / MANIFEST).exists():
            assert count is not None
            _create(folder, count, settings)
        manifest = read_manifest(folder)
        if count is not None and count != manifest.shards:
            raise ViewDBError(f"holds {manifest.shards} shards, not {count}", folder)
        for path in manifest.files:
            dbs.append(open_db(path, create=False, **settings))
        if any(db.config != dbs[0].config for db in dbs):
            raise StorageError("holds shards built with different settings", folder)
        return ShardFiles(manifest, dbs, lock)
    except BaseException:
        for db in dbs:
            db.close()
        lock.release()
        raise


def _create(folder: Path, count: int, settings: dict[str, Any]) -> None:
    """A new sharded catalogue of ``count`` empty shard files in ``folder``."""
    if not 1 <= count <= MAX_SHARDS:
        raise ViewDBError(f"`count` must be in [1, {MAX_SHARDS}], got {count}")
    check_new_folder(folder, "`folder`")
    partial = folder.with_name(f".{folder.name}.partial")
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir()
    try:
        for i in range(count):
            open_db(partial / shard_file(i), **settings).close()
        write_manifest(Manifest(folder, [folder / shard_file(i) for i in range(count)], [0] * count),
                       partial)
        if folder.is_dir():
            folder.rmdir()
        os.replace(partial, folder)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise


class ShardFiles:
    """Every shard file of a sharded catalogue, open for writing (:func:`open_shards`)."""

    def __init__(self, manifest: Manifest, dbs: list[ViewDB], lock: FolderLock) -> None:
        self.manifest = manifest
        self.dbs = dbs
        self.lock = lock

    @property
    def config(self) -> BuildConfig:
        return self.dbs[0].config

    def close(self) -> None:
        try:
            for db in self.dbs:
                db.close()
        finally:
            self.lock.release()

    def __enter__(self) -> ShardFiles:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def ingest(
        self,
        paths: Iterable[str | Path],
        *,
        jobs: int = 1,
        skim: bool = True,
        progress: Callable[[IngestProgress], None] | None = None,
        max_faces: int | None = DEFAULT_MAX_FACES,
        allow_missing_textures: bool = False,
        ray: str | None = None,
        ray_config: RayIngestConfig | None = None,
        look_progress: Callable[[int, int], None] | None = None,
    ) -> IngestReport:
        """:meth:`viewdb.ViewDB.ingest` into the shards: each object goes to the shard the
        placement rule names, and is written there in one transaction. When it ends, one
        look model is fitted over every shard's objects and stored in each
        (:func:`viewdb.api.fit_shared_looks`)."""
        options = checked_options(jobs, max_faces, allow_missing_textures)
        report = run_ingest(list(paths), self.config, self.target(), jobs=jobs, skim=skim,
                            progress=progress, options=options, ray=ray, ray_config=ray_config)
        for db in self.dbs:
            db.write_tier_files()
        fit_shared_looks(self.dbs, look_progress)
        self._count([{o.name for o in db.objects()} for db in self.dbs])  # from the files themselves
        return report

    def target(self) -> IngestTarget:
        """The shards as one ingest target: what they hold, and a writer that places each
        object and keeps the manifest's counts."""
        parts = [db.ingest_target() for db in self.dbs]
        n = len(parts)
        names = [set(part.existing_hashes) for part in parts]
        for i, held in enumerate(names):
            misplaced = sorted(name for name in held if shard_of(name, n) != i)
            if misplaced:
                raise StorageError(f"holds {misplaced[0]!r}, which the placement puts in shard "
                                   f"{shard_of(misplaced[0], n)}", self.manifest.files[i])
        self._count(names)

        def write(desc: ObjectDescription) -> None:
            i = shard_of(desc.name, n)
            parts[i].write(desc)
            names[i].add(desc.name)
            self._count(names)

        def write_upgrade(upgrade: Upgrade) -> None:
            parts[shard_of(upgrade.name, n)].write_upgrade(upgrade)

        return IngestTarget(
            {k: v for part in parts for k, v in part.existing_hashes.items()}, write,
            frozenset().union(*(part.lacking_perspective for part in parts)),
            {k: v for part in parts for k, v in part.lacking_appearance.items()}, write_upgrade,
        )

    def _count(self, names: list[set[str]]) -> None:
        """The manifest rewritten if its object counts are not those of ``names``."""
        counts = [len(held) for held in names]
        if counts != self.manifest.objects:
            self.manifest = replace(self.manifest, objects=counts)
            write_manifest(self.manifest)


def export_client_from_shards(
    folder: str | Path, out: str | Path, *, client_gap: float | None = None,
    progress: Callable[[int, int], None] | None = None, file: ClientFileConfig | None = None,
) -> BuildConfig:
    """Write the one client file of the sharded catalogue in ``folder`` to ``out`` (which
    must not exist): equal to the one the single file it was split from exports
    (:meth:`viewdb.ViewDB.export_client`). Returns the client's configuration."""
    manifest = read_manifest(folder)
    stores: list[Store] = []
    try:
        for path in manifest.files:
            stores.append(Store(path, create=False, read_only=True))
        return export_client(stores, out, client_gap, progress, file)
    finally:
        for store in stores:
            store.close()
