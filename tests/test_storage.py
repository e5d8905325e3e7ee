"""The database file: schema via migrations, versioning, corrupt and foreign files."""

import sqlite3

import pytest
import sqlalchemy as sa

import viewdb
from viewdb.errors import SchemaMismatch, StorageError
from viewdb.storage import schema
from viewdb.storage.store import Store


def test_new_file_is_wal_with_the_migrated_schema(tmp_path):
    path = tmp_path / "new.db"
    store = Store(path)
    try:
        with store.read() as conn:
            assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
            assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
            inspector = sa.inspect(conn)
            tables = set(inspector.get_table_names()) - {"alembic_version"}
            assert tables == set(schema.metadata.tables)
            for name, table in schema.metadata.tables.items():
                migrated = {c["name"] for c in inspector.get_columns(name)}
                assert migrated == {c.name for c in table.columns}, name
        assert store.revision() == schema.SCHEMA_REVISION
    finally:
        store.close()


def test_file_from_a_newer_viewdb_is_refused(tmp_path):
    path = tmp_path / "future.db"
    Store(path).close()
    with sqlite3.connect(path) as conn:
        conn.execute("UPDATE alembic_version SET version_num = '9999'")
    with pytest.raises(SchemaMismatch, match="newer viewdb") as info:
        viewdb.open(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    "content",
    [b"definitely not a database" * 100, bytes(range(256)) * 64, b"SQLite format 3\x00" + b"\xff" * 5000],
)
def test_foreign_or_random_files_get_a_clear_error(tmp_path, content):
    path = tmp_path / "junk.db"
    path.write_bytes(content)
    with pytest.raises(StorageError) as info:
        viewdb.open(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)
    assert path.read_bytes() == content  # nothing was written to it


def test_other_sqlite_databases_are_not_taken_over(tmp_path):
    path = tmp_path / "other.db"
    with sqlite3.connect(path) as conn:
        conn.execute("CREATE TABLE customers (id INTEGER)")
    with pytest.raises(StorageError, match="not a viewdb database"):
        viewdb.open(path)
    with sqlite3.connect(path) as conn:
        names = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")]
    assert names == ["customers"]


def test_truncated_database_gets_a_clear_error(tmp_path, small_db):
    data = small_db.read_bytes()
    path = tmp_path / "truncated.db"
    # checkpointed copy: read via sqlite backup so the WAL content is inside
    src = sqlite3.connect(small_db)
    dst = sqlite3.connect(path)
    src.backup(dst)
    src.close()
    dst.close()
    full = path.read_bytes()
    assert len(full) >= len(data) // 2
    path.write_bytes(full[: len(full) // 3])
    with pytest.raises(StorageError):
        with viewdb.open(path, create=False) as db:
            db.objects()
            for o in db.objects():
                db.views(o.name)


def test_missing_file_without_create(tmp_path):
    with pytest.raises(StorageError, match="no such database"):
        viewdb.open(tmp_path / "absent.db", create=False)
    assert not (tmp_path / "absent.db").exists()


def test_existing_db_keeps_its_build_config(tmp_path):
    path = tmp_path / "a.db"
    viewdb.open(path, gap=45, image_size=128).close()
    with viewdb.open(path) as db:
        assert db.config.gap == 45 and db.config.render.image_size == 128
    with pytest.raises(viewdb.ViewDBError, match="`gap` 45"):
        viewdb.open(path, gap=10)


def test_a_file_from_schema_0001_is_upgraded_in_place_with_its_data(tmp_path):
    import shutil

    from tests.conftest import ROOT

    path = tmp_path / "old.db"
    shutil.copy(ROOT / "tests" / "data" / "schema_0001.db", path)
    with sqlite3.connect(path) as conn:
        before = conn.execute("SELECT v.azimuth, v.elevation, c.samples FROM views v JOIN curves c ON c.view_id = v.id ORDER BY v.id").fetchall()
        assert conn.execute("SELECT version_num FROM alembic_version").fetchone()[0] == "0001"
    with viewdb.open(path, create=False) as db:
        assert [o.name for o in db.objects()] == ["cone", "pyramid"]
        assert db.check().ok
    with sqlite3.connect(path) as conn:
        assert conn.execute("SELECT version_num FROM alembic_version").fetchone()[0] == schema.SCHEMA_REVISION
        after = conn.execute("SELECT v.azimuth, v.elevation, c.samples FROM views v JOIN curves c ON c.view_id = v.id ORDER BY v.id").fetchall()
        assert after == before
        assert conn.execute("SELECT DISTINCT skimmed FROM objects").fetchall() == [(0,)]


def test_a_file_whose_creation_was_cut_short_is_not_taken_as_built_with_defaults(tmp_path):
    path = tmp_path / "cut.db"
    Store(path).close()  # schema, but no build configuration (as an older viewdb could leave)
    with pytest.raises(StorageError, match="unfinished database"):
        viewdb.open(path, create=False)
    with viewdb.open(path, gap=45) as db:  # an ingest may still finish creating it
        assert db.config.gap == 45
    with viewdb.open(path, create=False) as db:
        assert db.config.gap == 45


def test_a_file_killed_before_its_creation_committed_is_not_built_with_defaults(tmp_path):
    # SQLite has written the file's header (the WAL switch), but the transaction creating
    # the schema and settings never committed: a file without tables
    path = tmp_path / "killed.db"
    sqlite3.connect(path).execute("PRAGMA journal_mode=WAL").connection.close()
    before = path.read_bytes()
    assert before
    with pytest.raises(StorageError, match="unfinished database"):
        viewdb.open(path, create=False)
    assert path.read_bytes() == before
    with viewdb.open(path, gap=30) as db:  # the ingest run again creates it as asked
        assert db.config.gap == 30
    with viewdb.open(path, create=False) as db:
        assert db.config.gap == 30


def test_a_new_file_gets_schema_and_configuration_together(tmp_path):
    path = tmp_path / "new.db"
    with viewdb.open(path, gap=45, client_gap=90):
        pass
    with sqlite3.connect(path) as conn:
        keys = {k for (k,) in conn.execute("SELECT key FROM settings")}
    assert keys == {"build", "role"}


def test_creating_a_file_is_one_transaction_ddl_included(tmp_path, monkeypatch):
    """The schema's CREATE TABLEs commit with the schema version and the settings, or
    not at all: a failure (as a kill) after the migration ran leaves no tables. Python's
    sqlite3 opens no transaction before DDL, so without an explicit BEGIN every table
    committed on its own (found by the SIGKILL test: 'not a viewdb database')."""
    from alembic import command

    upgrade = command.upgrade

    def upgrade_then_fail(*args, **kwargs):
        upgrade(*args, **kwargs)
        raise RuntimeError("killed after the migration, before the commit")

    monkeypatch.setattr(command, "upgrade", upgrade_then_fail)
    path = tmp_path / "cut.db"
    with pytest.raises(RuntimeError, match="killed"):
        viewdb.open(path, gap=30)
    with sqlite3.connect(path) as conn:
        assert conn.execute("SELECT name FROM sqlite_master WHERE type='table'").fetchall() == []
    monkeypatch.setattr(command, "upgrade", upgrade)
    with viewdb.open(path, gap=30) as db:  # and it is created as asked next time
        assert db.config.gap == 30
