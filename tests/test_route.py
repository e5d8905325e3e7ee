"""The one search route (viewdb.search.route) on a tier in memory: the brute-force answer
as candidates, with the views' directions, the versions asked for and the client bounds
used only where they hold; a quantised tier's distances raised to upper bounds."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.test_knn import smooth_curves
from viewdb.search.knn import TierArrays, brute_force_knn
from viewdb.search.plans import Candidate, RefineRequest
from viewdb.search.route import nearest_candidates


class ArraysTier(TierArrays):
    """A tier in memory as a snapshot opens it (view id = row); ``errors``: each view's
    quantisation error norms (None: exact curves)."""

    errors: np.ndarray | None = None

    @property
    def quantised(self) -> bool:
        return self.errors is not None

    def view_errors(self, view_id):
        return np.zeros(2) if self.errors is None else self.errors[view_id]


class ArraysSnapshot:
    """A read snapshot of one tier in memory: view ``i`` at azimuth ``i``, elevation ``-i``."""

    def __init__(self, tier):
        self.source = tier

    def tier(self, name):
        return self.source

    def view_projections(self, view_ids):
        return {i: (float(i), -float(i), None) for i in view_ids}

    def object_versions(self):
        return {name: f"v{name}" for name in self.source.names}

    def fast_index(self, name):
        return None


def _tier(rng, objects, errors=None):
    owner = rng.integers(0, objects, 60)
    owner[:objects] = np.arange(objects)
    tier = ArraysTier([f"o{i}" for i in range(objects)], owner, smooth_curves(rng, 60), group_views=5)
    tier.errors = errors
    return tier


@settings(max_examples=40)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(0, 4), st.integers(2, 8), st.booleans())
def test_route_answers_brute_force_as_candidates(seed, k, band, objects, versioned):
    rng = np.random.default_rng(seed)
    tier = _tier(rng, objects)
    query = smooth_curves(rng, 1)[0]
    want = brute_force_knn(query, tier, k, band)
    # a client candidate of an object the tier lacks, and one of another version: no bounds
    client = [Candidate("stranger", 0.0, 0, 0, False), Candidate("o0", 0.0, 0, 0, False, version="old")]
    found, _ = nearest_candidates(ArraysSnapshot(tier), RefineRequest(query, band, k, client),
                                  versioned=versioned)
    assert [c.object for c in found] == [n.object for n in want]
    np.testing.assert_allclose([c.distance for c in found], [n.distance for n in want], rtol=0, atol=1e-9)
    for c, n in zip(found, want, strict=True):
        assert (c.azimuth, c.elevation, c.camera_distance) == (float(n.view), -float(n.view), None)
        assert c.version == (f"v{c.object}" if versioned else None)
        assert c.shift is None and c.curve_index is None


def test_a_stack_answers_the_best_row_and_names_it():
    rng = np.random.default_rng(3)
    tier = _tier(rng, 5)
    stack = smooth_curves(rng, 3)
    found, _ = nearest_candidates(ArraysSnapshot(tier), RefineRequest.of_stack(stack, 2, 3, []))
    rows = [{n.object: (n.distance, i) for n in brute_force_knn(q, tier, 5, 2)} for i, q in enumerate(stack)]
    for c in found:
        best = min(r[c.object] for r in rows)
        assert math.isclose(c.distance, best[0], abs_tol=1e-9) and c.curve_index == best[1]


def test_bounded_raises_a_quantised_tiers_distances_only():
    rng = np.random.default_rng(5)
    errors = np.tile([0.01, 0.002], (60, 1))
    exact, quantised = _tier(rng, 4), _tier(np.random.default_rng(5), 4, errors)
    query = smooth_curves(rng, 1)[0]
    request = RefineRequest(query, 3, 4, [])
    plain, _ = nearest_candidates(ArraysSnapshot(quantised), request)
    raised, _ = nearest_candidates(ArraysSnapshot(quantised), request, bounded=True)
    same, _ = nearest_candidates(ArraysSnapshot(exact), request, bounded=True)
    assert [c.distance for c in same] == [c.distance for c in plain]
    by_object = {c.object: c.distance for c in plain}
    assert all(c.distance > by_object[c.object] for c in raised)
    assert [c.distance for c in raised] == sorted(c.distance for c in raised)
