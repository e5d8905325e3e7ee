"""viewdb: an embedded, SQLite-backed view database that recognises which known 3-D object
a photo shows and from which viewpoint (after Tak & Hwang, "3D Object Retrieval and Pose
Estimation for a Single-view Query Image in a Mobile Environment").

>>> import viewdb
>>> with viewdb.open("catalogue.db", gap=30) as db:          # doctest: +SKIP
...     db.ingest(["mug.glb", "chair.obj"])
...     db.query("photo.jpg").results[0].object

The wire messages of the client–server plans live in :mod:`viewdb.http`.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

# cheap and needed to report any error: imported at once
from .config import (
    DEFAULT_MAX_FACES,
    AppearanceConfig,
    BuildConfig,
    FeatureConfig,
    IndexConfig,
    MatchedPoseConfig,
    PerspectiveConfig,
    RecognitionConfig,
    RenderConfig,
    SiftConfig,
    SkimConfig,
)
from .errors import (
    FeatureError,
    ImageError,
    MeshError,
    NotFound,
    PoseError,
    QueryError,
    RenderError,
    SchemaMismatch,
    ServerError,
    StorageError,
    UpgradeNeeded,
    ViewDBError,
)

#: Where each of the other public names lives. They are imported on first use (PEP 562),
#: so ``import viewdb`` (and ``viewdb --help``) does not load trimesh, SciPy, numba or
#: SQLAlchemy; ``viewdb.open`` and the rest work as plain attributes.
_LAZY: dict[str, str] = {
    **dict.fromkeys(("DatabaseInfo", "ViewDB", "describe_paths", "open", "render_model"), "api"),
    "Appearance": "catalogue.appearance",
    **dict.fromkeys(("FileOutcome", "IngestProgress", "IngestReport", "IngestTarget"), "catalogue.ingest"),
    "NormalisedMesh": "catalogue.mesh",
    **dict.fromkeys(("CandidatePose", "CatalogueReader", "ObjectInfo", "StoredView"), "catalogue.reading"),
    "RenderedView": "catalogue.render",
    "ViewClasses": "catalogue.skimming",
    "SymmetryType": "catalogue.symmetry",
    "RemoteServer": "http.client",
    **dict.fromkeys(("PoseConfig", "PoseEstimate"), "pose.estimate"),
    **dict.fromkeys(("Intrinsics", "parse_intrinsics"), "pose.intrinsics"),
    "LocalServerTier": "recognition.local_tier",
    "QueryOptions": "recognition.options",
    **dict.fromkeys(("Box", "Point", "Region", "parse_box", "parse_point"), "recognition.regions"),
    **dict.fromkeys(("ObjectResult", "QueryMatch", "QueryResult"), "recognition.results"),
    "Recognition": "recognition.retrieval",
    **dict.fromkeys(("Exchange", "ServerTier"), "recognition.server_tier"),
    **dict.fromkeys(("SearchStats", "TierArrays"), "search.knn"),
    "ColourMatch": "search.colour_index",
    "Candidate": "search.plans",
    "ShiftWindow": "search.shifts",
    "SearchHit": "recognition.results",
    "CheckReport": "storage.integrity",
}

if TYPE_CHECKING:  # what the lazy names are, for type checkers and editors
    from .api import DatabaseInfo, ViewDB, describe_paths, open, render_model
    from .catalogue.appearance import Appearance
    from .catalogue.ingest import FileOutcome, IngestProgress, IngestReport, IngestTarget
    from .catalogue.mesh import NormalisedMesh
    from .catalogue.reading import CandidatePose, CatalogueReader, ObjectInfo, StoredView
    from .catalogue.render import RenderedView
    from .catalogue.skimming import ViewClasses
    from .catalogue.symmetry import SymmetryType
    from .http.client import RemoteServer
    from .pose.estimate import PoseConfig, PoseEstimate
    from .pose.intrinsics import Intrinsics, parse_intrinsics
    from .recognition.local_tier import LocalServerTier
    from .recognition.options import QueryOptions
    from .recognition.regions import Box, Point, Region, parse_box, parse_point
    from .recognition.results import ObjectResult, QueryMatch, QueryResult, SearchHit
    from .recognition.retrieval import Recognition
    from .recognition.server_tier import Exchange, ServerTier
    from .search.colour_index import ColourMatch
    from .search.knn import SearchStats, TierArrays
    from .search.plans import Candidate
    from .search.shifts import ShiftWindow
    from .storage.integrity import CheckReport

    __version__: str


def __getattr__(name: str) -> Any:
    if name == "__version__":  # the installed distribution's, as pyproject.toml gives it
        from importlib.metadata import version

        return version("viewdb")
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'viewdb' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # the next look-up is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = [
    "Appearance",
    "AppearanceConfig",
    "Box",
    "BuildConfig",
    "Candidate",
    "CandidatePose",
    "CatalogueReader",
    "CheckReport",
    "ColourMatch",
    "DEFAULT_MAX_FACES",
    "DatabaseInfo",
    "Exchange",
    "FeatureConfig",
    "FeatureError",
    "FileOutcome",
    "ImageError",
    "IndexConfig",
    "IngestProgress",
    "IngestReport",
    "IngestTarget",
    "Intrinsics",
    "LocalServerTier",
    "MatchedPoseConfig",
    "MeshError",
    "NormalisedMesh",
    "NotFound",
    "ObjectInfo",
    "ObjectResult",
    "PerspectiveConfig",
    "Point",
    "PoseConfig",
    "PoseError",
    "PoseEstimate",
    "QueryError",
    "QueryMatch",
    "QueryOptions",
    "QueryResult",
    "Recognition",
    "RecognitionConfig",
    "Region",
    "RemoteServer",
    "RenderConfig",
    "RenderError",
    "RenderedView",
    "SchemaMismatch",
    "SearchHit",
    "SearchStats",
    "ServerError",
    "ServerTier",
    "ShiftWindow",
    "SiftConfig",
    "SkimConfig",
    "StorageError",
    "StoredView",
    "SymmetryType",
    "TierArrays",
    "UpgradeNeeded",
    "ViewClasses",
    "ViewDB",
    "ViewDBError",
    "__version__",
    "describe_paths",
    "open",
    "parse_box",
    "parse_intrinsics",
    "parse_point",
    "render_model",
]
