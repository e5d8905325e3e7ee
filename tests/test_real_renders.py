"""Shape features on real renders: the mirror pairing the paper relies on, and invariances."""

import numpy as np
import pytest

from tests.conftest import sample
from viewdb.catalogue.features import distance_curve, fourier_point, mirror_curve
from viewdb.catalogue.mesh import load_mesh
from viewdb.catalogue.render import get_renderer
from viewdb.config import RenderConfig

#: RMS difference allowed between curves of views that are mirror images in 3-D: the
#: rasteriser's tie rule for edges on pixel centres is the only source of difference.
MIRROR_RMS = 0.01


def rms(a, b):
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


@pytest.mark.parametrize("stem", ["car", "l_bracket", "arrow", "chair", "mug", "torus"])
def test_opposite_view_gives_the_reversed_curve_and_equal_dft_magnitudes(stem):
    mesh = load_mesh(sample(stem))
    renderer = get_renderer()
    rng = np.random.default_rng(len(stem))
    for h, v in rng.integers(0, 36, size=(6, 2)) * 10:
        a = distance_curve(renderer.render(mesh, h, v, shaded=False).mask)
        b = distance_curve(renderer.render(mesh, (h + 180) % 360, (-v) % 360, shaded=False).mask)
        assert rms(b, mirror_curve(a)) < MIRROR_RMS, (h, v)
        fa, fb = fourier_point(a, 8), fourier_point(b, 8)
        np.testing.assert_allclose(np.abs(fa), np.abs(fb), atol=0.05)


def test_mirror_pairs_differ_from_unrelated_views():
    # the tolerance above must separate a mirror pair from merely nearby views
    mesh = load_mesh(sample("car"))
    renderer = get_renderer()
    a = distance_curve(renderer.render(mesh, 30, 20, shaded=False).mask)
    near = distance_curve(renderer.render(mesh, 40, 20, shaded=False).mask)
    assert rms(near, a) > 3 * MIRROR_RMS


def test_flipped_render_is_exactly_the_reversed_curve():
    mesh = load_mesh(sample("arrow"))
    mask = get_renderer().render(mesh, 35, 25, shaded=False).mask
    np.testing.assert_allclose(distance_curve(mask[:, ::-1]), mirror_curve(distance_curve(mask)), atol=1e-12)


@pytest.mark.parametrize("stem", ["car", "chair"])
def test_curve_is_nearly_independent_of_image_size(stem):
    mesh = load_mesh(sample(stem))
    small = distance_curve(get_renderer(RenderConfig(image_size=128)).render(mesh, 60, 30).mask)
    large = distance_curve(get_renderer(RenderConfig(image_size=512)).render(mesh, 60, 30).mask)
    assert rms(small, large) < 0.03
