"""viewdb: an embedded, SQLite-backed view database that recognises which known 3-D object
a photo shows and from which viewpoint (after Tak & Hwang, "3D Object Retrieval and Pose
Estimation for a Single-view Query Image in a Mobile Environment").

>>> import viewdb
>>> with viewdb.open("catalogue.db", gap=30) as db:          # doctest: +SKIP
...     db.ingest(["mug.glb", "chair.obj"])
...     db.objects()
"""

from .api import (
    CandidatePose,
    DatabaseInfo,
    ObjectInfo,
    QueryResult,
    Recognition,
    SearchHit,
    StoredView,
    ViewDB,
    describe_paths,
    open,
    render_model,
)
from .catalogue.ingest import FileOutcome, IngestProgress, IngestReport
from .catalogue.mesh import DEFAULT_MAX_FACES
from .catalogue.render import RenderedView
from .catalogue.symmetry import SymmetryType
from .config import (
    BuildConfig,
    FeatureConfig,
    IndexConfig,
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
    ViewDBError,
)
from .http.client import RemoteServer
from .pose.intrinsics import parse_intrinsics
from .search.plans import Candidate, RefineRequest, ServerReply, WalkRequest
from .search.shifts import ShiftWindow

__version__ = "0.1.0"

__all__ = [
    "BuildConfig",
    "DEFAULT_MAX_FACES",
    "Candidate",
    "CandidatePose",
    "DatabaseInfo",
    "FeatureConfig",
    "FeatureError",
    "FileOutcome",
    "ImageError",
    "IndexConfig",
    "IngestProgress",
    "IngestReport",
    "MeshError",
    "NotFound",
    "ObjectInfo",
    "PoseError",
    "QueryError",
    "QueryResult",
    "Recognition",
    "RefineRequest",
    "RemoteServer",
    "RenderConfig",
    "RenderError",
    "RenderedView",
    "SchemaMismatch",
    "SearchConfig",
    "SearchHit",
    "ServerError",
    "ServerReply",
    "ShiftWindow",
    "SiftConfig",
    "SkimConfig",
    "StorageError",
    "StoredView",
    "SymmetryType",
    "ViewDB",
    "ViewDBError",
    "WalkRequest",
    "__version__",
    "describe_paths",
    "open",
    "parse_intrinsics",
    "render_model",
]
