import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from viewdb.camera import (
    camera_direction,
    camera_pose,
    grid_views,
    normalise_angle,
    pixel_rays_to_camera,
    rotation_x,
    rotation_y,
    sphere_views,
)

angles = st.floats(0, 360, exclude_max=True, allow_nan=False)


def test_rotations_are_right_handed():
    # a right-handed rotation by 90° about +Y takes +Z to +X; about +X takes +Y to +Z
    np.testing.assert_allclose(rotation_y(90) @ [0, 0, 1], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(rotation_x(90) @ [0, 1, 0], [0, 0, 1], atol=1e-12)


@given(angles, angles)
def test_pose_is_rigid_and_camera_sits_on_its_direction(h, v):
    pose = camera_pose(h, v, 3.0)
    rot = pose[:3, :3]
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rot) == pytest.approx(1.0)
    np.testing.assert_allclose(pose[:3, 3], 3.0 * camera_direction(h, v), atol=1e-12)
    # the camera looks down its -Z axis, i.e. at the origin
    np.testing.assert_allclose(rot @ [0, 0, -1], -camera_direction(h, v), atol=1e-12)


@given(angles, angles)
def test_opposite_view_shares_the_up_vector_and_flips_right(h, v):
    a, b = camera_pose(h, v)[:3, :3], camera_pose(h + 180, -v)[:3, :3]
    np.testing.assert_allclose(b @ [0, 0, 1], -(a @ [0, 0, 1]), atol=1e-12)  # opposite
    np.testing.assert_allclose(b @ [0, 1, 0], a @ [0, 1, 0], atol=1e-12)  # same up
    np.testing.assert_allclose(b @ [1, 0, 0], -(a @ [1, 0, 0]), atol=1e-12)  # mirrored


@given(angles, angles)
def test_reflective_view_is_same_direction_turned_180(h, v):
    a, b = camera_pose(h, v)[:3, :3], camera_pose(h + 180, 180 - v)[:3, :3]
    np.testing.assert_allclose(b @ [0, 0, 1], a @ [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(b @ [0, 1, 0], -(a @ [0, 1, 0]), atol=1e-12)


def test_documented_special_views():
    np.testing.assert_allclose(camera_direction(0, 0), [0, 0, 1], atol=1e-12)  # front
    np.testing.assert_allclose(camera_direction(90, 0), [1, 0, 0], atol=1e-12)  # towards +X
    np.testing.assert_allclose(camera_direction(0, 90), [0, 1, 0], atol=1e-12)  # top


@pytest.mark.parametrize("gap", [10, 20, 30, 40, 45, 60, 90])
def test_grid_has_360_over_gap_squared_views(gap):
    views = grid_views(gap)
    assert len(views) == (360 // gap) ** 2 == len(set(views))
    assert all(0 <= h < 360 and 0 <= v < 360 for h, v in views)


def test_grid_rejects_gaps_that_do_not_divide_360():
    with pytest.raises(ValueError):
        grid_views(7)
    with pytest.raises(ValueError):
        sphere_views(7)


def _directions(views):
    return np.array([camera_direction(h, v) for h, v in views])


@pytest.mark.parametrize("gap", [5, 10, 15, 20, 30, 45, 90])
def test_sphere_views_are_grid_views_each_direction_once_and_upright(gap):
    views = sphere_views(gap)
    assert len(set(views)) == len(views) and set(views) <= set(grid_views(gap))
    assert all(v <= 90 or v >= 270 for _, v in views)  # |elevation| <= 90: an upright camera
    directions = _directions(views)
    off_pole = np.abs(directions[:, 1]) < 1 - 1e-9  # at a pole every azimuth is one position
    cos = directions[off_pole] @ directions[off_pole].T
    np.fill_diagonal(cos, -1)
    assert cos.max() < 1 - 1e-9


@given(st.floats(-1, 1), st.floats(0, 2 * np.pi), st.sampled_from([5, 10, 20, 30]))
def test_sphere_views_cover_every_direction_almost_as_closely_as_the_square_grid(y, phi, gap):
    r = np.sqrt(1 - y * y)
    direction = np.array([r * np.sin(phi), y, r * np.cos(phi)])
    nearest = {name: np.degrees(np.arccos(np.clip((_directions(f(gap)) @ direction).max(), -1, 1)))
               for name, f in (("sphere", sphere_views), ("square", grid_views))}
    assert nearest["square"] <= 0.71 * gap
    assert nearest["sphere"] <= 0.71 * gap


@pytest.mark.parametrize("gap", [5, 10, 20])
def test_sphere_views_are_far_fewer_than_the_square_grid(gap):
    assert len(sphere_views(gap)) < 0.4 * len(grid_views(gap))


def test_normalise_angle():
    assert normalise_angle(-10) == 350
    assert normalise_angle(720) == 0
    assert normalise_angle(359.9999999999) == 0


def test_pixel_centres_are_symmetric_about_the_optical_axis():
    pts = pixel_rays_to_camera(np.array([0, 255]), np.array([0, 255]), np.array([3.0, 3.0]), 256)
    np.testing.assert_allclose(pts[0, :2], -pts[1, :2])
    assert pts[0, 0] == pytest.approx(-1 + 1 / 256) and pts[0, 1] == pytest.approx(1 - 1 / 256)
