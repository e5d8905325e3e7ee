"""R-trees whose pages live in the SQLite file (viewdb.storage.spatial)."""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from viewdb.errors import NotFound, StorageError
from viewdb.storage.spatial import FourierIndex, ensure_table

D = 6
N = 3000
ROOT = Path(__file__).resolve().parent.parent


def connect(path: Path) -> sqlite3.Connection:
    conn = sqlite3.connect(path)
    conn.execute("PRAGMA journal_mode=WAL")
    conn.execute("PRAGMA synchronous=NORMAL")
    return conn


def points(n: int = N, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(n, D))


def brute(P: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.flatnonzero(((P >= lo) & (P <= hi)).all(axis=1)).astype(np.int64)


BOXES = [(np.full(D, -0.5), np.full(D, 1.0)), (np.full(D, -3.0), np.full(D, 3.0)),
         (np.r_[-1.0, -2, -1, -9, -9, -9], np.r_[1.0, 0, 2, 9, 9, 9])]


def snapshot(idx: FourierIndex) -> dict:
    return {
        "count": idx.count,
        "hits": [idx.intersection(lo, hi).tolist() for lo, hi in BOXES],
        "leaves": sorted(
            (node, sorted(ch.tolist()), lo.tolist(), hi.tolist())
            for node, ch, lo, hi in idx.leaves()
        ),
    }


def pages(conn: sqlite3.Connection, tier: str) -> dict[int, bytes]:
    return dict(conn.execute("SELECT page, data FROM rtree_pages WHERE tier = ?", (tier,)))


@pytest.fixture(params=["insert", "bulk"])
def built(request: pytest.FixtureRequest, tmp_path: Path):
    """A file with tier 'f' of N random 6-D points, committed and closed."""
    path = tmp_path / "v.db"
    P = points()
    conn = connect(path)
    if request.param == "insert":
        idx = FourierIndex.create(conn, "f", D)
        for i, p in enumerate(P):
            idx.insert(i, p)
    else:
        idx = FourierIndex.bulk_create(conn, "f", np.arange(N), P)
    snap = snapshot(idx)
    idx.close()
    conn.commit()
    conn.close()
    return path, P, snap


# ----------------------------------------------------------------- persistence
def test_reopen_same_results_without_reinserting(built) -> None:
    path, P, snap = built
    conn = connect(path)
    idx = FourierIndex.open(conn, "f")  # no dimension given
    assert idx.dimension == D
    stores = idx.storage.stats["stores"]
    assert snapshot(idx) == snap
    assert idx.storage.stats["stores"] == stores  # reading wrote nothing
    for lo, hi in BOXES:
        assert idx.intersection(lo, hi).tolist() == brute(P, lo, hi).tolist()
    assert idx.count == N
    assert sum(len(ch) for _, ch, _, _ in idx.leaves()) == N
    idx.close()
    conn.close()


def test_reopen_in_a_new_process(built) -> None:
    path, _, snap = built
    code = f"""
import json, sqlite3, sys
sys.path.insert(0, {str(ROOT)!r}); sys.path.insert(0, {str(Path(__file__).parent)!r})
from test_spatial import snapshot
from viewdb.storage.spatial import FourierIndex
conn = sqlite3.connect({str(path)!r})
print(json.dumps(snapshot(FourierIndex.open(conn, "f"))))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout) == json.loads(json.dumps(snap))


def test_pages_are_rows_and_no_side_files(built) -> None:
    path, _, _ = built
    conn = connect(path)
    n_pages = conn.execute("SELECT count(*) FROM rtree_pages WHERE tier = 'f'").fetchone()[0]
    leaves = len(FourierIndex.open(conn, "f").leaves())
    assert n_pages > leaves > 1
    assert conn.execute("SELECT dimension FROM rtree_meta WHERE tier='f'").fetchone() == (D,)
    conn.close()
    allowed = {"v.db", "v.db-wal", "v.db-shm"}
    assert {p.name for p in path.parent.iterdir()} <= allowed


def test_dimension_survives_and_tiers_are_separate(tmp_path: Path) -> None:
    path = tmp_path / "v.db"
    conn = connect(path)
    a = FourierIndex.create(conn, "a", 3)
    b = FourierIndex.create(conn, "b", 8)
    a.insert(1, [0.0, 0.0, 0.0])
    b.insert(2, np.ones(8))
    a.close(), b.close()
    conn.commit()
    conn.close()
    conn = connect(path)
    a, b = FourierIndex.open(conn, "a"), FourierIndex.open(conn, "b")
    assert (a.dimension, b.dimension) == (3, 8)
    assert a.intersection(-np.ones(3), np.ones(3)).tolist() == [1]
    assert b.intersection(np.zeros(8), np.ones(8)).tolist() == [2]
    with pytest.raises(ValueError):
        a.insert(3, [0.0, 0.0])  # a 2-D point into a 3-D tree
    with pytest.raises(NotFound):
        FourierIndex.open(conn, "c")
    with pytest.raises(StorageError):
        FourierIndex.create(conn, "a", 3)
    a.close(), b.close()
    conn.close()


def test_open_without_tables_is_not_found(tmp_path: Path) -> None:
    conn = connect(tmp_path / "v.db")
    with pytest.raises(NotFound):
        FourierIndex.open(conn, "f")


def test_delete_and_bulk_load(tmp_path: Path) -> None:
    path = tmp_path / "v.db"
    P = points(500, seed=3)
    conn = connect(path)
    idx = FourierIndex.create(conn, "f", D)
    idx.bulk_load(np.arange(500), P)  # empty tree: STR bulk loader
    assert idx.count == 500
    idx.bulk_load([500, 501], P[:2] + 10)  # non-empty: one by one
    assert idx.count == 502
    for i in range(0, 500, 2):
        idx.delete(i, P[i])
    idx.close()
    conn.commit()
    conn.close()
    conn = connect(path)
    idx = FourierIndex.open(conn, "f")
    big = np.full(D, 100.0)
    expect = sorted(list(range(1, 500, 2)) + [500, 501])
    assert idx.intersection(-big, big).tolist() == expect
    assert idx.count == len(expect)
    idx.close()
    conn.close()


# ----------------------------------------------------------------- transactions
@pytest.mark.parametrize(
    "options", [{}, {"buffer_pages": 4}, {"writethrough": True}], ids=["buffered", "evicting", "writethrough"]
)
def test_failed_transaction_leaves_index_as_before(built, options) -> None:
    path, P, snap = built
    conn = connect(path)
    idx = FourierIndex.open(conn, "f", **options)
    before = pages(conn, "f")
    extra = points(2000, seed=9)
    with pytest.raises(RuntimeError), idx.transaction():
        for i, p in enumerate(extra):
            idx.insert(N + i, p)
        idx.delete(0, P[0])
        assert idx.count == N + 1999
        raise RuntimeError("boom")
    assert snapshot(idx) == snap  # the live object was reloaded
    assert pages(conn, "f") == before  # the table is untouched
    assert not conn.in_transaction
    idx.close()
    conn.close()
    conn = connect(path)
    assert snapshot(FourierIndex.open(conn, "f")) == snap
    conn.close()


def test_successful_transaction_commits(built) -> None:
    path, P, snap = built
    conn = connect(path)
    idx = FourierIndex.open(conn, "f")
    with idx.transaction():
        idx.insert(N, np.zeros(D))
    assert not conn.in_transaction  # it ran BEGIN ... COMMIT itself
    # Dropping the object without close() must not write anything more.
    del idx
    other = connect(path)
    reopened = FourierIndex.open(other, "f")
    assert reopened.count == N + 1
    assert N in reopened.intersection(np.full(D, -1e-9), np.full(D, 1e-9)).tolist()
    other.close()
    conn.close()


def test_savepoint_inside_caller_transaction_and_caller_rollback(built) -> None:
    path, P, snap = built
    conn = connect(path)
    idx = FourierIndex.open(conn, "f")
    conn.execute("CREATE TABLE other (x INTEGER)")
    conn.commit()
    conn.execute("INSERT INTO other VALUES (1)")  # legacy sqlite3 opens a transaction
    assert conn.in_transaction
    with idx.transaction():  # a SAVEPOINT inside the caller's transaction
        idx.insert(N, np.zeros(D))
    assert conn.in_transaction  # not committed by the index
    assert idx.count == N + 1
    conn.rollback()  # the caller undoes everything...
    idx.reload()  # ...and must tell the index
    assert snapshot(idx) == snap
    assert conn.execute("SELECT count(*) FROM other").fetchone() == (0,)
    # Without transaction(): insert, flush, rollback, reload.
    idx.insert(N + 5, np.zeros(D))
    idx.flush()
    assert conn.in_transaction
    conn.rollback()
    idx.reload()
    assert snapshot(idx) == snap
    idx.close()
    conn.commit()
    conn.close()
    conn = connect(path)
    assert snapshot(FourierIndex.open(conn, "f")) == snap
    conn.close()


def test_write_errors_raise_instead_of_aborting(tmp_path: Path) -> None:
    conn = connect(tmp_path / "v.db")
    idx = FourierIndex.create(conn, "f", 3)
    for i in range(300):
        idx.insert(i, np.full(3, float(i)))
    conn.close()
    with pytest.raises(StorageError):
        idx.flush()  # libspatialindex writes from its destructor: must not abort
    idx.close()


def test_rolled_back_creation(tmp_path: Path) -> None:
    conn = connect(tmp_path / "v.db")
    ensure_table(conn)
    conn.commit()
    idx = FourierIndex.create(conn, "f", D)
    idx.insert(1, np.zeros(D))
    idx.flush()
    conn.rollback()
    with pytest.raises(NotFound):
        idx.reload()
    assert conn.execute("SELECT count(*) FROM rtree_pages").fetchone() == (0,)
    conn.close()


def test_sqlalchemy_connection(tmp_path: Path) -> None:
    sa = pytest.importorskip("sqlalchemy")
    engine = sa.create_engine(f"sqlite:///{tmp_path / 'v.db'}")
    P = points(300, seed=5)
    with engine.begin() as conn:
        idx = FourierIndex.create(conn, "f", D)
        idx.bulk_load(np.arange(300), P)
        idx.close()
    with engine.connect() as conn:
        idx = FourierIndex.open(conn, "f")
        lo, hi = BOXES[0]
        assert idx.intersection(lo, hi).tolist() == brute(P, lo, hi).tolist()
        idx.close()
    engine.dispose()


# ----------------------------------------------------------------- correctness
@pytest.fixture(scope="module")
def shared_index(tmp_path_factory: pytest.TempPathFactory):
    path = tmp_path_factory.mktemp("spatial") / "v.db"
    P = points(N, seed=11)
    conn = connect(path)
    idx = FourierIndex.create(conn, "f", D)
    for i, p in enumerate(P[: N // 2]):
        idx.insert(i, p)
    idx.close()
    conn.commit()
    idx = FourierIndex.open(conn, "f")
    idx.bulk_load(np.arange(N // 2, N), P[N // 2 :])  # non-empty: inserted one by one
    idx.flush()
    conn.commit()
    yield idx, P
    idx.close()
    conn.close()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    centre=st.lists(st.floats(-2.5, 2.5), min_size=D, max_size=D),
    half=st.lists(st.floats(0.0, 3.0), min_size=D, max_size=D),
)
def test_intersection_equals_brute_force(shared_index, centre, half) -> None:
    idx, P = shared_index
    lo, hi = np.array(centre) - np.array(half), np.array(centre) + np.array(half)
    assert idx.intersection(lo, hi).tolist() == brute(P, lo, hi).tolist()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    boxes=st.lists(
        st.tuples(st.lists(st.floats(-2.5, 2.5), min_size=D, max_size=D),
                  st.lists(st.floats(0.0, 2.0), min_size=D, max_size=D)),
        min_size=1, max_size=4,
    )
)
def test_intersection_of_many_boxes_equals_brute_force(shared_index, boxes) -> None:
    idx, P = shared_index
    los = np.array([np.array(c) - np.array(h) for c, h in boxes])
    his = np.array([np.array(c) + np.array(h) for c, h in boxes])
    expected = sorted(set().union(*(brute(P, lo, hi).tolist() for lo, hi in zip(los, his, strict=True))))
    assert idx.intersection_many(los, his).tolist() == expected


def test_box_on_a_point_is_closed(shared_index) -> None:
    idx, P = shared_index
    assert 7 in idx.intersection(P[7], P[7]).tolist()
    with pytest.raises(ValueError):
        idx.intersection(P[7] + 1, P[7])
