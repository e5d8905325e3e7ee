"""``viewdb check`` finds each kind of damage, and passes a healthy file."""

import sqlite3

import numpy as np
import pytest

import viewdb
from viewdb.storage.codecs import encode_array
from viewdb_cli.main import main


@pytest.fixture
def copy_db(small_db, tmp_path):
    path = tmp_path / "copy.db"
    src, dst = sqlite3.connect(small_db), sqlite3.connect(path)
    src.backup(dst)
    src.close()
    dst.close()
    return path


def check(path):
    with viewdb.open(path, create=False) as db:
        return db.check()


def test_healthy_db_passes(copy_db, capsys):
    report = check(copy_db)
    assert report.ok, report.problems
    assert report.checked["objects"] == 4 and report.checked["views"] > 20
    assert main(["check", "--db", str(copy_db)]) == 0
    assert "ok" in capsys.readouterr().out


@pytest.mark.parametrize(
    "damage, finding",
    [
        ("UPDATE curves SET samples = x'00' WHERE view_id = 3", "array blob"),
        ("DELETE FROM sift_features WHERE view_id = 5", "missing curve, Fourier point or SIFT row"),
        ("UPDATE objects SET mesh_glb = x'0000000000' WHERE name = 'car'", "not a GLB"),
        ("UPDATE objects SET mesh_glb = x'' WHERE name = 'car'", "not a GLB"),
        ("DELETE FROM views WHERE id = 7", "views + 0 empty != "),
        ("UPDATE objects SET symmetry = '{}' WHERE name = 'mug'", "symmetry type does not decode"),
        ("UPDATE sift_features SET count = count + 1 WHERE view_id = 9", "array blob has shape"),
        ("UPDATE alembic_version SET version_num = '0000'", "schema revision"),
        ("DELETE FROM index_groups WHERE id = (SELECT MIN(id) FROM index_groups)",
         "has no group row"),
        ("UPDATE index_groups SET curves = (SELECT MAX(curves) FROM index_groups g2 WHERE"
         " g2.object_id != index_groups.object_id) WHERE id = (SELECT MIN(id) FROM index_groups"
         " WHERE tier = 'full')", "index_groups"),
        ("UPDATE index_groups SET tier = 'sparse' WHERE id = (SELECT MIN(id) FROM index_groups"
         " WHERE tier = 'full')", "not in the R-tree"),
        ("DELETE FROM rtree_meta WHERE tier = 'sparse'", "sparse tier: R-tree cannot be opened"),
        ("UPDATE perspective_views SET samples = (SELECT samples FROM curves LIMIT 1)"
         " WHERE id = (SELECT MIN(id) FROM perspective_views)", "differs from the stored curve"),
        ("DELETE FROM perspective_views WHERE id = (SELECT MIN(id) FROM perspective_views)",
         "is not a view of its object"),
        ("UPDATE perspective_views SET samples = x'00' WHERE id = (SELECT MAX(id) FROM perspective_views)",
         "perspective view"),
        ("DELETE FROM rtree_pages WHERE tier = 'full'", "full tier: R-tree cannot be opened"),
    ],
)
def test_each_kind_of_damage_is_reported(copy_db, capsys, damage, finding):
    with sqlite3.connect(copy_db) as conn:
        conn.execute("PRAGMA foreign_keys=OFF")
        conn.execute(damage)
    if "alembic_version" in damage:
        with pytest.raises(viewdb.SchemaMismatch):
            check(copy_db)
        return
    report = check(copy_db)
    assert not report.ok
    if finding == "index_groups":  # another group's curves: wrong shape, curve or box
        finding = "group"
    assert any(finding in p for p in report.problems), report.problems
    assert main(["check", "--db", str(copy_db)]) == 1
    assert "FAILED" in capsys.readouterr().out


def test_a_fourier_point_that_does_not_match_its_curve_is_reported(copy_db):
    with sqlite3.connect(copy_db) as conn:
        blob = encode_array(np.ones(8, np.complex128))
        conn.execute("UPDATE fourier_points SET coefficients = ? WHERE view_id = 11", (blob,))
    report = check(copy_db)
    assert any("does not match its curve" in p for p in report.problems)


def test_flipped_bytes_inside_a_page_are_found(copy_db, tmp_path):
    data = bytearray(copy_db.read_bytes())
    page = 4096
    rng = np.random.default_rng(0)
    for offset in rng.integers(page * 3, len(data) - 16, size=40):
        data[offset : offset + 8] = rng.integers(0, 256, 8, dtype=np.uint8).tobytes()
    bad = tmp_path / "flipped.db"
    bad.write_bytes(bytes(data))
    try:
        report = check(bad)
    except viewdb.StorageError:
        return  # refused outright: also a clear failure
    assert not report.ok


def test_check_does_not_modify_the_file(copy_db):
    before = copy_db.read_bytes()
    check(copy_db)
    assert copy_db.read_bytes() == before


def test_r_tree_damage_is_reported(copy_db):
    from viewdb.storage.codecs import decode_array
    from viewdb.storage.spatial import FourierIndex

    with sqlite3.connect(copy_db) as conn:
        gid, lo, hi = conn.execute(
            "SELECT id, lo, hi FROM index_groups WHERE tier = 'full' ORDER BY id LIMIT 1"
        ).fetchone()
        index = FourierIndex.open(conn, "full")
        lo, hi = decode_array(lo, np.float64, (6,)), decode_array(hi, np.float64, (6,))
        index.delete_box(gid, lo, hi)
        index.insert_box(gid, lo - 0.5, hi)  # the entry is there, with the wrong box
        index.insert_box(10**6, lo, hi)  # and an entry no group row has
        index.close()
    problems = check(copy_db).problems
    assert any(f"group {gid}: R-tree box differs" in p for p in problems), problems
    assert any("R-tree entry 1000000 has no group row" in p for p in problems), problems


def test_a_group_whose_box_misses_its_views_is_reported(copy_db):
    with sqlite3.connect(copy_db) as conn:
        gid = conn.execute("SELECT MIN(id) FROM index_groups").fetchone()[0]
        blob = conn.execute("SELECT curves FROM index_groups WHERE id = ?", (gid,)).fetchone()[0]
        from viewdb.storage.codecs import decode_array

        curves = decode_array(blob, np.float32, (None, 128)).copy()
        curves[0] = curves[0][::-1].copy() * 1.5
        conn.execute("UPDATE index_groups SET curves = ? WHERE id = ?", (encode_array(curves), gid))
    problems = check(copy_db).problems
    assert any(f"group {gid}" in p and ("outside its box" in p or "differs from the stored" in p)
               for p in problems), problems
