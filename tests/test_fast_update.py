"""Growing the ``fast`` index in place: after an ingest the index keeps the keys of the
groups whose curves did not change, adds the others' views under new keys, leaves the
views of groups gone in the graph as dead keys that name no row, and is built anew once
those pass ``dead_share``. Whatever it went through, every key the search meets names the
view whose embedding it holds, or none."""

import shutil
from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import viewdb
from tests.conftest import copy_db, mixed_query_curves, sample
from viewdb.config import FastConfig
from viewdb.search.embedding import embed_curves
from viewdb.search.fast_update import KeyTable, group_digests, plan_update
from viewdb.search.knn import brute_force_knn
from viewdb.storage.ann_file import ann_file_path, index_file_key, map_ann_file
from viewdb.storage.tiers import TierReader

groups = st.lists(st.tuples(st.integers(0, 5), st.integers(1, 4)), max_size=12)


def _table(old):
    digests = np.array([d for d, _ in old], dtype=np.uint64)
    return KeyTable.fresh(digests, np.array([c for _, c in old], dtype=np.int64))


@settings(max_examples=300, deadline=None)
@given(groups, groups, st.integers(0, 2))
def test_a_planned_table_keeps_each_unchanged_group_s_keys_once_and_adds_the_rest(old, new, grown):
    table = _table(old)
    for _ in range(grown):  # a table that was grown already: runs out of row order, dead keys
        table, _ = plan_update(table, table.digests[::-1].copy(), table.counts[::-1].copy())
    digests = np.array([d for d, _ in new], dtype=np.uint64)
    counts = np.array([c for _, c in new], dtype=np.int64)
    planned, added = plan_update(table, digests, counts)
    # the brute force: as many groups keep their keys as old and new groups pair up by content
    kept = sum((Counter(zip(table.digests.tolist(), table.counts.tolist(), strict=True))
                & Counter(new)).values())
    assert int((~added).sum()) == kept
    old_runs = Counter(zip(table.digests.tolist(), table.first.tolist(), table.counts.tolist(), strict=True))
    kept_runs = Counter(zip(digests[~added].tolist(), planned.first[~added].tolist(), counts[~added].tolist(),
                            strict=True))
    assert not kept_runs - old_runs  # a kept group's run is an old run of the same curves, used once
    # the added runs follow the old keys, in the tier's order, without a gap
    assert planned.first[added].tolist() == (table.keys + np.cumsum(counts[added]) - counts[added]).tolist()
    assert planned.keys == table.keys + int(counts[added].sum())
    # each live key names its view's row; every other key names none
    row_of_key = planned.row_of_key()
    rows = np.arange(planned.keys) if row_of_key is None else row_of_key
    starts = np.cumsum(counts) - counts
    for g in range(len(new)):
        for i in range(int(counts[g])):
            assert rows[planned.first[g] + i] == starts[g] + i
    assert int((rows < 0).sum()) == planned.dead == planned.keys - int(counts.sum())
    # and the table survives its file form
    again = KeyTable.from_array(planned.to_array(), planned.keys)
    assert again.digests.tolist() == planned.digests.tolist() and again.first.tolist() == planned.first.tolist()


@pytest.mark.parametrize("table, keys", [
    ([[1, 0, 3], [2, 2, 3]], 6),   # runs overlap
    ([[1, 0, 3], [2, 3, 3]], 5),   # a run past the keys
    ([[1, -1, 2]], 4),             # a negative key
    ([[1, 0, -1]], 4),             # a negative count
])
def test_a_key_table_that_does_not_describe_separate_runs_is_refused(table, keys):
    with pytest.raises(ValueError, match="overlap or pass"):
        KeyTable.from_array(np.array(table, dtype=np.int64), keys)


def _replace(db, name, mesh, tmp_path):
    """Ingest ``mesh``'s shape under the name of the stored object ``name``."""
    folder = tmp_path / "swap"
    folder.mkdir(exist_ok=True)
    target = folder / f"{name}{mesh.suffix}"
    shutil.copy(mesh, target)
    with viewdb.open(db, create=False) as vdb:
        report = vdb.ingest([target])
    assert not report.failed, report.failed


def _check_keys(db, config):
    """Every view of ``db``'s full tier is found by its own embedding under a key whose
    row holds that embedding (the index's keys name the right views), and the table's
    dead keys name no row. Returns the key table."""
    reader = TierReader(db, write_files=False)
    try:
        with reader.snapshot():
            source = reader.tier("full")
            found = reader.fast_index("full", config)
            assert found is not None
            curves = source.rows(np.arange(source.n_groups, dtype=np.int64))[0]
            vectors = embed_curves(np.asarray(curves), config.coefficients, config.quantiles)
            rows, distances = found.nearest_rows(vectors, 1)
            assert (rows[:, 0] >= 0).all()  # a dead key is never an answer
            # the graph search is approximate: nearly every view finds its own embedding,
            # and a key that is found at distance 0 names a view with that embedding
            hit = distances[:, 0] < 1e-9
            assert hit.mean() > 0.95
            np.testing.assert_allclose(vectors[rows[hit, 0]], vectors[hit], atol=1e-5)
            return map_ann_file(ann_file_path(db, "full"), index_file_key(source.key, config), "full",
                                len(source.row_owner))[1]
    finally:
        reader.close()


def test_an_ingest_grows_the_index_and_its_keys_name_the_right_views(tiered_db, tmp_path):
    db = copy_db(tiered_db, tmp_path / "copy.db")
    shutil.copy(ann_file_path(tiered_db, "full"), ann_file_path(db, "full"))
    before = _check_keys(db, FastConfig())
    with viewdb.open(db, create=False) as vdb:
        assert not vdb.ingest([sample("cone")]).failed
    added = _check_keys(db, FastConfig())
    # the old groups keep their runs; the cone's views follow
    assert added.keys == added.rows and added.first[: len(before.first)].tolist() == before.first.tolist()
    # a replaced object's views stay in the graph, dead, while they are few (the cube's: 4 %)
    with viewdb.open(db, create=False, read_only=True) as vdb:
        arrays, _ = vdb.search_tier("full")
        cube = int((arrays.owner == arrays.names.index("marked_cube")).sum())
    _replace(db, "marked_cube", sample("pyramid"), tmp_path)
    replaced = _check_keys(db, FastConfig())
    assert replaced.dead == cube and replaced.keys == added.keys + replaced.rows - (added.rows - cube)


@pytest.mark.parametrize("dead_share, grown", [(0.9, True), (0.0, False)])
def test_a_replaced_object_leaves_dead_keys_until_they_pass_their_share(tiered_db, tmp_path, dead_share, grown):
    db = copy_db(tiered_db, tmp_path / "copy.db")
    shutil.copy(ann_file_path(tiered_db, "full"), ann_file_path(db, "full"))
    stale = ann_file_path(db, "full").read_bytes()
    _replace(db, "car", sample("cone"), tmp_path)  # the ingest writes the index as its default says
    ann_file_path(db, "full").write_bytes(stale)  # back to the index of before, to grow it with dead_share
    config = FastConfig(dead_share=dead_share)
    reader = TierReader(db, write_files=True)
    try:
        with reader.snapshot():
            reader.tier("full")
            index = reader.fast_index("full", config)
            assert index is not None
            assert (index.row_of_key is not None) == grown
    finally:
        reader.close()
    table = _check_keys(db, config)
    assert (table.dead > 0) == grown and (table.keys > table.rows) == grown
    # the plan's answers are still true distances, the server's with every object listed
    rng = np.random.default_rng(5)
    with viewdb.open(db, create=False, read_only=True) as vdb:
        arrays, _ = vdb.search_tier("full")
        for q in mixed_query_curves(vdb, rng, 4):
            exact = {nb.object: nb.distance for nb in brute_force_knn(q, arrays, len(arrays.names), 6)}
            fast = vdb.recognise(q, 3, plan="fast", fast_shortlist=2)
            assert fast.server_stats["fast_index"] == 1.0
            for c in fast.results:
                assert c.distance == pytest.approx(exact[c.object], abs=1e-9)
            full = vdb.recognise(q, 3, plan="fast", fast_shortlist=len(arrays.names))
            assert [c.object for c in full.results] == [c.object for c in vdb.recognise(q, 3, plan="server").results]


def test_a_stale_index_with_a_damaged_key_table_is_built_anew(tiered_db, tmp_path):
    db = copy_db(tiered_db, tmp_path / "copy.db")
    stale = bytearray(ann_file_path(tiered_db, "full").read_bytes())
    with viewdb.open(db, create=False) as vdb:
        assert not vdb.ingest([sample("cone")]).failed
    # the first group's run moved onto the second's: the table no longer describes the keys
    header = int.from_bytes(stale[8:12], "little")
    at = -(-(12 + header) // 64) * 64
    stale[at + 8 : at + 16] = stale[at + 32 : at + 40]
    ann_file_path(db, "full").write_bytes(bytes(stale))
    config = FastConfig()
    reader = TierReader(db, write_files=True)
    try:
        with reader.snapshot():
            source = reader.tier("full")
            assert reader.fast_index("full", config) is not None
            digests = group_digests(source)
    finally:
        reader.close()
    table = _check_keys(db, config)
    assert table.row_of_key() is None and table.digests.tolist() == digests.tolist()
