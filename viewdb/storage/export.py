"""``export-client``: the small one-file database that ships to devices.

It holds what a client needs to run its half of CS1/CS2 and nothing else: the objects'
names and symmetry types, the views of the sparse tier (the client grid, possibly coarser
than the full file's) with their curves and Fourier points, and the sparse tier's
R-tree. No meshes, no SIFT features, no full tier. By default the file is *compact*
(:class:`~viewdb.config.ClientFileConfig`): the curves are stored once, in the sparse
tier's groups, as 8-bit codes with a per-curve offset and scale and each curve's proven
error (``curve_errors``, :mod:`viewdb.search.quantised`); no per-view curve or Fourier
rows (a reader derives both from the groups); the R-tree boxes are the decoded curves';
small pages and a final ``VACUUM``. A catalogue split over several files (the shards of
:mod:`viewdb.shards`) exports to the same one file: the objects of all of them, in name
order, as the single file they were split from would give. The file is written under a temporary
name next to the target and renamed into place when complete, so a failed or interrupted
export leaves nothing behind.
"""

from __future__ import annotations

import json
import os
import sqlite3
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy.engine import Connection

from ..catalogue.symmetry import SymmetryType
from ..config import BuildConfig, ClientFileConfig
from ..errors import StorageError, ViewDBError
from ..search.grouping import tier_members
from .codecs import decode_array
from .store import Store
from .tiers import write_groups

__all__ = ["export_client"]


def export_client(
    source: Store | Sequence[Store],
    out: str | Path,
    client_gap: float | None = None,
    progress: Callable[[int, int], None] | None = None,
    file: ClientFileConfig | None = None,
) -> BuildConfig:
    """Write the client file of ``source`` (one full file, or several built with the same
    settings and holding different objects) to ``out``; returns the client's configuration.

    ``client_gap`` (default: the source's client gap) must be a multiple of the source's
    grid gap. ``out`` must not exist. ``file``: how the file is written (default compact).
    """
    file = file or ClientFileConfig()
    out = Path(out)
    sources = [source] if isinstance(source, Store) else list(source)
    config = _common_config(sources)
    source = sources[0]
    if out.exists():
        raise ViewDBError("already exists; remove it or choose another `out`", out)
    if not out.parent.is_dir():
        raise ViewDBError("its folder does not exist", out)
    try:
        client = replace(config, index=replace(
            config.index, client_gap=float(client_gap) if client_gap is not None else config.client_gap))
    except ValueError as exc:
        raise ViewDBError(str(exc), source.path) from exc
    partial = out.with_name(out.name + ".partial")
    for stale in (partial, Path(f"{partial}-wal"), Path(f"{partial}-shm")):
        stale.unlink(missing_ok=True)
    try:
        target = Store(partial, initial=(client, "client"))
        try:
            _copy(sources, target, client, progress, file.curve_bits)
        finally:
            target.close()
        with sqlite3.connect(partial) as conn:  # fold the WAL in: one self-contained file
            conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            conn.execute("PRAGMA journal_mode=DELETE")
            conn.execute(f"PRAGMA page_size={int(file.page_size)}")
            conn.execute("VACUUM")
        os.replace(partial, out)
    except BaseException:
        for stale in (partial, Path(f"{partial}-wal"), Path(f"{partial}-shm")):
            stale.unlink(missing_ok=True)
        raise
    return client


def _common_config(sources: Sequence[Store]) -> BuildConfig:
    """The build configuration of full files that share it."""
    if not sources:
        raise ViewDBError("nothing to export: no database files given")
    configs: list[BuildConfig] = []
    for source in sources:
        config = source.build_config()
        if config is None:
            raise StorageError("has no build configuration", source.path)
        if source.role() != "full":
            raise ViewDBError("is a client database; export from the full database", source.path)
        if configs and config != configs[0]:
            raise ViewDBError(f"was built with other settings than {sources[0].path}", source.path)
        configs.append(config)
    return configs[0]


def _objects_by_name(
    connections: list[sqlite3.Connection], where: Path,
) -> list[tuple[tuple[Any, ...], sqlite3.Connection]]:
    """Every object row of the files, with the file's connection, in name order (as
    SQLite's ``ORDER BY name``: binary, which is code point order); a name in two files
    is refused."""
    objects = sorted(
        ((row, src) for src in connections for row in src.execute(
            "SELECT id, name, source, content_hash, n_faces, n_vertices, centre, scale,"
            " empty_views, ingest_seconds, created_at, skimmed, h_type, v_type, h_period,"
            " v_period, symmetry FROM objects")),
        key=lambda found: str(found[0][1]),
    )
    for (a, _), (b, _) in zip(objects, objects[1:], strict=False):
        if a[1] == b[1]:
            raise ViewDBError(f"object {a[1]!r} is in more than one of the files exported", where)
    return objects


def _driver(conn: Connection) -> sqlite3.Connection:
    """The sqlite3 connection under an open SQLAlchemy connection."""
    raw = conn.connection.driver_connection
    assert raw is not None  # None only once the connection is closed or invalidated
    return raw


def _copy(sources: Sequence[Store], target: Store, client: BuildConfig, progress, bits: int) -> None:  # type: ignore[no-untyped-def]
    with ExitStack() as stack:
        connections = [_driver(stack.enter_context(s.read())) for s in sources]
        objects = _objects_by_name(connections, sources[0].path)
        for done, (row, src) in enumerate(objects, 1):
            (oid, name, path, digest, faces, vertices, centre, scale, empty, seconds, created,
             skimmed, h_type, v_type, h_period, v_period, symmetry) = row
            views = src.execute(
                "SELECT v.id, v.azimuth, v.elevation, v.grid_gap, c.samples, f.coefficients"
                " FROM views v JOIN curves c ON c.view_id = v.id"
                " JOIN fourier_points f ON f.view_id = v.id WHERE v.object_id = ? ORDER BY v.id",
                (oid,),
            ).fetchall()
            sym = None if symmetry is None else SymmetryType.from_dict(json.loads(symmetry))
            positions = [(float(v[1]), float(v[2])) for v in views]
            keep = tier_members(positions, client.gap, client.client_gap, sym, bool(skimmed))["sparse"]
            with target.transaction() as tconn:
                dst = _driver(tconn)
                new_id = dst.execute(
                    "INSERT INTO objects (name, source, content_hash, n_faces, n_vertices, centre,"
                    " scale, mesh_glb, empty_views, ingest_seconds, created_at, skimmed, h_type,"
                    " v_type, h_period, v_period, symmetry)"
                    " VALUES (?, ?, ?, ?, ?, ?, ?, x'', ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (name, path, digest, faces, vertices, centre, scale, empty, seconds, created,
                     skimmed, h_type, v_type, h_period, v_period, symmetry),
                ).lastrowid
                assert new_id is not None  # an INSERT sets it
                ids, curves = [], []
                for i in keep:
                    _, az, el, gap, samples, coefficients = views[i]
                    vid = dst.execute(
                        "INSERT INTO views (object_id, azimuth, elevation, grid_gap) VALUES (?, ?, ?, ?)",
                        (new_id, az, el, gap),
                    ).lastrowid
                    assert vid is not None
                    if not bits:  # a compact file keeps the curves in its groups only
                        dst.execute("INSERT INTO curves (view_id, samples) VALUES (?, ?)", (vid, samples))
                        dst.execute("INSERT INTO fourier_points (view_id, coefficients) VALUES (?, ?)",
                                    (vid, coefficients))
                    ids.append(vid)
                    curves.append(decode_array(samples, np.float32, (None,)))
                if ids:
                    write_groups(dst, new_id, ids, np.stack(curves), {"sparse": range(len(ids))},
                                 client.index.group_views, bits)
            if progress is not None:
                progress(done, len(objects))
