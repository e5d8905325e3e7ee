"""Algorithm 2 returns exactly the brute-force top-k distinct objects."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import viewdb
from viewdb.features import distance_curve
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


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.integers(0, 6), st.integers(2, 10))
def test_knn_equals_brute_force_on_random_tiers(seed, k, r, objects):
    rng = np.random.default_rng(seed)
    owner = rng.integers(0, objects, 80)
    owner[:objects] = np.arange(objects)
    tier = TierArrays([f"o{i}" for i in range(objects)], owner, smooth_curves(rng, 80))
    query = smooth_curves(rng, 1)[0]
    if rng.random() < 0.5:  # a noisy copy (or mirror) of a stored curve
        query = tier.curves[rng.integers(80)][:: rng.choice([1, -1])] + rng.normal(0, 0.01, 64)
    result, stats = knn(query, tier, k, r)
    same(result, brute_force_knn(query, tier, k, r))
    assert len(result) == min(k, objects)


def test_knn_on_real_curves_of_a_skimmed_db_prunes_most_views(small_db):
    with viewdb.open(small_db, create=False) as db:
        tier, views = db.search_tier()
        names, curves = tier.names, tier.curves
        for (o, h, v), c in zip(views, curves, strict=True):  # the tier is what is stored
            np.testing.assert_array_equal(c, db.view(names[o], h, v).curve)
        rng = np.random.default_rng(3)
        dtws = []
        for name in names:
            for h, v in rng.uniform(0, 360, (3, 2)):
                q = distance_curve(db.render(name, h, v).mask, 128)
                for k in (1, 3):
                    result, stats = knn(q, tier, k, 4)
                    same(result, brute_force_knn(q, tier, k, 4))
                    dtws.append(stats.dtw)
    assert np.mean(dtws) < 0.5 * 2 * len(curves)  # most views never reach DTW


@pytest.mark.parametrize("r", [0, 3])
def test_r0_is_euclidean(r):
    rng = np.random.default_rng(1)
    tier = TierArrays(["a", "b"], np.array([0, 1, 0, 1]), smooth_curves(rng, 4))
    q = smooth_curves(rng, 1)[0]
    res, _ = knn(q, tier, 2, r)
    if r == 0:
        best = min(np.linalg.norm(q - tier.curves[res[0].view]),
                   np.linalg.norm(q - np.roll(tier.curves[res[0].view][::-1], 1)))
        assert res[0].distance == pytest.approx(best)


def test_db_search_finds_the_object_of_a_rendered_query(small_db):
    with viewdb.open(small_db, create=False) as db:
        for name in ("car", "mug", "l_bracket"):
            q = distance_curve(db.render(name, 37, 22).mask, db.config.features.curve_samples)
            hits, stats = db.search(q, k=2)
            assert len(hits) == 2 and hits[0].distance <= hits[1].distance
            # the best hit's view, regenerated, is at the reported distance from the query
            best = db.view(hits[0].object, hits[0].azimuth, hits[0].elevation).curve
            from viewdb.features import mirror_curve
            from viewdb.search.bounds import dtw

            target = mirror_curve(best) if hits[0].mirrored else best
            assert dtw(q, target, 6) == pytest.approx(hits[0].distance)
        with pytest.raises(viewdb.QueryError):
            db.search(np.ones(5))
        with pytest.raises(viewdb.QueryError):
            db.search(q, k=0)
