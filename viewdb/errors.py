"""Every error viewdb raises on purpose.

Catch :class:`ViewDBError` to handle them all. The tree::

    ViewDBError                 root; str(err) is one line naming the file and the problem
    ├── MeshError               a mesh file cannot be loaded, is empty, or has no area
    ├── RenderError             the offscreen renderer (EGL/OSMesa) is unavailable or failed
    ├── FeatureError            a silhouette has no usable contour
    ├── ImageError              a query image is unreadable or shows no object
    ├── StorageError            the database file is unreadable, corrupt or busy
    │   ├── SchemaMismatch      the file's schema is newer than this viewdb knows
    │   ├── UpgradeNeeded       opened read-only, the file's schema is too old to read as it is
    │   ├── NotFound            an object or view asked for is not in the database
    │   └── ShardUnavailable    a shard of a sharded catalogue stopped answering (its actor died)
    ├── QueryError              a query cannot be answered as asked
    ├── PoseError               a pose cannot be estimated
    └── ServerError             a viewdb server cannot be reached or refused a request

Every error carries an optional ``path`` (the file it is about), so the CLI can print
``viewdb: <path>: <problem>`` on one line.
"""

from __future__ import annotations

from os import PathLike

__all__ = [
    "FeatureError",
    "ImageError",
    "MeshError",
    "NotFound",
    "PoseError",
    "QueryError",
    "RenderError",
    "SchemaMismatch",
    "ServerError",
    "ShardUnavailable",
    "StorageError",
    "UpgradeNeeded",
    "ViewDBError",
]


class ViewDBError(Exception):
    """Root of every error viewdb raises on purpose."""

    def __init__(self, message: str, path: str | PathLike[str] | None = None) -> None:
        self.message = " ".join(str(message).split())  # always one line
        self.path = None if path is None else str(path)
        super().__init__(self.__str__())

    def __str__(self) -> str:
        return f"{self.path}: {self.message}" if self.path else self.message


class MeshError(ViewDBError):
    """A mesh file cannot be loaded, is empty, or has no area."""


class RenderError(ViewDBError):
    """The offscreen renderer is unavailable or failed."""


class FeatureError(ViewDBError):
    """A silhouette has no usable contour."""


class ImageError(ViewDBError):
    """A query image is unreadable or shows no object."""


class StorageError(ViewDBError):
    """The database file is unreadable, corrupt or busy."""


class SchemaMismatch(StorageError):
    """The file's schema is newer (or otherwise unknown) to this version of viewdb."""


class UpgradeNeeded(StorageError):
    """Opened read-only, the file's schema is older than this viewdb reads as it is: it
    must be opened once normally (which upgrades it in place)."""


class NotFound(StorageError):
    """An object or view asked for is not in the database."""


class ShardUnavailable(StorageError):
    """A shard of a sharded catalogue did not answer (its Ray actor died or its node was
    lost): the query fails as a whole rather than answer from the other shards.
    ``retry_after``: seconds after which the shard is expected back (its actor is being
    restarted), or None if it is not coming back by itself."""

    def __init__(self, message: str, path: str | PathLike[str] | None = None,
                 retry_after: float | None = None) -> None:
        super().__init__(message, path)
        self.retry_after = retry_after


class QueryError(ViewDBError):
    """A query cannot be answered as asked."""


class PoseError(ViewDBError):
    """A pose cannot be estimated."""


class ServerError(ViewDBError):
    """A viewdb server (``viewdb serve``) cannot be reached, or refused a request; the
    ``path`` is its URL, ``status`` the HTTP status (None if none came back)."""

    def __init__(self, message: str, path: str | PathLike[str] | None = None,
                 status: int | None = None) -> None:
        super().__init__(message, path)
        self.status = status
