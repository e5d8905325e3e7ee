"""Tests of viewdb.catalogue.features: contour, centroid distance curve, Fourier point (paper II.A)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.reference import (
    largest_area,
    largest_is_unique,
    naive_contour,
    naive_dft,
    naive_distance_curve,
)
from viewdb.catalogue.features import (
    MIN_AREA,
    distance_curve,
    fourier_point,
    largest_contour,
    mirror_curve,
)
from viewdb.errors import FeatureError

EXACT = 1e-9  # "exact up to floating-point rounding"

SETTINGS = settings(
    max_examples=60,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)

# ---------------------------------------------------------------------------------------
# Mask strategies
# ---------------------------------------------------------------------------------------


@st.composite
def noise_masks(draw: st.DrawFn) -> np.ndarray:
    """Small random bit patterns: one-pixel spurs, diagonal pinches, holes, specks."""
    h = draw(st.integers(2, 16))
    w = draw(st.integers(2, 16))
    return draw(hnp.arrays(np.bool_, (h, w), elements=st.booleans()))


@st.composite
def shape_masks(draw: st.DrawFn) -> np.ndarray:
    """Unions of ellipses, polygons, thin lines and checkerboard patches, with bites."""
    h = draw(st.integers(16, 48))
    w = draw(st.integers(16, 48))
    m = np.zeros((h, w), np.uint8)
    coord = st.tuples(st.integers(0, w - 1), st.integers(0, h - 1))
    for _ in range(draw(st.integers(1, 5))):
        kind = draw(st.sampled_from(["ellipse", "polygon", "line", "checker", "erase"]))
        if kind == "ellipse":  # zero axes give lines and single points
            axes = (draw(st.integers(0, w // 2)), draw(st.integers(0, h // 2)))
            cv2.ellipse(m, draw(coord), axes, draw(st.floats(0, 180)), 0, 360, 1, -1)
        elif kind == "polygon":
            pts = np.array(draw(st.lists(coord, min_size=3, max_size=6)), np.int32)
            cv2.fillPoly(m, [pts], 1)
        elif kind == "line":  # one pixel wide: spurs and diagonal staircases
            cv2.line(m, draw(coord), draw(coord), 1, 1)
        elif kind == "checker":  # diagonal pinches everywhere
            (x, y), size = draw(coord), draw(st.integers(2, 8))
            yy, xx = np.mgrid[y : min(y + size, h), x : min(x + size, w)]
            m[yy, xx] = (yy + xx + draw(st.integers(0, 1))) % 2
        else:  # bites and holes
            cv2.circle(m, draw(coord), draw(st.integers(1, 6)), 0, -1)
    return m


any_masks = st.one_of(noise_masks(), shape_masks())


def usable(mask: np.ndarray) -> np.ndarray:
    """Keep masks with a unique largest region big enough to describe (else reject)."""
    assume(largest_area(mask) >= MIN_AREA)
    assume(largest_is_unique(mask))
    return mask


def same_cycle(a: np.ndarray, b: np.ndarray) -> bool:
    """True if polygons a and b are the same cyclic sequence of vertices."""
    if a.shape != b.shape:
        return False
    starts = np.flatnonzero((a == b[0]).all(axis=1))
    return any(np.array_equal(np.roll(a, -int(k), axis=0), b) for k in starts)


def corners_only(poly: np.ndarray) -> np.ndarray:
    """Drop vertices lying on a straight line through their neighbours."""
    prev, nxt = np.roll(poly, 1, axis=0), np.roll(poly, -1, axis=0)
    d1, d2 = poly - prev, nxt - poly
    return poly[d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0] != 0]


# ---------------------------------------------------------------------------------------
# Contour
# ---------------------------------------------------------------------------------------


@SETTINGS
@given(any_masks)
def test_contour_is_the_reference_iso_line(mask: np.ndarray) -> None:
    usable(mask)
    fast = largest_contour(mask)
    slow = naive_contour(mask)
    assert slow is not None
    assert same_cycle(corners_only(fast), corners_only(slow))


@SETTINGS
@given(any_masks)
def test_contour_is_simple_clockwise_and_on_the_half_pixel_lattice(mask: np.ndarray) -> None:
    usable(mask)
    c = largest_contour(mask)
    assert c.dtype == np.float64 and c.ndim == 2 and c.shape[1] == 2
    assert len(np.unique(c, axis=0)) == len(c), "a vertex is visited twice"
    np.testing.assert_array_equal(c * 2, np.round(c * 2))
    steps = np.hypot(*(np.roll(c, -1, axis=0) - c).T)
    assert np.all(np.isclose(steps, 0.5) | np.isclose(steps, np.sqrt(0.5)))
    x, y = c[:, 0], c[:, 1]
    twice_area = np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)
    assert twice_area > 0, "not clockwise on screen (y down)"
    rows, cols = np.nonzero(mask)
    assert x.min() >= cols.min() - 0.5 and x.max() <= cols.max() + 0.5
    assert y.min() >= rows.min() - 0.5 and y.max() <= rows.max() + 0.5


@SETTINGS
@given(any_masks)
def test_contour_of_mirrored_mask_is_the_mirrored_contour_reversed(mask: np.ndarray) -> None:
    usable(mask)
    c = largest_contour(mask)
    mirrored = np.column_stack([mask.shape[1] - 1 - c[:, 0], c[:, 1]])[::-1]
    assert same_cycle(largest_contour(mask[:, ::-1]), mirrored)


def test_contour_prefers_the_region_enclosing_most_area() -> None:
    m = np.zeros((30, 40), np.uint8)
    m[2:6, 2:30] = 1  # 4 x 28 = 112 pixels, far from round
    m[10:21, 5:16] = 1  # 11 x 11 = 121 pixels
    c = largest_contour(m)
    assert c[:, 1].min() == 9.5 and c[:, 1].max() == 20.5


# ---------------------------------------------------------------------------------------
# Distance curve: oracle, mirror, translation, rotation, scale
# ---------------------------------------------------------------------------------------


@SETTINGS
@given(any_masks, st.integers(8, 128))
def test_distance_curve_matches_naive_reference(mask: np.ndarray, n: int) -> None:
    usable(mask)
    c = distance_curve(mask, n)
    assert c.dtype == np.float64 and c.shape == (n,)
    np.testing.assert_allclose(c, naive_distance_curve(mask, n), rtol=0, atol=EXACT)


@SETTINGS
@given(any_masks, st.integers(8, 160), st.integers(1, 8))
def test_mirror_gives_exactly_the_reversed_curve(mask: np.ndarray, n: int, m: int) -> None:
    usable(mask)
    c = distance_curve(mask, n)
    cm = distance_curve(mask[:, ::-1], n)
    np.testing.assert_allclose(cm, mirror_curve(c), rtol=0, atol=EXACT)
    assert cm[0] == pytest.approx(c[0], abs=EXACT)  # same start point
    x, xm = fourier_point(c, m), fourier_point(cm, m)
    np.testing.assert_allclose(xm, np.conj(x), rtol=0, atol=EXACT)
    np.testing.assert_allclose(np.abs(xm), np.abs(x), rtol=0, atol=EXACT)


@SETTINGS
@given(any_masks, st.integers(0, 9), st.integers(0, 9), st.integers(0, 9), st.integers(0, 9))
def test_integer_translation_is_exact(mask, top, left, bottom, right) -> None:
    usable(mask)
    h, w = mask.shape
    moved = np.zeros((h + top + bottom, w + left + right), np.uint8)
    moved[top : top + h, left : left + w] = mask
    np.testing.assert_array_equal(distance_curve(moved, 64), distance_curve(mask, 64))


@SETTINGS
@given(any_masks, st.integers(8, 128))
def test_half_turn_starts_at_the_opposite_end_of_the_centroid_line(mask, n) -> None:
    # A 180-degree turn maps the lowest contour point on the vertical line through the
    # centroid to the topmost one, so the turned curve is the original contour sampled
    # from there.  That is in general a *fractional* cyclic shift of the original curve,
    # not a whole-sample one, so no exact cyclic-shift property is claimed.
    usable(mask)
    turned = distance_curve(mask[::-1, ::-1], n)
    np.testing.assert_allclose(turned, naive_distance_curve(mask, n, start="bottom"), atol=EXACT)


def _draw(poly: np.ndarray, size: int) -> np.ndarray:
    """Fill a float polygon (sub-pixel vertices, no anti-aliasing)."""
    m = np.zeros((size, size), np.uint8)
    cv2.fillPoly(m, [np.round(poly * 256).astype(np.int32)], 1, cv2.LINE_8, shift=8)
    return m


@st.composite
def smooth_shapes(draw: st.DrawFn) -> tuple[str, np.ndarray]:
    """A unit-size ellipse or round-ish polygon (4-8 vertices), as a float outline."""
    turn = draw(st.floats(0, 2 * np.pi))
    if draw(st.booleans()):
        t = np.linspace(0, 2 * np.pi, 256, endpoint=False)
        x, y = np.cos(t), draw(st.floats(0.5, 1.0)) * np.sin(t)
        kind = "ellipse"
    else:
        k = draw(st.integers(4, 8))
        jitter = np.array(draw(st.lists(st.floats(-0.3, 0.3), min_size=k, max_size=k)))
        radii = np.array(draw(st.lists(st.floats(0.7, 1.0), min_size=k, max_size=k)))
        t = 2 * np.pi * np.arange(k) / k + jitter * np.pi / k
        x, y = radii * np.cos(t), radii * np.sin(t)
        kind = "polygon"
    c, s = np.cos(turn), np.sin(turn)
    return kind, np.column_stack([c * x - s * y, s * x + c * y])


# Max |difference| between curves of the same shape drawn at radius R and 2R, R in
# [30, 50] px (measured worst case over 3000 random shapes: 0.049 and 0.062).
SCALE_TOLERANCE = {"ellipse": 0.06, "polygon": 0.08}


@settings(SETTINGS, max_examples=40)
@given(smooth_shapes(), st.floats(30, 50), st.floats(0, 1), st.floats(0, 1))
def test_scale_invariance_within_tolerance(shape, radius, dx, dy) -> None:
    kind, outline = shape
    size = int(2 * radius) + 12
    small = _draw(outline * radius + size / 2 + np.array([dx, dy]), size)
    large = _draw(outline * 2 * radius + size + 2 * np.array([dx, dy]), 2 * size)
    c1, c2 = distance_curve(small, 128), distance_curve(large, 128)
    assert np.abs(c1 - c2).max() < SCALE_TOLERANCE[kind]
    f1, f2 = np.abs(fourier_point(c1, 8)), np.abs(fourier_point(c2, 8))
    assert np.abs(f1 - f2).max() < 0.15  # |X_0| is about sqrt(128) = 11.3


@settings(SETTINGS, max_examples=30)
@given(smooth_shapes(), st.floats(30, 50), st.floats(0, 1), st.floats(0, 1))
def test_half_turn_keeps_fourier_magnitudes_approximately(shape, radius, dx, dy) -> None:
    _, outline = shape
    size = int(2 * radius) + 12
    mask = _draw(outline * radius + size / 2 + np.array([dx, dy]), size)
    a = np.abs(fourier_point(distance_curve(mask, 128), 8))
    b = np.abs(fourier_point(distance_curve(mask[::-1, ::-1], 128), 8))
    assert np.abs(a - b).max() < 0.02  # measured worst case 0.0103


def test_disc_has_flat_curve_and_ellipse_peaks_on_its_long_axis() -> None:
    disc = np.zeros((101, 101), np.uint8)
    cv2.circle(disc, (50, 50), 40, 1, -1)
    assert np.abs(distance_curve(disc, 128) - 1).max() < 0.02
    # axis-aligned ellipse, long axis horizontal: start at the top (short-axis end),
    # so the minima are at samples 0 and n/2 and the maxima at n/4 and 3n/4
    ell = np.zeros((101, 141), np.uint8)
    cv2.ellipse(ell, (70, 50), (60, 20), 0, 0, 360, 1, -1)
    c = distance_curve(ell, 128)
    assert c[0] == pytest.approx(c.min(), abs=0.02)
    assert c[64] == pytest.approx(c.min(), abs=0.02)
    assert c[32] == pytest.approx(c.max(), abs=0.02)
    assert c[96] == pytest.approx(c.max(), abs=0.02)
    assert c.max() / c.min() == pytest.approx(3.0, rel=0.05)


@SETTINGS
@given(any_masks)
def test_curve_is_scale_normalised_and_ignores_mask_dtype(mask: np.ndarray) -> None:
    usable(mask)
    c = distance_curve(mask.astype(bool), 50)
    assert c.mean() == pytest.approx(1.0, abs=1e-12)
    assert np.all(c > 0)
    np.testing.assert_array_equal(distance_curve(mask.astype(np.uint8) * 255, 50), c)
    np.testing.assert_array_equal(distance_curve(mask.astype(np.float32) * 0.5, 50), c)


# ---------------------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(0, 0), (0, 7), (5, 0)])
def test_mask_without_pixels_is_a_feature_error(shape) -> None:
    with pytest.raises(FeatureError, match="no pixels"):
        distance_curve(np.zeros(shape, np.uint8))


def test_blank_mask_is_a_feature_error() -> None:
    with pytest.raises(FeatureError, match="blank"):
        distance_curve(np.zeros((64, 64), bool))
    with pytest.raises(FeatureError, match="blank"):
        largest_contour(np.zeros((64, 64), np.uint8))


@pytest.mark.parametrize(
    "pixels",
    [
        [(5, 5)],  # single pixel
        [(5, 5), (5, 6), (5, 7)],  # short line
        [(5, 5), (6, 6), (7, 7)],  # short diagonal
        [(5, 5), (5, 6), (6, 5)],  # L tromino
    ],
)
def test_tiny_region_is_a_feature_error(pixels) -> None:
    m = np.zeros((12, 12), np.uint8)
    for r, c in pixels:
        m[r, c] = 1
    m[0, 0] = m[11, 11] = 1  # stray specks elsewhere do not help
    with pytest.raises(FeatureError, match="too small") as info:
        distance_curve(m)
    assert "\n" not in str(info.value) and "square pixels" in str(info.value)


def test_four_pixel_line_is_just_big_enough() -> None:
    m = np.zeros((8, 8), np.uint8)
    m[3, 2:6] = 1
    c = distance_curve(m, 16)
    assert c.shape == (16,) and np.isfinite(c).all()


@SETTINGS
@given(noise_masks())
def test_feature_error_exactly_when_largest_area_is_below_minimum(mask: np.ndarray) -> None:
    area = largest_area(mask)
    if area < MIN_AREA:
        with pytest.raises(FeatureError):
            distance_curve(mask, 16)
    else:
        assert distance_curve(mask, 16).shape == (16,)


def test_bad_arguments_are_value_errors() -> None:
    disc = np.zeros((32, 32), np.uint8)
    cv2.circle(disc, (16, 16), 10, 1, -1)
    with pytest.raises(ValueError, match="2-D"):
        distance_curve(disc[None])
    with pytest.raises(ValueError, match="n_samples"):
        distance_curve(disc, 0)
    c = distance_curve(disc, 16)
    with pytest.raises(ValueError, match="m must be"):
        fourier_point(c, 0)
    with pytest.raises(ValueError, match="m must be"):
        fourier_point(c, 17)
    with pytest.raises(ValueError, match="1-D"):
        fourier_point(c[None], 4)


# ---------------------------------------------------------------------------------------
# Fourier point and mirror_curve
# ---------------------------------------------------------------------------------------

curves = hnp.arrays(np.float64, st.integers(1, 64), elements=st.floats(-1e3, 1e3, allow_nan=False))


@SETTINGS
@given(curves, st.data())
def test_fourier_point_matches_naive_dft(curve: np.ndarray, data: st.DataObject) -> None:
    m = data.draw(st.integers(1, len(curve)))
    x = fourier_point(curve, m)
    assert x.dtype == np.complex128 and x.shape == (m,)
    scale = 1e-9 * (1 + np.abs(curve).sum())
    np.testing.assert_allclose(x, naive_dft(curve, m), rtol=0, atol=scale)


@SETTINGS
@given(curves)
def test_parseval(curve: np.ndarray) -> None:
    x = fourier_point(curve, len(curve))
    assert np.linalg.norm(x) == pytest.approx(np.linalg.norm(curve), rel=1e-12, abs=1e-9)


@SETTINGS
@given(curves, st.integers(0, 100))
def test_magnitudes_ignore_start_and_mirror_conjugates(curve: np.ndarray, shift: int) -> None:
    n = len(curve)
    x = fourier_point(curve, n)
    atol = 1e-9 * (1 + np.abs(curve).sum())
    np.testing.assert_allclose(
        np.abs(fourier_point(np.roll(curve, shift), n)), np.abs(x), atol=atol
    )
    np.testing.assert_allclose(fourier_point(mirror_curve(curve), n), np.conj(x), atol=atol)


@SETTINGS
@given(curves)
def test_mirror_curve_reverses_about_the_start(curve: np.ndarray) -> None:
    n = len(curve)
    mc = mirror_curve(curve)
    assert [mc[i] for i in range(n)] == [curve[(-i) % n] for i in range(n)]
    np.testing.assert_array_equal(mirror_curve(mc), curve)


@SETTINGS
@given(hnp.arrays(np.float64, st.tuples(st.integers(1, 4), st.integers(1, 64)),
                  elements=st.floats(-1e3, 1e3, allow_nan=False)))
def test_a_stack_of_curves_is_mirrored_curve_by_curve(stack: np.ndarray) -> None:
    stacked = mirror_curve(stack)
    assert stacked.shape == stack.shape
    for row, curve in zip(stacked, stack, strict=True):
        np.testing.assert_array_equal(row, mirror_curve(curve))
    with pytest.raises(ValueError, match="at least 1-D"):
        mirror_curve(np.float64(1.0))
