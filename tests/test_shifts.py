"""One search over many query curves (a stack, or the circular shifts of one curve) returns
exactly the brute-force top-k over every curve; its bounds hold for every curve of a set;
windows, bearings and turns agree with the silhouettes they stand for."""

import json
import math

import cv2
import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

import viewdb
from tests.reference import naive_dtw, naive_knn_over_curves, naive_lb_keogh, naive_shifted
from viewdb.catalogue.features import distance_curve, mirror_curve, sample_bearings
from viewdb.http import RefineRequest
from viewdb.recognition.shapes import WHOLE_PHOTO_TURNS, rotated_curves
from viewdb.search.bounds import dtw, envelope, lb_keogh, paa_edges, paa_means
from viewdb.search.grouping import indexed_coordinates
from viewdb.search.knn import TierArrays, deal_objects, knn, knn_stack
from viewdb.search.multirefine import scan_stack
from viewdb.search.shifts import CurveQuery, ShiftWindow, shift_turn, shifted, shifted_curves, turn_window


def smooth_curves(rng, count, n):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    out = np.ones((count, n))
    for j in range(1, 4):
        out += rng.normal(0, 0.3 / j, (count, 1)) * np.cos(j * t + rng.uniform(0, 2 * np.pi, (count, 1)))
    return out / out.mean(axis=1, keepdims=True)


def random_tier(rng, objects, views, n, group_views):
    owner = rng.integers(0, objects, views)
    owner[:objects] = np.arange(objects)
    curves = smooth_curves(rng, views, n)
    symmetric = rng.random(views) < 0.2  # curves equal to their own mirrors: ties
    curves[symmetric] = (curves[symmetric] + np.roll(curves[symmetric][:, ::-1], 1, axis=1)) / 2
    return TierArrays([f"o{i}" for i in range(objects)], owner, curves, group_views=group_views)


def windows():
    return st.builds(ShiftWindow, st.integers(0, 40), st.none() | st.integers(0, 12), st.integers(1, 5))


def check_against_oracle(result, expected, stack, tier, r):
    assert [nb.object for nb in result] == [e[1] for e in expected]
    np.testing.assert_allclose([nb.distance for nb in result], [e[0] for e in expected], rtol=0, atol=1e-9)
    for nb in result:  # the reported view and curve achieve the reported distance
        c = tier.curves[nb.view]
        assert dtw(stack[nb.shift], mirror_curve(c) if nb.mirrored else c, r) == pytest.approx(
            nb.distance, abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 4), st.integers(0, 4), st.integers(1, 6), st.integers(1, 8),
       windows(), st.integers(1, 9), st.sampled_from([1e-4, 0.01, 0.125]))
def test_shift_search_equals_brute_force_over_the_window(seed, k, r, objects, group_views, window, block,
                                                          initial_radius):
    rng = np.random.default_rng(seed)
    n = 20
    tier = random_tier(rng, objects, 24, n, group_views)
    q = smooth_curves(rng, 1, n)[0]
    if rng.random() < 0.5:  # a stored view, turned and noisy (or mirrored)
        q = np.roll(tier.curves[rng.integers(24)][:: rng.choice([1, -1])], rng.integers(n)) + rng.normal(0, 0.01, n)
    result, _ = knn(q, tier, k, r, shifts=window, block=block, initial_radius=initial_radius)
    starts = window.shifts(n)
    stack = [naive_shifted(q, int(s)) for s in starts]
    expected = naive_knn_over_curves(stack, tier.curves, tier.owner, tier.names, k, r)
    check_against_oracle([nb.__class__(nb.object, nb.view, nb.distance, nb.mirrored,
                                       int(np.flatnonzero(starts == nb.shift)[0])) for nb in result],
                         expected, np.array(stack), tier, r)
    assert all(nb.shift in set(starts.tolist()) for nb in result)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 4), st.integers(0, 5), st.integers(1, 5), st.integers(1, 6),
       st.integers(1, 4))
def test_a_stack_of_unrelated_curves_equals_brute_force(seed, k, r, objects, block, threads):
    rng = np.random.default_rng(seed)
    n = 16
    tier = random_tier(rng, objects, 20, n, int(rng.integers(1, 7)))
    stack = smooth_curves(rng, int(rng.integers(1, 7)), n)
    result, _ = knn_stack(stack, tier, k, r, block=block, threads=threads)
    expected = naive_knn_over_curves(stack, tier.curves, tier.owner, tier.names, k, r)
    check_against_oracle(result, expected, stack, tier, r)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(0, 6), st.integers(2, 8), windows(),
       st.integers(1, 16), st.sampled_from([1e-4, 0.01, 0.125]), st.floats(0.0, 1.0))
def test_bounded_and_unbounded_shift_searches_report_the_same_views(seed, k, r, objects, window, block,
                                                                    initial_radius, slack):
    """What a CS1 server is handed (the k-th distance, some objects' distances, tight or
    loose) changes neither the objects, the distances, nor the view, orientation and shift
    reported (the window's earliest shift, the lowest row, unmirrored at a tie), with
    repeated and symmetric views making ties."""
    rng = np.random.default_rng(seed)
    n = 32
    tier = random_tier(rng, objects, 60, n, int(rng.integers(2, 9)))
    for i in rng.integers(0, 60, 10):  # copies of views within and across objects
        tier.curves[rng.integers(0, 60)] = tier.curves[i]
    tier = TierArrays(tier.names, tier.owner, tier.curves, group_views=tier.group_views)
    q = np.roll(tier.curves[rng.integers(60)], rng.integers(n)) + (rng.normal(0, 0.02, n) if rng.random() < 0.5
                                                                   else 0.0)
    reference, _ = knn(q, tier, k, r, shifts=window, block=block)
    everything, _ = knn(q, tier, objects, r, shifts=window, block=1)
    distances = scan_stack(CurveQuery.of(shifted_curves(q, window.shifts(n)), r), tier.curves)
    best = {tier.names[o]: distances[tier.owner == o].min() for o in range(objects)}
    assert [nb.object for nb in everything] == sorted(best, key=lambda o: (best[o], o))
    np.testing.assert_allclose([nb.distance for nb in everything], sorted(best.values()), rtol=0, atol=1e-9)
    known = {tier.names.index(nb.object): nb.distance * (1 + slack * rng.random())
             for nb in everything if rng.random() < 0.6}
    upper = everything[k - 1].distance * (1 + slack) if len(everything) >= k else math.inf
    bounded, _ = knn(q, tier, k, r, shifts=window, block=block, upper=upper, known=known,
                     initial_radius=initial_radius)
    assert bounded == reference


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.integers(0, 6), st.integers(2, 9), st.integers(2, 5),
       st.integers(1, 4), st.booleans(), st.floats(0.0, 1.0))
def test_a_search_split_over_threads_reports_what_one_search_reports(seed, k, r, objects, threads, block,
                                                                     bounded, slack):
    """The objects dealt to threads sharing their bounds: the same objects, distances,
    views, orientations and curves as one search, ties included (copies of views within
    and across objects, symmetric views), bounded (a CS1 server) or not, the objects dealt
    by a priority (a fast shortlist's order) or by their views, and the brute force's
    objects and distances."""
    rng = np.random.default_rng(seed)
    n = 24
    tier = random_tier(rng, objects, 80, n, int(rng.integers(1, 9)))
    for i in rng.integers(0, 80, 12):
        tier.curves[rng.integers(0, 80)] = tier.curves[i]
    tier = TierArrays(tier.names, tier.owner, tier.curves, group_views=tier.group_views)
    stack = np.concatenate([smooth_curves(rng, int(rng.integers(0, 5)), n),
                            tier.curves[rng.integers(0, 80, int(rng.integers(1, 4)))]])
    one, _ = knn_stack(stack, tier, k, r, block=block, threads=1)
    upper, known = math.inf, None
    if bounded:
        everything, _ = knn_stack(stack, tier, objects, r, block=block, threads=1)
        known = {tier.names.index(nb.object): nb.distance * (1 + slack * rng.random())
                 for nb in everything if rng.random() < 0.6}
        upper = everything[k - 1].distance * (1 + slack) if len(everything) >= k else math.inf
    listed = rng.permutation(objects)[: int(rng.integers(0, objects + 1))]
    priority = listed.astype(np.int64) if len(listed) else None
    split, stats = knn_stack(stack, tier, k, r, block=block, threads=threads, upper=upper, known=known,
                             priority=priority)
    assert split == one
    check_against_oracle(split, naive_knn_over_curves(stack, tier.curves, tier.owner, tier.names, k, r),
                         stack, tier, r)
    assert stats.dtw >= len(split)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(0, 5), st.integers(2, 8), st.integers(1, 3),
       st.sampled_from(["stack", "shifts", "fixed"]), st.booleans())
def test_a_search_over_some_objects_equals_brute_force_over_them(seed, k, r, objects, threads, kind, bounded):
    """CS2's shortlist search (``only``): exactly the brute force over a tier of the
    listed objects alone, on one thread or split over several, bounded by those objects'
    distances or not; the objects left out never appear, whatever their distances."""
    rng = np.random.default_rng(seed)
    n = 20
    tier = random_tier(rng, objects, 48, n, int(rng.integers(1, 7)))
    only = rng.random(objects) < 0.5
    rows = only[tier.owner]
    q = tier.curves[rng.integers(48)] + rng.normal(0, 0.02, n)  # near some view, listed or not
    window = ShiftWindow(int(rng.integers(n)), int(rng.integers(0, 6)), 1)
    stack = (np.stack([q, *smooth_curves(rng, 2, n)]) if kind == "stack"
             else shifted_curves(q, window.shifts(n)) if kind == "shifts" else q[None, :])
    expected = naive_knn_over_curves(stack, tier.curves[rows], tier.owner[rows], tier.names, k, r)
    upper, known = math.inf, None
    if bounded and expected:
        known = {tier.names.index(e[1]): e[0] * (1 + rng.random()) for e in expected if rng.random() < 0.6}
        upper = expected[k - 1][0] * (1 + rng.random()) if len(expected) >= k else math.inf
    if kind == "stack":
        result, _ = knn_stack(stack, tier, k, r, threads=threads, only=only, upper=upper, known=known)
    elif kind == "shifts":
        result, _ = knn(q, tier, k, r, shifts=window, only=only, upper=upper, known=known)
        starts = window.shifts(n).tolist()
        result = [nb.__class__(nb.object, nb.view, nb.distance, nb.mirrored, starts.index(nb.shift))
                  for nb in result]
    else:
        result, _ = knn(q, tier, k, r, only=only, upper=upper, known=known)
    check_against_oracle(result, expected, stack, tier, r)
    assert all(only[tier.names.index(nb.object)] for nb in result)


def test_a_search_over_some_objects_needs_a_mask_of_every_object():
    rng = np.random.default_rng(0)
    tier = random_tier(rng, 3, 20, 16, 4)
    with pytest.raises(ValueError, match="only must mask"):
        knn_stack(smooth_curves(rng, 2, 16), tier, 2, 2, only=np.ones(2, dtype=bool))


def test_threads_must_be_positive():
    rng = np.random.default_rng(0)
    tier = random_tier(rng, 3, 20, 16, 4)
    with pytest.raises(ValueError, match="threads"):
        knn_stack(smooth_curves(rng, 2, 16), tier, 2, 2, threads=0)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(0, 6))
def test_a_window_of_one_shift_is_the_fixed_start_search(seed, k, r):
    rng = np.random.default_rng(seed)
    tier = random_tier(rng, 5, 60, 48, 6)
    q = smooth_curves(rng, 1, 48)[0]
    fixed, _ = knn(q, tier, k, r)
    one, _ = knn(q, tier, k, r, shifts=ShiftWindow(0, 0))
    assert [(nb.object, nb.view, nb.mirrored) for nb in one] == [(nb.object, nb.view, nb.mirrored) for nb in fixed]
    np.testing.assert_allclose([nb.distance for nb in one], [nb.distance for nb in fixed], rtol=0, atol=1e-9)
    s = int(rng.integers(48))
    turned, _ = knn(q, tier, k, r, shifts=ShiftWindow(s, 0))
    expected, _ = knn(shifted(q, s), tier, k, r)
    assert [(nb.object, nb.distance) for nb in turned] == pytest.approx([(nb.object, nb.distance) for nb in expected])
    assert all(nb.shift == s for nb in turned)


# ---------------------------------------------------------------------------------------
# the bounds, for every curve of a set
# ---------------------------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 5), st.integers(1, 6), st.integers(1, 5))
def test_every_bound_of_a_set_is_below_every_curves_distance(seed, r, count, block):
    """The chain for a set of curves: for each view (and its mirror) and each block, the
    wedge's LB_Keogh, LB_PAA and Fourier_Dist of the union box, the group keys and the
    ring bound are at most the DTW of every curve of the block (of the stack)."""
    rng = np.random.default_rng(seed)
    n = 24
    stack = smooth_curves(rng, count, n)
    query = CurveQuery.of(stack, r, block)
    tier = random_tier(rng, 2, 12, n, 4)
    coords = indexed_coordinates(tier.curves)
    exact = np.array([[[naive_dtw(q, cc, r) for q in stack] for cc in (c, mirror_curve(c))] for c in tier.curves])
    for b, (lo_t, hi_t) in enumerate(zip(query.block_start, query.block_end, strict=True)):
        for m in range(2):
            floor = exact[:, m, lo_t:hi_t].min(axis=1)
            wedge = [naive_lb_keogh(query.wedge_lo[m, b], query.wedge_hi[m, b], c) for c in tier.curves]
            assert np.all(np.array(wedge) <= floor + 1e-9)
            own = np.array([[naive_lb_keogh(query.env_lo[m, t], query.env_hi[m, t], c)
                             for t in range(lo_t, hi_t)] for c in tier.curves]).min(axis=1)
            assert np.all(own <= floor + 1e-9)
            # the union of the boxes holds every member's box (not the wedge's): below
            # each member's LB_Keogh
            gap = np.maximum(query.wbox_lo[m, b] - coords, 0) + np.maximum(coords - query.wbox_hi[m, b], 0)
            assert np.all(np.sqrt((gap**2).sum(axis=1)) <= own + 1e-9)
            means = paa_means(tier.curves, paa_edges(n))
            e = np.maximum(query.wseg_lo[m, b] - means, 0) + np.maximum(means - query.wseg_hi[m, b], 0)
            assert np.all(np.sqrt((query.widths * e**2).sum(axis=1)) <= np.array(wedge) + 1e-9)
            for t in range(lo_t, hi_t):  # each curve's own envelope is the fixed search's
                L, U = envelope(stack[t] if m == 0 else mirror_curve(stack[t]), r)
                if m == 0:
                    np.testing.assert_array_equal(query.env_lo[0, t], L)
                assert np.all(query.wedge_lo[m, b] <= query.env_lo[m, t])
                assert np.all(query.wedge_hi[m, b] >= query.env_hi[m, t])
    floor = exact.min(axis=(1, 2))
    mind, keys = query.group_keys(tier.mbr_lo, tier.mbr_hi, tier.curve_lo, tier.curve_hi)
    for g, views in enumerate(tier.groups):
        assert mind[g] <= keys[g] <= floor[views].min() + 1e-9
    # the rings alone, on each point: shift-invariant and below every distance
    X = np.fft.fft(tier.curves, axis=1, norm="ortho")[:, 1:4]
    ring = np.maximum(np.maximum(np.abs(X) - query.ring_hi, query.ring_lo - np.abs(X)), 0)
    assert np.all(np.sqrt((ring**2).sum(axis=1)) <= floor + 1e-9)


def test_rings_are_the_same_for_every_shift_and_bound_a_turned_stored_curve():
    rng = np.random.default_rng(3)
    q = smooth_curves(rng, 1, 64)[0]
    everyone = CurveQuery.of(shifted_curves(q, np.arange(64)), 4, 8)
    turned = CurveQuery.of(shifted_curves(shifted(q, 17), np.arange(64)), 4, 8)
    np.testing.assert_allclose(everyone.ring_lo, turned.ring_lo, atol=1e-12)
    np.testing.assert_allclose(everyone.ring_hi, turned.ring_hi, atol=1e-12)
    # the curve itself, turned any way, is inside every ring and every union box
    c = shifted(q, 40)
    X = np.abs(np.fft.fft(c, norm="ortho")[1:4])
    assert np.all((everyone.ring_lo <= X) & (X <= everyone.ring_hi))
    p = indexed_coordinates(c)[0]
    assert np.all((everyone.box[0] <= p) & (p <= everyone.box[1]))


def test_lb_keogh_of_a_wedge_is_below_each_member_and_not_vacuous_for_a_narrow_block():
    rng = np.random.default_rng(5)
    q = smooth_curves(rng, 1, 128)[0]
    far = smooth_curves(rng, 50, 128)
    narrow = CurveQuery.of(shifted_curves(q, np.arange(4)), 6, 4)
    wedge = np.array([lb_keogh(narrow.wedge_lo[0, 0], narrow.wedge_hi[0, 0], c) for c in far])
    own = np.array([[lb_keogh(narrow.env_lo[0, t], narrow.env_hi[0, t], c) for t in range(4)] for c in far])
    assert np.all(wedge <= own.min(axis=1) + 1e-12)
    assert np.median(wedge / own.min(axis=1)) > 0.5  # four neighbouring shifts: still a useful bound


# ---------------------------------------------------------------------------------------
# windows, bearings and turns
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(("window", "n", "expected"), [
    (ShiftWindow(), 6, [0, 1, 2, 3, 4, 5]),
    (ShiftWindow(0, 0), 6, [0]),
    (ShiftWindow(1, 2), 8, [7, 0, 1, 2, 3]),
    (ShiftWindow(1, 4), 8, [1, 2, 3, 4, 5, 6, 7, 0]),
    (ShiftWindow(2, 5, 2), 16, [14, 0, 2, 4, 6]),
    (ShiftWindow(3, None, 4), 10, [3, 7, 1]),
])
def test_window_shifts(window, n, expected):
    assert window.shifts(n).tolist() == expected


@given(windows(), st.integers(1, 64))
def test_windows_hold_each_shift_once_within_reach_and_round_trip(window, n):
    got = window.shifts(n)
    assert len(set(got.tolist())) == len(got) and np.all((got >= 0) & (got < n)) and window.centre % n in got
    if window.half_width is not None and 2 * window.half_width + 1 < n:
        off = (got - window.centre + n // 2) % n - n // 2
        assert np.all(np.abs(off) <= window.half_width)
    assert ShiftWindow.from_dict(json.loads(json.dumps(window.to_dict()))) == window


@pytest.mark.parametrize("bad", [{"centre": 1.5}, {"half_width": -1}, {"step": 0}, {"centre": True}, [],
                                 {"centre": 0, "width": 3}])
def test_bad_windows_are_refused(bad):
    with pytest.raises(viewdb.QueryError):
        ShiftWindow.from_dict(bad)


def _blob(size=301):
    # an irregular star-shaped silhouette: no symmetry, so each turn has one best shift
    angles = np.linspace(0, 2 * np.pi, 90, endpoint=False)
    radius = 80 + 30 * np.cos(angles) + 22 * np.sin(2 * angles + 0.7) + 12 * np.cos(3 * angles + 2.0)
    pts = np.stack([size / 2 + radius * np.sin(angles), size / 2 - radius * np.cos(angles)], axis=1)
    mask = np.zeros((size, size), np.uint8)
    cv2.fillPoly(mask, [np.round(pts).astype(np.int32)], 1)
    return mask > 0


def test_a_turned_silhouette_is_a_shift_of_the_upright_curve_at_its_predicted_start():
    mask = _blob()
    q, bearings = distance_curve(mask, 128), sample_bearings(mask, 128)
    assert bearings[0] == pytest.approx(0.0, abs=1e-9)
    for angle, turned in rotated_curves(mask, 128, 12)[1:]:
        errors = [dtw(shifted(q, s), turned, 6) for s in range(128)]
        best = int(np.argmin(errors))
        window = turn_window(bearings, angle, 0.0)
        assert min(abs(best - window.centre), 128 - abs(best - window.centre)) <= 2
        assert shift_turn(bearings, window.centre) == pytest.approx(angle, abs=360 / 128 * 2)
        assert errors[window.centre] < 0.2 * np.median(errors)


def _jagged_silhouette(rng):
    """A cut-out's kind of silhouette: a noisy blob with a ragged edge, 20-120 px."""
    h, w = (int(x) for x in rng.integers(20, 120, 2))
    noise = cv2.GaussianBlur(rng.random((h, w)).astype(np.float32), (0, 0), rng.uniform(1, 4))
    yy, xx = np.mgrid[:h, :w]
    ellipse = ((yy - h / 2) / (h / 2)) ** 2 + ((xx - w / 2) / (w / 2)) ** 2
    return (noise > np.median(noise) - 0.3 * (1 - ellipse)) & (ellipse < 1)


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 1500), st.integers(0, 1200), st.integers(1, 12))
@example(seed=28, dx=1088, dy=192, rotations=8)  # turned whole, a pixel of these fell apart
@example(seed=51, dx=1139, dy=944, rotations=8)
def test_a_large_photo_s_silhouette_is_turned_in_its_own_box(seed, dx, dy, rotations):
    """In a photo past :data:`WHOLE_PHOTO_TURNS` pixels, a silhouette's turned curves are
    those of its own box, bit for bit, wherever it lies."""
    small = _jagged_silhouette(np.random.default_rng(seed))
    assume(small.sum() >= 50)
    ys, xs = np.nonzero(small)
    box = small[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    photo = np.zeros((1440, 1920), bool)  # 2.8 megapixels
    assert photo.size > WHOLE_PHOTO_TURNS
    photo[dy:dy + small.shape[0], dx:dx + small.shape[1]] = small
    alone = rotated_curves(box, 128, rotations)
    placed = rotated_curves(photo, 128, rotations)
    assert [a for a, _ in placed] == [a for a, _ in alone]
    for (_, p), (_, a) in zip(placed, alone, strict=True):
        np.testing.assert_array_equal(p, a)


def test_turn_windows_cover_the_tolerance():
    bearings = (np.arange(128) * 360 / 128 + 1.0) % 360  # a circle's samples, 2.8125 deg apart
    for turn, tolerance in ((0.0, 15.0), (90.0, 40.0), (200.0, 0.0), (10.0, 180.0)):
        w = turn_window(bearings, turn, tolerance)
        near = np.abs((bearings + turn + 180) % 360 - 180)
        assert w.centre == int(np.argmin(near))
        inside = set(np.flatnonzero(near <= tolerance).tolist())
        assert inside <= set(w.shifts(128).tolist())
        assert len(w.shifts(128)) <= len(inside) + 2  # no wider than it must be
    with pytest.raises(viewdb.QueryError):
        turn_window(bearings, 0.0, -1.0)


def test_a_turn_window_follows_the_contour_and_not_a_concavity_passing_the_same_bearing():
    # a contour that passes the bearings near 0 twice: samples 126..4 and, across a
    # concavity, samples 60..63; only the run the start moves along counts
    bearings = np.linspace(0, 360, 128, endpoint=False).copy()
    bearings[60:64] = [356.0, 358.0, 2.0, 4.0]
    w = turn_window(bearings, 0.0, 8.0)
    assert w.centre == 0 and w.half_width == 2
    assert not set(w.shifts(128).tolist()) & set(range(60, 64))


# ---------------------------------------------------------------------------------------
# through the file's R-trees, and CS1 == server
# ---------------------------------------------------------------------------------------


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 4), st.integers(0, 8), windows())
def test_stored_tier_shift_search_equals_brute_force(tiered_db, seed, k, band, window):
    rng = np.random.default_rng(seed)
    with viewdb.open(tiered_db, create=False) as db:
        arrays, _ = db.search_tier("full")
        q = np.roll(arrays.curves[rng.integers(len(arrays.curves))], rng.integers(128))
        q = q + rng.normal(0, rng.choice([0.0, 0.02, 0.2]), 128)
        hits, _ = db.search(q, k, band=band, shifts=window)
        distances = scan_stack(CurveQuery.of(shifted_curves(q, window.shifts(128)), band), arrays.curves)
        best = sorted((distances[arrays.owner == o].min(), name) for o, name in enumerate(arrays.names))[:k]
        assert [h.object for h in hits] == [name for _, name in best]
        np.testing.assert_allclose([h.distance for h in hits], [d for d, _ in best], rtol=0, atol=1e-9)
        assert all(h.shift in set(window.shifts(128).tolist()) for h in hits)


@pytest.fixture(scope="module")
def client_file(tiered_db, tmp_path_factory):
    out = tmp_path_factory.mktemp("client") / "client.db"
    with viewdb.open(tiered_db, create=False) as db:
        db.export_client(out, client_gap=90)
    return out


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(0, 8), windows())
def test_cs1_equals_server_over_shifts(tiered_db, client_file, seed, k, band, window):
    rng = np.random.default_rng(seed)
    with viewdb.open(tiered_db, create=False) as db, viewdb.open(client_file, create=False) as client:
        arrays, _ = db.search_tier("full")
        q = np.roll(arrays.curves[rng.integers(len(arrays.curves))], rng.integers(128))
        q = q + rng.normal(0, rng.choice([0.0, 0.02, 0.2]), 128)
        server = db.recognise(q, k, band=band, plan="server", shifts=window)
        for side in (None, client):
            cs1 = db.recognise(q, k, band=band, plan="cs1", client=side, shifts=window)
            assert [c.to_dict() for c in cs1.results] == [c.to_dict() for c in server.results]


def test_a_client_candidate_from_outside_the_window_is_no_bound(tiered_db):
    with viewdb.open(tiered_db, create=False) as db:
        arrays, _ = db.search_tier("full")
        q = np.roll(arrays.curves[3], 40)
        window = ShiftWindow(0, 5)
        truth = db.recognise(q, 2, plan="server", shifts=window).results
        # a lying client: the true best object's distance at a shift the window leaves out
        bogus = viewdb.Candidate(arrays.names[0], 0.0, 0.0, 0.0, False, shift=40)
        reply, _ = db.server_tier().refine(RefineRequest(q, 6, 2, [bogus], window))
        assert [c.to_dict() for c in reply.results] == [c.to_dict() for c in truth]


def test_shift_requests_round_trip_through_json_and_bad_ones_are_refused():
    req = RefineRequest(np.linspace(0.5, 1.5, 128), 6, 3,
                               [viewdb.Candidate("mug", 0.25, 30.0, 60.0, True, shift=7)], ShiftWindow(3, 9, 2))
    back = RefineRequest.from_dict(json.loads(json.dumps(req.to_dict())))
    assert back.shifts == req.shifts and back.client == req.client
    assert RefineRequest.from_dict({**req.to_dict(), "shifts": None}).shifts is None
    for bad in ({**req.to_dict(), "shifts": {"centre": -1}}, {**req.to_dict(), "shifts": {"step": 0}},
                {**req.to_dict(), "shifts": "all"},
                {**req.to_dict(), "client": [{**req.client[0].to_dict(), "shift": -2}]}):
        with pytest.raises(viewdb.QueryError):
            RefineRequest.from_dict(json.loads(json.dumps(bad)))


@pytest.mark.parametrize("name", ["arrow", "l_bracket"])
def test_a_query_turned_in_the_image_is_found_by_one_shift_search_within_the_roll_window(tiered_db, name):
    with viewdb.open(tiered_db, create=False) as db:
        view = db.render(name, 60.0, 30.0)  # a stored view: distance 0 at the right turn
        rgba = np.dstack([view.color, view.mask.astype(np.uint8) * 255])
        photo = np.ascontiguousarray(np.rot90(rgba))  # turned 90 degrees anticlockwise on screen
        upright = db.query(rgba, k=3, pose=False, colour=False, verify=False, rotations=1).results[0]
        bearings = sample_bearings(photo[..., 3] > 0, 128)
        window = turn_window(bearings, 90.0, viewdb.RecognitionConfig().roll_tolerance)
        turns = {round(shift_turn(bearings, int(s)), 6) for s in window.shifts(128)}
        for options in ({"shifts": ShiftWindow()}, {"roll": 90.0}):
            top = db.query(photo, k=3, pose=False, colour=False, verify=False, **options).results[0]
            assert top.object == name, options
            assert top.distance <= upright.distance + 0.3  # the turned curve is resampled (96 px)
            if "roll" in options:  # only the turns near the hint were searched
                assert round(top.inplane, 6) in turns


def test_the_cli_passes_the_gravity_hint(tiered_db, tmp_path, capsys):
    from viewdb_cli.main import main

    with viewdb.open(tiered_db, create=False) as db:
        view = db.render("arrow", 60.0, 30.0)
        rgba = np.ascontiguousarray(np.rot90(np.dstack([view.color, view.mask.astype(np.uint8) * 255])))
        hinted = {roll: db.query(rgba, k=2, pose=False, colour=False, verify=False, roll=roll).to_dict()
                  for roll in (90.0, 0.0)}
    photo = tmp_path / "turned.png"
    cv2.imwrite(str(photo), cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGRA))
    common = ["query", str(photo), "--db", str(tiered_db), "-k", "2", "--no-pose", "--no-colour", "--no-verify",
              "--json"]
    for flags, roll in ((["--roll", "90"], 90.0), (["--upright"], 0.0)):
        capsys.readouterr()
        assert main(common + flags) == 0
        got = json.loads(capsys.readouterr().out)
        assert got["results"] == hinted[roll]["results"], flags
    assert hinted[90.0]["results"] != hinted[0.0]["results"]  # the hint changed the search
    capsys.readouterr()
    assert main(common + ["--roll", "90", "--upright"]) == 2
    assert "not both" in capsys.readouterr().err


def test_a_priority_deals_its_objects_to_the_threads_in_turn():
    rng = np.random.default_rng(3)
    tier = random_tier(rng, 6, 24, 16, 4)
    parts = deal_objects(tier, 2, priority=np.array([5, 0, 3, 1], dtype=np.int64))
    assert [int(parts[o]) for o in (5, 0, 3, 1)] == [0, 1, 1, 0]  # 0, 1, then back: 1, 0
    assert sorted(np.bincount(parts, minlength=2).tolist()) == [3, 3]
