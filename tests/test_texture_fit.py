"""The texture score: a pose's render of the mesh's own colours against the photo's
gradients inside the object (viewdb.pose.texture_fit), and the silhouette fit that uses it
to tell apart poses whose silhouettes are the same (the faces of a dice)."""

from __future__ import annotations

import itertools
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import viewdb
from tests.conftest import sample
from viewdb.catalogue.mesh import load_mesh
from viewdb.catalogue.pinhole import get_pinhole_renderer
from viewdb.config import PoseConfig, SilhouetteConfig
from viewdb.errors import PoseError, RenderError
from viewdb.pose.frames import GL_TO_CV, rotation_angle, view_rotation
from viewdb.pose.matched import pose_silhouette
from viewdb.pose.texture_fit import TextureScore
from viewdb.pose.views import QueryView

INTRINSICS = (520.0, 520.0, 319.5, 239.5)
SIZE = (480, 640)


def _cube_turns() -> list[np.ndarray]:
    """The 24 rotations that map an axis-aligned cube onto itself."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            for row, (col, sign) in enumerate(zip(perm, signs, strict=True)):
                m[row, col] = sign
            if np.linalg.det(m) > 0:
                out.append(m)
    return out


def _photo(mesh, rotation, translation):
    """A grey-background photo of ``mesh``'s colours at the OpenCV pose, and its mask."""
    rgb, covered = get_pinhole_renderer().colour(mesh, rotation, translation, INTRINSICS, SIZE[1])
    rgb, covered = rgb[:SIZE[0]], covered[:SIZE[0]]
    photo = np.where(covered[..., None], rgb, np.uint8(90))
    return np.ascontiguousarray(photo, dtype=np.uint8), covered


POSES = [(30.0, 20.0, 10.0), (135.0, -35.0, 70.0), (250.0, 50.0, -40.0)]


def _pose(h, v, a):
    return GL_TO_CV @ view_rotation(h, v, a), np.array([0.05, -0.03, 4.0])


@pytest.mark.parametrize("view", POSES)
def test_the_true_pose_of_a_dice_explains_its_photo_better_than_every_turn_with_the_same_silhouette(view):
    mesh = load_mesh(sample("cube_dice"))
    rotation, translation = _pose(*view)
    photo, mask = _photo(mesh, rotation, translation)
    score = TextureScore(mesh, QueryView(photo, mask), INTRINSICS, 128)
    true = score(rotation, translation)
    others = [score(rotation @ turn, translation) for turn in _cube_turns() if not np.allclose(turn, np.eye(3))]
    assert len(others) == 23
    assert true > 0.9
    assert true > max(others) + 0.03, (true, sorted(others)[-3:])


def test_a_mesh_without_colour_renders_flat_and_scores_nothing():
    mesh = load_mesh(sample("box_long"))
    rotation, translation = _pose(*POSES[0])
    photo, mask = _photo(mesh, rotation, translation)
    photo = (np.random.default_rng(1).integers(0, 255, photo.shape)).astype(np.uint8)  # busy inside
    assert TextureScore(mesh, QueryView(photo, mask), INTRINSICS, 128)(rotation, translation) == 0.0


def test_a_flat_photo_scores_every_pose_alike():
    mesh = load_mesh(sample("cube_dice"))
    rotation, translation = _pose(*POSES[1])
    _, mask = _photo(mesh, rotation, translation)
    flat = np.full(mask.shape + (3,), 120, np.uint8)
    score = TextureScore(mesh, QueryView(flat, mask), INTRINSICS, 128)
    assert {score(rotation @ turn, translation) for turn in _cube_turns()} == {0.0}


def test_pixels_that_may_hide_the_object_are_left_out():
    mesh = load_mesh(sample("cube_dice"))
    rotation, translation = _pose(*POSES[0])
    photo, mask = _photo(mesh, rotation, translation)
    hidden = np.ones(mask.shape, bool)
    assert TextureScore(mesh, QueryView(photo, mask, ignore=hidden), INTRINSICS, 128)(rotation, translation) == 0.0


def test_an_empty_query_is_refused_and_a_mesh_that_cannot_be_rendered_scores_nothing(monkeypatch):
    mesh = load_mesh(sample("cube_dice"))
    rotation, translation = _pose(*POSES[0])
    photo, mask = _photo(mesh, rotation, translation)
    with pytest.raises(PoseError, match="empty"):
        TextureScore(mesh, QueryView(photo, np.zeros_like(mask)), INTRINSICS, 128)
    score = TextureScore(mesh, QueryView(photo, mask), INTRINSICS, 128)
    assert score(rotation, translation) > 0.9

    def no_gl(*args, **kwargs):
        raise RenderError("cannot create an offscreen renderer: no EGL display")

    monkeypatch.setattr(get_pinhole_renderer(), "colour", no_gl)
    assert score(rotation, translation) == 0.0
    assert score.unavailable


def test_threads_score_alike():
    """Each thread renders in its own GL context, with its own scene."""
    mesh = load_mesh(sample("cube_dice"))
    rotation, translation = _pose(*POSES[2])
    photo, mask = _photo(mesh, rotation, translation)
    score = TextureScore(mesh, QueryView(photo, mask), INTRINSICS, 128)
    poses = [(rotation @ turn, translation) for turn in _cube_turns()[:6]]
    alone = [score(*pose) for pose in poses]
    with ThreadPoolExecutor(2) as pool:
        assert list(pool.map(lambda pose: score(*pose), poses)) == alone


@pytest.fixture(scope="module")
def dice_db(tmp_path_factory):
    path = tmp_path_factory.mktemp("dice") / "dice.db"
    with viewdb.open(path, gap=30, image_size=128) as db:
        report = db.ingest([sample("cube_dice")])
    assert not report.failed, report.failed
    return path


@pytest.mark.parametrize("view", POSES)
def test_among_fits_with_the_same_silhouette_the_dice_fit_keeps_the_one_its_faces_show(dice_db, view):
    """Started from the true pose turned by each of the dice's 24 turns (and slightly off),
    every fit reaches the photo's silhouette: the IoU alone cannot choose, the pips can."""
    mesh = load_mesh(sample("cube_dice"))
    rotation, translation = _pose(*view)
    photo, mask = _photo(mesh, rotation, translation)
    nudge = GL_TO_CV @ view_rotation(3.0, -2.0, 4.0) @ GL_TO_CV  # a few degrees off, OpenCV frame
    turns = _cube_turns()[::-1]  # the true pose last: ties of the IoU keep the first
    starts = [(nudge @ rotation @ turn, translation * 1.02) for turn in turns]
    search = SilhouetteConfig(coarse_starts=1, fine_starts=len(starts))
    with viewdb.open(dice_db, read_only=True) as db:
        found = pose_silhouette(db._catalogue, "cube_dice", QueryView(photo, mask), PoseConfig(), INTRINSICS,
                                search, starts)
    assert found.iou > 0.9
    assert rotation_angle(found.rotation, rotation) < 10.0


def test_texture_settings_are_checked():
    with pytest.raises(ValueError, match="texture"):
        SilhouetteConfig(texture_weight=-1.0)
    with pytest.raises(ValueError, match="texture"):
        SilhouetteConfig(texture_size=8)
