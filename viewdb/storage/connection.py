"""The database file's connections: opening, schema versioning and transactions.

One SQLite file per database, in WAL mode. Every connection sets ``journal_mode=WAL``,
``busy_timeout``, ``synchronous=NORMAL`` and ``foreign_keys=ON``. The schema is created and
upgraded only by the Alembic migrations in ``migrations/``; opening an older file upgrades
it, a file from a newer viewdb is refused with :class:`~viewdb.errors.SchemaMismatch`.
SQLAlchemy and sqlite3 errors are turned into :class:`~viewdb.errors.StorageError` here.

``Database(path, read_only=True)`` never writes to the file: it connects through SQLite's
``mode=ro`` URI with ``query_only`` on, sets no journal mode and runs no migration (a file
that would need one is refused with a message saying to open it once normally, unless the
migrations since its revision only add tables it can do without:
:data:`READ_ONLY_COMPATIBLE`, TEMP tables standing in for them). A file
in a folder that cannot be written, with no WAL beside it, is opened ``immutable=1``
(SQLite could not make its ``-shm`` there); such a file must not change while it is open.

The rows themselves are read and written by :class:`~viewdb.storage.store.Store`.
"""

from __future__ import annotations

import json
import os
import sqlite3
import urllib.parse
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import sqlalchemy as sa
from sqlalchemy import event
from sqlalchemy.engine import Connection, Engine

from ..config import BuildConfig
from ..errors import SchemaMismatch, StorageError, UpgradeNeeded
from ..paths import not_regular
from . import schema as s
from .tier_file import generation, stamp_tiers

__all__ = ["READ_ONLY_COMPATIBLE", "Database", "alembic_config", "known_revisions", "read_only_uri"]

SQLITE_HEADER = b"SQLite format 3\x00"
BUSY_TIMEOUT_MS = 10_000
MIGRATIONS_DIR = Path(__file__).resolve().parents[2] / "migrations"


def _migrations_dir() -> Path:
    try:  # installed layout: migrations are shipped as the viewdb_migrations package
        import viewdb_migrations

        return Path(viewdb_migrations.__file__).resolve().parent
    except ImportError:  # pragma: no cover - running from a source tree without install
        return MIGRATIONS_DIR


def alembic_config(connection: Connection):  # type: ignore[no-untyped-def]
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(_migrations_dir()))
    cfg.attributes["connection"] = connection
    return cfg


def known_revisions() -> set[str]:
    """Revisions of ``migrations/versions`` (what this viewdb can read)."""
    from alembic.config import Config
    from alembic.script import ScriptDirectory

    cfg = Config()
    cfg.set_main_option("script_location", str(_migrations_dir()))
    return {rev.revision for rev in ScriptDirectory.from_config(cfg).walk_revisions()}


def _set_pragmas(dbapi_conn: sqlite3.Connection, _record: object) -> None:
    cur = dbapi_conn.cursor()
    cur.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")
    cur.execute("PRAGMA journal_mode=WAL")
    cur.execute("PRAGMA synchronous=NORMAL")
    cur.execute("PRAGMA foreign_keys=ON")
    cur.close()


#: Older schema revisions a read-only open accepts, with what the revisions since then
#: added: empty tables, which TEMP tables of the same shape stand in for on each
#: connection (SQLite keeps TEMP tables out of the file, so the file is never written).
#: Revision 0004 only added the perspective views: a file from 0003 (a client file
#: shipped to a device, say) has none and searches as before. Revision 0005 only added
#: the stored appearance: without it a query renders what it compares (slower).
_PERSPECTIVE_STAND_IN = (
    "CREATE TEMP TABLE IF NOT EXISTS perspective_views (id INTEGER PRIMARY KEY,"
    " object_id INTEGER NOT NULL, azimuth FLOAT NOT NULL, elevation FLOAT NOT NULL,"
    " distance FLOAT NOT NULL, samples BLOB NOT NULL)"
)
_APPEARANCE_STAND_INS = (
    "CREATE TEMP TABLE IF NOT EXISTS appearances (id INTEGER PRIMARY KEY,"
    " object_id INTEGER NOT NULL, azimuth FLOAT NOT NULL, elevation FLOAT NOT NULL,"
    " offset INTEGER NOT NULL, size INTEGER NOT NULL)",
    "CREATE TEMP TABLE IF NOT EXISTS appearance_blobs (object_id INTEGER PRIMARY KEY, data BLOB NOT NULL)",
)
#: Revision 0006 only added the quantisation errors of a compact client file's curves:
#: a file without them stores exact curves.
_CURVE_ERRORS_STAND_IN = (
    "CREATE TEMP TABLE IF NOT EXISTS curve_errors (group_id INTEGER PRIMARY KEY, errors BLOB NOT NULL)"
)
#: Revision 0007 only added an index (`migrations/versions/0007_object_versions_index.py`):
#: without it the same rows are read through the table, more slowly. Revision 0008 only
#: marked the objects whose appearance records cover every grid direction, which only an
#: ingest reads (a query renders any view without a record, as before).
_SCOPES_STAND_IN = (
    "CREATE TEMP TABLE IF NOT EXISTS appearance_scopes (object_id INTEGER PRIMARY KEY, scope TEXT NOT NULL)"
)
#: Revision 0009 only added the tiers' stamped keys: without them a tier's key is computed.
_STAMPS_STAND_IN = (
    "CREATE TEMP TABLE IF NOT EXISTS tier_stamps (tier TEXT PRIMARY KEY, generation TEXT NOT NULL,"
    " key TEXT NOT NULL)"
)
#: Revision 0010 only added the coloured objects' look samples, which only an ingest reads.
_LOOK_SAMPLES_STAND_IN = (
    "CREATE TEMP TABLE IF NOT EXISTS look_samples (object_id INTEGER PRIMARY KEY, config TEXT NOT NULL,"
    " looks BLOB NOT NULL)"
)
#: The stand-ins each revision's tables need in a file from before it, in revision order.
_ADDED_BY: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("0004", (_PERSPECTIVE_STAND_IN,)),
    ("0005", _APPEARANCE_STAND_INS),
    ("0006", (_CURVE_ERRORS_STAND_IN,)),
    ("0007", ()),
    ("0008", (_SCOPES_STAND_IN,)),
    ("0009", (_STAMPS_STAND_IN,)),
    ("0010", (_LOOK_SAMPLES_STAND_IN,)),
)
#: Per older revision a file may be read at, the stand-ins of every revision after it.
READ_ONLY_COMPATIBLE: dict[str, tuple[str, ...]] = {
    older: tuple(sql for _, added in _ADDED_BY[i:] for sql in added)
    for i, older in enumerate(("0003", *(revision for revision, _ in _ADDED_BY[:-1])))
}


def _read_only_setup(dbapi_conn: sqlite3.Connection, stand_ins: tuple[str, ...]) -> None:
    """Busy timeout, the stand-in TEMP tables (before ``query_only`` forbids them), then
    ``query_only``."""
    cur = dbapi_conn.cursor()
    cur.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")
    for statement in stand_ins:
        cur.execute(statement)
    cur.execute("PRAGMA query_only=1")
    cur.close()


def read_only_uri(path: Path) -> str:
    """The ``file:`` URI that opens ``path`` read-only (``immutable`` where SQLite could
    not create a WAL file's ``-shm`` beside it: a folder that cannot be written)."""
    base = "file:" + urllib.parse.quote(str(path.resolve()), safe="/") + "?mode=ro"
    folder = path.resolve().parent
    if not os.access(folder, os.W_OK) and not Path(f"{path}-wal").exists():
        return base + "&immutable=1"
    return base


def _peek(path: Path) -> tuple[str | None, int]:
    """``(schema revision or None, number of tables)`` of an existing file, read through a
    read-only connection: one that may write switches the file to WAL (changing its
    header) before anything could tell it is another program's database."""
    try:
        conn = sqlite3.connect(read_only_uri(path), uri=True)
    except sqlite3.Error as exc:
        raise StorageError(f"cannot be opened: {exc}", path) from exc
    try:
        names = {str(r[0]) for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        row = (conn.execute("SELECT version_num FROM alembic_version").fetchone()
               if "alembic_version" in names else None)
    except sqlite3.DatabaseError as exc:
        raise StorageError(f"database is corrupt or unreadable: {exc}", path) from exc
    finally:
        conn.close()
    return (None if row is None else str(row[0])), len(names)


def _recognise(path: Path, revision: str | None, tables: int) -> None:
    """Refuse a file that is not a viewdb database (tables but no schema revision) or
    was written by a newer viewdb."""
    if revision is None and tables:
        raise StorageError("is an SQLite file but not a viewdb database (no schema version)", path)
    # this viewdb's own revision needs no look at the migrations (importing Alembic to
    # list them costs more than the rest of an open)
    if revision is not None and revision != s.SCHEMA_REVISION and revision not in known_revisions():
        raise SchemaMismatch(
            f"was written by a newer viewdb (schema revision {revision}; this viewdb "
            f"knows up to {s.SCHEMA_REVISION}); upgrade viewdb to open it", path,
        )


class Database:
    """An open database file: its connections, schema revision and transactions."""

    def __init__(
        self, path: str | Path, *, create: bool = True,
        initial: tuple[BuildConfig, str] | None = None, read_only: bool = False,
    ) -> None:
        """Open ``path`` (creating it if ``create``). A new file gets its schema and, given
        ``initial = (config, role)``, its build configuration in one transaction, so a
        creation that is interrupted leaves no file that looks built with defaults.
        ``read_only`` opens an existing file without ever writing to it."""
        self.path = Path(path)
        self._initial = initial
        self._create = create
        self.read_only = read_only
        why = not_regular(self.path)
        if why not in (None, "does not exist"):  # a FIFO would block SQLite for good
            raise StorageError(why or "", self.path)
        exists = why is None and self.path.stat().st_size > 0
        if not exists and (read_only or not create):
            raise StorageError("no such database", self.path)
        if exists:
            self._check_header()
            _recognise(self.path, *_peek(self.path))  # before a connection that may write
        elif not self.path.parent.exists():
            raise StorageError("its folder does not exist", self.path)
        #: TEMP tables standing in for what an older file lacks (read-only opens only).
        self._stand_ins: tuple[str, ...] = ()
        if read_only:
            self._uri = read_only_uri(self.path)
            self.engine: Engine = sa.create_engine("sqlite://", creator=lambda: sqlite3.connect(
                self._uri, uri=True, check_same_thread=False))
            event.listen(self.engine, "connect",
                         lambda conn, _record: _read_only_setup(conn, self._stand_ins))
        else:
            self.engine = sa.create_engine(f"sqlite:///{self.path}")
            event.listen(self.engine, "connect", _set_pragmas)
        try:
            self._migrate()
        except Exception:
            self.engine.dispose()
            raise

    # ----------------------------------------------------------------- lifecycle
    def close(self) -> None:
        self.engine.dispose()

    def connect(self) -> sqlite3.Connection:
        """A new raw sqlite3 connection to the file (read-only if the store is), usable
        from any thread; for readers that manage their own transactions."""
        if self.read_only:
            conn = sqlite3.connect(self._uri, uri=True, check_same_thread=False, isolation_level=None)
            _read_only_setup(conn, self._stand_ins)
            return conn
        return sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)

    def _check_header(self) -> None:
        try:
            with open(self.path, "rb") as f:
                header = f.read(len(SQLITE_HEADER))
        except OSError as exc:
            raise StorageError(f"cannot be read: {exc.strerror}", self.path) from exc
        if header != SQLITE_HEADER:
            raise StorageError("is not a viewdb database (not an SQLite file)", self.path)

    @contextmanager
    def _errors(self) -> Iterator[None]:
        try:
            yield
        except sa.exc.OperationalError as exc:
            msg = str(exc.orig) if exc.orig else str(exc)
            if "locked" in msg or "busy" in msg:
                raise StorageError("database is busy (another process is writing)", self.path) from exc
            raise StorageError(f"database error: {msg}", self.path) from exc
        except sa.exc.DatabaseError as exc:
            msg = str(exc.orig) if exc.orig else str(exc)
            raise StorageError(f"database is corrupt or unreadable: {msg}", self.path) from exc

    @contextmanager
    def read(self) -> Iterator[Connection]:
        with self._errors(), self.engine.connect() as conn:
            yield conn

    @contextmanager
    def transaction(self) -> Iterator[Connection]:
        """One write transaction: everything inside commits together or not at all.

        It begins explicitly, taking the write lock (waiting up to the busy timeout for
        another writer): Python's sqlite3 opens a transaction only before INSERT and the
        like, so without this a CREATE or ALTER TABLE (a migration) commits on its own,
        a kill left tables without a schema version, and reads before the first write
        ran outside the transaction."""
        if self.read_only:
            raise StorageError("is open read-only; open it normally to change it", self.path)
        with self._errors(), self.engine.begin() as conn:
            dbapi = conn.connection.driver_connection
            assert dbapi is not None  # None only once the connection is closed or invalidated
            if not dbapi.in_transaction:
                dbapi.execute("BEGIN IMMEDIATE")
            before = generation(dbapi)
            yield conn
            if generation(dbapi) != before:  # the groups changed: the tiers' keys, stamped
                stamp_tiers(dbapi)

    def revision(self) -> str | None:
        with self.read() as conn:
            has = conn.exec_driver_sql(
                "SELECT 1 FROM sqlite_master WHERE type='table' AND name='alembic_version'"
            ).first()
            if not has:
                return None
            row = conn.exec_driver_sql("SELECT version_num FROM alembic_version").first()
            return None if row is None else str(row[0])

    def _migrate(self) -> None:
        current = self.revision()
        if current == s.SCHEMA_REVISION:
            return
        if current is None:
            with self.read() as conn:
                tables = conn.exec_driver_sql(
                    "SELECT count(*) FROM sqlite_master WHERE type='table'"
                ).scalar_one()
            _recognise(self.path, None, int(tables))
        else:
            _recognise(self.path, current, 1)
        if current is None and (self.read_only or not self._create):
            # an SQLite file without tables: a creation killed before its first commit;
            # only a caller that may create a file makes it a database (with its settings)
            raise StorageError("is an unfinished database (its creation was interrupted); "
                               "delete it and ingest again", self.path)
        if self.read_only:
            if current in READ_ONLY_COMPATIBLE:
                self._stand_ins = READ_ONLY_COMPATIBLE[current]
                self.engine.dispose()  # the next connections get the stand-ins
                return
            raise UpgradeNeeded(
                f"has schema revision {current}, older than this viewdb's {s.SCHEMA_REVISION}: "
                "open it once writable (`read_only` False) to upgrade it",
                self.path,
            )
        from alembic import command

        with self.transaction() as conn:  # the DDL too: see transaction()
            command.upgrade(alembic_config(conn), "head")
            if current is None and self._initial is not None:
                config, role = self._initial
                conn.execute(sa.insert(s.settings), [
                    {"key": "build", "value": json.dumps(config.to_dict())},
                    {"key": "role", "value": json.dumps(role)},
                ])
