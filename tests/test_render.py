"""The camera convention, checked from rendered images of the marked cube and others."""

import cv2
import numpy as np
import pytest
import trimesh

from tests.conftest import sample
from viewdb.catalogue.mesh import load_mesh
from viewdb.catalogue.render import get_renderer
from viewdb.catalogue.sift import lift_points
from viewdb.config import RenderConfig

RED, GREEN, BLUE = (255, 0, 0), (0, 255, 0), (0, 0, 255)
CYAN, MAGENTA, YELLOW = (0, 255, 255), (255, 0, 255), (255, 255, 0)


@pytest.fixture(scope="module")
def cube():
    return load_mesh(sample("marked_cube"))


def hue_of(pixel):
    """The pure colour a lit pixel came from (shading only scales it)."""
    p = np.asarray(pixel, float)
    return tuple(int(c) for c in np.where(p > 0.5 * p.max(), 255, 0))


def centre(view):
    s = view.image_size // 2
    return view.color[s, s]


@pytest.mark.parametrize(
    "h, v, colour",
    [(0, 0, RED), (90, 0, GREEN), (180, 0, CYAN), (270, 0, MAGENTA), (0, 90, BLUE), (0, 270, YELLOW)],
)
def test_the_face_seen_at_each_axis_view(cube, h, v, colour):
    view = get_renderer().render(cube, h, v)
    assert hue_of(centre(view)) == colour


def test_growing_azimuth_orbits_towards_plus_x(cube):
    # at h = 30 the camera is between +Z (red) and +X (green); +X lies on the image's right
    view = get_renderer().render(cube, 30, 0)
    row = view.color[view.image_size // 2]
    cols = np.flatnonzero(view.mask[view.image_size // 2])
    left, right = row[cols[3]], row[cols[-4]]
    assert hue_of(left) == RED and hue_of(right) == GREEN


def test_top_is_up_and_front_is_down_in_a_high_view(cube):
    # from (0, 60) the top face (blue) is at the image's top and the front (red) below it
    view = get_renderer().render(cube, 0, 60)
    s = view.image_size // 2
    rows = np.flatnonzero(view.mask[:, s])
    assert hue_of(view.color[rows[3], s]) == BLUE
    assert hue_of(view.color[rows[-4], s]) == RED


@pytest.mark.parametrize("stem", ["l_bracket", "car", "arrow"])
@pytest.mark.parametrize("h, v", [(0, 0), (40, 20), (130, 310), (250, 80)])
def test_opposite_view_has_the_mirrored_silhouette(stem, h, v):
    mesh = load_mesh(sample(stem))
    r = get_renderer()
    a = r.render(mesh, h, v).mask
    b = r.render(mesh, (h + 180) % 360, (-v) % 360).mask[:, ::-1]
    # exact up to the rasteriser's tie rule for edges that fall on pixel centres, which
    # is not mirror-symmetric: every difference lies on the silhouette's one-pixel rim
    kernel = np.ones((3, 3), np.uint8)
    rim = cv2.dilate(a.astype(np.uint8), kernel) != cv2.erode(a.astype(np.uint8), kernel)
    assert not np.any((a ^ b) & ~rim)
    assert (a ^ b).sum() <= 0.05 * a.sum()


def test_depth_lifts_pixels_onto_the_mesh_surface():
    mesh = load_mesh(sample("l_bracket"))
    cfg = RenderConfig(image_size=128)
    view = get_renderer(cfg).render(mesh, 35, 25)
    rng = np.random.default_rng(0)
    rows, cols = np.nonzero(view.mask)
    pick = rng.choice(len(rows), 200, replace=False)
    xy = np.stack([cols[pick], rows[pick]], axis=1).astype(float)
    points, valid = lift_points(xy, view.depth, view.pose, cfg.xmag)
    assert valid.all()
    _, dist, _ = trimesh.proximity.closest_point(mesh.geometry, points)
    pixel = 2.0 / cfg.image_size
    assert np.median(dist) < 0.1 * pixel and dist.max() < 2 * pixel


def test_depth_only_render_gives_the_same_silhouette(cube):
    r = get_renderer()
    full, fast = r.render(cube, 20, 30), r.render(cube, 20, 30, shaded=False)
    np.testing.assert_array_equal(full.mask, fast.mask)
    np.testing.assert_array_equal(full.depth, fast.depth)
    assert not fast.color.any()


def test_shading_darkens_faces_turned_away_from_the_camera(cube):
    # at (30, 0) the red face is turned 30° away, the green face 60°: green is darker
    view = get_renderer().render(cube, 30, 0)
    s = view.image_size // 2
    cols = np.flatnonzero(view.mask[s])
    red_level = view.color[s, cols[3]].max()
    green_level = view.color[s, cols[-4]].max()
    assert green_level < red_level
    assert red_level == pytest.approx(255 * (0.3 + 0.7 * np.cos(np.radians(30))), abs=6)


def test_back_faces_are_drawn_in_both_render_modes(tmp_path):
    # an open shell: one triangle facing +Z; from behind (h = 180) only its back is seen
    tri = trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [0, 1, 0.2]], [[0, 1, 2]], process=False)
    path = tmp_path / "tri.ply"
    tri.export(path)
    mesh = load_mesh(path)
    r = get_renderer()
    front, back = r.render(mesh, 0, 0, shaded=False).mask, r.render(mesh, 180, 0, shaded=False).mask
    assert back.sum() > 1000
    np.testing.assert_array_equal(back, r.render(mesh, 180, 0).mask)
    np.testing.assert_array_equal(back, front[:, ::-1])


def test_coplanar_parts_render_the_same_every_time(tmp_path):
    # two parts of different colours sharing one plane (z-fighting): whichever is drawn
    # last wins, so the draw order must not depend on anything that changes between
    # renders (pyrender draws a scene's meshes in set order)
    scene = trimesh.Scene()
    for i, colour in enumerate(([255, 0, 0, 255], [0, 0, 255, 255], [0, 255, 0, 255])):
        part = trimesh.creation.box((1.0, 1.0, 0.2))
        part.visual.face_colors = colour
        scene.add_geometry(part, node_name=f"part{i}")
    path = tmp_path / "coplanar.glb"
    scene.export(path)
    mesh = load_mesh(path)
    renderer = get_renderer(RenderConfig(image_size=64))
    first = renderer.render(mesh, 0, 0).color
    for _ in range(8):
        renderer._mesh = None  # a new GL scene of the same mesh, as after rendering another
        assert np.array_equal(renderer.render(mesh, 0, 0).color, first)
