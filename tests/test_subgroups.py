"""Subgroups split each index group into runs of a few views whose ranges hold every member,
and a search pruning runs by those ranges still returns the brute-force answer."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.reference import naive_knn_over_curves
from tests.test_shifts import random_tier
from viewdb.search.bounds import paa_edges, paa_means
from viewdb.search.knn import knn_stack
from viewdb.search.subgroups import SUBGROUP_VIEWS, fill_subgroups, subgroup_layout


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(1, 70), min_size=1, max_size=12), st.integers(1, 9), st.integers(0, 2**31),
       st.sampled_from([np.float32, np.float64]))
def test_runs_partition_each_group_and_their_ranges_hold_their_members(counts, size, seed, dtype):
    rng = np.random.default_rng(seed)
    count = np.array(counts, dtype=np.int64)
    start_of = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
    curves = rng.normal(1.0, 0.3, (int(count.sum()), 16)).astype(dtype)
    curves[rng.random(len(curves)) < 0.2] = curves[0]  # equal curves: ties in the split
    means = paa_means(curves.astype(np.float64), paa_edges(16, 4))
    first, start = subgroup_layout(start_of, count, size)
    runs = len(start) - 1
    order = np.full(len(curves), -1, dtype=np.int64)
    lo, hi = np.empty((runs, 16), np.float32), np.empty((runs, 16), np.float32)
    fill_subgroups(np.arange(len(count), dtype=np.int64), curves, means, start_of, count, first, start,
                   order, lo, hi, size)
    for g, (a, n) in enumerate(zip(start_of.tolist(), count.tolist(), strict=True)):
        own = range(int(first[g]), int(first[g + 1]))
        sizes = [int(start[s + 1] - start[s]) for s in own]
        assert sum(sizes) == n and max(sizes) <= size and min(sizes) >= min(n, size // 2 or 1)
        assert sorted(order[a : a + n].tolist()) == list(range(a, a + n))
        for s in own:
            members = curves[order[start[s] : start[s + 1]]].astype(np.float64)
            assert (lo[s] <= members.min(axis=0)).all() and (hi[s] >= members.max(axis=0)).all()
            # the range is the members' range, rounded outward to float32 and no further
            assert (np.abs(lo[s] - members.min(axis=0)) <= np.spacing(np.abs(lo[s]))).all()
            assert (np.abs(hi[s] - members.max(axis=0)) <= np.spacing(np.abs(hi[s]))).all()


def test_runs_group_similar_curves():
    # two kinds of curves mixed in one group: the split puts each kind in runs of its own
    rng = np.random.default_rng(3)
    t = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    kinds = np.stack([1 + 0.3 * np.cos(2 * t), 1 + 0.3 * np.cos(3 * t)])
    which = np.tile([0, 1], 16)
    curves = kinds[which] + rng.normal(0, 0.01, (32, 32))
    means = paa_means(curves, paa_edges(32, 8))
    count, start_of = np.array([32]), np.array([0])
    first, start = subgroup_layout(start_of, count)
    order = np.zeros(32, dtype=np.int64)
    lo, hi = np.empty((len(start) - 1, 32), np.float32), np.empty((len(start) - 1, 32), np.float32)
    fill_subgroups(np.array([0]), curves, means, start_of, count, first, start, order, lo, hi)
    assert len(start) - 1 == 32 // SUBGROUP_VIEWS
    for s in range(len(start) - 1):
        assert len(set(which[order[start[s] : start[s + 1]]].tolist())) == 1


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31), st.integers(1, 4), st.sampled_from([8, 24, 64]))
def test_a_search_pruning_runs_returns_the_brute_force_answer(seed, k, group_views):
    rng = np.random.default_rng(seed)
    tier = random_tier(rng, 5, 160, 32, group_views)
    curves = tier.curves[rng.integers(0, len(tier.curves), 3)] + rng.normal(0, 0.05, (3, 32))
    found, stats = knn_stack(curves, tier, k, 3, block=1, threads=1)
    expected = naive_knn_over_curves(curves, tier.curves, tier.owner, tier.names, k, 3)
    assert [(nb.object, round(nb.distance, 9)) for nb in found] == [(o, round(d, 9)) for d, o, *_ in expected]
    assert stats.points_visited <= 2 * 3 * len(tier.curves)
