"""SIFT features of shaded views: compact storage and 2-D–3-D correspondences."""

import cv2
import numpy as np
import pytest
import trimesh

from tests.conftest import sample
from viewdb.catalogue.mesh import load_mesh
from viewdb.catalogue.render import get_renderer
from viewdb.catalogue.sift import extract_sift, lift_points
from viewdb.config import RenderConfig


@pytest.fixture(scope="module")
def mug_view():
    mesh = load_mesh(sample("mug"))
    return mesh, get_renderer().render(mesh, 20, 15)


def test_opencv_sift_descriptors_are_integers_so_uint8_is_lossless(mug_view):
    _, view = mug_view
    gray = cv2.cvtColor(view.color, cv2.COLOR_RGB2GRAY)
    _, raw = cv2.SIFT_create(nfeatures=128).detectAndCompute(gray, view.mask.astype(np.uint8))
    assert raw is not None and len(raw) > 20
    assert raw.min() >= 0 and raw.max() <= 255
    np.testing.assert_array_equal(raw, np.rint(raw))  # integral floats
    _, stored = extract_sift(view.color, view.mask, 128)
    assert stored.dtype == np.uint8
    # whatever subset extract_sift keeps, each stored descriptor is one of OpenCV's, exactly
    raw_set = {r.astype(np.uint8).tobytes() for r in raw}
    assert sum(d.tobytes() in raw_set for d in stored) >= 0.9 * len(stored)


def test_keypoints_are_capped_and_inside_the_silhouette(mug_view):
    _, view = mug_view
    kps, desc = extract_sift(view.color, view.mask, 16)
    assert 0 < len(kps) <= 16 and desc.shape == (len(kps), 128)
    cols, rows = np.rint(kps[:, 0]).astype(int), np.rint(kps[:, 1]).astype(int)
    assert view.mask[rows, cols].mean() > 0.9


def test_textureless_flat_view_stores_an_empty_set():
    image = np.full((64, 64, 3), 120, np.uint8)
    mask = np.zeros((64, 64), bool)
    mask[16:48, 16:48] = True
    kps, desc = extract_sift(image * mask[:, :, None], mask, 64)
    assert kps.shape[1] == 5 and desc.shape == (len(kps), 128)
    kps, desc = extract_sift(image, np.zeros((64, 64), bool), 64)
    assert kps.shape == (0, 5) and desc.shape == (0, 128)


def test_lifted_keypoints_lie_on_the_model(mug_view):
    mesh, view = mug_view
    kps, _ = extract_sift(view.color, view.mask, 128)
    points, valid = lift_points(kps[:, :2], view.depth, view.pose, 1.0)
    assert valid.mean() > 0.95
    _, dist, _ = trimesh.proximity.closest_point(mesh.geometry, points[valid])
    pixel = 2.0 / view.image_size
    assert np.median(dist) < 0.5 * pixel and np.percentile(dist, 90) < 3 * pixel


def test_lifted_points_reproject_to_their_keypoints():
    mesh = load_mesh(sample("car"))
    cfg = RenderConfig(image_size=200)
    view = get_renderer(cfg).render(mesh, 300, 25)
    kps, _ = extract_sift(view.color, view.mask, 64)
    points, valid = lift_points(kps[:, :2], view.depth, view.pose, cfg.xmag)
    cam = (points[valid] - view.pose[:3, 3]) @ view.pose[:3, :3]  # world -> camera
    u = (cam[:, 0] + 1) * cfg.image_size / 2 - 0.5
    w = (1 - cam[:, 1]) * cfg.image_size / 2 - 0.5
    err = np.hypot(u - kps[valid, 0], w - kps[valid, 1])
    assert np.max(err) <= 0.75  # nearest-pixel depth: within the pixel
