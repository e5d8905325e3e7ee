"""The real-photo benchmark's ground truth: BOP's ADD / ADD-S, symmetries, and the
visible masks rendered from the poses (``viewdb.bench.groundtruth``)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import trimesh

from viewdb.bench.groundtruth import add_error, load_model, mask_iou, pose_errors, read_frames, visible_masks


def _turn(axis, degrees):
    r, _ = cv2.Rodrigues(np.asarray(axis, np.float64) * np.radians(degrees))
    return r


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("gt")
    cylinder = folder / "cylinder.ply"
    trimesh.creation.cylinder(radius=0.03, height=0.1, sections=64).export(cylinder)
    block = folder / "block.ply"
    trimesh.creation.box(extents=(0.04, 0.06, 0.1)).export(block)
    wedge = folder / "wedge.ply"
    trimesh.Trimesh([[0, 0, 0], [0.08, 0, 0], [0, 0.05, 0], [0, 0, 0.03]],
                    [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]).export(wedge)
    return folder, cylinder, block, wedge


def test_add_measures_how_far_the_points_move(meshes):
    _, _, _, wedge = meshes
    model = load_model(wedge)
    r, t = _turn((0.2, 0.5, 0.1), 40), np.array([0.01, -0.02, 0.5])
    assert add_error(model, r, t, r, t, symmetric=False) == pytest.approx(0.0, abs=1e-12)
    shift = np.array([0.003, 0.0, 0.004])
    assert add_error(model, r, t + shift, r, t, symmetric=False) == pytest.approx(0.005)
    turned = r @ _turn((0, 0, 1), 30)
    assert add_error(model, turned, t, r, t, symmetric=True) < add_error(model, turned, t, r, t, symmetric=False)
    assert not model.symmetry.symmetric


def test_a_cylinder_turned_about_its_axis_is_the_same_pose(meshes):
    _, cylinder, _, _ = meshes
    model = load_model(cylinder)
    assert model.symmetry.axis is not None and abs(model.symmetry.axis[2]) > 0.99
    assert model.diameter == pytest.approx(np.hypot(0.06, 0.1), rel=1e-3)
    r, t = np.eye(3), np.array([0.0, 0.0, 0.6])
    spun = _turn((0, 0, 1), 75)
    assert add_error(model, spun, t, r, t, symmetric=True) < 0.002 < add_error(model, spun, t, r, t, False)
    # the axes are the sampled surface's principal axes: within a degree of the true ones
    assert pose_errors(model.symmetry, spun, t, r, t)["rotation_deg"] < 1.0
    tilted = _turn((1, 0, 0), 20)
    assert pose_errors(model.symmetry, tilted, t, r, t)["rotation_deg"] == pytest.approx(20.0, abs=1.0)


def test_the_box_has_its_half_turns(meshes):
    _, _, block, _ = meshes
    sym = load_model(block).symmetry
    assert sym.axis is None and len(sym.group) == 4  # identity and a half turn about each axis
    r, t = np.eye(3), np.zeros(3)
    assert pose_errors(sym, _turn((0, 1, 0), 180), t, r, t)["rotation_deg"] < 1.0
    assert pose_errors(sym, _turn((0, 1, 0), 90), t, r, t)["rotation_deg"] == pytest.approx(90.0, abs=1.0)


def test_a_hidden_object_is_visible_only_where_nothing_is_in_front(meshes):
    """Two blocks on the optical axis, one in front of the other: the one behind is seen
    only around the one in front, within its visible box."""
    folder, _, block, _ = meshes
    k = [[500.0, 0, 160], [0, 500.0, 120], [0, 0, 1]]
    near = {"name": "near", "mesh": block.name, "R": np.eye(3).tolist(), "t": [0.0, 0.0, 0.5],
            "bbox_visib_xywh": [0, 0, 320, 240]}
    far = {**near, "name": "far", "t": [0.02, 0.0, 0.8]}
    (folder / "gt.json").write_text(json.dumps({"frames": {"000001": {
        "color": "x.png", "K": k, "width": 320, "height": 240, "objects": [near, far]}}}))
    frame, = read_frames(folder)
    (near_whole, near_seen), (far_whole, far_seen) = visible_masks(frame)
    assert mask_iou(near_whole, near_seen) == 1.0
    ys, xs = np.nonzero(near_whole)  # its front face, 0.04 x 0.06 at 0.45 m: 44.4 x 66.7 pixels
    assert abs((xs.max() - xs.min() + 1) - 44.4) <= 1.5 and abs((ys.max() - ys.min() + 1) - 66.7) <= 1.5
    assert not (far_seen & near_whole).any()
    assert far_seen.any() and np.count_nonzero(far_seen) < np.count_nonzero(far_whole)
