"""Colour signatures and the colour re-ranking of query results (viewdb.recognition.colour)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import trimesh
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import viewdb
from tests.conftest import sample
from viewdb.bench.photos import composite_photo
from viewdb.config import BuildConfig, IndexConfig, RecognitionConfig, RenderConfig
from viewdb.http.wire import ColourReply, ColourRequest
from viewdb.recognition.colour import (
    carries_colour,
    colour_distance,
    colour_signature,
    core_signature,
    has_colour,
    rerank,
)


def patch(rgb: tuple[int, int, int], size: int = 48) -> tuple[np.ndarray, np.ndarray]:
    img = np.zeros((size, size, 3), np.uint8)
    img[:] = rgb
    mask = np.zeros((size, size), bool)
    mask[8:-8, 8:-8] = True
    return img, mask


def test_a_signature_is_a_distribution_and_equal_colours_are_at_distance_zero():
    img, mask = patch((200, 40, 30))
    s = colour_signature(img, mask)
    assert s.shape == (16, 16) and s.dtype == np.float32
    assert s.sum() == pytest.approx(1.0, abs=1e-5) and (s >= 0).all()
    assert colour_distance(s, colour_signature(img, mask)) == pytest.approx(0.0, abs=1e-6)
    for primary in ((255, 0, 0), (0, 255, 0), (0, 0, 255)):  # the range's edges count
        assert colour_signature(*patch(primary)).sum() == pytest.approx(1.0, abs=1e-5)


def test_pixels_off_the_mask_do_not_count():
    img, mask = patch((200, 40, 30))
    other = img.copy()
    other[~mask] = (20, 40, 220)  # a blue background around the same red object
    assert colour_distance(colour_signature(img, mask), colour_signature(other, mask)) < 0.05


def _ringed(width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A red disc cut out with a ring of blue background ``width`` pixels wide: the
    photo, the cut-out (disc and ring) and the disc alone."""
    img = np.zeros((120, 120, 3), np.uint8)
    img[:] = (20, 40, 220)
    disc = np.zeros((120, 120), np.uint8)
    cv2.circle(disc, (60, 60), 40, 1, -1)
    img[disc > 0] = (200, 40, 30)
    cut = np.zeros((120, 120), np.uint8)
    cv2.circle(cut, (60, 60), 40 + width, 1, -1)
    return img, cut > 0, disc > 0


def test_a_core_signature_leaves_the_cut_outs_rim_out():
    img, cut, disc = _ringed(6)
    truth = colour_signature(img, disc)
    whole, core = colour_signature(img, cut), core_signature(img, cut, 0.1)  # erodes 9 pixels
    assert colour_distance(core, truth) < 0.02 < colour_distance(whole, truth)
    assert colour_distance(core_signature(img, cut, 0.0), whole) == pytest.approx(0.0, abs=1e-6)


def _whole_photo_signature(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """:func:`colour_signature`'s definition, read over the whole photo."""
    from viewdb.catalogue.appearance import BINS, DARK_SUM, MIN_PIXELS, TOP

    inner = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    inner = inner if np.count_nonzero(inner) >= MIN_PIXELS else mask
    x = rgb.astype(np.float32)
    total = x.sum(axis=2)
    lit = inner & (total >= DARK_SUM)
    inner = lit if np.count_nonzero(lit) >= MIN_PIXELS else inner
    chroma = np.ascontiguousarray(x[:, :, :2] / np.maximum(total, 1.0)[:, :, None])
    hist = cv2.GaussianBlur(cv2.calcHist([chroma], [0, 1], inner.astype(np.uint8), [BINS, BINS], [0.0, TOP, 0.0, TOP]),
                            (3, 3), 0)
    return (hist / hist.sum()).astype(np.float32)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(-30, 230), st.integers(-30, 190), st.sampled_from([0.0, 0.1, 0.3]))
def test_a_cut_out_s_colours_are_read_as_from_the_whole_photo(seed, cx, cy, share):
    """Read from the mask's own box (a large photo costs the cut-out's size), a cut-out's
    signature and core signature are those of the whole photo, at its edges too."""
    from viewdb.recognition.colour import CORE_MIN_PIXELS

    rng = np.random.default_rng(seed)
    rgb = rng.integers(0, 256, (200, 220, 3), dtype=np.uint8)
    drawn = np.zeros((200, 220), np.uint8)
    cv2.ellipse(drawn, (cx, cy), (int(rng.integers(8, 40)), int(rng.integers(8, 40))), float(rng.uniform(0, 180)),
                0, 360, 1, -1)
    mask = drawn > 0
    assume(mask.sum() >= 30)
    np.testing.assert_array_equal(colour_signature(rgb, mask), _whole_photo_signature(rgb, mask))
    radius = int(round(share * np.sqrt(mask.sum())))
    core = mask
    if radius > 0:
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
        eroded = cv2.erode(mask.astype(np.uint8), disc).astype(bool)
        core = eroded if eroded.sum() >= CORE_MIN_PIXELS else mask
    np.testing.assert_array_equal(core_signature(rgb, mask, share), _whole_photo_signature(rgb, core))


def test_a_large_photo_s_colour_is_told_from_a_share_of_its_pixels():
    """A 12-megapixel photo is read at every 4th row and column: a grey one has no colour,
    the same with a coloured object on 2 % of it has."""
    grey = np.full((3000, 4000, 3), 128, np.uint8)
    assert not has_colour(grey)
    grey[1000:1245, 1000:1980] = (180, 60, 40)
    assert has_colour(grey)


def test_a_core_too_small_falls_back_to_the_whole_cut_out():
    img = np.zeros((20, 20, 3), np.uint8)
    img[:] = (200, 40, 30)
    mask = np.zeros((20, 20), bool)
    mask[5:12, 5:12] = True  # 49 pixels: any erosion leaves fewer than CORE_MIN_PIXELS
    assert np.array_equal(core_signature(img, mask, 0.5), colour_signature(img, mask))


@pytest.mark.parametrize("share", [-0.1, 0.6])
def test_a_core_share_outside_its_range_is_refused(share):
    with pytest.raises(ValueError, match="colour_core"):
        RecognitionConfig(colour_core=share)


@settings(max_examples=40, deadline=None)
@given(hue=st.integers(0, 179), light=st.floats(0.45, 1.0))
def test_darker_light_keeps_a_colour_and_another_hue_is_far(hue, light):
    """Lightness is left out: the same paint under dimmer light stays close, while the
    opposite hue (same saturation and value) is far."""
    def paint(h: int, value: float) -> np.ndarray:
        hsv = np.uint8([[[h, 230, round(255 * value)]]])
        return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0, 0]

    base, mask = patch(tuple(int(x) for x in paint(hue, 1.0)))
    dim, _ = patch(tuple(int(x) for x in paint(hue, light)))
    opposite, _ = patch(tuple(int(x) for x in paint((hue + 90) % 180, 1.0)))
    s = colour_signature(base, mask)
    near = colour_distance(s, colour_signature(dim, mask))
    far = colour_distance(s, colour_signature(opposite, mask))
    assert near < far and far > 0.6


def test_an_empty_signature_shares_nothing():
    img, mask = patch((10, 200, 10))
    empty = colour_signature(img, np.zeros_like(mask))
    assert not empty.any()
    assert colour_distance(empty, colour_signature(img, mask)) == 1.0


def test_grey_images_have_no_colour():
    grey = np.dstack([np.tile(np.arange(64, dtype=np.uint8) * 4, (64, 1))] * 3)
    assert not has_colour(grey)
    assert not has_colour(grey[:, :, 0])
    tinted = grey.copy()
    tinted[20:40, 20:40] = (180, 60, 40)
    assert has_colour(tinted)


def test_colour_messages_round_trip_and_reject_bad_input():
    views = [("mug", 30.0, -20.0), ("car", 0.0, 10.0)]
    assert ColourRequest.from_dict(ColourRequest(views).to_dict()).views == views
    sigs = [colour_signature(*patch((200, 40, 30))), colour_signature(*patch((30, 40, 200)))]
    back = ColourReply.from_dict(ColourReply(sigs, {"server_ms": 1.0}).to_dict())
    assert all(np.array_equal(a, b) for a, b in zip(back.signatures, sigs, strict=True))
    for bad in ({}, {"views": []}, {"views": [{"object": "mug", "azimuth": "x", "elevation": 0}]},
                {"views": [{"object": 3, "azimuth": 0, "elevation": 0}]},
                {"views": [{"object": "mug", "azimuth": 0}]}):
        with pytest.raises(viewdb.QueryError):
            ColourRequest.from_dict(bad)
    for bad in ({}, {"signatures": [[0.5] * 3]}, {"signatures": [[-1.0] * 256]},
                {"signatures": [[float("nan")] * 256]}):
        with pytest.raises(viewdb.QueryError):
            ColourReply.from_dict(bad)


# ------------------------------------------------------------------- re-ranking queries
@pytest.fixture(scope="module")
def twins_db(tmp_path_factory):
    """The same bracket twice, painted red (``a_red``) and blue (``b_blue``): equal
    outlines from every side, so only colour tells them apart."""
    folder = tmp_path_factory.mktemp("twins")
    paths = []
    for name, rgba in (("a_red", (210, 30, 30, 255)), ("b_blue", (30, 60, 210, 255))):
        mesh = trimesh.load(sample("l_bracket"), force="mesh")
        mesh.visual = trimesh.visual.ColorVisuals(mesh, face_colors=np.tile(rgba, (len(mesh.faces), 1)))
        path = folder / f"{name}.ply"
        mesh.export(path)
        paths.append(path)
    db_path = folder / "twins.db"
    config = BuildConfig(gap=30, render=RenderConfig(image_size=96), index=IndexConfig(client_gap=90))
    with viewdb.open(db_path, config=config) as db:
        report = db.ingest(paths)
    assert not report.failed, report.failed
    return db_path


def _photo(db, name, h, v):
    return composite_photo(db.render(name, h, v), background=170)[0]


def test_colour_tells_apart_objects_of_the_same_shape(twins_db):
    with viewdb.open(twins_db, read_only=True) as db:
        img = _photo(db, "b_blue", 47, 22)
        outline = db.query(img, k=2, rotations=4, pose=False, colour=False)
        coloured = db.query(img, k=2, rotations=4, pose=False)
    # by outline alone the twins tie, and the name breaks the tie: the wrong one first
    assert [m.object for m in outline.results] == ["a_red", "b_blue"]
    assert outline.results[0].distance == pytest.approx(outline.results[1].distance, rel=1e-6)
    assert all(m.colour is None for m in outline.results)
    # with colour the photographed one wins; distances stay the outline's
    assert [m.object for m in coloured.results] == ["b_blue", "a_red"]
    assert coloured.results[0].colour < 0.3 < coloured.results[1].colour
    assert coloured.results[0].distance == pytest.approx(outline.results[1].distance)
    assert coloured.results[0].score < coloured.results[1].score
    assert coloured.timing_ms["colour"] > 0


def test_a_grey_photo_is_ranked_by_outline_alone(twins_db):
    with viewdb.open(twins_db, read_only=True) as db:
        grey = cv2.cvtColor(cv2.cvtColor(_photo(db, "b_blue", 47, 22), cv2.COLOR_RGB2GRAY),
                            cv2.COLOR_GRAY2RGB)
        result = db.query(grey, k=2, rotations=4, pose=False)
    assert [m.object for m in result.results] == ["a_red", "b_blue"]
    assert all(m.colour is None for m in result.results)


def test_k_one_still_re_ranks_among_the_pool(twins_db):
    """With k = 1 the plan still finds the colour pool's objects, so the photographed
    twin, second by outline, is the one answer."""
    with viewdb.open(twins_db, read_only=True) as db:
        result = db.query(_photo(db, "b_blue", 200, -30), k=1, rotations=4, pose=False)
    assert [m.object for m in result.results] == ["b_blue"]


def test_view_colours_of_an_unknown_object_is_a_clear_error(twins_db):
    with viewdb.open(twins_db, read_only=True) as db, pytest.raises(viewdb.NotFound, match="nope"):
        db.server_tier().view_colours([("nope", 0.0, 0.0)])


def test_a_result_without_colour_counts_as_the_pools_mean_mismatch():
    red = colour_signature(*patch((210, 30, 30)))
    blue = colour_signature(*patch((30, 60, 210)))
    # outline distances 1.0, 1.1, 1.2: the red one matches, the blue one does not, the
    # third has no colour and is scored with the mean of the two colour distances
    order, colours, scores = rerank([1.0, 1.1, 1.2], blue, [red, blue, None])
    assert colours[2] is None and colours[1] == pytest.approx(0.0, abs=1e-6) and colours[0] > 0.9
    neutral = (colours[0] + colours[1]) / 2
    expected = [1.0 * (1 + colours[0]), 1.1 * (1 + colours[1]), 1.2 * (1 + neutral)]
    assert scores == pytest.approx(expected)
    assert order == sorted(range(3), key=lambda i: expected[i])
    assert rerank([1.0, 0.5], blue, [None, None]) == ([1, 0], [None, None], [1.0, 0.5])


def test_only_meshes_with_colour_of_their_own_carry_colour(twins_db, tiered_db):
    with viewdb.open(twins_db, read_only=True) as db:
        assert carries_colour(db.mesh("b_blue"))
    with viewdb.open(tiered_db, read_only=True) as db:
        assert not carries_colour(db.mesh("l_bracket"))  # an STL: no colour at all
        assert db.server_tier().view_colours([("l_bracket", 0.0, 0.0)]) == [None]
        assert carries_colour(db.mesh("mug"))


# ---------------------------------------------------------------- busy surroundings
def test_surround_spread_tells_a_plain_table_from_a_cluttered_desk():
    """The ring around a box: a plain, lightly noisy table reads under the
    ``busy_surround`` threshold, a patchwork of other objects' colours above it; the box's
    own pixels never count, and a box at the photo's edge is measured on what is left."""
    from viewdb.bench.photos import table_photo
    from viewdb.recognition.regions import surround_spread

    threshold = RecognitionConfig().busy_surround
    plain, _ = table_photo([], (320, 240), [])
    box = (120, 80, 200, 160)
    assert surround_spread(plain, box) < threshold
    rng = np.random.default_rng(3)
    patches = rng.integers(0, 256, (12, 16, 3), dtype=np.uint8)
    busy = np.asarray(cv2.resize(patches, (320, 240), interpolation=cv2.INTER_NEAREST), np.uint8)
    assert surround_spread(busy, box) > threshold
    # whatever the box holds, only its ring counts
    inside = busy.copy()
    inside[80:160, 120:200] = plain[80:160, 120:200]
    assert surround_spread(inside, box) == pytest.approx(surround_spread(busy, box))
    edged = plain.copy()
    edged[80:160, 120:200] = busy[80:160, 120:200]
    assert surround_spread(edged, box) < threshold
    assert surround_spread(busy, (0, 0, 40, 30)) > threshold  # clipped at the corner
    assert surround_spread(plain, (0, 0, 320, 240)) == 0.0  # no ring at all


@pytest.mark.parametrize("name", ["prompt_outline_weight", "busy_outline_weight", "busy_surround"])
def test_outline_weights_cannot_be_negative(name):
    with pytest.raises(ValueError, match=name):
        RecognitionConfig(**{name: -0.1})
