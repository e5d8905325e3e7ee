"""The databases a benchmark needs, built once and kept: a full file per skimming setting
and a client file per client gap.

Each cached file has a sidecar ``<file>.bench.json`` saying which models it was asked to
hold, whether that ingest finished, which files failed and how long building took (summed
over interrupted and resumed runs). A killed build resumes: ingest is idempotent (files
already in the db are skipped by content hash), so running again only adds what is
missing. A full db built elsewhere (e.g. by ``viewdb ingest``) is reused when it sits in
the cache folder with the same grid gap and image size, every object stored with the
wanted skimming setting, and no object outside the selected models.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..api import describe_paths
from ..api import open as open_db
from ..catalogue.ingest import IngestProgress
from ..errors import ViewDBError
from .config import BenchConfig

__all__ = ["CachedDb", "client_db", "full_db", "index_row", "select_models"]


def select_models(folder: Path, subset: int | None) -> list[Path]:
    """The mesh files of ``folder`` (sorted by name); ``subset`` keeps that many, evenly
    spaced over the sorted list (deterministic, independent of the seed)."""
    if not folder.is_dir():
        raise ViewDBError("is not a folder of models", folder)
    files = describe_paths([folder])
    if not files:
        raise ViewDBError("holds no mesh files (OBJ, PLY, STL, OFF, GLB, glTF)", folder)
    stems = [f.stem for f in files]
    if len(set(stems)) != len(stems):
        dup = sorted({s for s in stems if stems.count(s) > 1})
        raise ViewDBError(f"two files give the same object name: {', '.join(dup[:3])}", folder)
    if subset is not None and subset < len(files):
        files = [files[(i * len(files)) // subset] for i in range(subset)]
    return files


@dataclass(frozen=True)
class CachedDb:
    """A ready database file and what building it cost."""

    path: Path
    skim: bool
    #: Client grid gap for a client file; None for a full file.
    client_gap: float | None
    #: Wall seconds of building it (ingest or export) on this machine, if known.
    build_seconds: float | None
    #: Worker processes the ingest used (full files).
    jobs: int | None
    #: Model files that failed to ingest: name -> error.
    failed: dict[str, str]
    #: The file was found in the cache, built elsewhere (no build time of ours).
    adopted: bool = False


def _sidecar(path: Path) -> Path:
    return path.with_name(path.name + ".bench.json")


def _read_sidecar(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(_sidecar(path).read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _write_sidecar(path: Path, data: dict[str, Any]) -> None:
    tmp = _sidecar(path).with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=2))
    os.replace(tmp, _sidecar(path))


def _models_key(names: list[str]) -> str:
    return hashlib.sha256("\n".join(sorted(names)).encode()).hexdigest()[:10]


def _full_name(config: BenchConfig, skim: bool, names: list[str]) -> str:
    return (f"full-g{config.gap:g}-{'skim' if skim else 'noskim'}-{config.image_size}px-"
            f"{len(names)}m-{_models_key(names)}.db")


def _matches(path: Path, config: BenchConfig, skim: bool, names: set[str]) -> bool:
    """Whether a db built elsewhere can stand for the wanted full db."""
    try:
        with open_db(path, create=False) as db:
            if db.role != "full" or db.config.gap != float(config.gap) or \
                    db.config.render.image_size != config.image_size:
                return False
            objects = db.objects()
    except ViewDBError:
        return False
    return bool(objects) and all(o.skimmed == skim and o.name in names for o in objects)


def _find(config: BenchConfig, skim: bool, files: list[Path]) -> tuple[Path, bool]:
    names = [f.stem for f in files]
    folder = config.cache_dir
    canonical = folder / _full_name(config, skim, names)
    if canonical.exists():
        return canonical, False
    for candidate in sorted(folder.glob("*.db")):
        if candidate.name.startswith(("full-", "client-")):
            continue
        if _matches(candidate, config, skim, set(names)):
            return candidate, True
    return canonical, False


def full_db(
    config: BenchConfig, files: list[Path], skim: bool,
    progress: Callable[[IngestProgress], None] | None = None,
) -> CachedDb:
    """The full database of ``files`` at the server gap, skimmed or not: from the cache,
    adopted from a file built elsewhere, or built (and resumed) here."""
    config.cache_dir.mkdir(parents=True, exist_ok=True)
    path, adopted = _find(config, skim, files)
    names = sorted(f.stem for f in files)
    side = _read_sidecar(path)
    if side.get("complete") and side.get("models") == _models_key(names) and path.exists():
        return CachedDb(path, skim, None, side.get("build_seconds"), side.get("jobs"),
                        dict(side.get("failed", {})), bool(side.get("adopted", adopted)))
    adopted = adopted or bool(side.get("adopted", False))
    spent = float(side.get("build_seconds") or 0.0)
    _write_sidecar(path, {**side, "models": _models_key(names), "complete": False,
                          "skim": skim, "adopted": adopted, "jobs": config.jobs})
    start = time.perf_counter()
    # the db's own sparse tier is the accuracy experiment's client grid
    with open_db(path, config=config.build_config(None if adopted else config.client_gap)) as db:
        report = db.ingest(files, jobs=config.jobs, skim=skim, progress=progress)
    added = sum(o.status in ("added", "replaced") for o in report.outcomes)
    seconds = None if adopted else spent + (time.perf_counter() - start)
    failed = {o.name: o.error or "failed" for o in report.failed}
    _write_sidecar(path, {
        "models": _models_key(names), "complete": True, "skim": skim, "adopted": adopted,
        "jobs": config.jobs, "build_seconds": seconds, "failed": failed,
        "added_this_run": added,
    })
    return CachedDb(path, skim, None, seconds, config.jobs, failed, adopted)


def client_db(
    config: BenchConfig, full: CachedDb, client_gap: float,
    progress: Callable[[int, int], None] | None = None,
) -> CachedDb:
    """The client file of ``full`` at ``client_gap`` (exported once; written atomically)."""
    path = full.path.with_name(f"client-g{client_gap:g}-of-{full.path.stem}.db")
    side = _read_sidecar(path)
    full_stamp = _stamp(full.path)
    if path.exists() and side.get("source") == full_stamp:
        return CachedDb(path, full.skim, client_gap, side.get("build_seconds"), None, {})
    path.unlink(missing_ok=True)  # stale: its full db changed since
    start = time.perf_counter()
    with open_db(full.path, create=False) as db:
        db.export_client(path, client_gap=client_gap, progress=progress)
    seconds = time.perf_counter() - start
    _write_sidecar(path, {"source": full_stamp, "build_seconds": seconds})
    return CachedDb(path, full.skim, client_gap, seconds, None, {})


def _stamp(path: Path) -> str:
    """Identifies a full db's content: its objects' names and content hashes."""
    with open_db(path, create=False) as db:
        objects = sorted((o.name, o.content_hash) for o in db.objects())
    return hashlib.sha256(json.dumps(objects).encode()).hexdigest()[:16]


def index_row(cached: CachedDb) -> dict[str, Any]:
    """Sizes of one file for the index table: rows, bytes, R-tree entries, build time."""
    with open_db(cached.path, create=False) as db:
        info = db.info()
        objects = info.objects
    tier = "sparse" if cached.client_gap is not None else "full"
    sizes = info.tiers.get(tier, {})
    return {
        "file": cached.path.name,
        "kind": "client" if cached.client_gap is not None else "full",
        "skim": cached.skim,
        "gap": cached.client_gap if cached.client_gap is not None else info.config.gap,
        "objects": len(objects),
        "views": int(info.rows.get("views", 0)),
        "views_grid": sum(o.views_grid for o in objects) if cached.client_gap is None else None,
        "rtree_entries": int(sizes.get("groups", 0)),
        "rtree_bytes": int(sizes.get("rtree_bytes", 0)),
        "file_bytes": int(info.file_bytes),
        "build_seconds": cached.build_seconds,
        "object_seconds": round(sum(o.ingest_seconds for o in objects), 3)
        if cached.client_gap is None else None,
        "jobs": cached.jobs,
        "adopted": cached.adopted,
        "failed": sorted(cached.failed),
    }
