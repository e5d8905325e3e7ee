"""The read side of a catalogue: the records a built file gives back, and the protocol the
later stages (recognition, pose) read it through.

:class:`CatalogueReader` is what recognition and pose need of a catalogue; the one that
reads a viewdb file is :class:`viewdb.storage.stored_catalogue.StoredCatalogue`. Depending on the
protocol, not on the file, keeps the stages free of storage and of the facade.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from ..config import BuildConfig
from .appearance import Appearance
from .mesh import NormalisedMesh
from .render import RenderedView
from .skimming import ViewClasses
from .symmetry import SymmetryType

__all__ = ["CandidatePose", "CatalogueReader", "ObjectInfo", "StoredView"]


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
    #: Whether only the skim plan's views are stored (``--no-skim`` stores the grid).
    skimmed: bool = False
    #: The symmetry type; None for objects ingested before schema revision 0002.
    symmetry: SymmetryType | None = None
    #: Perspective silhouettes stored (0 for objects ingested before revision 0004).
    perspective_views: int = 0
    #: Appearance records stored (0 for objects ingested before revision 0005).
    appearances: int = 0

    def to_dict(self) -> dict[str, Any]:
        sym = self.symmetry
        return {
            "name": self.name, "source": self.source, "content_hash": self.content_hash,
            "faces": self.n_faces, "vertices": self.n_vertices, "scale": self.scale,
            "centre": list(self.centre),
            "h_type": sym.h_type if sym else None, "v_type": sym.v_type if sym else None,
            "h_period": sym.h_period if sym else None,
            "v_period": sym.v_period if sym else None,
            "base_view": [sym.base_azimuth, sym.base_elevation] if sym else None,
            "skimmed": self.skimmed, "views_stored": self.views_stored,
            "views_grid": self.views_grid, "empty_views": self.empty_views,
            "perspective_views": self.perspective_views, "appearances": self.appearances,
            "ingest_seconds": round(self.ingest_seconds, 3), "created_at": self.created_at,
        }


@dataclass(frozen=True, eq=False)
class StoredView:
    """A view's features: read from the database, or regenerated from the stored mesh."""

    object: str
    azimuth: float
    elevation: float
    curve: NDArray[np.float32] = field(repr=False)
    fourier: NDArray[np.complex128] = field(repr=False)
    keypoints: NDArray[np.float32] = field(repr=False)
    descriptors: NDArray[np.uint8] = field(repr=False)
    points3d: NDArray[np.float32] = field(repr=False)
    #: False when read from the database; True when rendered and described on demand
    #: (a view the skim plan pruned, or one off the grid).
    regenerated: bool = False
    #: For a pruned grid view: the stored view it maps to, and whether its curve is that
    #: view's curve reversed. None for stored and off-grid views.
    stored_as: tuple[float, float] | None = None
    mirrored: bool = False


@dataclass(frozen=True)
class CandidatePose:
    """A grid view whose silhouette is the same as (or the mirror of) a matched view's."""

    azimuth: float
    elevation: float
    #: The candidate's distance curve is the matched view's curve reversed.
    mirrored: bool
    #: Whether the database stores this view (otherwise it is regenerated on demand).
    stored: bool


class CatalogueReader(Protocol):
    """What recognition and pose read of a full catalogue (meshes and every view)."""

    @property
    def config(self) -> BuildConfig: ...

    def object(self, name: str) -> ObjectInfo:
        """The object ``name`` (:class:`~viewdb.errors.NotFound` if there is none)."""
        ...

    def mesh(self, name: str) -> NormalisedMesh:
        """The stored normalised mesh of ``name``."""
        ...

    def view(self, name: str, azimuth: float, elevation: float) -> StoredView:
        """Any view's features: stored, or regenerated from the mesh."""
        ...

    def render(self, name: str, azimuth: float, elevation: float) -> RenderedView:
        """Any view rendered from the stored mesh (arrays read-only)."""
        ...

    def appearance(self, name: str, azimuth: float, elevation: float) -> Appearance:
        """Any view's appearance: stored, or made from its render."""
        ...

    def view_plan(self, name: str) -> ViewClasses:
        """How the object's grid views map to its stored ones."""
        ...

    def candidate_poses(self, name: str, azimuth: float, elevation: float) -> list[CandidatePose]:
        """Every grid view with the same or the mirrored silhouette as grid view (h, v)."""
        ...

    def nearest_views(
        self, name: str, curve: NDArray[np.floating], n: int, *, band: int = 6
    ) -> list[tuple[float, float, float]]:
        """The ``n`` stored views of ``name`` nearest a query curve, ``(h, v, distance)``."""
        ...
