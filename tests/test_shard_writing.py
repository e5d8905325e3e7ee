"""Writing sharded catalogues: an ingest straight into shard files places each object by
the stable hash and keeps the manifest true; ``export-client --shards`` writes the very
client file the single file exports."""

import json
import os
import shutil
import socket
import sqlite3
import subprocess
import sys
import threading

import numpy as np
import pytest

import viewdb
from tests.conftest import TIERED_DB_MODELS, sample
from viewdb.shards.layout import read_manifest, shard_of, split_catalogue
from viewdb.shards.lock import lock_path
from viewdb.shards.writing import export_client_from_shards, open_shards
from viewdb_cli.main import main

SMALL = ("cone", "pyramid", "chair", "mug", "car")
SETTINGS = {"gap": 90, "image_size": 64}


def _rows(path):
    """Every row of every table of a SQLite file, table by table (the schema too), but the
    tiers' stamped keys (derived from the index's generation)"""
    with sqlite3.connect(f"file:{path}?mode=ro", uri=True) as conn:
        tables = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'"
                                             " AND name != 'tier_stamps' ORDER BY name")]
        # but the index's generation, a fresh token on every write
        return {t: conn.execute(f'SELECT * FROM "{t}"' + (" WHERE key != 'index_generation'" if t == "settings"
                                                          else "")).fetchall() for t in tables}, \
            conn.execute("SELECT type, name, sql FROM sqlite_master ORDER BY name").fetchall()


@pytest.mark.parametrize("bits", [8, 0])
def test_export_client_from_shards_writes_the_single_files_client_file(tiered_db, tmp_path, bits):
    file = viewdb.config.ClientFileConfig(curve_bits=bits)
    single = tmp_path / "single.db"
    with viewdb.open(tiered_db, read_only=True) as db:
        db.export_client(single, file=file)
    for n in (1, 3, 5):
        manifest = split_catalogue(tiered_db, n, tmp_path / f"s{n}")
        sharded = tmp_path / f"from{n}.db"
        export_client_from_shards(manifest.folder, sharded, file=file)
        mine, theirs = _rows(sharded), _rows(single)
        assert mine[1] == theirs[1]
        assert mine[0].keys() == theirs[0].keys()
        for table, rows in theirs[0].items():
            assert mine[0][table] == rows, table
        assert len(mine[0]["objects"]) == len(TIERED_DB_MODELS) and mine[0]["index_groups"]
        assert viewdb.open(sharded, read_only=True).check().ok


def test_export_client_cli_from_shards_and_its_refusals(tiered_db, tmp_path, capsys):
    manifest = split_catalogue(tiered_db, 2, tmp_path / "s")
    out = tmp_path / "c.db"
    assert main(["export-client", "--shards", str(manifest.folder), "--out", str(out)]) == 0
    assert f"wrote {out}: {len(TIERED_DB_MODELS)} objects" in capsys.readouterr().out
    assert main(["export-client", "--shards", str(manifest.folder), "--out", str(out)]) == 1  # exists
    assert main(["export-client", "--db", str(tiered_db), "--shards", str(manifest.folder),
                 "--out", str(tmp_path / "d.db")]) == 2
    twice = tmp_path / "twice"
    shutil.copytree(manifest.folder, twice)
    shutil.copy(twice / "shard-000.viewdb", twice / "shard-001.viewdb")  # shard 0's objects twice
    capsys.readouterr()
    assert main(["export-client", "--shards", str(twice), "--out", str(tmp_path / "e.db")]) == 1
    err = capsys.readouterr().err
    assert "is in more than one of the files exported" in err and err.count("\n") == 1
    assert not (tmp_path / "e.db").exists()


def test_ingest_into_new_shards_places_each_object_and_keeps_the_manifest(tmp_path, capsys):
    folder = tmp_path / "shards"
    with open_shards(folder, count=3, **SETTINGS) as shards:
        report = shards.ingest([sample(n) for n in SMALL])
    assert report.counts()["added"] == len(SMALL)
    manifest = read_manifest(folder)
    assert manifest.shards == 3
    for i, path in enumerate(manifest.files):
        with viewdb.open(path, read_only=True) as shard:
            assert shard.check().ok
            names = {o.name for o in shard.objects()}
            assert names == {n for n in SMALL if shard_of(n, 3) == i}
            assert manifest.objects[i] == len(names)
    # the same objects as a single file holds
    single = tmp_path / "single.db"
    with viewdb.open(single, **SETTINGS) as db:
        db.ingest([sample(n) for n in SMALL])
        for name in SMALL:
            with viewdb.open(manifest.files[shard_of(name, 3)], read_only=True) as shard:
                assert sorted(shard.views(name)) == sorted(db.views(name))
                for at in db.views(name):
                    np.testing.assert_array_equal(shard.view(name, *at).curve, db.view(name, *at).curve)
        # one look model over every shard's objects, in each: the single file's
        single_model = db._catalogue.look_model()
        assert single_model is not None
        probe = np.random.default_rng(0).random(single_model.mean.shape).astype(np.float32)
        for path in manifest.files:
            with viewdb.open(path, read_only=True) as shard:
                key, model = shard._catalogue.shard_look()
                assert key == db._catalogue.look_key() and shard._catalogue.look_model() is None
                assert shard.info().look == {"objects": len(single_model.objects), "shared": True}
                assert model.distances(probe) == pytest.approx(single_model.distances(probe))

    # through the CLI: re-running is a no-op, a new object lands in its shard
    code = main(["ingest", *map(str, [sample("cone"), sample("torus")]), "--shards", str(folder), "--json"])
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    assert (data["added"], data["unchanged"]) == (1, 1)
    manifest = read_manifest(folder)
    assert sum(manifest.objects) == len(SMALL) + 1
    assert manifest.objects[shard_of("torus", 3)] == 1 + sum(shard_of(n, 3) == shard_of("torus", 3) for n in SMALL)
    keys = set()
    for path in manifest.files:  # fitted again over the six objects, in every shard
        with viewdb.open(path, read_only=True) as shard:
            keys.add(shard._catalogue.shard_look()[0])
    assert len(keys) == 1 and keys != {key}


def test_a_stale_manifest_is_repaired_and_misplaced_objects_refused(small_db, tmp_path):
    manifest = split_catalogue(small_db, 2, tmp_path / "s")
    data = json.loads((manifest.folder / "manifest.json").read_text())
    true_counts = [e["objects"] for e in data["shards"]]
    data["shards"][0]["objects"] += 1  # as after a kill between an object's commit and its count
    (manifest.folder / "manifest.json").write_text(json.dumps(data))
    with open_shards(manifest.folder) as shards:
        shards.ingest([])
    assert read_manifest(manifest.folder).objects == true_counts

    swapped = tmp_path / "swapped"
    shutil.copytree(manifest.folder, swapped)
    (swapped / "shard-000.viewdb").rename(swapped / "x")
    (swapped / "shard-001.viewdb").rename(swapped / "shard-000.viewdb")
    (swapped / "x").rename(swapped / "shard-001.viewdb")
    with open_shards(swapped) as shards, pytest.raises(viewdb.StorageError, match=r"holds .*which the placement puts in shard"):
        shards.ingest([sample("cone")])


def test_ingest_shards_cli_refusals_leave_nothing(tmp_path, capsys):
    cone = str(sample("cone"))
    assert main(["ingest", cone, "--shards", str(tmp_path / "new")]) == 1
    err = capsys.readouterr().err
    assert "--shard-count" in err and err.count("\n") == 1
    assert main(["ingest", cone, "--db", str(tmp_path / "a.db"), "--shards", str(tmp_path / "new")]) == 2
    assert main(["ingest", cone, "--db", str(tmp_path / "a.db"), "--shard-count", "2"]) == 2
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    assert main(["ingest", cone, "--shards", str(tmp_path / "full"), "--shard-count", "2"]) == 1
    assert "exists and is not empty; remove it or choose another --shards" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["full"]


def _ingest_cli(folder, *names):
    """``viewdb ingest NAMES --shards FOLDER`` in another process: (exit code, stderr)."""
    proc = subprocess.run([sys.executable, "-m", "viewdb_cli.main", "ingest", *map(str, map(sample, names)),
                           "--shards", str(folder)], capture_output=True, text=True, timeout=600)
    return proc.returncode, proc.stderr


def test_two_concurrent_sharded_ingests_one_writes_the_other_is_refused(tmp_path):
    folder = tmp_path / "shards"
    errors = []
    with open_shards(folder, count=3, **SETTINGS) as first:
        assert lock_path(folder).read_text().startswith(f"pid {os.getpid()} on {socket.gethostname()} since ")
        writing = threading.Thread(target=lambda: errors.append(first.ingest([sample(n) for n in SMALL])))
        writing.start()
        code, err = _ingest_cli(folder, "torus", "cone")  # the second ingest, while the first writes
        writing.join()
    assert code == 1 and err.count("\n") == 1
    assert f"is being written by another ingest (pid {os.getpid()} on {socket.gethostname()}" in err
    assert errors[0].counts()["added"] == len(SMALL)
    assert not lock_path(folder).exists()  # released with the files

    code, err = _ingest_cli(folder, "torus", "cone")  # now alone: it writes
    assert code == 0, err
    manifest = read_manifest(folder)
    for i, path in enumerate(manifest.files):  # the counts are what the files hold
        with viewdb.open(path, read_only=True) as shard:
            assert manifest.objects[i] == len(shard.objects())
    assert sum(manifest.objects) == len(SMALL) + 1

    # a writer asked to wait takes the folder once the first lets it go
    first = open_shards(folder)
    got = []
    waiting = threading.Thread(target=lambda: got.append(open_shards(folder, wait=60)))
    waiting.start()
    waiting.join(1.0)
    assert waiting.is_alive()
    first.close()
    waiting.join(60)
    with got[0] as second:
        second.ingest([sample("torus")])
        with pytest.raises(viewdb.StorageError, match="is being written by another ingest"):
            open_shards(folder)
