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
        ("DELETE FROM views WHERE id = 7", "views + 0 empty != "),
        ("UPDATE objects SET symmetry = '{}' WHERE name = 'mug'", "symmetry type does not decode"),
        ("UPDATE sift_features SET count = count + 1 WHERE view_id = 9", "array blob has shape"),
        ("UPDATE alembic_version SET version_num = '0000'", "schema revision"),
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
