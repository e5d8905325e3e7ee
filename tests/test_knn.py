"""Algorithm 2 returns exactly the brute-force top-k distinct objects, in memory and
through the R-trees stored in a database file."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import viewdb
from viewdb.catalogue.features import distance_curve, mirror_curve
from viewdb.catalogue.render import get_renderer
from viewdb.search.bounds import dtw
from viewdb.search.knn import TierArrays, brute_force_knn, knn


def smooth_curves(rng, count, n=64):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    out = np.ones((count, n))
    for j in range(1, 4):
        a = rng.normal(0, 0.3 / j, (count, 1))
        phase = rng.uniform(0, 2 * np.pi, (count, 1))
        out += a * np.cos(j * t + phase)
    return out / out.mean(axis=1, keepdims=True)


def same(a, b):
    assert [x.object for x in a] == [x.object for x in b]
    np.testing.assert_allclose([x.distance for x in a], [x.distance for x in b], rtol=0, atol=1e-9)


@settings(max_examples=120)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.integers(0, 6), st.integers(2, 10),
       st.integers(1, 12), st.sampled_from([1e-4, 0.01, 0.125, 10.0]))
def test_knn_equals_brute_force_on_random_tiers(seed, k, r, objects, group_views, initial_radius):
    rng = np.random.default_rng(seed)
    owner = rng.integers(0, objects, 80)
    owner[:objects] = np.arange(objects)
    tier = TierArrays([f"o{i}" for i in range(objects)], owner, smooth_curves(rng, 80),
                      group_views=group_views)
    query = smooth_curves(rng, 1)[0]
    if rng.random() < 0.5:  # a noisy copy (or mirror) of a stored curve
        query = tier.curves[rng.integers(80)][:: rng.choice([1, -1])] + rng.normal(0, 0.01, 64)
    # a small first radius makes the search browse outwards many times
    result, stats = knn(query, tier, k, r, initial_radius=initial_radius)
    same(result, brute_force_knn(query, tier, k, r))
    assert len(result) == min(k, objects)
    assert stats.dtw <= 2 * len(tier.curves)


def test_groups_partition_each_objects_views():
    rng = np.random.default_rng(0)
    owner = rng.integers(0, 5, 300)
    tier = TierArrays([f"o{i}" for i in range(5)], owner, smooth_curves(rng, 300), group_views=7)
    members = np.concatenate(tier.groups)
    assert sorted(members.tolist()) == list(range(300))
    for g in tier.groups:
        assert len(g) <= 7 and len(set(owner[g].tolist())) == 1


@pytest.mark.parametrize("r", [0, 3])
def test_r0_is_euclidean(r):
    rng = np.random.default_rng(1)
    tier = TierArrays(["a", "b"], np.array([0, 1, 0, 1]), smooth_curves(rng, 4))
    q = smooth_curves(rng, 1)[0]
    res, _ = knn(q, tier, 2, r)
    best = min(dtw(q, c, r) for c in (tier.curves[res[0].view], mirror_curve(tier.curves[res[0].view])))
    assert res[0].distance == pytest.approx(best)
    if r == 0:
        assert res[0].distance == pytest.approx(min(
            np.linalg.norm(q - tier.curves[res[0].view]),
            np.linalg.norm(q - mirror_curve(tier.curves[res[0].view]))))


def _render_queries(db, rng, count):
    names = [o.name for o in db.objects()]
    out = []
    for _ in range(count):
        name = names[rng.integers(len(names))]
        h, v = rng.uniform(0, 360, 2)
        out.append(distance_curve(db.render(name, h, v).mask, db.config.features.curve_samples))
    return out


@pytest.mark.parametrize("tier_name", ["full", "sparse"])
def test_stored_tier_search_equals_brute_force_on_rendered_queries(tiered_db, tier_name):
    rng = np.random.default_rng(5 if tier_name == "full" else 6)
    with viewdb.open(tiered_db, create=False) as db:
        tier, rows = db.search_tier(tier_name)
        queries = _render_queries(db, rng, 12)
        queries += [mirror_curve(q) + rng.normal(0, 0.02, len(q)) for q in queries[:6]]
        dtws = []
        for q in queries:
            for k, band in ((1, 6), (3, 0), (5, 4)):
                hits, stats = db.search(q, k=k, band=band, tier=tier_name)
                expected = brute_force_knn(q, tier, k, band)
                assert [h.object for h in hits] == [e.object for e in expected]
                np.testing.assert_allclose([h.distance for h in hits],
                                           [e.distance for e in expected], rtol=0, atol=1e-9)
                for h in hits:  # the reported view is at that distance (a perspective view
                    # has a negative id, and one per camera distance)
                    rows_of = [j for j, row in enumerate(rows) if row[1:] == (h.azimuth, h.elevation)
                               and tier.names[tier.owner[j]] == h.object
                               and (row[0] < 0) == (h.camera_distance is not None)]
                    assert rows_of
                    at = [dtw(q, mirror_curve(tier.curves[j]) if h.mirrored else tier.curves[j], band)
                          for j in rows_of]
                    assert min(at, key=lambda d: abs(d - h.distance)) == pytest.approx(h.distance, abs=1e-9)
                dtws.append(stats.dtw)
    assert np.mean(dtws) < 0.5 * 2 * len(tier.curves)  # most curves never reach DTW


@settings(max_examples=40)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.integers(0, 8), st.sampled_from(["full", "sparse"]))
def test_stored_tier_equals_brute_force_on_perturbed_stored_curves(tiered_db, seed, k, band, tier_name):
    rng = np.random.default_rng(seed)
    with viewdb.open(tiered_db, create=False) as db:
        tier, _ = db.search_tier(tier_name)
        q = tier.curves[rng.integers(len(tier.curves))]
        q = q * rng.uniform(0.9, 1.1) + rng.normal(0, rng.choice([0.0, 0.01, 0.1]), len(q))
        if rng.random() < 0.5:
            q = mirror_curve(q)
        hits, _ = db.search(q, k=k, band=band, tier=tier_name)
        expected = brute_force_knn(q, tier, k, band)
        assert [h.object for h in hits] == [e.object for e in expected]
        np.testing.assert_allclose([h.distance for h in hits], [e.distance for e in expected],
                                   rtol=0, atol=1e-9)


def test_db_search_finds_the_object_of_a_rendered_query(small_db):
    with viewdb.open(small_db, create=False) as db:
        for name in ("car", "mug", "l_bracket"):
            q = distance_curve(db.render(name, 37, 22).mask, db.config.features.curve_samples)
            hits, stats = db.search(q, k=2)
            assert len(hits) == 2 and hits[0].distance <= hits[1].distance
            # the best hit's view, regenerated, is at the reported distance from the query
            top = hits[0]
            if top.camera_distance is None:
                best = db.view(top.object, top.azimuth, top.elevation).curve
            else:
                mask = get_renderer(db.config.render).perspective_mask(
                    db.mesh(top.object), top.azimuth, top.elevation, top.camera_distance)
                best = distance_curve(mask, db.config.features.curve_samples)
            target = mirror_curve(best) if hits[0].mirrored else best
            assert dtw(q, target, 6) == pytest.approx(hits[0].distance)
        with pytest.raises(viewdb.QueryError):
            db.search(np.ones(5))
        with pytest.raises(viewdb.QueryError):
            db.search(q, k=0)
        with pytest.raises(viewdb.QueryError, match="tier"):
            db.search(q, tier="medium")


@settings(max_examples=30)
@given(st.integers(0, 2**32 - 1), st.integers(1, 4), st.integers(0, 8))
def test_unskimmed_db_search_equals_brute_force(small_db_full, seed, k, band):
    rng = np.random.default_rng(seed)
    with viewdb.open(small_db_full, create=False) as db:
        tier, _ = db.search_tier("full")
        assert not any(o.skimmed for o in db.objects())
        q = tier.curves[rng.integers(len(tier.curves))] + rng.normal(0, rng.choice([0.01, 0.1]), 128)
        hits, _ = db.search(q, k=k, band=band)
        expected = brute_force_knn(q, tier, k, band)
        assert [h.object for h in hits] == [e.object for e in expected]
        np.testing.assert_allclose([h.distance for h in hits], [e.distance for e in expected],
                                   rtol=0, atol=1e-9)


@settings(max_examples=120)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(0, 6), st.integers(2, 10),
       st.sampled_from([1e-4, 0.01, 0.125]), st.floats(0.0, 1.0))
def test_knn_with_a_clients_upper_bounds_equals_brute_force(seed, k, r, objects, initial_radius, slack):
    # CS1 hands the server upper bounds (the k-th distance, and some objects' distances);
    # any valid bounds, tight or loose, leave the answer unchanged
    rng = np.random.default_rng(seed)
    owner = rng.integers(0, objects, 80)
    owner[:objects] = np.arange(objects)
    tier = TierArrays([f"o{i}" for i in range(objects)], owner, smooth_curves(rng, 80), group_views=6)
    query = smooth_curves(rng, 1)[0]
    everything = brute_force_knn(query, tier, objects, r)
    known = {tier.names.index(nb.object): nb.distance * (1 + slack * rng.random())
             for nb in everything if rng.random() < 0.6}
    upper = everything[k - 1].distance * (1 + slack) if len(everything) >= k else np.inf
    result, _ = knn(query, tier, k, r, upper=upper, known=known, initial_radius=initial_radius)
    same(result, everything[:k])


@settings(max_examples=100)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(0, 6), st.integers(2, 8),
       st.sampled_from([1e-4, 0.01, 0.125]), st.floats(0.0, 1.0))
def test_the_view_reported_at_a_tie_does_not_depend_on_the_search_order(seed, k, r, objects, initial_radius,
                                                                       slack):
    """Symmetric silhouettes give curves equal to their own mirrors, and symmetric objects
    repeat views: several views (or orientations) at exactly the same distance. Whatever
    bounds a search gets (a CS1 client's) and however it browses, it reports the same
    view for each object: the lowest row, unmirrored first."""
    rng = np.random.default_rng(seed)
    owner = rng.integers(0, objects, 60)
    owner[:objects] = np.arange(objects)
    curves = smooth_curves(rng, 60)
    symmetric = rng.random(60) < 0.4
    curves[symmetric] = (curves[symmetric] + np.array([mirror_curve(c) for c in curves[symmetric]])) / 2
    for i in rng.integers(0, 60, 15):  # copies of views within and across objects
        curves[rng.integers(0, 60)] = curves[i]
    tier = TierArrays([f"o{i}" for i in range(objects)], owner, curves, group_views=int(rng.integers(2, 9)))
    query = curves[rng.integers(60)] + (rng.normal(0, 0.02, 64) if rng.random() < 0.5 else 0.0)
    reference, _ = knn(query, tier, k, r)
    everything = brute_force_knn(query, tier, objects, r)
    known = {tier.names.index(nb.object): nb.distance * (1 + slack * rng.random())
             for nb in everything if rng.random() < 0.6}
    upper = everything[k - 1].distance * (1 + slack) if len(everything) >= k else np.inf
    bounded, _ = knn(query, tier, k, r, upper=upper, known=known, initial_radius=initial_radius)
    assert bounded == reference
    for nb in reference:
        c = tier.curves[nb.view]
        if nb.mirrored:  # mirrored only when strictly better than the view as it is
            assert dtw(query, mirror_curve(c), r) < dtw(query, c, r)
