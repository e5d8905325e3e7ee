"""The sparse and full tiers: what they hold, how ingest keeps their R-trees in step with
the views, range queries for CS1, and readers that see other processes' commits."""

import sqlite3

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import viewdb
from tests.conftest import copy_db, sample
from viewdb.catalogue.describe import perspective_grid
from viewdb.catalogue.features import distance_curve, mirror_curve
from viewdb.search.knn import brute_force_knn
from viewdb.storage.tiers import SCAN_SAMPLE


def tier_views_of(db, tier, perspective=False):
    """Per object, the (h, v) of the tier's orthographic views (or of its perspective
    views: negative ids)."""
    arrays, rows = db.search_tier(tier)
    out = {}
    for j, (vid, h, v) in enumerate(rows):
        if (vid < 0) == perspective:
            out.setdefault(arrays.names[arrays.owner[j]], set()).add((h, v))
    return out


def test_full_tier_is_every_stored_view_and_sparse_the_client_grid(tiered_db):
    with viewdb.open(tiered_db, create=False) as db:
        assert db.config.gap == 30 and db.config.client_gap == 90
        full, sparse = tier_views_of(db, "full"), tier_views_of(db, "sparse")
        assert sum(map(len, sparse.values())) < sum(map(len, full.values()))
        pinhole = tier_views_of(db, "full", perspective=True)
        assert not tier_views_of(db, "sparse", perspective=True)
        grid = {(h, v) for h, v, _ in perspective_grid(db.config)}
        for info in db.objects():
            assert full[info.name] == set(db.views(info.name))
            assert pinhole[info.name] <= grid and len(pinhole[info.name]) > 0
            plan = db.view_plan(info.name)
            client = [(float(h), float(v)) for h in range(0, 360, 90) for v in range(0, 360, 90)]
            stand_ins = set()
            for view in client:
                kept = plan.mapping[view][0]
                if kept in full[info.name]:  # else: no silhouette there
                    stand_ins.add(kept)
            assert sparse.get(info.name, set()) == stand_ins
            # a stand-in's curve (or its mirror) is the client view's curve
            for view in client[:4]:
                kept, mirrored = plan.mapping[view]
                if kept in stand_ins:
                    stored = db.view(info.name, *kept).curve
                    rendered = distance_curve(db.render(info.name, *view).mask, 128)
                    target = mirror_curve(stored) if mirrored else stored
                    assert np.sqrt(np.mean((rendered - target) ** 2)) < 0.05


_copy = copy_db


def test_replacing_and_adding_objects_keeps_the_r_trees_in_step(tiered_db, tmp_path):
    import shutil

    path = _copy(tiered_db, tmp_path / "copy.db")
    # a different mesh under the same name: the l_bracket's file renamed to car
    shutil.copy(sample("l_bracket"), tmp_path / "car.stl")
    with viewdb.open(path, create=False) as db:
        report = db.ingest([tmp_path / "car.stl", sample("sphere")])
        assert report.counts()["replaced"] == 1 and report.counts()["added"] == 1
        assert db.check().ok, db.check().problems
        q = distance_curve(db.render("l_bracket", 40, 20).mask, 128)
        hits, _ = db.search(q, k=2)
        # the new "car" is an l_bracket: both are at the same distance
        assert {h.object for h in hits} == {"car", "l_bracket"}
        assert hits[0].distance == pytest.approx(hits[1].distance, abs=1e-6)
    with sqlite3.connect(path) as conn:
        n_groups = conn.execute("SELECT count(*) FROM index_groups").fetchone()[0]
        objects = {r[0] for r in conn.execute("SELECT DISTINCT object_id FROM index_groups")}
        assert objects == {r[0] for r in conn.execute("SELECT id FROM objects")}
        assert n_groups > 0


def test_a_reader_sees_objects_another_connection_adds(tiered_db, tmp_path):
    path = _copy(tiered_db, tmp_path / "copy.db")
    with viewdb.open(path, create=False) as reader:
        q = distance_curve(viewdb.render_model(sample("sphere"), 10, 10, image_size=96).mask, 128)
        before, _ = reader.search(q, k=1)
        assert before[0].object != "sphere"
        with viewdb.open(path, create=False) as writer:
            writer.ingest([sample("sphere")])
        after, _ = reader.search(q, k=1)
        assert after[0].object == "sphere" and after[0].distance < before[0].distance


def test_searching_does_not_write_to_the_file(tiered_db, tmp_path):
    path = _copy(tiered_db, tmp_path / "copy.db")
    before = path.read_bytes()
    with viewdb.open(path, create=False) as db:
        q = distance_curve(db.render("mug", 12, 34).mask, 128)
        for tier in ("full", "sparse"):
            db.search(q, k=3, tier=tier)
    assert path.read_bytes() == before


@settings(max_examples=30)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 3.0), st.integers(0, 8),
       st.sampled_from(["full", "sparse"]))
def test_objects_within_a_distance_miss_no_object_at_that_distance(tiered_db, seed, radius, band, tier):
    rng = np.random.default_rng(seed)
    with viewdb.open(tiered_db, create=False) as db:
        arrays, _ = db.search_tier(tier)
        q = arrays.curves[rng.integers(len(arrays.curves))] + rng.normal(0, 0.05, 128)
        found = db.objects_within(q, radius, band=band, tier=tier)
        exact = {nb.object: nb.distance for nb in brute_force_knn(q, arrays, len(arrays.names), band)}
        for name, distance in exact.items():
            if distance <= radius:
                assert name in found and found[name] <= distance + 1e-9
        # and exactly the objects with a group whose bound is within the radius
        from viewdb.search.knn import QueryBoxes

        _, keys = QueryBoxes.of(q, band).group_keys(arrays.mbr_lo, arrays.mbr_hi, arrays.curve_lo,
                                                 arrays.curve_hi)
        owners = {arrays.names[arrays.owner[g[0]]] for g, key in zip(arrays.groups, keys, strict=True)
                  if key <= radius}
        assert set(found) == owners


def test_an_upgraded_file_is_searched_through_its_new_r_trees(tmp_path):
    import shutil

    from tests.conftest import ROOT

    path = tmp_path / "old.db"
    shutil.copy(ROOT / "tests" / "data" / "schema_0001.db", path)
    with viewdb.open(path, create=False) as db:
        assert db.check().ok
        arrays, _ = db.search_tier("full")
        assert len(arrays.curves) == sum(len(db.views(o.name)) for o in db.objects())
        q = distance_curve(db.render("cone", 20, 30).mask, db.config.features.curve_samples)
        hits, _ = db.search(q, k=2)
        expected = brute_force_knn(q, arrays, 2, 6)
        assert [h.object for h in hits] == [e.object for e in expected] and hits[0].object == "cone"


@pytest.mark.parametrize("gap, client_gap", [(20, 50), (30, 20), (30, 75)])
def test_a_client_gap_off_the_server_grid_is_refused_before_any_file_is_made(tmp_path, gap, client_gap):
    path = tmp_path / "new.db"
    with pytest.raises(viewdb.ViewDBError, match="client gap must be a multiple"):
        viewdb.open(path, gap=gap, client_gap=client_gap)
    assert not path.exists()


def test_info_reports_both_tiers(tiered_db, capsys):
    from viewdb_cli.main import main

    with viewdb.open(tiered_db, create=False) as db:
        tiers = db.info().tiers
        full, _ = db.search_tier("full")
        sparse, _ = db.search_tier("sparse")
    assert tiers["full"]["views"] == len(full.curves) and tiers["sparse"]["views"] == len(sparse.curves)
    assert tiers["full"]["gap"] == 30 and tiers["sparse"]["gap"] == 90
    assert tiers["sparse"]["groups"] <= tiers["full"]["groups"] and tiers["full"]["rtree_bytes"] > 0
    assert main(["info", "--db", str(tiered_db)]) == 0
    assert "sparse tier: 90° grid" in capsys.readouterr().out


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.lists(st.floats(0.0, 2.0), min_size=1, max_size=4),
       st.sampled_from([0.0, 0.25, 1.0]))
def test_groups_within_answers_each_ask_as_the_r_tree_does(tiered_db, seed, radii, scan_share):
    """The threads of one search ask for the same boxes in turn, each for its own objects
    (the last answer is kept for that): every ask, repeated or not, gives the groups whose
    MBR meets the widened boxes and that are not yet seen, with their keys, whether the
    R-tree answers or the MBRs are compared (``scan_share`` 1: always the R-tree; 0: always
    the comparison); and the R-tree is asked exactly when the sample says it should be."""
    from viewdb.search.shifts import CurveQuery

    rng = np.random.default_rng(seed)
    with viewdb.open(tiered_db, read_only=True) as db:
        arrays, _ = db.search_tier("full")
        curves = arrays.curves[rng.integers(len(arrays.curves), size=3)] + rng.normal(0, 0.05, (3, 128))
        query = CurveQuery.of(curves, 4)
        with db._catalogue.tier_reader().snapshot() as reader:
            tier = reader.tier("full")
            tier.scan_share = scan_share
            asked = []
            r_tree = tier.index.intersection_many
            tier.index.intersection_many = lambda los, his: asked.append(1) or r_tree(los, his)
            lo, hi, curve_lo, curve_hi = tier.group_boxes()
            part = rng.integers(2, size=tier.n_objects)
            for radius in [r for r in radii for _ in range(2)]:  # each radius asked twice
                for thread in (0, 1):
                    seen = part[tier.group_owner] != thread
                    before = len(asked)
                    his = (np.stack([query.box[1], query.mirrored_box[1]]) + radius).tobytes()
                    fresh = tier._last_within is None or tier._last_within[0][1] != his
                    got, keys = tier.groups_within(query, radius, seen.copy())
                    meets = np.zeros(tier.n_groups, dtype=bool)
                    for box_lo, box_hi in (query.box, query.mirrored_box):
                        meets |= ((lo <= box_hi + radius) & (hi >= box_lo - radius)).all(axis=1)
                    expected = np.flatnonzero(meets & ~seen)
                    assert sorted(got.tolist()) == expected.tolist()
                    _, want = query.group_keys(lo, hi, curve_lo, curve_hi, got)
                    assert np.array_equal(keys, want)
                    # the R-tree is asked for a fresh ask whose sample share is at most scan_share
                    sample = np.arange(0, tier.n_groups, max(1, tier.n_groups // SCAN_SAMPLE))
                    share = meets[sample].mean()
                    assert len(asked) - before == int(fresh and share <= scan_share)
