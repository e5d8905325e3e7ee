"""The ``fast`` plan: a shortlist of objects from an approximate index over a turn-free
embedding of every view, searched exactly. Every distance it reports is a view's exact
DTW distance; over its shortlist it is the brute force; with every object shortlisted it
is the ``server`` plan; its index file next to the database is used only when it matches
the database (a stale, foreign or damaged one is rebuilt or ignored, never trusted)."""

import json
import sqlite3

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import viewdb
from tests.conftest import copy_db, mixed_query_curves, sample
from viewdb.catalogue.features import mirror_curve
from viewdb.config import FastConfig, RecognitionConfig
from viewdb.search.bounds import dtw
from viewdb.search.embedding import embed_curves
from viewdb.search.fast import build_fast_index, fast_knn, merged_queries, shortlist_objects, view_distances
from viewdb.search.knn import TierArrays, brute_force_knn, knn_stack
from viewdb.search.plans import PLANS, RefineRequest
from viewdb.search.subset import SubsetSource
from viewdb.storage.ann_file import ann_file_path, index_file_key, map_ann_file
from viewdb.storage.tier_file import tier_key


def _same(a, b):
    assert [c.object for c in a] == [c.object for c in b]
    np.testing.assert_allclose([c.distance for c in a], [c.distance for c in b], rtol=0, atol=1e-9)


def _stack_brute(curves, arrays, k, band, objects=None):
    """The brute force of a stack of curves: each object's smallest distance over the rows,
    over ``objects`` (indices) alone if given."""
    best = {}
    for q in curves:
        for nb in brute_force_knn(q, arrays, len(arrays.names), band):
            o = arrays.names.index(nb.object)
            if objects is not None and o not in objects:
                continue
            if nb.object not in best or nb.distance < best[nb.object].distance:
                best[nb.object] = nb
    return sorted(best.values(), key=lambda nb: (nb.distance, nb.object))[:k]


# ---------------------------------------------------------------- the embedding


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 127), st.sampled_from([0, 16, 32]))
def test_the_embedding_ignores_turns_and_mirrors(seed, shift, quantiles):
    rng = np.random.default_rng(seed)
    curve = 1 + 0.3 * rng.standard_normal(128)
    e = embed_curves(curve, 16, quantiles)
    assert e.shape == (1, 16 + quantiles) and e.dtype == np.float32
    np.testing.assert_allclose(embed_curves(np.roll(curve, shift), 16, quantiles), e, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(embed_curves(mirror_curve(curve), 16, quantiles), e, rtol=1e-4, atol=1e-6)
    # but it is not blind: another curve embeds elsewhere
    other = 1 + 0.3 * rng.standard_normal(128)
    assert np.abs(embed_curves(other, 16, quantiles) - e).max() > 1e-3


def test_the_sorted_values_tell_apart_curves_whose_magnitudes_agree():
    """Detail past the kept coefficients widens the curve's range: the magnitudes cannot
    see it, the sorted values can."""
    t = np.arange(128) / 128
    plain = 1 + 0.2 * np.cos(2 * np.pi * 3 * t)
    wiggly = plain + 0.1 * np.cos(2 * np.pi * 40 * t)
    np.testing.assert_allclose(embed_curves(wiggly, 16), embed_curves(plain, 16), atol=1e-6)
    apart = embed_curves(wiggly, 16, 16) - embed_curves(plain, 16, 16)
    assert np.abs(apart[0, :16]).max() < 1e-6 and np.abs(apart[0, 16:]).max() > 0.01


def test_the_embedding_refuses_coefficients_past_nyquist_and_too_many_sorted_values():
    with pytest.raises(ValueError, match="at least 33 samples"):
        embed_curves(np.ones(32), 16)
    with pytest.raises(ValueError, match="64 sorted values need curves of at least 64 samples"):
        embed_curves(np.ones(40), 8, 64)


# ---------------------------------------------------------------- the search, on arrays


def _random_tier(rng, objects, views, n=32):
    t = np.arange(n) / n
    names = [f"o{i}" for i in range(objects)]
    owner = np.repeat(np.arange(objects), views)
    curves = []
    for _ in range(objects):
        base = 1 + sum(rng.uniform(-0.3, 0.3) * np.cos(2 * np.pi * (f * t + rng.random())) for f in (1, 2, 3))
        for _view in range(views):
            c = np.roll(base, int(rng.integers(n))) + rng.normal(0, 0.05, n)
            curves.append(np.clip(c, 0.05, None) / np.clip(c, 0.05, None).mean())
    return TierArrays(names, owner, np.array(curves), group_views=4)


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5))
def test_a_seed_view_s_distance_is_the_one_the_exact_search_finds(seed, turns):
    """The radius the search starts from is measured as the search measures: with one view
    per object, each object's exact distance is its only view's."""
    rng = np.random.default_rng(seed)
    arrays = _random_tier(rng, 6, 1)
    stack = np.stack([np.roll(arrays.curves[int(rng.integers(6))], int(rng.integers(32)))
                      + rng.normal(0, 0.05, 32) for _ in range(turns)])
    found, _ = knn_stack(stack, arrays, 6, 3)
    measured = view_distances(stack, arrays, np.arange(6, dtype=np.int64), 3)
    for nb in found:
        assert measured[arrays.names.index(nb.object)] == pytest.approx(nb.distance, rel=1e-12)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(1, 4), st.integers(1, 9), st.integers(0, 4), st.sampled_from([1, 2]),
       st.sampled_from([1e-4, 1.0]))
def test_a_subset_source_searches_exactly_the_objects_it_holds(seed, k, picks, band, threads, radius):
    """On one thread or two sharing the subset's group keys, from a radius that must widen
    many times or not at all."""
    rng = np.random.default_rng(seed)
    arrays = _random_tier(rng, 9, 6)
    objects = sorted(set(rng.integers(0, 9, picks).tolist()))
    curves = np.stack([arrays.curves[rng.integers(len(arrays.curves))] + rng.normal(0, 0.05, 32)
                       for _ in range(2)])
    found, _ = knn_stack(curves, SubsetSource(arrays, objects), k, band, block=1, threads=threads,
                         initial_radius=radius)
    only = np.isin(np.arange(9), objects)
    masked, _ = knn_stack(curves, arrays, k, band, block=1, only=only)
    _same(found, masked)
    _same(found, _stack_brute(curves, arrays, k, band, set(objects)))
    assert {nb.object for nb in found} <= {arrays.names[o] for o in objects}


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(1, 4), st.integers(1, 12), st.integers(0, 4))
def test_fast_is_the_brute_force_over_its_shortlist(seed, k, shortlist, band):
    rng = np.random.default_rng(seed)
    arrays = _random_tier(rng, 12, 5)
    config = FastConfig(coefficients=8, views_per_object=2)
    index = build_fast_index(arrays, config)
    curves = np.stack([np.roll(arrays.curves[rng.integers(len(arrays.curves))], int(rng.integers(32)))
                       + rng.normal(0, 0.05, 32) for _ in range(3)])
    listed, _ = shortlist_objects(curves, index, max(shortlist, k), arrays)
    assert len(listed) == min(max(shortlist, k), 12) == len(set(listed.tolist()))
    found, stats = fast_knn(curves, arrays, index, k, band, max(shortlist, k))
    _same(found, _stack_brute(curves, arrays, k, band, set(listed.tolist())))
    assert stats.to_dict()["shortlisted"] == len(listed)
    for nb in found:  # each distance is the reported view's own exact one
        c = arrays.curves[nb.view]
        assert dtw(curves[nb.shift], mirror_curve(c) if nb.mirrored else c, band) == pytest.approx(nb.distance)
    if max(shortlist, k) >= 12:
        _same(found, _stack_brute(curves, arrays, k, band))


@pytest.mark.parametrize("exact_share", [0.0, 1.0])
def test_the_shortlist_ranks_objects_by_their_nearest_view_in_the_embedding(exact_share):
    rng = np.random.default_rng(5)
    arrays = _random_tier(rng, 10, 4)
    config = FastConfig(coefficients=8, exact_share=exact_share, views_per_object=1)
    index = build_fast_index(arrays, config)
    index.cache.clear()  # the exact ranking embeds the views again
    q = arrays.curves[17][None, :]
    for size in (3, 10):
        listed, asked = shortlist_objects(q, index, size, arrays)
        if size == 10:  # 10 views name fewer than 10 objects: asked again (a share of 1), or ranked exactly
            assert (asked > 10) == (exact_share == 1.0) and (asked == 0) == (exact_share == 0.0)
        e, every = (embed_curves(c, 8, config.quantiles) for c in (q, arrays._curves))
        nearest = [np.min(((every[arrays.row_owner == o] - e) ** 2).sum(axis=1)) for o in range(10)]
        # a small catalogue's HNSW search is exact
        assert listed.tolist() == np.argsort(nearest, kind="stable").tolist()[:size]
        assert listed[0] == arrays.owner[17]


def _crowded_tier(rng):
    """Object 0: 30 views of nearly one curve; objects 1-9: 4 views each of others."""
    crowd = _random_tier(rng, 1, 30)
    crowd_curves = crowd.curves[0] + rng.normal(0, 0.002, (30, 32))
    rest = _random_tier(rng, 9, 4)
    owner = np.r_[np.zeros(30, dtype=np.int64), rest.owner + 1]
    return TierArrays([f"o{i}" for i in range(10)], owner, np.vstack([crowd_curves, rest.curves]), group_views=4)


@pytest.mark.parametrize("least", [1, 2])
def test_views_that_crowd_into_few_objects_shortlist_those_without_ranking_every_view(least):
    """The index is asked for at most ``exact_share`` of its views; when the nearest
    views name fewer objects than asked for, those objects are the shortlist (every view
    is not embedded), unless they are fewer than ``least``."""
    arrays = _crowded_tier(np.random.default_rng(11))
    config = FastConfig(coefficients=8, exact_share=0.3, views_per_object=1)  # at most 19 of 66 views
    index = build_fast_index(arrays, config)
    index.cache.clear()
    listed, asked = shortlist_objects(arrays.curves[3][None, :], index, 5, arrays, least)
    if least == 1:
        assert listed.tolist() == [0] and asked == 19 and "vectors" not in index.cache
    else:
        assert len(listed) == 5 and listed[0] == 0 and asked == 0 and "vectors" in index.cache
    found, stats = fast_knn(arrays.curves[3][None, :], arrays, index, least, 3, 5)
    assert [nb.object for nb in found][:1] == ["o0"] and len(found) == least
    assert stats.to_dict()["shortlisted"] == (1 if least == 1 else 5)


def test_a_photos_turns_ask_the_index_once_and_other_outlines_apart():
    rng = np.random.default_rng(8)
    a, b = rng.random(16).astype(np.float32), rng.random(16).astype(np.float32) + 1
    turns = np.stack([a + rng.normal(0, 0.002, 16) for _ in range(12)] + [b + rng.normal(0, 0.002, 16)
                                                                           for _ in range(12)]).astype(np.float32)
    merged = merged_queries(turns, 0.03)
    assert merged.shape == (2, 16)
    np.testing.assert_allclose(merged[0], turns[:12].mean(axis=0), rtol=1e-5)
    assert merged_queries(turns, 0.0).shape == (24, 16)


def test_without_an_index_fast_is_the_exact_search():
    rng = np.random.default_rng(6)
    arrays = _random_tier(rng, 8, 4)
    curves = arrays.curves[[3, 9]] + 0.01
    found, stats = fast_knn(curves, arrays, None, 3, 2, 2)
    _same(found, _stack_brute(curves, arrays, 3, 2))
    assert stats.to_dict()["fast_index"] == 0.0


# ---------------------------------------------------------------- the plan, on a file


def test_fast_is_a_plan_everywhere_plans_are_listed():
    assert "fast" in PLANS
    assert viewdb.QueryOptions(plan="fast").plan == "fast"
    with pytest.raises(ValueError, match="fast_shortlist"):
        RecognitionConfig(fast_shortlist=0)


def test_the_fast_plan_reports_exact_distances_and_equals_server_with_every_object(tiered_db):
    rng = np.random.default_rng(21)
    with viewdb.open(tiered_db, create=False, read_only=True) as db:
        arrays, _ = db.search_tier("full")
        names = [o.name for o in db.objects()]
        for q in mixed_query_curves(db, rng, 10):
            for k, shortlist, band in ((1, 1, 6), (2, 3, 4), (3, 2, 6), (3, len(names), 5)):
                fast = db.recognise(q, k, band=band, plan="fast", fast_shortlist=shortlist)
                assert fast.server_stats["fast_index"] == 1.0
                # fewer when the index's nearest views name fewer objects (never fewer than k)
                assert k <= fast.server_stats["shortlisted"] <= min(max(shortlist, k), len(names))
                assert len(fast.results) == k
                everything = brute_force_knn(q, arrays, len(names), band)
                exact = {nb.object: nb.distance for nb in everything}
                for c in fast.results:  # a true distance: the object's best over all its views
                    assert c.distance == pytest.approx(exact[c.object], abs=1e-9)
                if shortlist >= len(names):
                    _same(fast.results, db.recognise(q, k, band=band, plan="server").results)


def test_a_photo_query_with_the_fast_plan(tiered_db):
    with viewdb.open(tiered_db, create=False, read_only=True) as db:
        photo = db.render("mug", 37.0, 21.0).color
        fast = db.query(photo, plan="fast", pose=False, k=3, fast_shortlist=6)
        server = db.query(photo, plan="server", pose=False, k=3)
        assert fast.plan == "fast"
        assert [r.object for r in fast.results] == [r.object for r in server.results]
        assert fast.to_dict()["plan"] == "fast"


def test_a_fast_request_goes_over_the_wire_and_bad_ones_are_refused():
    request = RefineRequest.of_stack(np.ones((2, 128)), 6, 3, [], fast=20)
    again = RefineRequest.from_dict(json.loads(json.dumps(request.to_dict())), 128)
    assert again.fast == 20 and again.curves.shape == (2, 128)
    assert RefineRequest.from_dict(RefineRequest(np.ones(128), 6, 3, []).to_dict()).fast is None
    for bad in (0, "20", 2.5, True):
        with pytest.raises(viewdb.QueryError, match="fast"):
            RefineRequest.from_dict({**request.to_dict(), "fast": bad})
    with pytest.raises(viewdb.QueryError, match="not both"):
        RefineRequest(np.ones(128), 6, 3, [], shortlist=True, fast=3)


# ---------------------------------------------------------------- the index file


_copy = copy_db


def _key(path, config=None):
    config = config or FastConfig()
    conn = sqlite3.connect(path)
    try:
        conn.execute("BEGIN")
        return index_file_key(tier_key(conn, "full"), config)
    finally:
        conn.close()


def _rows(path):
    with viewdb.open(path, create=False, read_only=True) as db:
        arrays, _ = db.search_tier("full")
        return len(arrays.curves)


def test_an_ingest_writes_the_index_file_and_a_fresh_process_maps_it(tiered_db):
    path = ann_file_path(tiered_db, "full")
    assert path.exists()
    found = map_ann_file(path, _key(tiered_db), "full", _rows(tiered_db))
    assert found is not None and found[0].size == found[1].keys == _rows(tiered_db)
    assert found[1].row_of_key() is None  # built anew: every key is its row
    # not for another tier, another key, another row count or other settings
    assert map_ann_file(path, _key(tiered_db), "sparse", _rows(tiered_db)) is None
    assert map_ann_file(path, "other", "full", _rows(tiered_db)) is None
    assert map_ann_file(path, _key(tiered_db), "full", _rows(tiered_db) + 1) is None
    assert map_ann_file(path, _key(tiered_db, FastConfig(coefficients=12)), "full", _rows(tiered_db)) is None
    assert map_ann_file(path, _key(tiered_db, FastConfig(quantiles=0)), "full", _rows(tiered_db)) is None


@pytest.mark.parametrize("damage", ["truncated", "foreign", "empty", "garbled"])
def test_a_damaged_index_file_is_never_used(tiered_db, tmp_path, damage):
    db = _copy(tiered_db, tmp_path / "copy.db")
    good = ann_file_path(tiered_db, "full").read_bytes()
    bad = {"truncated": good[: len(good) // 2], "foreign": b"not an index" * 100, "empty": b"",
           "garbled": good[:200] + bytes(len(good) - 200)}[damage]
    ann_file_path(db, "full").write_bytes(bad)
    # the copy has the original's key (a backup copies the generation): only the damage differs
    assert map_ann_file(ann_file_path(db, "full"), _key(db), "full", _rows(db)) is None or damage == "garbled"
    rng = np.random.default_rng(3)
    with viewdb.open(db, create=False, read_only=True) as vdb:
        arrays, _ = vdb.search_tier("full")
        for q in mixed_query_curves(vdb, rng, 3):
            fast = vdb.recognise(q, 3, plan="fast", fast_shortlist=2)
            exact = {nb.object: nb.distance for nb in brute_force_knn(q, arrays, len(arrays.names), 6)}
            for c in fast.results:  # whatever the damage, a true distance
                assert c.distance == pytest.approx(exact[c.object], abs=1e-9)
            if damage != "garbled":  # ignored: the exact search of every object
                assert fast.server_stats["fast_index"] == 0.0
                _same(fast.results, vdb.recognise(q, 3, plan="server").results)


def test_a_stale_index_is_ignored_read_only_and_rebuilt_by_a_writer(tiered_db, tmp_path):
    db = _copy(tiered_db, tmp_path / "copy.db")
    stale = ann_file_path(tiered_db, "full").read_bytes()
    with viewdb.open(db, create=False) as vdb:
        report = vdb.ingest([sample("cone")])
        assert not report.failed
    fresh = ann_file_path(db, "full").read_bytes()
    assert fresh != stale  # the ingest wrote the index anew
    assert map_ann_file(ann_file_path(db, "full"), _key(db), "full", _rows(db)) is not None
    # put the index of the database as it was back: its key no longer matches
    ann_file_path(db, "full").write_bytes(stale)
    assert map_ann_file(ann_file_path(db, "full"), _key(db), "full", _rows(db)) is None
    rng = np.random.default_rng(4)
    with viewdb.open(db, create=False, read_only=True) as vdb:
        queries = mixed_query_curves(vdb, rng, 4)
        for q in queries:
            fast = vdb.recognise(q, 2, plan="fast", fast_shortlist=1)
            assert fast.server_stats["fast_index"] == 0.0  # not trusted: searched exactly
            _same(fast.results, vdb.recognise(q, 2, plan="server").results)
    assert ann_file_path(db, "full").read_bytes() == stale  # a read-only open writes nothing
    with viewdb.open(db, create=False) as vdb:  # a writer's first fast search rebuilds it
        fast = vdb.recognise(queries[0], 2, plan="fast", fast_shortlist=7)
        assert fast.server_stats["fast_index"] == 1.0
    assert map_ann_file(ann_file_path(db, "full"), _key(db), "full", _rows(db)) is not None


@given(st.lists(st.integers(1, 5), min_size=1, max_size=12), st.randoms(use_true_random=False))
def test_the_group_of_a_row_is_found_whatever_the_groups_order(counts, rnd):
    """Groups laid out in row order are bisected, others scanned: the same group either way."""
    from viewdb.search.fast import _group_of

    counts_a = np.array(counts, dtype=np.int64)
    starts_a = np.concatenate([[0], np.cumsum(counts_a)[:-1]]).astype(np.int64)
    order = list(range(len(counts)))
    rnd.shuffle(order)
    for starts, sizes in ((starts_a, counts_a), (starts_a[order], counts_a[order])):
        for row in range(int(counts_a.sum())):
            g = _group_of(starts, sizes, row)
            assert starts[g] <= row < starts[g] + sizes[g]
