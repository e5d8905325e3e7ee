"""viewdb: an embedded, SQLite-backed view database that recognises which known 3-D object
a photo shows and from which viewpoint (after Tak & Hwang, "3D Object Retrieval and Pose
Estimation for a Single-view Query Image in a Mobile Environment").

>>> import viewdb
>>> with viewdb.open("catalogue.db", gap=30) as db:          # doctest: +SKIP
...     db.ingest(["mug.glb", "chair.obj"])
...     db.query("photo.jpg").results[0].object

The wire messages of the client–server plans live in :mod:`viewdb.http`.
"""

from .api import DatabaseInfo, ViewDB, describe_paths, open, render_model
from .catalogue.appearance import Appearance
from .catalogue.ingest import FileOutcome, IngestProgress, IngestReport
from .catalogue.mesh import DEFAULT_MAX_FACES, NormalisedMesh
from .catalogue.reading import CandidatePose, CatalogueReader, ObjectInfo, StoredView
from .catalogue.render import RenderedView
from .catalogue.skimming import ViewClasses
from .catalogue.symmetry import SymmetryType
from .config import (
    AppearanceConfig,
    BuildConfig,
    FeatureConfig,
    IndexConfig,
    PerspectiveConfig,
    PosingConfig,
    RecognitionConfig,
    RenderConfig,
    SearchConfig,
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
from .http.client import RemoteServer
from .pose.estimate import PoseConfig, PoseEstimate
from .pose.intrinsics import Intrinsics, parse_intrinsics
from .recognition.local_tier import LocalServerTier
from .recognition.options import QueryOptions
from .recognition.results import QueryMatch, QueryResult
from .recognition.retrieval import Recognition
from .recognition.server_tier import Exchange, ServerTier
from .search.knn import SearchStats, TierArrays
from .search.plans import Candidate
from .search.shifts import ShiftWindow
from .storage.catalogue import SearchHit
from .storage.integrity import CheckReport

__version__ = "0.1.0"

__all__ = [
    "Appearance",
    "AppearanceConfig",
    "BuildConfig",
    "Candidate",
    "CandidatePose",
    "CatalogueReader",
    "CheckReport",
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
    "Intrinsics",
    "LocalServerTier",
    "MeshError",
    "NormalisedMesh",
    "NotFound",
    "ObjectInfo",
    "PerspectiveConfig",
    "PoseConfig",
    "PoseError",
    "PoseEstimate",
    "PosingConfig",
    "QueryError",
    "QueryMatch",
    "QueryOptions",
    "QueryResult",
    "Recognition",
    "RecognitionConfig",
    "RemoteServer",
    "RenderConfig",
    "RenderError",
    "RenderedView",
    "SchemaMismatch",
    "SearchConfig",
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
    "parse_intrinsics",
    "render_model",
]
