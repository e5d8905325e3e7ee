"""Tests for viewdb.search.bounds: DTW and the chain of lower bounds of Algorithm 2.

The chain MINDIST <= Fourier_Dist <= LB_Keogh <= DTW is checked property-based on random
sequences, random walks, sequences with many ties and smooth positive mean-1 curves,
for the candidate and for its mirror image (through the mirrored query box), against
plain-Python oracles in ``tests/reference.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchmarks.support.curves import smooth_curve
from tests import reference as R
from viewdb.catalogue.features import fourier_point, mirror_curve
from viewdb.search import bounds as B

SETTINGS = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
KINDS = ("normal", "walk", "smooth", "ties")


def make_seq(rng: np.random.Generator, n: int, kind: str) -> np.ndarray:
    if kind == "normal":
        return rng.normal(scale=rng.uniform(0.1, 5.0), size=n)
    if kind == "walk":
        return np.cumsum(rng.normal(size=n))
    if kind == "smooth":
        return smooth_curve(rng, n)
    return rng.integers(-2, 3, size=n).astype(np.float64)  # many ties / flat runs


@st.composite
def cases(draw, max_n: int = 128):
    n = draw(st.one_of(st.just(max_n), st.integers(8, max_n)))  # often the real N
    r = draw(st.integers(0, n // 4))
    kind = draw(st.sampled_from(KINDS))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    q = make_seq(rng, n, kind)
    # candidates: unrelated, or a perturbed / shifted copy of the query (tight cases)
    how = draw(st.sampled_from(("other", "noisy", "shift")))
    if how == "other":
        c = make_seq(rng, n, kind)
    elif how == "noisy":
        c = q + rng.normal(scale=draw(st.sampled_from((1e-3, 0.05, 0.5))), size=n)
    else:
        c = np.roll(q, draw(st.integers(-3, 3)))
    return q, c, r, rng


def leq(a: float, b: float, rel: float = 1e-9) -> bool:
    return a <= b + rel * (1.0 + abs(b))


# --------------------------------------------------------------------------- DTW ----


@SETTINGS
@given(cases())
def test_dtw_matches_naive(case):
    q, c, r, _ = case
    got = B.dtw(q, c, r)
    want = R.naive_dtw(q, c, r)
    assert got == pytest.approx(want, rel=1e-9, abs=1e-9)
    assert B.dtw(c, q, r) == pytest.approx(got, rel=1e-9, abs=1e-9)  # symmetric band


@settings(max_examples=60, deadline=None)
@given(cases(max_n=40))
def test_dtw_wide_band_is_unconstrained(case):
    q, c, _, _ = case
    n = len(q)
    want = R.naive_dtw(q, c, None)
    assert B.dtw(q, c, n - 1) == pytest.approx(want, rel=1e-9, abs=1e-9)
    assert B.dtw(q, c, 10 * n) == pytest.approx(want, rel=1e-9, abs=1e-9)


@SETTINGS
@given(cases())
def test_dtw_r0_is_euclidean_and_monotone_in_r(case):
    q, c, r, _ = case
    assert B.dtw(q, c, 0) == pytest.approx(float(np.linalg.norm(q - c)), rel=1e-12, abs=1e-12)
    assert leq(B.dtw(q, c, r + 1), B.dtw(q, c, r))  # wider band, never larger


def test_dtw_float32_input_and_identity():
    rng = np.random.default_rng(0)
    c = smooth_curve(rng, 128).astype(np.float32)
    assert B.dtw(c, c, 6) == 0.0
    assert B.dtw(c, c.astype(np.float64) + 1.0, 0) == pytest.approx(math.sqrt(128))
    assert B.dtw(np.ones(128, np.float32), np.full(128, 3.0), 6) == pytest.approx(2 * math.sqrt(128))
    assert B.dtw([1.0], [4.0], 0) == 3.0


@SETTINGS
@given(cases(), st.floats(0.0, 2.0))
def test_early_abandoning(case, frac):
    q, c, r, _ = case
    exact = B.dtw(q, c, r)
    for bsf in (exact * frac, exact, exact * (1 - 1e-6), exact * (1 + 1e-6), 0.0, math.inf):
        got = B.dtw(q, c, r, best_so_far=bsf)
        if got == math.inf:
            assert exact > bsf
        else:
            assert got == exact
    assert B.dtw(q, c, r, best_so_far=exact) == exact  # a tie is never abandoned


def test_early_abandoning_abandons():
    q = np.zeros(128)
    c = np.full(128, 10.0)
    assert B.dtw(q, c, 6, best_so_far=1.0) == math.inf
    assert B.dtw(q, c, 6, best_so_far=200.0) == pytest.approx(math.sqrt(128) * 10)


# ----------------------------------------------------------------- time-domain LBs ----


@SETTINGS
@given(cases())
def test_envelope_and_lb_keogh_match_naive(case):
    q, c, r, _ = case
    L, U = B.envelope(q, r)
    nL, nU = R.naive_envelope(q, r)
    np.testing.assert_array_equal(L, nL)
    np.testing.assert_array_equal(U, nU)
    lb = B.lb_keogh(L, U, c)
    assert lb == pytest.approx(R.naive_lb_keogh(nL, nU, c), rel=1e-12, abs=1e-12)
    C = np.stack([c, q, np.roll(c, 1)])
    np.testing.assert_allclose(
        B.lb_keogh_many(L, U, C), [B.lb_keogh(L, U, x) for x in C], rtol=1e-12, atol=1e-12
    )


def test_envelope_r0_and_wide():
    q = np.array([3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0, 6.0])
    L, U = B.envelope(q, 0)
    np.testing.assert_array_equal(L, q)
    np.testing.assert_array_equal(U, q)
    L, U = B.envelope(q, 100)
    np.testing.assert_array_equal(L, np.full(8, 1.0))
    np.testing.assert_array_equal(U, np.full(8, 9.0))
    L, U = B.envelope(q, 1)
    np.testing.assert_array_equal(U, [3, 4, 4, 5, 9, 9, 9, 6])
    np.testing.assert_array_equal(L, [1, 1, 1, 1, 1, 2, 2, 2])


# ----------------------------------------------------------------- Fourier coordinates --


@pytest.mark.parametrize("n", [1, 2, 7, 8, 128])
def test_fourier_coordinates_match_fft(n):
    rng = np.random.default_rng(n)
    x = rng.normal(size=n)
    for m in sorted({1, max(1, n // 2), n}):
        F = B.fourier_coordinates(m, n)
        assert F.shape == (2 * m, n)
        X = np.fft.fft(x, norm="ortho")[:m]
        np.testing.assert_allclose(F @ x, np.concatenate([X.real, X.imag]), atol=1e-12)
        np.testing.assert_allclose(B.complex_to_coordinates(fourier_point(x, m)), F @ x, atol=1e-12)
        assert np.all(F[m] == 0.0)  # Im X_0 is kept as an all-zero row
        # contraction (Parseval): ||F v|| <= ||v||, i.e. largest singular value <= 1
        assert np.linalg.eigvalsh(F.T @ F).max() <= 1 + 1e-12
    if n == 8:
        np.testing.assert_allclose(
            B.fourier_coordinates(3, 8) @ x,
            np.concatenate([R.naive_dft(x, 3).real, R.naive_dft(x, 3).imag]),
            atol=1e-12,
        )


def test_box_is_exact_range_by_vertex_enumeration():
    rng = np.random.default_rng(1)
    for n in (8, 9, 11):
        for r in (0, 1, 2):
            q = rng.normal(size=n)
            L, U = B.envelope(q, r)
            F = B.fourier_coordinates(4, n)
            lo, hi = B.envelope_box(L, U, F)
            vlo, vhi = R.naive_box_by_vertices(L, U, F)
            np.testing.assert_allclose(lo, vlo, atol=1e-12)
            np.testing.assert_allclose(hi, vhi, atol=1e-12)
            assert np.all(lo <= vlo) and np.all(hi >= vhi)  # rounded outward
            # every point of the envelope maps into the box
            X = L + rng.uniform(size=(200, n)) * (U - L)
            P = X @ F.T
            assert np.all(P >= lo) and np.all(P <= hi)
            assert np.all(B.fourier_dist_many(lo, hi, P) == 0.0)


# ----------------------------------------------------------------------- the chain ----


def mbr_containing(rng, p, n_other, scale):
    pts = np.vstack([p, p + rng.normal(scale=scale, size=(n_other, p.shape[0]))])
    pts[:, p.shape[0] // 2] = 0.0  # Im X_0 of any real curve
    return pts.min(axis=0), pts.max(axis=0)


@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases(), st.integers(1, 16), st.booleans())
def test_lower_bound_chain(case, m, all_coeffs):
    q, c, r, rng = case
    n = len(q)
    m = n if all_coeffs and rng.uniform() < 0.2 else min(m, n)
    F = B.fourier_coordinates(m, n)
    L, U = B.envelope(q, r)
    box = B.envelope_box(L, U, F)
    mbox = B.mirror_box(*box)

    for cand, the_box, stored in (
        (c, box, c),  # the view itself
        (mirror_curve(c), mbox, c),  # its mirror, via the mirrored box on the stored point
    ):
        p = B.complex_to_coordinates(fourier_point(stored, m))  # as stored: FFT, not F @ c
        d = B.dtw(q, cand, r)
        lbk = B.lb_keogh(L, U, cand)
        fd = B.fourier_dist(*the_box, p)
        mbr = mbr_containing(rng, p, int(rng.integers(0, 5)), rng.uniform(0.01, 1.0))
        md = B.mindist(*the_box, *mbr)
        assert leq(md, fd), (md, fd)
        assert leq(fd, lbk), (fd, lbk)
        assert leq(lbk, d), (lbk, d)
        assert leq(B.lb_kim(q, cand), d)
        assert leq(B.lb_keogh_reverse(q, cand, r), d)
        # batched versions agree
        assert B.fourier_dist_many(*the_box, p[None])[0] == pytest.approx(fd, rel=1e-12)
        assert B.mindist_many(*the_box, mbr[0][None], mbr[1][None])[0] == pytest.approx(md, rel=1e-12)
        if lbk == 0.0:  # candidate inside the envelope: no false dismissal, even by rounding
            assert fd == 0.0 and md == 0.0


@SETTINGS
@given(cases(), st.integers(1, 40))
def test_lb_paa_bounds_lb_keogh_for_a_view_and_its_mirror(case, segments):
    """LB_PAA <= LB_Keogh (so <= DTW), against a plain-Python sum over the segments; for the
    mirror through the mirrored envelope on the stored curve's segment means, as the
    search computes it."""
    q, c, r, rng = case
    n = len(q)
    edges = B.paa_edges(n, segments)
    assert edges[0] == 0 and edges[-1] == n and np.all(np.diff(edges) >= 1)
    assert len(edges) - 1 == min(segments, n)
    L, U = B.envelope(q, r)
    stored = c.astype(np.float32)  # as the tiers hold them
    means = B.paa_means(stored, edges)
    for envelope, cand in (((L, U), stored.astype(np.float64)),
                           ((mirror_curve(L), mirror_curve(U)), mirror_curve(stored.astype(np.float64)))):
        lo, hi, widths = B.paa_envelope(*envelope, edges)
        got = B.lb_paa(lo, hi, widths, means)
        naive = 0.0
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            m = float(np.mean(stored[a:b].astype(np.float64)))
            lo_j, hi_j = float(np.min(envelope[0][a:b])), float(np.max(envelope[1][a:b]))
            naive += (b - a) * max(m - hi_j, lo_j - m, 0.0) ** 2
        assert got == pytest.approx(math.sqrt(naive), rel=1e-9, abs=1e-12)
        lbk = B.lb_keogh(L, U, cand)  # the query's envelope against the candidate itself
        assert lbk == pytest.approx(B.lb_keogh(*envelope, stored.astype(np.float64)), rel=1e-9, abs=1e-12)
        assert leq(got, lbk), (got, lbk)
        assert leq(lbk, B.dtw(q, cand, r))
        if segments >= n:  # one sample per segment: LB_Keogh itself
            assert got == pytest.approx(lbk, rel=1e-9, abs=1e-12)


def test_lb_paa_is_tighter_than_the_fourier_box_on_real_looking_curves():
    """The reason for LB_PAA: on smooth curves it passes far fewer candidates than
    Fourier_Dist at the same threshold (measured: about a fifth)."""
    n, r = 128, 6
    rng = np.random.default_rng(11)
    F = B.fourier_coordinates(4, n)
    edges = B.paa_edges(n)
    paa_wins = 0
    for _ in range(200):
        q, c = smooth_curve(rng, n), smooth_curve(rng, n)
        L, U = B.envelope(q, r)
        fd = B.fourier_dist(*B.envelope_box(L, U, F), F @ c)
        paa = B.lb_paa(*B.paa_envelope(L, U, edges), B.paa_means(c, edges))
        paa_wins += paa > fd
    assert paa_wins > 150


@SETTINGS
@given(cases(), st.integers(1, 16))
def test_mirror_box_is_the_mirrored_query(case, m):
    q, c, r, rng = case
    n = len(q)
    m = min(m, n)
    F = B.fourier_coordinates(m, n)
    box = B.envelope_box(*B.envelope(q, r), F)
    p = F @ c
    pm = F @ mirror_curve(c)
    np.testing.assert_allclose(B.mirror_coordinates(p), pm, atol=1e-12)  # conj(X)
    np.testing.assert_allclose(
        B.complex_to_coordinates(fourier_point(mirror_curve(c), m)),
        B.complex_to_coordinates(np.conj(fourier_point(c, m))),
        atol=1e-12,
    )
    mbox = B.mirror_box(*box)
    assert B.fourier_dist(*mbox, p) == pytest.approx(B.fourier_dist(*box, pm), rel=1e-9, abs=1e-12)
    mbr = mbr_containing(rng, p, 3, 0.1)
    mirrored_mbr = B.mirror_box(*mbr)  # MBR of the mirrored points
    assert B.mindist(*mbox, *mbr) == pytest.approx(B.mindist(*box, *mirrored_mbr), rel=1e-12)
    np.testing.assert_array_equal(B.mirror_box(*mbox)[0], box[0])  # an involution
    np.testing.assert_array_equal(B.mirror_box(*mbox)[1], box[1])


def test_inside_envelope_gives_zero_bounds():
    rng = np.random.default_rng(5)
    for _ in range(200):
        q = smooth_curve(rng, 128)
        L, U = B.envelope(q, 6)
        c = L + rng.uniform(size=128) * (U - L)  # anywhere inside the envelope
        for m in (4, 8, 16):
            box = B.envelope_box(L, U, B.fourier_coordinates(m, 128))
            p = B.complex_to_coordinates(fourier_point(c, m))
            assert B.lb_keogh(L, U, c) == 0.0
            assert B.fourier_dist(*box, p) == 0.0


def test_plain_fourier_distance_is_not_a_lower_bound():
    n, m, r = 64, 8, 1
    q = np.zeros(n)
    c = np.zeros(n)
    q[10] = 1.0
    c[11] = 1.0  # the same spike one sample later
    assert B.dtw(q, c, r) == 0.0
    plain = np.linalg.norm(np.fft.fft(q, norm="ortho")[:m] - np.fft.fft(c, norm="ortho")[:m])
    assert plain > 0.05
    F = B.fourier_coordinates(m, n)
    L, U = B.envelope(q, r)
    assert B.lb_keogh(L, U, c) == 0.0
    assert B.fourier_dist(*B.envelope_box(L, U, F), F @ c) == 0.0


def test_bounds_are_not_vacuous_on_real_looking_curves():
    n, r, m = 128, 6, 8
    t = np.arange(n) / n
    ellipse = 1 + 0.3 * np.cos(4 * np.pi * t)  # two lobes
    triangle = 1 + 0.2 * np.cos(6 * np.pi * t + 0.4)  # three lobes
    F = B.fourier_coordinates(m, n)
    L, U = B.envelope(ellipse, r)
    box = B.envelope_box(L, U, F)
    d = B.dtw(ellipse, triangle, r)
    lbk = B.lb_keogh(L, U, triangle)
    fd = B.fourier_dist(*box, F @ triangle)
    assert lbk > 0.5 * d and fd > 0.25 * d > 0  # tight, not just > 0
    # the query box is much tighter than the trivial box of the flat envelope [min, max]
    trivial = B.envelope_box(np.full(n, ellipse.min()), np.full(n, ellipse.max()), F)
    width = np.sum(box[1] - box[0])
    trivial_width = np.sum(trivial[1] - trivial[0])
    assert width < 0.4 * trivial_width  # 0.37 at r = 6, 0.13 at r = 2
    # and over many random smooth curves
    rng = np.random.default_rng(7)
    ratios, lbs = [], []
    for _ in range(50):
        q, c = smooth_curve(rng, n), smooth_curve(rng, n)
        L, U = B.envelope(q, r)
        lo, hi = B.envelope_box(L, U, F)
        tlo, thi = B.envelope_box(np.full(n, q.min()), np.full(n, q.max()), F)
        ratios.append(np.sum(hi - lo) / np.sum(thi - tlo))
        lbs.append(B.lb_keogh(L, U, c) / B.dtw(q, c, r))
    assert np.median(ratios) < 0.55  # about 0.47
    assert np.median(lbs) > 0.3


# ------------------------------------------------------------------------- validation --


@pytest.mark.parametrize(
    "call",
    [
        lambda: B.dtw(np.zeros(4), np.zeros(5), 1),
        lambda: B.dtw(np.zeros((2, 2)), np.zeros((2, 2)), 1),
        lambda: B.dtw(np.array([0.0, np.nan]), np.zeros(2), 1),
        lambda: B.dtw(np.zeros(4), np.array([0, 0, np.inf, 0]), 1),
        lambda: B.dtw(np.zeros(4), np.zeros(4), -1),
        lambda: B.dtw(np.zeros(4), np.zeros(4), 1, best_so_far=float("nan")),
        lambda: B.dtw(np.zeros(4), np.zeros(4), 1, best_so_far=-1.0),
        lambda: B.dtw(np.zeros(0), np.zeros(0), 1),
        lambda: B.envelope(np.zeros(4), -2),
        lambda: B.lb_keogh(np.ones(4), np.zeros(4), np.zeros(4)),
        lambda: B.lb_keogh(np.zeros(4), np.ones(4), np.zeros(3)),
        lambda: B.lb_keogh_many(np.zeros(4), np.ones(4), np.zeros((2, 3))),
        lambda: B.lb_kim(np.zeros(3), np.zeros(4)),
        lambda: B.fourier_coordinates(0, 8),
        lambda: B.fourier_coordinates(9, 8),
        lambda: B.envelope_box(np.zeros(4), np.ones(4), np.zeros((2, 5))),
        lambda: B.fourier_dist(np.ones(2), np.zeros(2), np.zeros(2)),
        lambda: B.fourier_dist(np.zeros(2), np.ones(2), np.zeros(3)),
        lambda: B.fourier_dist_many(np.zeros(2), np.ones(2), np.zeros((3, 4))),
        lambda: B.mindist(np.zeros(2), np.ones(2), np.zeros(3), np.ones(3)),
        lambda: B.mindist_many(np.zeros(2), np.ones(2), np.ones((1, 2)), np.zeros((1, 2))),
        lambda: B.mirror_box(np.zeros(3), np.ones(3)),
    ],
)
def test_invalid_inputs_raise(call):
    with pytest.raises(ValueError):
        call()


@pytest.mark.parametrize("r", [1.5, "2", True, None])
def test_band_must_be_an_integer(r):
    with pytest.raises(TypeError):
        B.dtw(np.zeros(4), np.zeros(4), r)


def test_small_values():
    assert B.lb_kim([1.0, 2.0], [1.0, 5.0]) == 3.0
    assert B.lb_kim([2.0], [5.0]) == 3.0 == B.dtw([2.0], [5.0], 0)
    assert B.fourier_dist([0, 0], [1, 1], [4, 5]) == 5.0
    assert B.mindist([0, 0], [1, 1], [4, 5], [6, 7]) == 5.0
    assert B.mindist([0, 0], [1, 1], [0.5, -3], [6, 0.2]) == 0.0
    lo, hi = B.mirror_box([1, 2, 3, 4], [5, 6, 7, 8])
    np.testing.assert_array_equal(lo, [1, 2, -7, -8])
    np.testing.assert_array_equal(hi, [5, 6, -3, -4])
    assert B.dtw(np.zeros(4), np.zeros(4), np.int64(2)) == 0.0


# ------------------------------------------------------------- group-level bounds ----


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases(), st.integers(1, 6))
def test_group_bounds_are_the_chain_for_each_curve_and_its_mirror(case, size):
    q, c, r, rng = case
    n = len(q)
    curves = np.vstack([c] + [c + rng.normal(scale=0.1, size=n) for _ in range(size - 1)])
    m = min(4, n)
    F = B.fourier_coordinates(m, n)
    rows = np.r_[1:m, m + 1 : 2 * m]
    L, U = B.envelope(q, r)
    lo, hi = B.envelope_box(L, U, F)
    mlo, mhi = B.mirror_box(lo, hi)
    box, mbox = (lo[rows], hi[rows]), (mlo[rows], mhi[rows])
    coords = np.ascontiguousarray((curves @ F.T)[:, rows])
    keys = B.group_bounds((L, U), (mirror_curve(L), mirror_curve(U)), box, mbox, coords,
                          np.ascontiguousarray(curves))
    for i, cand in enumerate(curves):
        for key, the_box, the_curve in ((keys[i], box, cand), (keys[size + i], mbox, mirror_curve(cand))):
            expected = max(B.fourier_dist(*the_box, coords[i]), B.lb_keogh(L, U, the_curve))
            assert key == pytest.approx(expected, rel=1e-9, abs=1e-12)
            assert leq(key, B.dtw(q, the_curve, r))
    # the per-sample box of the group bounds LB_Keogh of every member, both orientations
    glo, ghi = curves.min(axis=0)[None], curves.max(axis=0)[None]
    direct = B.curve_box_lb_many(L, U, glo, ghi)[0]
    mirrored = B.curve_box_lb_many(mirror_curve(L), mirror_curve(U), glo, ghi)[0]
    for cand in curves:
        assert leq(direct, B.lb_keogh(L, U, cand))
        assert leq(mirrored, B.lb_keogh(L, U, mirror_curve(cand)))


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases(), st.integers(1, 6), st.sampled_from((1.0, 1e-3, 1e3)))
def test_float32_curve_box_bound_is_at_most_the_exact_one(case, size, scale):
    q, c, r, rng = case
    n = len(q)
    curves = (np.vstack([c] + [c + rng.normal(scale=0.1, size=n) for _ in range(size - 1)]) * scale)
    curves = curves.astype(np.float32)
    glo, ghi = curves.min(axis=0)[None], curves.max(axis=0)[None]
    L, U = B.envelope(q * scale, r)
    wlo, whi = B.outward32(L, U)
    assert (wlo <= L).all() and (whi >= U).all()
    key = B.curve_box32(glo, ghi, 0, wlo, whi)
    exact = math.fsum(float(e) ** 2 for e in np.maximum(glo[0] - U, 0) + np.maximum(L - ghi[0], 0))
    assert key <= exact
    # and no weaker than the exact bound by more than its rounding and the envelope's
    assert key >= exact * (1 - 1e-4) - 4 * n * (np.spacing(np.float32(np.abs(L).max() + 1)) ** 2 + (
        np.spacing(np.float32(np.abs(L).max() + 1)) * 2 * math.sqrt(exact)))
    for cand in curves:
        assert leq(math.sqrt(key), B.lb_keogh(L, U, cand.astype(np.float64)))


@SETTINGS
@given(cases(), st.floats(0.0, 2.0))
def test_cascade_dtw_is_dtw_unless_beyond_the_threshold(case, frac):
    q, c, r, _ = case
    exact = B.dtw(q, c, r)
    threshold = exact * frac
    got = B.cascade_dtw(q, c, r, threshold)
    if exact <= threshold:
        assert got == exact
    else:
        assert got == math.inf or got == exact
    assert B.cascade_dtw(q, c, r) == exact


def test_cascade_dtw_abandons_a_far_candidate_by_its_envelope():
    rng = np.random.default_rng(2)
    q = smooth_curve(rng, 128)
    far = q + 1.0  # LB_Keogh either way is > 1: abandoned before any DTW row
    assert B.lb_keogh_reverse(q, far, 6) > 1.0
    assert B.cascade_dtw(q, far, 6, 1.0) == math.inf
    assert B.cascade_dtw(q, far, 6) == B.dtw(q, far, 6) > 1.0
