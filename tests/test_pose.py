"""Pose estimation (viewdb.pose): the rotation convention, SIFT poses off the grid, PnP with
intrinsics, the silhouette fallback for texture-less objects, and the errors."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import viewdb
from tests.conftest import sample
from viewdb.camera import camera_direction, camera_pose, grid_views, normalise_angle
from viewdb.catalogue.sift import extract_sift
from viewdb.errors import PoseError
from viewdb.pose.estimate import CandidateView, PoseConfig, QueryView, estimate_pose
from viewdb.pose.frames import (
    GL_TO_CV,
    inplane_angle,
    rotation_angle,
    rotation_to_view,
    rotation_z,
    view_rotation,
)
from viewdb.pose.solvers import solve_pnp

GAP = 30
SIZE = 256
#: Query images are not square and not the views' size, to exercise the scale convention.
QUERY_W, QUERY_H = 300, 260

angles = st.floats(min_value=-720.0, max_value=720.0, allow_nan=False)


def angle_gap(a: float, b: float) -> float:
    d = abs(a - b) % 360.0
    return min(d, 360.0 - d)


# ---------------------------------------------------------------------- rotations
@given(angles, angles)
def test_view_rotation_is_the_inverse_of_the_camera_pose(h, v):
    pose = camera_pose(h, v)
    rot = view_rotation(h, v)
    np.testing.assert_allclose(rot, pose[:3, :3].T, atol=1e-12)
    # model-to-camera of the pose: the model origin sits at (0, 0, -3) in front of the camera
    world_to_camera = np.linalg.inv(pose)
    np.testing.assert_allclose(world_to_camera[:3, 3], [0.0, 0.0, -3.0], atol=1e-9)
    np.testing.assert_allclose(world_to_camera[:3, :3], rot, atol=1e-9)
    # the camera direction maps to the camera's +Z (it looks down -Z at the model)
    np.testing.assert_allclose(rot @ camera_direction(h, v), [0.0, 0.0, 1.0], atol=1e-12)


@given(angles, angles, angles)
def test_rotation_to_view_round_trips(h, v, a):
    rot = view_rotation(h, v, a)
    h2, v2, a2 = rotation_to_view(rot)
    assert all(0.0 <= x < 360.0 for x in (h2, v2, a2))
    np.testing.assert_allclose(view_rotation(h2, v2, a2), rot, atol=1e-9)
    assert math.cos(math.radians(v2)) >= -1e-12
    if abs(math.cos(math.radians(v))) > 1e-3:  # away from straight up/down h and a are unique
        same = (angle_gap(h2, h), angle_gap(v2, v), angle_gap(a2, a))
        turned = (angle_gap(h2, h + 180), angle_gap(v2, 180 - v), angle_gap(a2, a + 180))
        assert max(same) < 1e-6 or max(turned) < 1e-6
    # with a reference the triple nearer it is chosen, e.g. the one given
    if abs(math.cos(math.radians(v))) > 1e-3:
        h3, v3, a3 = rotation_to_view(rot, reference=(h, v))
        assert max(angle_gap(h3, h), angle_gap(v3, v), angle_gap(a3, a)) < 1e-6


@given(st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=4, max_size=4)
       .filter(lambda q: np.linalg.norm(q) > 0.1))
def test_any_rotation_decomposes(q):
    w, x, y, z = np.asarray(q) / np.linalg.norm(q)
    rot = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    np.testing.assert_allclose(view_rotation(*rotation_to_view(rot)), rot, atol=1e-9)


@given(st.floats(-180, 180), st.floats(0, 359), st.floats(-80, 80))
def test_inplane_angle_is_counter_clockwise_on_screen(alpha, h, v):
    """R_z(α)·R_viewᵀ projects a model point where cv2's counter-clockwise rotation by α of
    the view image puts it (pixel conventions of the README)."""
    points = np.array([[0.3, -0.5, 0.2], [-0.7, 0.1, 0.4], [0.0, 0.6, -0.6]])

    def pixels(rot):
        cam = points @ rot.T
        return np.stack([(cam[:, 0] + 1) * SIZE / 2 - 0.5, (1 - cam[:, 1]) * SIZE / 2 - 0.5], axis=1)

    centre = (SIZE - 1) / 2.0  # the pixel where the optical axis lands
    m = cv2.getRotationMatrix2D((centre, centre), alpha, 1.0)
    turned = pixels(view_rotation(h, v)) @ m[:, :2].T + m[:, 2]
    np.testing.assert_allclose(pixels(view_rotation(h, v, alpha)), turned, atol=1e-9)
    np.testing.assert_allclose(view_rotation(h, v, alpha), rotation_z(alpha) @ view_rotation(h, v),
                               atol=1e-12)


@given(st.floats(-179, 179), angles, angles)
def test_inplane_angle_recovers_the_turn_of_a_view(alpha, h, v):
    assert inplane_angle(view_rotation(h, v, alpha), h, v) == pytest.approx(alpha, abs=1e-6)


def test_rotation_angle():
    assert rotation_angle(np.eye(3), np.eye(3)) == pytest.approx(0.0, abs=1e-6)
    assert rotation_angle(view_rotation(10, 0), view_rotation(40, 0)) == pytest.approx(30.0)
    assert rotation_angle(np.eye(3), rotation_z(-170)) == pytest.approx(170.0)


# ---------------------------------------------------------------------- fixtures and queries
@pytest.fixture(scope="module")
def pose_db(tmp_path_factory):
    path = tmp_path_factory.mktemp("pose") / "pose.db"
    with viewdb.open(path, gap=GAP, image_size=SIZE) as db:
        report = db.ingest([sample(n) for n in ("cube_dice", "car", "mug", "l_bracket")])
        assert not report.failed, report.failed
        db.candidate_cache = {}  # type: ignore[attr-defined]
        yield db


def candidate_view(db, name: str, h: float, v: float, mirrored: bool = False) -> CandidateView:
    view = db.view(name, h, v)
    return CandidateView(h, v, mirrored, view.keypoints, view.descriptors, view.points3d,
                         db.render(name, h, v).mask, SIZE)


def candidates(db, name: str, h0: float, v0: float) -> list[CandidateView]:
    """The candidate poses of grid view (h0, v0), with their views' features."""
    key = (name, h0, v0)
    if key not in db.candidate_cache:
        db.candidate_cache[key] = [candidate_view(db, name, c.azimuth, c.elevation, c.mirrored)
                                   for c in db.candidate_poses(name, h0, v0)]
    return db.candidate_cache[key]


def nearest_grid(h: float, v: float) -> tuple[float, float]:
    return normalise_angle(round(h / GAP) * GAP), normalise_angle(round(v / GAP) * GAP)


def make_query(db, name, h, v, angle, scale, shift):
    """Render (h, v), turn it by ``angle`` counter-clockwise, scale it and shift it into a
    QUERY_W x QUERY_H image. Returns the query and the true (R, scale, translation) in the
    viewdb frame, and the warp."""
    view = db.render(name, h, v)
    centre = (SIZE - 1) / 2.0
    m = cv2.getRotationMatrix2D((centre, centre), angle, scale)
    m[:, 2] += [(QUERY_W - SIZE) / 2 + shift[0], (QUERY_H - SIZE) / 2 + shift[1]]
    color = cv2.warpAffine(view.color, m, (QUERY_W, QUERY_H), flags=cv2.INTER_LINEAR)
    mask = cv2.warpAffine(view.mask.astype(np.uint8), m, (QUERY_W, QUERY_H),
                          flags=cv2.INTER_NEAREST).astype(bool)
    assert not mask[0].any() and not mask[-1].any() and not mask[:, 0].any() and not mask[:, -1].any()
    # the model origin is at the view's centre pixel; scale is relative to a view as wide as
    # the query: a view of width W shows W/2 pixels per model unit
    u, w = m @ [centre, centre, 1.0]
    true_scale = scale * (SIZE / 2) / (QUERY_W / 2)
    x = (u + 0.5 - QUERY_W / 2) * 2 / QUERY_W / true_scale
    y = (QUERY_H / 2 - w - 0.5) * 2 / QUERY_W / true_scale
    truth = (view_rotation(h, v, angle), true_scale, np.array([x, y, -3.0]))
    return QueryView(color, mask), truth, m


# ---------------------------------------------------------------------- SIFT, no intrinsics
# Measured (python -m pytest tests/test_pose.py -k off_grid -s): rotation errors 0.1-1.2 deg
# after refinement, against 10-13 deg for the grid-only baseline; scale within 1.1 %, origin
# within 0.01 model units.
OFF_GRID = [
    ("cube_dice", 37, 22, 25, 0.8, (10, -6)),
    ("cube_dice", 52, -20, 150, 0.7, (-20, 15)),
    ("car", 37, 22, -60, 1.1, (0, 0)),
    ("car", 130, 10, 150, 0.6, (-20, 15)),
    ("mug", 37, 22, 25, 0.8, (10, -6)),
]


@pytest.mark.parametrize(("name", "h", "v", "angle", "scale", "shift"), OFF_GRID)
def test_sift_pose_off_the_grid(pose_db, name, h, v, angle, scale, shift):
    query, (rot, true_scale, true_t), _ = make_query(pose_db, name, h, v, angle, scale, shift)
    cands = candidates(pose_db, name, *nearest_grid(h, v))
    est = estimate_pose(query, cands)
    err = rotation_angle(est.rotation, rot)
    print(f"{name} ({h}, {v}) turned {angle} scaled {scale}: rotation error {err:.2f} deg, "
          f"scale {est.scale / true_scale - 1:+.4f}, origin {np.abs(est.translation - true_t).max():.4f}, "
          f"inliers {est.inliers}, score {est.score:.2f}")
    assert est.method == "sift" and est.frame == "viewdb"
    assert est.inliers >= PoseConfig().min_inliers and 0 < est.score <= 1
    assert err <= 3.0
    # the reported angles are the canonical decomposition of the rotation (cos v >= 0)
    assert angle_gap(est.azimuth, h) <= 3.0 and angle_gap(est.elevation, v) <= 3.0
    assert angle_gap(est.inplane, angle) <= 3.0
    np.testing.assert_allclose(view_rotation(est.azimuth, est.elevation, est.inplane), est.rotation,
                               atol=1e-9)
    assert est.scale == pytest.approx(true_scale, rel=0.05)
    assert est.translation[2] == -3.0
    assert np.abs(est.translation[:2] - true_t[:2]).max() <= 0.04
    # the refinement is what gets off the grid: the grid-only baseline is as far off as the
    # nearest grid view
    baseline = estimate_pose(query, cands, PoseConfig(refine=False))
    assert rotation_angle(baseline.rotation, rot) >= 3 * max(err, 1.0)


def test_sift_picks_the_textured_pose_among_look_alike_candidates(pose_db):
    """The dice's 32 candidate poses all have the same silhouette; the texture decides."""
    query, (rot, _, _), _ = make_query(pose_db, "cube_dice", 30, 30, 0, 1.0, (0, 0))
    cands = candidates(pose_db, "cube_dice", 30, 30)
    assert len(cands) > 8
    est = estimate_pose(query, cands)
    assert est.method == "sift"
    assert rotation_angle(est.rotation, rot) <= 1.5
    chosen = cands[est.candidate]
    # the chosen candidate looks from the true direction (possibly as (h+180, 180-v) turned)
    assert camera_direction(chosen.azimuth, chosen.elevation) @ camera_direction(30, 30) > 0.999


# ---------------------------------------------------------------------- with intrinsics
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_solve_pnp_recovers_a_known_pose(pose_db, seed):
    rng = np.random.default_rng(seed)
    points = pose_db.view("car", 30, 30).points3d.astype(np.float64)
    intrinsics = (600.0, 610.0, 320.0, 240.0)
    rot = GL_TO_CV @ view_rotation(30 + rng.uniform(-15, 15), 30 + rng.uniform(-15, 15), rng.uniform(0, 360))
    t = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(4, 8)])
    cam = points @ rot.T + t
    pixels = cam[:, :2] / cam[:, 2:] * [600.0, 610.0] + [320.0, 240.0]
    pixels += rng.normal(scale=0.5, size=pixels.shape)
    outliers = rng.random(len(pixels)) < 0.3
    pixels[outliers] = rng.uniform([0, 0], [640, 480], size=(int(outliers.sum()), 2))
    fit = solve_pnp(pixels, points, intrinsics, threshold=2.0)
    assert fit is not None
    print(f"PnP seed {seed}: {rotation_angle(fit.rotation, rot):.3f} deg, "
          f"translation {np.abs(fit.translation - t).max():.4f} at depth {t[2]:.2f}")
    # measured: <= 0.31 deg and <= 0.012 model units for these three seeds
    assert rotation_angle(fit.rotation, rot) <= 1.0
    assert np.abs(fit.translation - t).max() <= 0.01 * t[2]
    found = set(fit.inliers.tolist())
    assert len(found & set(np.flatnonzero(~outliers).tolist())) >= 0.9 * int((~outliers).sum())
    assert len(found & set(np.flatnonzero(outliers).tolist())) <= 2


def test_solve_pnp_needs_six_points():
    assert solve_pnp(np.zeros((5, 2)), np.zeros((5, 3)), (500, 500, 320, 240), 2.0) is None


def test_sift_pose_with_intrinsics_in_the_opencv_frame(pose_db):
    """An orthographic render is a pinhole image with a long focal length (depth 100: the
    perspective error is under 1 %), so the PnP path can be checked end to end."""
    query, (rot, true_scale, true_t), m = make_query(pose_db, "car", 37, 22, 25, 0.8, (10, -6))
    depth = 100.0
    fx = true_scale * QUERY_W / 2 * depth
    intrinsics = (fx, fx, (QUERY_W - 1) / 2, (QUERY_H - 1) / 2)
    est = estimate_pose(query, candidates(pose_db, "car", 30, 30), intrinsics=intrinsics)
    print(f"PnP end to end: {rotation_angle(est.rotation, GL_TO_CV @ rot):.2f} deg, "
          f"scale {est.scale / true_scale - 1:+.4f}, depth {est.translation[2] / depth - 1:+.4f}")
    assert est.method == "sift" and est.frame == "opencv"
    # measured: 0.5 deg, scale -0.5 %, depth +0.5 %
    assert rotation_angle(est.rotation, GL_TO_CV @ rot) <= 3.0
    assert angle_gap(est.inplane, 25) <= 3.0 and angle_gap(est.azimuth, 37) <= 3.0
    assert est.scale == pytest.approx(true_scale, rel=0.05)
    assert est.translation[2] == pytest.approx(depth, rel=0.05)
    np.testing.assert_allclose(est.translation[:2] / est.translation[2],
                               [true_t[0] * true_scale * QUERY_W / 2 / fx,
                                -true_t[1] * true_scale * QUERY_W / 2 / fx], atol=2e-4)


# ---------------------------------------------------------------------- shape fallback
def neighbourhood(db, name, h0, v0):
    """The candidate poses of (h0, v0) plus its 8 neighbouring grid views as distractors."""
    out = list(candidates(db, name, h0, v0))
    seen = {(c.azimuth, c.elevation) for c in out}
    for dh in (-GAP, 0, GAP):
        for dv in (-GAP, 0, GAP):
            hv = (normalise_angle(h0 + dh), normalise_angle(v0 + dv))
            if hv not in seen and hv in set(grid_views(GAP)):
                seen.add(hv)
                out.append(candidate_view(db, name, *hv))
    return out


def flat(query: QueryView) -> QueryView:
    """The query with no texture and no shading at all (a black image, the segmentation
    kept): SIFT finds no keypoints, so only the silhouette can decide. (A silhouette
    filled with one grey is not enough: its corners match the views' and can reach
    ``min_inliers``, correctly.)"""
    return QueryView(np.zeros_like(query.color), query.mask)


@pytest.mark.parametrize(("h0", "v0"), [(30, 30), (120, 60), (240, 330)])
def test_shape_fallback_for_a_texture_less_query(pose_db, h0, v0):
    query, (rot, true_scale, true_t), _ = make_query(pose_db, "l_bracket", h0, v0, 37.3, 0.85, (5, -8))
    cands = neighbourhood(pose_db, "l_bracket", h0, v0)
    assert len(extract_sift(flat(query).color, query.mask, 512)[0]) == 0
    est = estimate_pose(flat(query), cands)
    print(f"shape ({h0}, {v0}): {rotation_angle(est.rotation, rot):.2f} deg, in-plane {est.inplane:.2f}, "
          f"scale {est.scale / true_scale - 1:+.4f}, origin {np.abs(est.translation - true_t).max():.4f}, "
          f"score {est.score:.3f}")
    assert est.method == "shape" and est.inliers == 0 and est.frame == "viewdb"
    chosen = cands[est.candidate]
    assert (chosen.azimuth, chosen.elevation) == (h0, v0)
    # measured: 0.2-0.3 deg (the angle search steps by 0.5 deg), scale 0.3 %, origin 0.002
    assert rotation_angle(est.rotation, rot) <= 1.0
    assert angle_gap(est.inplane, 37.3) <= 1.0
    assert max(angle_gap(est.azimuth, h0), angle_gap(est.elevation, v0)) <= 1e-6
    assert est.scale == pytest.approx(true_scale, rel=0.02)
    assert np.abs(est.translation - true_t).max() <= 0.02
    assert 0.9 < est.score <= 1.0


@pytest.mark.parametrize("offset", [-12.0, 0.0, 9.0])
def test_shape_fallback_near_a_known_turn(pose_db, offset):
    """``inplane_near`` (refining a known pose) searches only near that turn: near the true
    one it finds the same pose as the full search; 90° away it cannot reach it."""
    query, (rot, _, _), _ = make_query(pose_db, "l_bracket", 30, 30, 37.3, 0.85, (5, -8))
    cands = neighbourhood(pose_db, "l_bracket", 30, 30)
    full = estimate_pose(flat(query), cands)
    near = estimate_pose(flat(query), cands, inplane_near=37.3 + offset)
    assert near.method == "shape" and near.candidate == full.candidate
    assert rotation_angle(near.rotation, full.rotation) <= 0.6
    far = estimate_pose(flat(query), cands, inplane_near=37.3 + 90.0)
    reach = PoseConfig().shape_near_window + PoseConfig().coarse_step  # the fine search's last step
    assert angle_gap(inplane_angle(far.rotation, cands[far.candidate].azimuth,
                                   cands[far.candidate].elevation), 37.3 + 90.0) <= reach + 1e-6
    assert rotation_angle(far.rotation, rot) > 30.0


@pytest.mark.parametrize(("h0", "v0"), [(30, 30), (120, 60), (240, 330)])
def test_texture_less_render_gets_the_right_pose_either_way(pose_db, h0, v0):
    """The bracket's flat shading gives a handful of keypoints: SIFT when they suffice,
    else the silhouette; both must land on the true pose."""
    query, (rot, _, _), _ = make_query(pose_db, "l_bracket", h0, v0, 40, 0.9, (5, -8))
    est = estimate_pose(query, neighbourhood(pose_db, "l_bracket", h0, v0))
    print(f"l_bracket ({h0}, {v0}): {est.method}, {est.inliers} inliers, "
          f"{rotation_angle(est.rotation, rot):.2f} deg")
    assert rotation_angle(est.rotation, rot) <= 2.0


def test_shape_fallback_with_intrinsics_is_weak_perspective(pose_db):
    query, (rot, true_scale, true_t), _ = make_query(pose_db, "l_bracket", 30, 30, 40, 0.9, (5, -8))
    fx = 800.0
    intrinsics = (fx, fx, (QUERY_W - 1) / 2, (QUERY_H - 1) / 2)
    est = estimate_pose(flat(query), candidates(pose_db, "l_bracket", 30, 30), intrinsics=intrinsics)
    assert est.method == "shape" and est.frame == "opencv"
    assert rotation_angle(est.rotation, GL_TO_CV @ rot) <= 1.0
    depth = 2 * fx / (true_scale * QUERY_W)
    assert est.translation[2] == pytest.approx(depth, rel=0.02)
    np.testing.assert_allclose(est.translation[:2], [true_t[0], -true_t[1]], atol=0.02)


def test_shape_fallback_when_sift_is_switched_off(pose_db):
    """A textured object judged by its silhouette alone: the car's candidate poses include
    its left-right mirror, which a rotation of the image cannot match."""
    query, (rot, _, _), _ = make_query(pose_db, "car", 30, 30, -70, 0.9, (0, 0))
    cands = candidates(pose_db, "car", 30, 30)
    assert any(c.mirrored for c in cands)
    est = estimate_pose(query, cands, PoseConfig(min_inliers=10**6))
    assert est.method == "shape"
    assert rotation_angle(est.rotation, rot) <= 1.0


# ---------------------------------------------------------------------- one outline, two poses
@pytest.fixture(scope="module")
def chair_renders():
    """Renders of the sample chair (untextured, left-right symmetric), without a database:
    ``.render(name, h, v)`` like a ViewDB's, for :func:`make_query`."""
    from types import SimpleNamespace

    from viewdb.catalogue.mesh import load_mesh
    from viewdb.catalogue.render import get_renderer
    from viewdb.config import RenderConfig

    mesh = load_mesh(sample("chair"))
    renderer = get_renderer(RenderConfig(image_size=SIZE))
    cache = {}

    def render(name, h, v):
        if (h, v) not in cache:
            cache[h, v] = renderer.render(mesh, h, v)
        return cache[h, v]

    return SimpleNamespace(render=render)


def shaded_candidate(renders, h, v) -> CandidateView:
    """A candidate with no SIFT at all (keypoints blacked out), only its silhouette and its
    shaded render."""
    view = renders.render("chair", h, v)
    return CandidateView(h, v, False, np.zeros((0, 5), np.float32), np.zeros((0, 128), np.uint8),
                         np.zeros((0, 3), np.float32), view.mask, SIZE, color=view.color)


@pytest.mark.parametrize(("h", "v", "angle"), [(30, 30, 37.3), (240, 60, -120.0), (150, 330, 75.0)])
def test_shape_fallback_tells_poses_with_one_outline_apart_by_their_internal_edges(chair_renders, h, v, angle):
    """The chair is mirror symmetric, so from (h, v) and from (180 − h, −v) (front and back)
    it has exactly the same silhouette: only the shading and the creases inside differ."""
    twin = (normalise_angle(180 - h), normalise_angle(-v))
    query, (rot, true_scale, true_t), _ = make_query(chair_renders, "chair", h, v, angle, 0.85, (5, -8))
    right, wrong = shaded_candidate(chair_renders, h, v), shaded_candidate(chair_renders, *twin)
    outline_only = PoseConfig(detail_weight=0.0)
    # the outline alone cannot tell them apart: equal fits, and the tie goes to the first given
    alone = [estimate_pose(query, [c], outline_only) for c in (right, wrong)]
    assert all(e.method == "shape" for e in alone)
    assert alone[0].score == pytest.approx(alone[1].score, abs=2e-3)
    assert rotation_angle(alone[1].rotation, rot) > 90.0
    assert estimate_pose(query, [wrong, right], outline_only).candidate == 0
    # the internal edges can, whichever comes first
    for cands in ([wrong, right], [right, wrong]):
        est = estimate_pose(query, cands)
        print(f"chair ({h}, {v}) turned {angle}: {rotation_angle(est.rotation, rot):.2f} deg, "
              f"score {est.score:.3f} (outline alone {alone[0].score:.3f})")
        assert est.method == "shape" and est.inliers == 0
        assert cands[est.candidate] is right
        assert rotation_angle(est.rotation, rot) <= 1.0
        assert est.scale == pytest.approx(true_scale, rel=0.02)
        assert np.abs(est.translation - true_t).max() <= 0.02
        # one score for both orders; the edge distance only lowers the outline's
        assert 0.8 < est.score <= alone[0].score
    # a query without any inside detail (flat black) falls back to the outline alone
    flat_est = estimate_pose(flat(query), [wrong, right])
    plain = estimate_pose(flat(query), [wrong, right], outline_only)
    assert (flat_est.candidate, flat_est.score) == (plain.candidate, plain.score)


# ---------------------------------------------------------------------- errors
def test_pose_errors(pose_db):
    query, _, _ = make_query(pose_db, "car", 30, 30, 0, 1.0, (0, 0))
    cands = candidates(pose_db, "car", 30, 30)
    with pytest.raises(PoseError, match="no candidate"):
        estimate_pose(query, [])
    empty = QueryView(query.color, np.zeros_like(query.mask))
    with pytest.raises(PoseError, match="empty"):
        estimate_pose(empty, cands)
    with pytest.raises(PoseError, match="do not match"):
        estimate_pose(QueryView(query.color[:-1], query.mask), cands)
    with pytest.raises(PoseError, match="uint8"):
        estimate_pose(QueryView(query.color.astype(np.float32), query.mask), cands)
    with pytest.raises(PoseError, match="intrinsics"):
        estimate_pose(query, cands, intrinsics=(0.0, 500.0, 100.0, 100.0))
    blank = CandidateView(30, 30, False, np.zeros((0, 5), np.float32), np.zeros((0, 128), np.uint8),
                          np.zeros((0, 3), np.float32), np.zeros((SIZE, SIZE), bool), SIZE)
    with pytest.raises(PoseError, match="no candidate view has a silhouette"):
        estimate_pose(query, [blank])
    # a candidate's shaded render must be an image of its silhouette's size
    bad = CandidateView(30, 30, False, np.zeros((0, 5), np.float32), np.zeros((0, 128), np.uint8),
                        np.zeros((0, 3), np.float32), cands[0].mask, SIZE, color=np.zeros((8, 8, 3), np.uint8))
    with pytest.raises(PoseError, match="colour"):
        estimate_pose(query, [bad], PoseConfig(min_inliers=10**6))


@pytest.mark.parametrize("kwargs", [{"min_inliers": 3}, {"ratio": 0.0}, {"fine_step": 10.0},
                                    {"pose_threshold": 0.0}, {"contour_samples": 4},
                                    {"detail_weight": -1.0}, {"detail_truncation": 0.0},
                                    {"detail_orientation": 1.5}])
def test_pose_config_is_validated(kwargs):
    with pytest.raises(ValueError):
        PoseConfig(**kwargs)


def test_a_small_object_is_enlarged_before_sift(pose_db):
    # the mug at 0.3 of the views' size: as it is, too few keypoints match and the outline
    # decides (60 deg off when measured); enlarged to the views' size, SIFT finds the pose
    query, (rot, _, _), _ = make_query(pose_db, "mug", 60, 30, 25, 0.3, (0, 0))
    est = estimate_pose(query, neighbourhood(pose_db, "mug", 60, 30))
    assert est.method == "sift" and rotation_angle(est.rotation, rot) <= 3.0
    plain = estimate_pose(query, neighbourhood(pose_db, "mug", 60, 30), PoseConfig(max_sift_upscale=1.0))
    assert plain.inliers < est.inliers


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0.1, 0.99), min_size=1, max_size=8), st.integers(0, 3))
def test_iou_reranking_fits_every_match_alike_and_only_the_best_again(quick_ious, full):
    """With ``rerank``, every match gets the quick fit (outlines only, no SIFT), and only the
    ``rerank_full`` best by the quick fits' IoU the full one, started from the quick pose."""
    from types import SimpleNamespace

    import viewdb.pose.matched as matched
    from viewdb.config import MatchedPoseConfig
    from viewdb.pose.estimate import PoseEstimate
    from viewdb.search.plans import Candidate

    names = [f"o{i}" for i in range(len(quick_ious))]
    calls: list[tuple[str, bool, bool]] = []

    def fake(catalogue, query, match, config, intrinsics, search=None, starts=(), curve=None,
             posing=None, *, sift=True):
        quick = search is matched.QUICK
        calls.append((match.object, quick, sift))
        iou = quick_ious[names.index(match.object)] + (0.0 if quick else 0.005)
        return PoseEstimate(0.0, 0.0, 0.0, 1.0, np.eye(3), np.array([0.0, 0.0, 3.0]), "shape", 0, 0,
                            "opencv", iou, refined="silhouette", iou=iou)

    catalogue = SimpleNamespace(config=SimpleNamespace(features=SimpleNamespace(curve_samples=128)),
                                object=lambda name: SimpleNamespace(centre=(0.0, 0.0, 0.0), scale=1.0))
    matches = [Candidate(n, 0.1 * i, 0.0, 0.0, False) for i, n in enumerate(names)]
    original = matched.pose_match
    matched.pose_match = fake
    try:
        matched.pose_matches(catalogue, QueryView(np.zeros((8, 8, 3), np.uint8), np.ones((8, 8), bool)),
                             matches, (10.0, 10.0, 4.0, 4.0), rerank=True,
                             posing=MatchedPoseConfig(rerank_full=full))
    finally:
        matched.pose_match = original
    quick = [(n, s) for n, q, s in calls if q]
    again = [n for n, q, _ in calls if not q]
    assert quick == [(n, False) for n in names]
    best = sorted(names, key=lambda n: (-quick_ious[names.index(n)], names.index(n)))
    assert again == best[:full]


def test_quick_fit_starts_from_the_candidate_poses_without_an_outline_pose(monkeypatch):
    """A re-ranking's quick fit (no SIFT, search started from the candidates) aligns the
    candidate poses' own silhouettes: their grid views are the search's directions, each
    once, and no outline pose (nor a candidate view's appearance) is made first."""
    from types import SimpleNamespace

    import viewdb.pose.matched as matched
    from viewdb.catalogue.reading import CandidatePose
    from viewdb.config import SilhouetteConfig
    from viewdb.pose.estimate import PoseEstimate
    from viewdb.search.plans import Candidate

    same = [CandidatePose(30.0, 40.0, False, True), CandidatePose(210.0, 140.0, True, False)]
    near = {(50.0, 40.0): [CandidatePose(50.0, 40.0, False, True), CandidatePose(30.0, 40.0, False, True)]}
    catalogue = SimpleNamespace(
        candidate_poses=lambda name, h, v: list(same) if (h, v) == (30.0, 40.0) else list(near[(h, v)]),
        nearest_views=lambda name, curve, n: [(50.0, 40.0, 0.1)],
        object=lambda name: SimpleNamespace(centre=(0.0, 0.0, 0.0), scale=1.0))
    seen = {}

    def fit(catalogue, name, query, config, intrinsics, search, starts, candidate=0, posing=None,
            directions=None):
        seen["directions"] = directions
        return PoseEstimate(0.0, 0.0, 0.0, 1.0, np.eye(3), np.array([0.0, 0.0, 3.0]), "shape", 0, 0,
                            "opencv", 0.9, refined="silhouette", iou=0.9)

    def no_outline_pose(*args, **kwargs):
        raise AssertionError("the quick fit made an outline pose")

    monkeypatch.setattr(matched, "pose_silhouette", fit)
    monkeypatch.setattr(matched, "appearance_view", no_outline_pose)
    monkeypatch.setattr(matched, "_sift_first", no_outline_pose)
    query = QueryView(np.zeros((8, 8, 3), np.uint8), np.ones((8, 8), bool))
    match = Candidate("o", 0.1, 30.0, 40.0, False)
    found = matched.pose_match(catalogue, query, match, PoseConfig(), (10.0, 10.0, 4.0, 4.0), matched.QUICK,
                               curve=np.zeros(8), sift=False)
    assert found.iou == 0.9
    assert seen["directions"] == [(30.0, 40.0), (210.0, 140.0), (50.0, 40.0)]
    with pytest.raises(AssertionError, match="outline pose"):  # the full search still makes one
        matched.pose_match(catalogue, query, match, PoseConfig(), (10.0, 10.0, 4.0, 4.0), SilhouetteConfig(),
                           curve=np.zeros(8), sift=False)
    with pytest.raises(ValueError, match="start_directions"):
        SilhouetteConfig(start_directions="grid")
