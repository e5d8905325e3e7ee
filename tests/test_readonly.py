"""``viewdb.open(path, read_only=True)``: never writes to the file, refuses what would."""

from __future__ import annotations

import os
import shutil
import sqlite3
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import viewdb
from tests.conftest import ROOT, mixed_query_curves, sample
from viewdb.config import PerspectiveConfig
from viewdb.errors import SchemaMismatch, StorageError
from viewdb.storage.schema import SCHEMA_REVISION
from viewdb.storage.store import Store


def _snapshot(path):
    st = path.stat()
    return path.read_bytes(), st.st_mtime_ns, st.st_size


def _use(db: viewdb.ViewDB) -> None:
    """Everything a server or a client does with a file."""
    names = [o.name for o in db.objects()]
    assert names
    info = db.info()
    assert info.objects
    curve = np.ones(db.config.features.curve_samples)
    curve[::7] = 1.3
    if db.role == "full":
        hits, _ = db.search(curve, k=2, tier="full")
        assert hits
        db.recognise(curve, 2, plan="cs1")
        db.recognise(curve, 2, plan="cs2")
        view = db.view(names[0], *db.views(names[0])[0])
        assert view.curve.shape == (db.config.features.curve_samples,)
        assert db.check().ok
    found, _ = db.client_candidates(curve, 2)
    assert found


def test_read_only_use_leaves_the_file_byte_for_byte_and_mtime_unchanged(tiered_db, tmp_path):
    path = tmp_path / "copy.db"
    shutil.copy(tiered_db, path)
    before = _snapshot(path)
    with viewdb.open(path, read_only=True) as db:
        assert db.read_only
        _use(db)
    assert _snapshot(path) == before


def test_a_file_without_write_permission_opens_read_only(tiered_db, tmp_path):
    path = tmp_path / "ro.db"
    shutil.copy(tiered_db, path)
    os.chmod(path, 0o444)
    before = _snapshot(path)
    try:
        with viewdb.open(path, read_only=True) as db:
            _use(db)
        assert _snapshot(path) == before
    finally:
        os.chmod(path, 0o644)


def test_a_client_file_read_only_creates_no_journal_files(tiered_db, tmp_path):
    client = tmp_path / "client.db"
    with viewdb.open(tiered_db, read_only=True) as db:
        db.export_client(client)  # reading the source read-only is enough to export
    before = _snapshot(client)
    with viewdb.open(client, read_only=True) as db:
        assert db.role == "client"
        _use(db)
    assert _snapshot(client) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["client.db"]


def test_writes_are_refused_with_a_clear_error(tiered_db, tmp_path):
    path = tmp_path / "copy.db"
    shutil.copy(tiered_db, path)
    before = _snapshot(path)
    with viewdb.open(path, read_only=True) as db:
        with pytest.raises(viewdb.ViewDBError, match="read-only") as info:
            db.ingest([sample("sphere")])
        assert str(path) in str(info.value)
        with pytest.raises(StorageError, match="read-only"):
            with db._store.transaction():
                pass
    assert _snapshot(path) == before


def test_an_old_schema_is_not_upgraded_read_only(tmp_path):
    path = tmp_path / "old.db"
    shutil.copy(ROOT / "tests" / "data" / "schema_0001.db", path)
    before = _snapshot(path)
    with pytest.raises(StorageError, match="older than this viewdb.*open it once writable") as info:
        viewdb.open(path, read_only=True)
    assert str(path) in str(info.value) and "\n" not in str(info.value)
    assert _snapshot(path) == before
    with viewdb.open(path, create=False):  # the upgrade the message asks for
        pass
    with viewdb.open(path, read_only=True) as db:
        assert [o.name for o in db.objects()] == ["cone", "pyramid"]


def _downgrade(path, revision):
    """Take a current file back to an older schema revision (Alembic's downgrade)."""
    import sqlalchemy as sa
    from alembic import command

    from viewdb.storage.connection import alembic_config

    engine = sa.create_engine(f"sqlite:///{path}")
    with engine.begin() as conn:
        command.downgrade(alembic_config(conn), revision)
    engine.dispose()


def test_a_client_file_from_revision_0003_is_used_read_only_as_it_is(tiered_db, tmp_path):
    """A client file shipped before the perspective views (revision 0004) cannot be
    upgraded on a read-only device: it opens read-only with an empty stand-in for the
    table it lacks, answers as the current file does, and is not written."""
    client = tmp_path / "client.db"
    with viewdb.open(tiered_db, read_only=True) as full:  # float32 curves, as files of then
        full.export_client(client, file=viewdb.config.ClientFileConfig(curve_bits=0))
        curves = mixed_query_curves(full, np.random.default_rng(11), 8)
    with viewdb.open(client, read_only=True) as db:
        expected = [db.client_candidates(q, 3)[0] for q in curves]
    _downgrade(client, "0003")
    with sqlite3.connect(client) as conn:
        tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    assert "perspective_views" not in tables
    before = _snapshot(client)
    with viewdb.open(client, read_only=True) as db, viewdb.open(tiered_db, read_only=True) as full:
        assert db.info().schema_revision == "0003"
        assert [db.client_candidates(q, 3)[0] for q in curves] == expected
        for q in curves[:4]:  # CS1 from the old client file is still exactly the server's answer
            assert (full.recognise(q, 3, plan="cs1", client=db).results
                    == full.recognise(q, 3, plan="server").results)
        assert all(o.perspective_views == 0 for o in db.objects())
        _use(db)
        assert db.check().ok
    assert _snapshot(client) == before
    with viewdb.open(client, create=False) as db:  # opened normally, it is upgraded
        assert db.info().schema_revision != "0003"


def test_a_full_file_from_revision_0003_searches_its_orthographic_views_read_only(tmp_path):
    path = tmp_path / "full.db"
    # as if built before the perspective views: none in the index, then no table for them
    config = viewdb.BuildConfig(gap=60, render=viewdb.RenderConfig(image_size=64),
                                perspective=PerspectiveConfig(distances=()))
    with viewdb.open(path, config=config) as db:
        db.ingest([sample("car"), sample("mug")])
    _downgrade(path, "0003")
    before = _snapshot(path)
    with viewdb.open(path, read_only=True) as db:
        assert [o.perspective_views for o in db.objects()] == [0, 0]
        _, rows = db.search_tier("full")
        assert rows and all(view_id > 0 for view_id, _, _ in rows)
        _use(db)
    assert _snapshot(path) == before


def test_a_file_from_revision_0006_answers_read_only_without_the_objects_index(tiered_db, tmp_path):
    """Revision 0007 only added an index: a file from 0006 opens read-only as it is, answers
    as the current file does (the CS1 server reads the objects' versions through the
    table), and opened normally gets the index."""
    path = tmp_path / "old.db"
    with sqlite3.connect(tiered_db) as src, sqlite3.connect(path) as dst:
        src.backup(dst)
    _downgrade(path, "0006")
    with sqlite3.connect(path) as conn:
        assert not conn.execute("SELECT 1 FROM sqlite_master WHERE name = 'ix_objects_versions'").fetchall()
    before = _snapshot(path)
    with viewdb.open(path, read_only=True) as db, viewdb.open(tiered_db, read_only=True) as ref:
        assert db.info().schema_revision == "0006"
        for q in mixed_query_curves(ref, np.random.default_rng(3), 4):
            assert db.recognise(q, 3, plan="cs1").results == ref.recognise(q, 3, plan="cs1").results
        _use(db)
    assert _snapshot(path) == before
    with viewdb.open(path, create=False) as db:
        assert db.info().schema_revision == SCHEMA_REVISION


def test_what_reads_the_columns_after_an_objects_mesh_reads_the_index(tiered_db):
    """The objects' versions and the key of a tier file without a generation read columns
    that lie after the mesh in an object's row; the planner answers both from the index of
    revision 0007, without the rows (and so without walking the meshes' pages)."""
    with sqlite3.connect(f"file:{tiered_db}?mode=ro", uri=True) as conn:
        for sql in ("SELECT name, content_hash, skimmed FROM objects",
                    "SELECT id, name, content_hash, created_at FROM objects"):
            plan = " ".join(str(r[-1]) for r in conn.execute("EXPLAIN QUERY PLAN " + sql))
            assert "COVERING INDEX ix_objects_versions" in plan, (sql, plan)


def test_unfinished_newer_missing_and_foreign_files_are_refused(tmp_path):
    cut = tmp_path / "cut.db"
    Store(cut).close()  # schema but no build configuration
    with pytest.raises(StorageError, match="unfinished"):
        viewdb.open(cut, read_only=True)
    empty = tmp_path / "empty.db"
    sqlite3.connect(empty).execute("PRAGMA user_version = 1").connection.close()
    before = _snapshot(empty)
    with pytest.raises(StorageError, match="unfinished"):
        viewdb.open(empty, read_only=True)
    assert _snapshot(empty) == before
    future = tmp_path / "future.db"
    Store(future).close()
    with sqlite3.connect(future) as conn:
        conn.execute("UPDATE alembic_version SET version_num = '9999'")
    with pytest.raises(SchemaMismatch, match="newer viewdb"):
        viewdb.open(future, read_only=True)
    with pytest.raises(StorageError, match="no such database"):
        viewdb.open(tmp_path / "absent.db", read_only=True)
    assert not (tmp_path / "absent.db").exists()
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"not a database" * 100)
    with pytest.raises(StorageError, match="not an SQLite file"):
        viewdb.open(junk, read_only=True)


def test_a_read_only_reader_sees_objects_ingested_after_it_opened(tmp_path):
    path = tmp_path / "live.db"
    with viewdb.open(path, gap=90, image_size=64) as db:
        db.ingest([sample("mug")])
    with viewdb.open(path, read_only=True) as reader:
        curve = reader.view("mug", 0, 0).curve
        assert [h.object for h in reader.search(curve, 5)[0]] == ["mug"]
        with viewdb.open(path) as writer:
            writer.ingest([sample("car")])
        assert sorted(h.object for h in reader.search(curve, 5)[0]) == ["car", "mug"]


def test_a_file_on_read_only_storage_opens(tiered_db, tmp_path):
    """A shipped file on storage nobody may write (SQLite cannot make a ``-shm`` there):
    a read-only bind mount in a private mount namespace when running as root, a folder
    without write permission otherwise."""
    folder, mount = tmp_path / "shipped", tmp_path / "mnt"
    folder.mkdir()
    mount.mkdir()
    shutil.copy(tiered_db, folder / "full.db")
    before = _snapshot(folder / "full.db")
    script = textwrap.dedent(f"""
        import os, viewdb
        path = {str(mount / "full.db")!r}
        assert not os.access(os.path.dirname(path), os.W_OK)
        with viewdb.open(path, read_only=True) as db:
            curve = db.view("mug", 0, 0).curve
            hits, _ = db.search(curve, 2)
            assert hits[0].object == "mug" and hits[0].distance == 0.0, hits
            print("ok", len(db.objects()))
    """)
    python = [sys.executable, "-c", script]
    if os.geteuid() == 0:
        if shutil.which("unshare") is None:
            pytest.skip("no unshare to make a read-only mount")
        shell = (f"mount --bind {folder} {mount} && mount -o remount,bind,ro {mount} && "
                 f"exec \"$@\"")
        probe = subprocess.run(["unshare", "-m", "sh", "-c", shell, "sh", "true"], capture_output=True)
        if probe.returncode != 0:
            pytest.skip(f"cannot make a read-only mount here: {probe.stderr.decode()[:200]}")
        cmd = ["unshare", "-m", "sh", "-c", shell, "sh", *python]
    else:
        mount.rmdir()
        mount.symlink_to(folder)
        os.chmod(folder / "full.db", 0o444)
        os.chmod(folder, 0o555)
        cmd = python
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=ROOT)
        assert done.returncode == 0, done.stderr[-2000:]
        assert done.stdout.startswith("ok 6")
    finally:
        os.chmod(folder, 0o755)
    assert _snapshot(folder / "full.db") == before
    assert sorted(p.name for p in folder.iterdir()) == ["full.db"]
