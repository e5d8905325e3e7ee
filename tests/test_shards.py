"""Sharded catalogues: the split (viewdb shard), the manifest, and the exact scatter-gather.

The search's exactness is proven on real shard files with the shards answering in this
process (any shard count, hypothesis); tests/test_shards_ray.py runs the same shards as
Ray actors behind the server tier and over HTTP."""

import json
import os
import shutil
import sqlite3
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import viewdb
from viewdb.search.knn import brute_force_knn
from viewdb.search.plans import Candidate, RefineRequest
from viewdb.search.shifts import ShiftWindow
from viewdb.shards.gather import scatter_gather, top_k
from viewdb.shards.layout import read_manifest, shard_of, split_catalogue
from viewdb.shards.shard import Shard
from viewdb_cli.main import main

COUNTS = (1, 2, 3, 5)


@pytest.fixture(scope="module")
def splits(tiered_db, tmp_path_factory):
    """The tiered catalogue split into 1, 2, 3 and 5 shards, each opened in this process."""
    out = {}
    for n in COUNTS:
        manifest = split_catalogue(tiered_db, n, tmp_path_factory.mktemp("shards") / f"s{n}")
        out[n] = (manifest, [Shard(f, i, check=False) for i, f in enumerate(manifest.files)])
    yield out
    for _, shards in out.values():
        for s in shards:
            s.close()


def _owners(shards):
    owners, versions = {}, {}
    for s in shards:
        owners.update(dict.fromkeys(s.versions, s.index))
        versions.update(s.versions)
    return owners, versions


def sharded_refine(shards, request, first_round=1):
    owners, versions = _owners(shards)

    body = request.to_dict()

    def run(at, bound, client):
        return [shards[s].refine({**body, "client": [c.to_dict() for c in client.get(s, [])]}, bound) for s in at]

    return scatter_gather(request, owners, versions, len(shards), first_round, run)


def _rows(candidates):
    return [c.to_dict() for c in candidates]


def test_placement_is_a_stable_hash_that_spreads_names():
    names = [f"part-{i:05d}" for i in range(4000)]
    here = [shard_of(n, 4) for n in names[:50]]
    # another interpreter with another string-hash seed places them the same way
    code = "import sys; from viewdb.shards.layout import shard_of; print([shard_of(f'part-{i:05d}', 4) for i in range(50)])"
    child = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                           env={**os.environ, "PYTHONHASHSEED": "12345"})
    assert json.loads(child.stdout) == here
    counts = np.bincount([shard_of(n, 4) for n in names], minlength=4)
    assert counts.min() > 0.2 * len(names) and counts.max() < 0.3 * len(names)


def test_each_shard_is_a_normal_file_holding_exactly_its_objects(tiered_db, splits, capsys):
    manifest, _ = splits[3]
    with viewdb.open(tiered_db, read_only=True) as full:
        objects = {o.name: o for o in full.objects()}
        seen = set()
        for i, path in enumerate(manifest.files):
            assert main(["check", "--db", str(path)]) == 0
            assert main(["info", "--db", str(path), "--json"]) == 0
            with viewdb.open(path, read_only=True) as shard:
                names = {o.name for o in shard.objects()}
                assert all(shard_of(n, 3) == i for n in names) and not names & seen
                seen |= names
                assert len(names) == manifest.objects[i]
                for name in names:
                    assert shard.object(name).content_hash == objects[name].content_hash
                    mine, theirs = shard.views(name), full.views(name)
                    assert sorted(mine) == sorted(theirs)
                    a, e = theirs[len(theirs) // 2]
                    assert np.array_equal(shard.view(name, a, e).curve, full.view(name, a, e).curve)
        assert seen == set(objects)
    assert read_manifest(manifest.folder).files == manifest.files


def test_shard_refuses_bad_folders_and_leaves_nothing(tiered_db, tmp_path):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    (tmp_path / "afile").write_text("x")
    cases = [(["--out", str(tmp_path / "full")], "exists and is not empty"),
             (["--out", str(tmp_path / "no" / "where")], "parent folder does not exist")]
    for extra, message in cases:
        with pytest.raises(viewdb.ViewDBError, match=message):
            split_catalogue(tiered_db, 2, extra[1])
        assert main(["shard", "--db", str(tiered_db), "--shards", "2", *extra]) == 1
    assert main(["shard", "--db", str(tiered_db), "--shards", "2", "--out", str(tmp_path / "afile")]) == 2
    assert main(["shard", "--db", str(tmp_path / "missing.db"), "--shards", "2",
                 "--out", str(tmp_path / "new")]) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "full"]


def test_an_interrupted_split_leaves_nothing(tiered_db, tmp_path, monkeypatch):
    from viewdb.shards import layout

    def boom(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(layout, "_rebuild_tier", boom)
    with pytest.raises(KeyboardInterrupt):
        split_catalogue(tiered_db, 2, tmp_path / "out")
    assert list(tmp_path.iterdir()) == []


def test_missing_or_damaged_shards_are_refused_naming_them(splits, tmp_path):
    manifest, _ = splits[2]
    folder = tmp_path / "copy"
    shutil.copytree(manifest.folder, folder)
    (folder / "shard-001.viewdb").unlink()
    with pytest.raises(viewdb.StorageError, match=r"shard-001\.viewdb.*missing"):
        read_manifest(folder)
    (folder / "manifest.json").write_text("{")
    with pytest.raises(viewdb.StorageError, match="manifest.json"):
        read_manifest(folder)
    with pytest.raises(viewdb.StorageError, match="no manifest.json"):
        read_manifest(tmp_path)
    damaged = tmp_path / "damaged.viewdb"
    shutil.copy(manifest.files[0], damaged)
    with sqlite3.connect(damaged) as conn:
        conn.execute("UPDATE curves SET samples = x'00' WHERE view_id = (SELECT MIN(view_id) FROM curves)")
    with pytest.raises(viewdb.StorageError, match=r"damaged\.viewdb: fails check"):
        Shard(damaged, 0).close()


WINDOWS = st.sampled_from([None, ShiftWindow(), ShiftWindow(step=8), ShiftWindow(40, 6)])


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from(COUNTS), st.integers(1, 8), st.integers(0, 8),
       st.sampled_from(["server", "cs1", "prior"]), st.integers(1, 3), WINDOWS)
def test_sharded_search_equals_the_single_file_exactly(tiered_db, splits, seed, count, k, band, plan, first,
                                                       window):
    rng = np.random.default_rng(seed)
    with viewdb.open(tiered_db, read_only=True) as db:
        arrays, _ = db.search_tier("full")
        q = arrays.curves[rng.integers(len(arrays.curves))]
        q = np.clip(q * rng.uniform(0.9, 1.1) + rng.normal(0, rng.choice([0.0, 0.02, 0.2]), 128), 0, None)
        client: list[Candidate] = []
        if window is not None:  # the query turned: a shift search finds it
            q = np.roll(q, int(rng.integers(0, 128)))
        if plan == "cs1":
            client, _ = db.client_candidates(q, k, band=band, shifts=window)
        elif plan == "prior":  # bounds from elsewhere: some objects' distances, loosened
            hits, _ = db.search(q, k + 2, band=band, shifts=window)
            client = [Candidate(h.object, h.distance * rng.uniform(1.0, 1.5), 0.0, 0.0, False)
                      for h in hits if rng.random() < 0.7]
        request = RefineRequest(q, band, k, client, window)
        single, _ = db.server_tier().refine(request)
    sharded = sharded_refine(splits[count][1], request, first)
    assert _rows(sharded.results) == _rows(single.results)


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from(COUNTS), st.integers(1, 4), st.integers(1, 7))
def test_the_fast_plan_over_shards_reports_true_distances(tiered_db, splits, seed, count, k, shortlist):
    """Each shard shortlists from its own index; every distance is the object's exact one,
    and a shortlist of every object is the single file's exact answer."""
    rng = np.random.default_rng(seed)
    with viewdb.open(tiered_db, read_only=True) as db:
        arrays, _ = db.search_tier("full")
        q = np.clip(arrays.curves[rng.integers(len(arrays.curves))] + rng.normal(0, 0.03, 128), 0, None)
        exact = {nb.object: nb.distance for nb in brute_force_knn(q, arrays, len(arrays.names), 6)}
        single, _ = db.server_tier().refine(RefineRequest(q, 6, k, []))
    sharded = sharded_refine(splits[count][1], RefineRequest(q, 6, k, [], fast=shortlist))
    for c in sharded.results:
        assert c.distance == pytest.approx(exact[c.object], abs=1e-9)
    if shortlist >= len(arrays.names):
        assert _rows(sharded.results) == _rows(single.results)
    for s in splits[count][1]:  # each shard's own index, written by the split, answered
        if s.versions:
            reply = s.refine(RefineRequest(q, 6, k, [], fast=shortlist).to_dict(), np.inf)
            assert reply["stats"]["fast_index"] == 1.0


def test_later_rounds_are_pruned_by_the_first(tiered_db, splits):
    rng = np.random.default_rng(7)
    shards = splits[5][1]
    with viewdb.open(tiered_db, read_only=True) as db:
        arrays, _ = db.search_tier("full")
    pruned = unbounded = 0
    for _ in range(10):
        q = arrays.curves[rng.integers(len(arrays.curves))] + rng.normal(0, 0.02, 128)
        request = RefineRequest(np.clip(q, 0, None), 6, 1, [])
        reply = sharded_refine(shards, request)
        pruned += reply.stats["dtw"]
        unbounded += sum(s.refine(request.to_dict(), np.inf)["stats"]["dtw"] for s in shards)
    assert pruned < unbounded


def test_merge_orders_ties_by_name_as_the_single_file_does():
    found = [Candidate(n, d, 0.0, 0.0, False) for n, d in (("b", 1.0), ("a", 1.0), ("c", 0.5), ("a", 2.0))]
    assert [c.object for c in top_k(found, 3)] == ["c", "a", "b"]
    assert [c.distance for c in top_k(found, 3)] == [0.5, 1.0, 1.0]


def test_import_viewdb_never_imports_ray():
    code = "import sys, viewdb, viewdb.shards.layout, viewdb_cli.main; print('ray' in sys.modules)"
    child = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert child.stdout.strip() == "False"
