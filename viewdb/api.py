"""The :class:`ViewDB` facade: the one module that wires the stages together.

It takes progress callbacks and never prints; the CLI (``cli/``) is a thin shell over it.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .camera import grid_views, normalise_angle
from .config import BuildConfig, RenderConfig
from .describe import ObjectDescription
from .errors import NotFound, ViewDBError
from .ingest import IngestProgress, IngestReport, run_ingest
from .mesh import NormalisedMesh, load_mesh, mesh_from_glb
from .render import RenderedView, get_renderer
from .storage.integrity import CheckReport, check_store
from .storage.schema import SCHEMA_REVISION
from .storage.store import ObjectRow, Store

__all__ = ["DatabaseInfo", "ObjectInfo", "StoredView", "ViewDB", "open", "render_model"]

#: How many decoded meshes a database keeps in memory for :meth:`ViewDB.render`.
MESH_CACHE_SIZE = 8


@dataclass(frozen=True)
class ObjectInfo:
    """One object of a database."""

    name: str
    source: str
    content_hash: str
    n_faces: int
    n_vertices: int
    #: Farthest-vertex distance in the file's units (normalised = (original − centre)/scale).
    scale: float
    centre: tuple[float, float, float]
    views_stored: int
    views_grid: int
    empty_views: int
    ingest_seconds: float
    created_at: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name, "source": self.source, "content_hash": self.content_hash,
            "faces": self.n_faces, "vertices": self.n_vertices, "scale": self.scale,
            "centre": list(self.centre), "views_stored": self.views_stored,
            "views_grid": self.views_grid, "empty_views": self.empty_views,
            "ingest_seconds": round(self.ingest_seconds, 3), "created_at": self.created_at,
        }


@dataclass(frozen=True, eq=False)
class StoredView:
    """A stored view's features, read back from the database."""

    object: str
    azimuth: float
    elevation: float
    curve: NDArray[np.float32] = field(repr=False)
    fourier: NDArray[np.complex128] = field(repr=False)
    keypoints: NDArray[np.float32] = field(repr=False)
    descriptors: NDArray[np.uint8] = field(repr=False)
    points3d: NDArray[np.float32] = field(repr=False)


@dataclass(frozen=True)
class DatabaseInfo:
    path: str
    file_bytes: int
    schema_revision: str
    config: BuildConfig
    objects: list[ObjectInfo]
    rows: dict[str, int]

    def to_dict(self) -> dict[str, Any]:
        return {
            "path": self.path, "file_bytes": self.file_bytes,
            "schema_version": self.schema_revision, "gap": self.config.gap,
            "image_size": self.config.render.image_size,
            "curve_samples": self.config.features.curve_samples,
            "fourier_coefficients": self.config.features.fourier_coefficients,
            "sift_max_keypoints": self.config.sift.max_keypoints,
            "rows": self.rows, "objects": [o.to_dict() for o in self.objects],
        }


class ViewDB:
    """An open view database. Use :func:`viewdb.open` to get one; close it (or use ``with``)."""

    def __init__(self, store: Store, config: BuildConfig) -> None:
        self._store = store
        self.config = config
        self._meshes: OrderedDict[str, NormalisedMesh] = OrderedDict()

    @property
    def path(self) -> Path:
        return self._store.path

    def close(self) -> None:
        self._store.close()

    def __enter__(self) -> ViewDB:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ ingest
    def ingest(
        self,
        paths: Iterable[str | Path],
        *,
        jobs: int = 1,
        progress: Callable[[IngestProgress], None] | None = None,
    ) -> IngestReport:
        """Add mesh files; an object is named after its file's stem.

        Unchanged files (same name and content hash) are skipped; changed ones replace
        their object. Each object is written in one transaction. Files that fail are
        listed in the report's ``failed`` and the rest still go in.
        """
        def write(desc: ObjectDescription) -> None:
            self._store.write_object(desc, self.config.gap)
            self._meshes.pop(desc.name, None)

        return run_ingest(
            list(paths), self.config, self._store.object_hashes(), write,
            jobs=jobs, progress=progress,
        )

    # ------------------------------------------------------------------ reading
    def _info(self, row: ObjectRow) -> ObjectInfo:
        return ObjectInfo(
            name=row.name, source=row.source, content_hash=row.content_hash,
            n_faces=row.n_faces, n_vertices=row.n_vertices, scale=row.scale,
            centre=row.centre, views_stored=row.views,
            views_grid=len(grid_views(self.config.gap)), empty_views=row.empty_views,
            ingest_seconds=row.ingest_seconds, created_at=row.created_at,
        )

    def objects(self) -> list[ObjectInfo]:
        """Every object, by name."""
        return [self._info(r) for r in self._store.objects()]

    def object(self, name: str) -> ObjectInfo:
        for info in self.objects():
            if info.name == name:
                return info
        raise NotFound(f"no object named {name!r}", self.path)

    def views(self, name: str) -> list[tuple[float, float]]:
        """``(azimuth, elevation)`` of every stored view of object ``name``."""
        return [(v.azimuth, v.elevation) for v in self._store.views(name)]

    def view(self, name: str, azimuth: float, elevation: float) -> StoredView:
        """The stored features of one view."""
        a, e = normalise_angle(azimuth), normalise_angle(elevation)
        f = self._store.view_features(name, a, e)
        return StoredView(name, a, e, f["curve"], f["fourier"], f["keypoints"],
                          f["descriptors"], f["points3d"])

    def mesh(self, name: str) -> NormalisedMesh:
        """The stored normalised mesh of ``name`` (decoded once, then cached)."""
        mesh = self._meshes.get(name)
        if mesh is None:
            mesh = mesh_from_glb(self._store.mesh_glb(name), name)
            self._meshes[name] = mesh
            while len(self._meshes) > MESH_CACHE_SIZE:
                self._meshes.popitem(last=False)
        else:
            self._meshes.move_to_end(name)
        return mesh

    def render(self, name: str, azimuth: float, elevation: float) -> RenderedView:
        """Render any view of a stored object from the database alone."""
        return get_renderer(self.config.render).render(self.mesh(name), azimuth, elevation)

    def check(self, progress: Callable[[int, int], None] | None = None) -> CheckReport:
        """Verify the file (see :mod:`viewdb.storage.integrity`); findings are in the report."""
        return check_store(self._store, progress)

    def info(self) -> DatabaseInfo:
        return DatabaseInfo(
            path=str(self.path), file_bytes=_file_bytes(self.path),
            schema_revision=self._store.revision() or SCHEMA_REVISION, config=self.config,
            objects=self.objects(), rows=self._store.table_counts(),
        )


def _file_bytes(path: Path) -> int:
    total = 0
    for suffix in ("", "-wal"):
        p = Path(str(path) + suffix)
        if p.exists():
            total += p.stat().st_size
    return total


def open(  # noqa: A001 - mirrors sqlite3.connect / builtins.open on purpose
    path: str | Path,
    *,
    create: bool = True,
    gap: float | None = None,
    image_size: int | None = None,
    config: BuildConfig | None = None,
) -> ViewDB:
    """Open (or create) a view database file.

    A new file takes its build configuration from ``config`` (default
    :class:`~viewdb.config.BuildConfig`), with ``gap`` and ``image_size`` overriding it. An
    existing file keeps the configuration it was built with; asking for a different
    ``gap`` or ``image_size`` raises :class:`~viewdb.errors.ViewDBError`.
    """
    store = Store(path, create=create)
    try:
        stored = store.build_config()
        if stored is None:
            wanted = config or BuildConfig()
            if gap is not None:
                wanted = replace(wanted, gap=float(gap))
            if image_size is not None:
                wanted = replace(wanted, render=replace(wanted.render, image_size=image_size))
            store.set_build_config(wanted)
            stored = wanted
        else:
            if gap is not None and float(gap) != stored.gap:
                raise ViewDBError(
                    f"was built with --gap {stored.gap:g}, not {gap:g}; "
                    "use a new database file for another grid", path,
                )
            if image_size is not None and image_size != stored.render.image_size:
                raise ViewDBError(
                    f"was built with --image-size {stored.render.image_size}, not {image_size}",
                    path,
                )
        return ViewDB(store, stored)
    except BaseException:
        store.close()
        raise


def render_model(
    path: str | Path, azimuth: float, elevation: float, *, image_size: int = 256
) -> RenderedView:
    """Render one view of a mesh file (normalised as ingest would) without a database."""
    mesh = load_mesh(path)
    return get_renderer(RenderConfig(image_size=image_size)).render(mesh, azimuth, elevation)


def describe_paths(paths: Sequence[str | Path]) -> list[Path]:
    """Expand folders into the mesh files they hold (sorted), keep files as given."""
    from .mesh import MESH_SUFFIXES

    out: list[Path] = []
    for raw in paths:
        p = Path(raw)
        if p.is_dir():
            out.extend(sorted(q for q in p.iterdir() if q.suffix.lower() in MESH_SUFFIXES))
        else:
            out.append(p)
    return out
