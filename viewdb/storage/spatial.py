"""R-trees (libspatialindex, via ``rtree``) whose pages live inside the SQLite database file.

A viewdb database stays one file: the nodes of each R-tree are rows of ``rtree_pages``
(one BLOB per libspatialindex page) and opening the file reads the tree as it is, nothing
is rebuilt.

Tables (created by :func:`ensure_table`; meant to move into an Alembic migration)::

    rtree_pages(tier TEXT, page INTEGER, data BLOB, PRIMARY KEY(tier, page))
    rtree_meta (tier TEXT PRIMARY KEY, dimension INTEGER, header_page INTEGER)

``tier`` names one tree, so several trees share the tables.  ``rtree_meta`` holds the
dimension (libspatialindex keeps it in its header page too, but the Python wrapper uses
``properties.dimension`` to marshal coordinates, and an ``rtree.index.Index`` reopened
without it silently becomes 2-D) and the page of the tree's header.

Connection
----------
Everything takes a plain :class:`sqlite3.Connection`.  From SQLAlchemy, pass the DBAPI
connection of a :class:`sqlalchemy.engine.Connection`: ``conn.connection.driver_connection``;
the pages are then written in the same SQLite transaction as the rest of the work.

Transactions
------------
The index never commits or rolls back on its own; its page writes go into whatever
transaction the connection has open (``sqlite3``'s legacy mode opens one implicitly on
the first write).  But libspatialindex keeps state *in memory* too: the tree header (root
page, height, entry count) is written only on :meth:`FourierIndex.flush` / ``close``, and
nodes are cached (and, unless ``writethrough=True``, dirty nodes are written only on flush).
Therefore:

* call :meth:`FourierIndex.flush` before committing (``transaction()`` does it for you);
* after a rollback that undid index writes, call :meth:`FourierIndex.reload`, which drops
  the in-memory tree *without writing anything* and reopens it from the table.

:meth:`FourierIndex.transaction` packages this: it runs the block in a SAVEPOINT (inside
the caller's transaction if one is open, else in its own ``BEGIN``/``COMMIT``), flushes on
success and on an exception rolls back to the savepoint and reloads, so the index is
exactly as before the block.  If the *caller's* outer transaction is later rolled back,
the caller must call :meth:`reload`.

Coordinates
-----------
The wrapped index is always created with ``interleaved=True``.  The public API never uses
rtree's flat coordinate tuples: points are length-``d`` vectors, boxes are two length-``d``
vectors ``lo`` and ``hi``, and :meth:`FourierIndex.leaves` returns ``(lo, hi)`` arrays
(``Index.leaves()`` returns ``mins + maxs`` whatever ``interleaved`` is).

Bulk loading uses rtree's stream loader (libspatialindex STR bulk load), which works with
custom storage (rtree's *array* loader does not accept a custom storage).  The bulk loader
sorts through temporary files of libspatialindex in the system temp folder (deleted when
done), not next to the database.
"""

from __future__ import annotations

import sqlite3
import uuid
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import rtree.core
import rtree.index
from numpy.typing import NDArray
from rtree.exceptions import RTreeError

from ..errors import NotFound, StorageError
from ..interrupts import interrupts_held

__all__ = ["FourierIndex", "SqlitePageStorage", "ensure_table", "raw_connection"]

#: Pages of libspatialindex nodes kept in memory per open index (a cache; see ``writethrough``).
DEFAULT_BUFFER_PAGES = 4096


def raw_connection(conn: Any) -> sqlite3.Connection:
    """A sqlite3 connection from a sqlite3 or SQLAlchemy connection."""
    if isinstance(conn, sqlite3.Connection):
        return conn
    dbapi = getattr(getattr(conn, "connection", None), "driver_connection", None)
    if isinstance(dbapi, sqlite3.Connection):
        return dbapi
    raise TypeError(f"need a sqlite3.Connection (or SQLAlchemy Connection), got {type(conn)!r}")


def ensure_table(conn: Any) -> None:
    """Create ``rtree_pages`` and ``rtree_meta`` if missing (does not commit)."""
    c = raw_connection(conn)
    c.execute(
        "CREATE TABLE IF NOT EXISTS rtree_pages ("
        " tier TEXT NOT NULL, page INTEGER NOT NULL, data BLOB NOT NULL,"
        " PRIMARY KEY (tier, page))"
    )
    c.execute(
        "CREATE TABLE IF NOT EXISTS rtree_meta ("
        " tier TEXT PRIMARY KEY, dimension INTEGER NOT NULL, header_page INTEGER NOT NULL)"
    )


class SqlitePageStorage(rtree.index.CustomStorage):
    """libspatialindex page storage in ``rtree_pages`` rows of one ``tier``.

    New pages (``page == NewPage``) get ``max(page) + 1`` of the tier (a counter kept in
    memory, initialised from the table).  An exception while *loading* is reported to
    libspatialindex as ``IllegalStateError`` (the rtree call fails with ``RTreeError``).
    An exception while *storing or deleting* is only kept in :attr:`error` and reported as
    success: libspatialindex also writes from its destructor, where an error code becomes
    a C++ exception that aborts the process.  :class:`FourierIndex` checks :attr:`error`
    after every call and raises :class:`~viewdb.errors.StorageError` (or, unchanged, an
    exception that is not an ``Exception``, such as ``KeyboardInterrupt``); the
    transaction is then incomplete and must be rolled back (and the index reloaded).
    :class:`FourierIndex` holds Ctrl-C during its calls (:mod:`viewdb.interrupts`), so a
    ``KeyboardInterrupt`` is raised after them, not inside these callbacks.

    When :attr:`detached` is set, writes and deletes are silently dropped: used to dispose
    of an in-memory tree that must not write back.
    """

    def __init__(self, conn: Any, tier: str) -> None:
        self.conn = raw_connection(conn)
        self.tier = str(tier)
        self.detached = False
        self.error: BaseException | None = None
        self.stats = {"loads": 0, "stores": 0, "deletes": 0}
        self._next_page = self._max_page() + 1

    def _max_page(self) -> int:
        row = self.conn.execute(
            "SELECT MAX(page) FROM rtree_pages WHERE tier = ?", (self.tier,)
        ).fetchone()
        return -1 if row is None or row[0] is None else int(row[0])

    def _fail(self, returnError: Any, exc: BaseException, code: int | None = None) -> None:
        self.error = exc
        returnError.contents.value = self.IllegalStateError if code is None else code

    # ---------------------------------------------------------------- contract
    @property
    def hasData(self) -> bool:  # type: ignore[override]
        return self._max_page() >= 0

    def create(self, returnError: Any) -> None:
        returnError.contents.value = self.NoError

    def destroy(self, returnError: Any) -> None:
        returnError.contents.value = self.NoError

    def flush(self, returnError: Any) -> None:
        # Pages are written as they come; committing is the caller's business.
        returnError.contents.value = self.NoError

    def clear(self) -> None:
        """Delete every page of the tier (rtree calls this for ``overwrite=True``)."""
        self.conn.execute("DELETE FROM rtree_pages WHERE tier = ?", (self.tier,))
        self._next_page = 0

    def loadByteArray(self, page: int, returnError: Any) -> bytes:
        try:
            row = self.conn.execute(
                "SELECT data FROM rtree_pages WHERE tier = ? AND page = ?", (self.tier, page)
            ).fetchone()
        except BaseException as exc:  # noqa: BLE001 - must not propagate into C
            self._fail(returnError, exc)
            return b""
        if row is None:
            returnError.contents.value = self.InvalidPageError
            return b""
        self.stats["loads"] += 1
        returnError.contents.value = self.NoError
        return bytes(row[0])

    def storeByteArray(self, page: int, data: bytes, returnError: Any) -> int:
        if page == self.NewPage:
            page = self._next_page
            self._next_page += 1
        if self.detached:
            returnError.contents.value = self.NoError
            return page
        try:
            self.conn.execute(
                "INSERT OR REPLACE INTO rtree_pages (tier, page, data) VALUES (?, ?, ?)",
                (self.tier, page, sqlite3.Binary(data)),
            )
        except BaseException as exc:  # noqa: BLE001
            self._fail(returnError, exc, self.NoError)  # see the class doc
            return page
        self.stats["stores"] += 1
        returnError.contents.value = self.NoError
        return page

    def deleteByteArray(self, page: int, returnError: Any) -> None:
        if self.detached:
            returnError.contents.value = self.NoError
            return
        try:
            cur = self.conn.execute(
                "DELETE FROM rtree_pages WHERE tier = ? AND page = ?", (self.tier, page)
            )
        except BaseException as exc:  # noqa: BLE001
            self._fail(returnError, exc, self.NoError)  # see the class doc
            return
        self.stats["deletes"] += 1
        returnError.contents.value = self.NoError if cur.rowcount else self.InvalidPageError


def _vec(x: object, d: int, name: str) -> NDArray[np.float64]:
    a = np.asarray(x, dtype=np.float64)
    if a.shape != (d,):
        raise ValueError(f"{name} must have shape ({d},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite")
    return a


def _stream(ids: NDArray[np.int64], pts: NDArray[np.float64]) -> Iterator[Any]:
    """rtree's stream-loader items (interleaved: mins then maxs; a point is a flat box)."""
    for i, p in zip(ids.tolist(), pts.tolist(), strict=True):
        yield int(i), (*p, *p), None


class FourierIndex:
    """An R-tree over ``d``-dimensional points stored in the database (see module doc).

    Use :meth:`create` or :meth:`open`, not the constructor.  Entry ids are int64; the
    index holds no payload objects.
    """

    def __init__(
        self,
        conn: Any,
        tier: str,
        dimension: int,
        header_page: int | None,
        *,
        stream: Iterable[tuple[int, tuple[float, ...], None]] | None = None,
        leaf_capacity: int = 100,
        index_capacity: int = 100,
        buffer_pages: int = DEFAULT_BUFFER_PAGES,
        writethrough: bool = False,
    ) -> None:
        self.conn = raw_connection(conn)
        self.tier = str(tier)
        self.dimension = int(dimension)
        self._options = {
            "leaf_capacity": leaf_capacity, "index_capacity": index_capacity,
            "buffer_pages": buffer_pages, "writethrough": writethrough,
        }
        self.header_page = header_page
        self.storage = SqlitePageStorage(self.conn, self.tier)
        self._index: rtree.index.Index | None = None
        self._open_index(stream)

    def _open_index(self, stream: Iterable[Any] | None = None) -> None:
        o = self._options
        props = rtree.index.Property()
        props.dimension = self.dimension
        props.leaf_capacity = o["leaf_capacity"]
        props.index_capacity = o["index_capacity"]
        props.buffering_capacity = o["buffer_pages"]
        props.writethrough = o["writethrough"]
        if self.header_page is not None:
            props.index_id = self.header_page
        args: tuple[Any, ...] = (self.storage,) if stream is None else (self.storage, stream)
        with self._native("cannot open the R-tree"):
            self._index = rtree.index.Index(*args, properties=props, interleaved=True)
        if self.header_page is None:
            # libspatialindex wrote its header page while constructing the tree; the live
            # properties of the index (not the Property passed in) say which page it is.
            live = rtree.index.Property(
                handle=rtree.core.rt.Index_GetProperties(self._index.handle), owned=True
            )
            self.header_page = int(live.index_id)

    def __del__(self) -> None:
        # Never write from the garbage collector (possibly after the connection is gone,
        # where a failing write inside libspatialindex's destructor aborts the process).
        try:
            self.discard()
        except Exception:  # noqa: BLE001  # pragma: no cover
            pass

    # ---------------------------------------------------------------- lifecycle
    @classmethod
    def create(
        cls, conn: Any, tier: str, dimension: int, **options: Any
    ) -> FourierIndex:
        """A new, empty tree ``tier`` (an existing one of that name is an error)."""
        c = raw_connection(conn)
        ensure_table(c)
        if int(dimension) < 1:
            raise ValueError("dimension must be >= 1")
        if c.execute("SELECT 1 FROM rtree_meta WHERE tier = ?", (tier,)).fetchone():
            raise StorageError(f"R-tree tier {tier!r} already exists")
        c.execute("DELETE FROM rtree_pages WHERE tier = ?", (tier,))  # orphans
        idx = cls(c, tier, dimension, None, **options)
        idx._register()
        return idx

    @classmethod
    def bulk_create(
        cls,
        conn: Any,
        tier: str,
        ids: Iterable[int] | NDArray[np.int64],
        points: NDArray[np.float64],
        **options: Any,
    ) -> FourierIndex:
        """A new tree ``tier`` built by libspatialindex's STR bulk loader (much faster and
        better packed than inserting one by one)."""
        c = raw_connection(conn)
        ensure_table(c)
        pts = np.asarray(points, dtype=np.float64)
        ids_arr = np.asarray(list(ids) if not isinstance(ids, np.ndarray) else ids, np.int64)
        if pts.ndim != 2 or len(pts) != len(ids_arr):
            raise ValueError("points must be (n, d) with one id per point")
        if not np.all(np.isfinite(pts)):
            raise ValueError("points must be finite")
        if c.execute("SELECT 1 FROM rtree_meta WHERE tier = ?", (tier,)).fetchone():
            raise StorageError(f"R-tree tier {tier!r} already exists")
        c.execute("DELETE FROM rtree_pages WHERE tier = ?", (tier,))
        d = pts.shape[1]
        if len(pts) == 0:
            return cls.create(c, tier, d, **options)
        idx = cls(c, tier, d, None, stream=_stream(ids_arr, pts), **options)
        idx._register()
        return idx

    @classmethod
    def open(cls, conn: Any, tier: str, **options: Any) -> FourierIndex:
        """The stored tree ``tier``, read as it is (nothing rebuilt)."""
        c = raw_connection(conn)
        try:
            row = c.execute(
                "SELECT dimension, header_page FROM rtree_meta WHERE tier = ?", (tier,)
            ).fetchone()
        except sqlite3.OperationalError as exc:
            if "no such table" in str(exc):
                raise NotFound(f"no R-tree tier {tier!r} (no R-tree tables)") from exc
            raise StorageError(f"database error: {exc}") from exc
        if row is None:
            raise NotFound(f"no R-tree tier {tier!r}")
        return cls(c, tier, int(row[0]), int(row[1]), **options)

    def _register(self) -> None:
        self.flush()
        self.conn.execute(
            "INSERT INTO rtree_meta (tier, dimension, header_page) VALUES (?, ?, ?)",
            (self.tier, self.dimension, self.header_page),
        )

    @property
    def index(self) -> rtree.index.Index:
        if self._index is None:
            raise StorageError(f"R-tree tier {self.tier!r} is closed")
        return self._index

    def flush(self) -> None:
        """Write the header and all buffered pages into the current SQLite transaction.

        ``rtree.index.Index.flush()`` writes the header but *not* the dirty pages of the
        libspatialindex buffer (only destroying the index does), so this closes the
        wrapped index and reopens it from the table (cheap: one header page is read).
        """
        self.close()
        self._open_index()

    def close(self) -> None:
        """Write everything (into the current transaction) and release the tree.  Does not
        commit.  An index dropped without ``close``/``flush`` writes nothing more."""
        if self._index is None:
            return
        index, self._index = self._index, None
        with self._native("cannot write the R-tree"):
            index.close()

    def discard(self) -> None:
        """Release the in-memory tree without writing anything to the database."""
        if self._index is None:
            return
        self.storage.detached = True
        index, self._index = self._index, None
        with interrupts_held():
            index.close()

    def reload(self) -> None:
        """Drop the in-memory state (without writing) and reopen the tree from the table;
        needed after a rollback that undid index writes."""
        self.discard()
        row = self.conn.execute(
            "SELECT dimension, header_page FROM rtree_meta WHERE tier = ?", (self.tier,)
        ).fetchone()
        if row is None:
            raise NotFound(f"no R-tree tier {self.tier!r} (rolled back its creation?)")
        self.dimension, self.header_page = int(row[0]), int(row[1])
        self.storage = SqlitePageStorage(self.conn, self.tier)
        self._open_index()

    @contextmanager
    def transaction(self) -> Iterator[FourierIndex]:
        """All-or-nothing changes to the index (see the module doc)."""
        outer = self.conn.in_transaction
        name = f"rtree_{uuid.uuid4().hex}"
        if not outer:
            self.conn.execute("BEGIN")
        self.conn.execute(f"SAVEPOINT {name}")
        try:
            yield self
            self.flush()
        except BaseException:
            self.conn.execute(f"ROLLBACK TO SAVEPOINT {name}")
            self.conn.execute(f"RELEASE SAVEPOINT {name}")
            if not outer:
                self.conn.rollback()
            self.reload()
            raise
        self.conn.execute(f"RELEASE SAVEPOINT {name}")
        if not outer:
            self.conn.commit()

    def __enter__(self) -> FourierIndex:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---------------------------------------------------------------- errors
    @contextmanager
    def _native(self, what: str) -> Iterator[None]:
        """A call into libspatialindex: Ctrl-C is held until it returns (see
        :mod:`viewdb.interrupts`); its errors and the page storage's are raised as
        :class:`~viewdb.errors.StorageError` saying ``what`` failed."""
        with interrupts_held():
            try:
                yield
            except RTreeError as exc:
                raise self._error(exc, what) from exc
        self._check_storage(what)

    def _error(self, exc: BaseException, what: str) -> BaseException:
        inner = self.storage.error
        self.storage.error = None
        if inner is not None and not isinstance(inner, Exception):
            return inner  # an interrupt or exit taken in a callback stays what it was
        detail = f"{inner}" if inner is not None else f"{exc}"
        return StorageError(f"{what} {self.tier!r}: {detail}")

    def _check_storage(self, what: str) -> None:
        if self.storage.error is not None:
            raise self._error(self.storage.error, what)

    # ---------------------------------------------------------------- contents
    def insert(self, id: int, point: object) -> None:
        p = _vec(point, self.dimension, "point")
        with self._native("cannot insert into the R-tree"):
            self.index.insert(int(id), (*p, *p))

    def insert_box(self, id: int, lo: object, hi: object) -> None:
        """Insert entry ``id`` with the box ``[lo, hi]`` (an MBR of several points)."""
        box = self._box(lo, hi)
        with self._native("cannot insert into the R-tree"):
            self.index.insert(int(id), box)

    def delete_box(self, id: int, lo: object, hi: object) -> None:
        """Remove entry ``id`` with the box ``[lo, hi]`` (exactly as inserted)."""
        box = self._box(lo, hi)
        with self._native("cannot delete from the R-tree"):
            self.index.delete(int(id), box)

    def intersection_boxes(
        self, lo: object, hi: object
    ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """Ids and boxes (``lo``, ``hi`` rows) of the entries that meet ``[lo, hi]``."""
        box = self._box(lo, hi)
        with self._native("cannot read the R-tree"):
            items = list(self.index.intersection(box, objects=True))
        d = self.dimension
        ids = np.fromiter((it.id for it in items), dtype=np.int64, count=len(items))
        bounds = np.array([it.bbox for it in items], dtype=np.float64).reshape(len(items), 2 * d)
        return ids, bounds[:, :d], bounds[:, d:]

    def bulk_load(self, ids: Iterable[int], points: object) -> None:
        """Insert many points.  Into an *empty* tree this rebuilds the tier with the STR
        bulk loader (the meta row is rewritten); otherwise it inserts one by one."""
        pts = np.asarray(points, dtype=np.float64)
        ids_arr = np.asarray(list(ids) if not isinstance(ids, np.ndarray) else ids, np.int64)
        if pts.ndim != 2 or pts.shape[1] != self.dimension or len(pts) != len(ids_arr):
            raise ValueError(f"points must be (n, {self.dimension}) with one id per point")
        if not np.all(np.isfinite(pts)):
            raise ValueError("points must be finite")
        if len(pts) and self.count == 0:
            self.discard()
            self.conn.execute("DELETE FROM rtree_meta WHERE tier = ?", (self.tier,))
            self.conn.execute("DELETE FROM rtree_pages WHERE tier = ?", (self.tier,))
            self.storage = SqlitePageStorage(self.conn, self.tier)
            self.header_page = None
            self._open_index(_stream(ids_arr, pts))
            self._register()
            return
        for i, p in zip(ids_arr.tolist(), pts, strict=True):
            self.insert(i, p)

    def delete(self, id: int, point: object) -> None:
        """Remove entry ``id`` at ``point`` (rtree needs the coordinates to find it)."""
        p = _vec(point, self.dimension, "point")
        with self._native("cannot delete from the R-tree"):
            self.index.delete(int(id), (*p, *p))

    def _box(self, lo: object, hi: object) -> tuple[float, ...]:
        a, b = _vec(lo, self.dimension, "lo"), _vec(hi, self.dimension, "hi")
        if np.any(a > b):
            raise ValueError("lo must be <= hi")
        return (*a, *b)

    def intersection(self, lo: object, hi: object) -> NDArray[np.int64]:
        """Ids of the points in the closed box ``[lo, hi]``, sorted."""
        box = self._box(lo, hi)
        with self._native("cannot read the R-tree"):
            out = np.fromiter(self.index.intersection(box), dtype=np.int64)
        out.sort()
        return out

    def intersection_many(self, los: NDArray[np.float64], his: NDArray[np.float64]) -> NDArray[np.int64]:
        """Ids of the points in any of the closed boxes ``[los[i], his[i]]`` (rows of
        ``(n, d)`` arrays), sorted and unique; one call into libspatialindex."""
        lo = np.ascontiguousarray(los, dtype=np.float64).reshape(-1, self.dimension)
        hi = np.ascontiguousarray(his, dtype=np.float64).reshape(-1, self.dimension)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(lo > hi):
            raise ValueError("boxes must be finite with lo <= hi")
        with self._native("cannot read the R-tree"):
            ids, _ = self.index.intersection_v(lo, hi)
        return np.unique(ids.astype(np.int64))

    @property
    def count(self) -> int:
        """Number of entries."""
        inf = np.full(self.dimension, np.inf)
        with self._native("cannot read the R-tree"):
            return int(self.index.count((*(-inf), *inf)))

    def __len__(self) -> int:
        return self.count

    def leaves(self) -> list[tuple[int, NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]]:
        """``(node page, child ids, lo, hi)`` for every leaf node (an empty tree has one
        empty leaf whose bounds are meaningless)."""
        with self._native("cannot read the R-tree"):
            raw = self.index.leaves()
        d = self.dimension
        out = []
        for node, children, bounds in raw:
            b = np.asarray(bounds, dtype=np.float64)
            out.append((int(node), np.asarray(children, np.int64), b[:d].copy(), b[d:].copy()))
        return out
