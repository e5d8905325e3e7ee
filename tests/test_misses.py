"""The miss analysis' parts: filled masks and IoU against oracles, the causes' order, the
twin test on moved copies and on other meshes, and the photo series and true silhouette
the synthetic photo benchmarks share."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.ndimage import binary_fill_holes
from scipy.spatial.transform import Rotation

from tests.conftest import sample
from viewdb.bench.config import MissConfig, TwinConfig
from viewdb.bench.misses import CAUSES, cause_of, filled, iou
from viewdb.bench.photos import draw_photo_spec, photo_series, render_photo, true_silhouette
from viewdb.bench.twins import Twins, normalised_cloud, rigid_alignment, twin_distance
from viewdb.catalogue.mesh import NormalisedMesh, load_mesh

masks = arrays(np.bool_, st.tuples(st.integers(1, 24), st.integers(1, 24)))


@given(masks)
def test_filled_is_scipy_fill_holes(mask: np.ndarray) -> None:
    assert np.array_equal(filled(mask), binary_fill_holes(mask))


def test_filled_fills_a_ring_and_keeps_a_notch_open() -> None:
    ring = np.zeros((9, 9), bool)
    ring[2:7, 2:7] = True
    ring[4, 4] = False
    assert filled(ring)[4, 4]
    notch = ring.copy()
    notch[4, 2:5] = False  # the hole now opens to the outside
    assert not filled(notch)[4, 4]


@given(masks.flatmap(lambda a: st.tuples(st.just(a), arrays(np.bool_, a.shape))))
def test_iou_counts_pixels(pair: tuple[np.ndarray, np.ndarray]) -> None:
    a, b = pair
    both, either = 0, 0
    for x, y in zip(a.ravel(), b.ravel(), strict=True):
        both += bool(x and y)
        either += bool(x or y)
    assert iou(a, b) == pytest.approx(1.0 if either == 0 else both / either)
    assert iou(a, b) == iou(b, a)


def test_iou_refuses_masks_of_different_sizes() -> None:
    with pytest.raises(ValueError, match="different sizes"):
        iou(np.zeros((3, 3), bool), np.zeros((3, 4), bool))


@pytest.mark.parametrize(("twin", "mask_iou", "listed", "cause"), [
    (True, 0.5, None, "twin"),
    (False, 0.5, 1, "segmentation"),
    (False, 0.95, None, "recall"),
    (False, 0.95, 3, "re-ranking"),
    (False, 0.9, 2, "re-ranking"),  # at the threshold the mask is good enough
])
def test_causes_are_tested_in_order(twin: bool, mask_iou: float, listed: int | None, cause: str) -> None:
    assert cause_of(twin, mask_iou, listed, MissConfig().min_iou) == cause
    assert cause in CAUSES


def _moved(mesh: NormalisedMesh, seed: int, mirror: bool) -> NormalisedMesh:
    """The same shape in another frame: turned, shifted, scaled and maybe mirrored."""
    rng = np.random.default_rng(seed)
    m = np.eye(4)
    m[:3, :3] = Rotation.random(random_state=seed).as_matrix() * rng.uniform(0.2, 5.0)
    if mirror:
        m[:3, 0] *= -1
    m[:3, 3] = rng.normal(0.0, 3.0, 3)
    geometry = mesh.geometry.copy()
    geometry.apply_transform(m)
    return NormalisedMesh(f"{mesh.name}_moved", trimesh.Scene(geometry), np.zeros(3), 1.0)


@pytest.mark.parametrize(("stem", "seed", "mirror"), [("l_bracket", 1, False), ("car", 2, True), ("mug", 3, True)])
def test_a_moved_copy_is_a_twin_and_another_mesh_is_not(stem: str, seed: int, mirror: bool) -> None:
    mesh = load_mesh(sample(stem))
    meshes = {m.name: m for m in (mesh, _moved(mesh, seed, mirror), load_mesh(sample("arrow")))}
    twins = Twins(meshes.__getitem__)
    # a mirrored copy's faces turn the other way, so its surface samples are other points
    assert twins.distance(stem, f"{stem}_moved") < 0.02
    assert twins.are_twins(stem, f"{stem}_moved")
    assert twins.distance(stem, "arrow") > 0.1
    assert not twins.are_twins("arrow", stem)
    assert twins.distance(stem, stem) == 0.0


@pytest.mark.parametrize(("stem", "seed"), [("l_bracket", 4), ("car", 5)])
def test_rigid_alignment_finds_the_turn_between_two_frames(stem: str, seed: int) -> None:
    mesh = load_mesh(sample(stem))
    turn = Rotation.random(random_state=seed).as_matrix()
    shift = np.random.default_rng(seed).normal(0.0, 0.05, 3)
    geometry = mesh.geometry.copy()
    geometry.vertices = geometry.vertices @ turn.T + shift  # x -> turn · x + shift
    turned = NormalisedMesh(f"{stem}_turned", trimesh.Scene(geometry), np.zeros(3), 1.0)
    distance, rotation, found_shift = rigid_alignment(mesh, turned)
    assert distance < 0.02
    assert np.linalg.det(rotation) > 0  # a turn, never a mirror
    points = np.asarray(mesh.geometry.vertices)
    np.testing.assert_allclose(points @ rotation + found_shift, points @ turn.T + shift, atol=0.02)


@settings(max_examples=20)
@given(st.integers(0, 2**31 - 1))
def test_normalised_cloud_ignores_the_frame(seed: int) -> None:
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(400, 3)) * [3.0, 1.5, 0.5]
    turn = Rotation.random(random_state=seed).as_matrix()
    a = normalised_cloud(points)
    b = normalised_cloud(points @ turn.T * rng.uniform(0.1, 10.0) + rng.normal(size=3))
    assert np.sqrt((a * a).sum(axis=1).mean()) == pytest.approx(1.0)
    # the same cloud up to the principal axes' signs: the twin distance finds it
    assert twin_distance(a, b, TwinConfig(samples=400, probes=400)) < 1e-6


def test_photo_series_draws_as_the_benchmarks_did() -> None:
    names = [f"object_{i}" for i in range(7)]
    rng = np.random.default_rng(5)
    by_hand = []
    for _ in range(6):
        name = names[rng.integers(len(names))]
        by_hand.append(draw_photo_spec(rng, name))
    assert photo_series(names, 5, 6) == by_hand
    assert photo_series(names, 6, 6) != by_hand


def test_true_silhouette_is_the_photo_s_object() -> None:
    mesh = load_mesh(sample("car"))
    spec = photo_series(["car"], 3, 1)[0]
    photo = render_photo(mesh, spec).astype(np.int16)
    truth = true_silhouette(mesh, spec)
    off = np.abs(photo - np.array(spec.background)).max(axis=2) > 3 * spec.noise + 10
    assert 0.02 < truth.mean() < 0.9
    assert iou(off, truth) > 0.9
    # a silhouette one pixel off would leave a rim of object pixels outside it
    shifted = np.roll(truth, 2, axis=1)
    assert iou(off, shifted) < iou(off, truth) - 0.02
