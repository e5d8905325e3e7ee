"""A depth image beside the photo: read, checked, and setting a pose's distance."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

import viewdb
from tests.conftest import sample
from viewdb.catalogue.pinhole import Window, get_pinhole_renderer
from viewdb.errors import ImageError, QueryError
from viewdb.pose.depth_distance import distance_from_depth
from viewdb.pose.frames import GL_TO_CV, view_rotation
from viewdb.pose.silhouette import to_mesh_units
from viewdb.pose.views import PoseEstimate
from viewdb.recognition.depth_image import load_depth
from viewdb_cli.main import main

WIDTH, HEIGHT = 320, 240
K = (400.0, 400.0, 171.5, 112.0)
#: The bracket's pose in normalised units (OpenCV frame).
ROTATION = GL_TO_CV @ view_rotation(47.0, 28.0, -20.0)
T_NORM = np.array([0.4, 0.2, 6.0])


@pytest.fixture(scope="module")
def bracket(tmp_path_factory):
    """A file of two sample meshes, and a perspective photo of one of them in front of a
    wall, with its depth image (16-bit PNG), its true mask and its true pose (mesh units)."""
    folder = tmp_path_factory.mktemp("depth")
    path = folder / "b.db"
    with viewdb.open(path, gap=30) as db:
        assert not db.ingest([sample("l_bracket"), sample("car")]).failed
        info = db.object("l_bracket")
        window = Window(0.0, 0.0, float(WIDTH), WIDTH)
        mask, depth_n = get_pinhole_renderer().render(db.mesh("l_bracket"), ROTATION, T_NORM,
                                                      window.intrinsics(*K), WIDTH)
    mask, depth_n = mask[:HEIGHT], depth_n[:HEIGHT].astype(np.float64)
    wall = 1.4 * T_NORM[2]
    depth_mesh = np.where(mask, depth_n, wall) * float(info.scale)  # the meshes' units
    scale = float(depth_mesh.max()) / 20000.0  # one PNG unit, in the meshes' units
    png = folder / "depth.png"
    cv2.imwrite(str(png), np.round(depth_mesh / scale).astype(np.uint16))
    photo = np.full((HEIGHT, WIDTH, 3), 90, np.uint8)
    photo[mask] = (200, 180, 160)
    t_true = to_mesh_units(ROTATION, T_NORM, info.centre, info.scale)
    return {"db": path, "png": png, "scale": scale, "mask": mask, "photo": photo, "t": t_true,
            "depth_n": np.where(mask, depth_n, wall), "folder": folder}


def _error(translation, truth) -> float:
    return float(np.linalg.norm(np.asarray(translation) - truth) / np.linalg.norm(truth))


def test_the_depth_sets_the_distance_a_loose_cut_got_wrong(bracket):
    """A cut that takes in a ring of background makes the object look larger, so nearer;
    the depth image puts it back where it is."""
    loose = cv2.dilate(bracket["mask"].astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
    with viewdb.open(bracket["db"], create=False) as db:
        plain = db.query(bracket["photo"], k=1, mask=loose, intrinsics=K).results[0]
        deep = db.query(bracket["photo"], k=1, mask=loose, intrinsics=K, depth=bracket["png"],
                        depth_scale=bracket["scale"]).results[0]
    assert plain.object == deep.object == "l_bracket"
    assert plain.pose is not None and deep.pose is not None
    assert plain.pose.depth_pixels is None and deep.pose.depth_pixels > 500
    np.testing.assert_allclose(deep.pose.rotation, plain.pose.rotation)  # the depth moves, never turns
    before, after = _error(plain.pose.translation, bracket["t"]), _error(deep.pose.translation, bracket["t"])
    assert after < 0.02 and after < before / 2, (before, after)


def _estimate(translation) -> PoseEstimate:
    return PoseEstimate(0.0, 0.0, 0.0, 1.0, ROTATION, np.asarray(translation, np.float64), "shape", 0, 0,
                        "opencv", 1.0)


def test_an_occluder_in_front_is_outvoted(bracket):
    """A third of the object's pixels read an occluder nearer the camera: the median of
    the other pixels' answers still sets the distance."""
    with viewdb.open(bracket["db"], create=False) as db:
        triangles = get_pinhole_renderer().triangles(db.mesh("l_bracket"))
    depth = bracket["depth_n"].copy()
    ys, xs = np.nonzero(bracket["mask"])
    hidden = xs < np.percentile(xs, 33)
    depth[ys[hidden], xs[hidden]] = 0.7 * T_NORM[2]
    window = Window(0.0, 0.0, float(WIDTH), WIDTH)
    for factor in (0.8, 1.25):
        fixed = distance_from_depth(_estimate(T_NORM * factor), triangles, bracket["mask"], depth,
                                    window.intrinsics(*K))
        assert _error(fixed.translation, T_NORM) < 0.015, factor
        assert fixed.scale == pytest.approx(factor, rel=0.02)  # farther, it looks smaller
    # no reading on the object: the pose is left as it was
    nothing = np.full_like(depth, np.nan)
    same = distance_from_depth(_estimate(T_NORM * 0.8), triangles, bracket["mask"], nothing, window.intrinsics(*K))
    assert same.depth_pixels is None and np.array_equal(same.translation, T_NORM * 0.8)


def test_depth_in_other_units_loses_the_pose_with_a_hint(bracket):
    with viewdb.open(bracket["db"], create=False) as db:
        result = db.query(bracket["photo"], k=1, mask=bracket["mask"], intrinsics=K, depth=bracket["png"],
                          depth_scale=bracket["scale"] * 1000)
    top = result.results[0]
    assert top.pose is None and "`depth_scale`" in top.pose_error


def test_depth_needs_intrinsics_and_the_meshes(bracket):
    with viewdb.open(bracket["db"], create=False) as db:
        with pytest.raises(QueryError, match="`depth` needs the camera's `intrinsics`"):
            db.query(bracket["photo"], mask=bracket["mask"], depth=bracket["png"])


def test_bad_depth_images_are_refused_naming_the_file(tmp_path):
    shape = (HEIGHT, WIDTH)
    other = tmp_path / "other.png"
    cv2.imwrite(str(other), np.ones((100, 100), np.uint16))
    colour = tmp_path / "colour.png"
    cv2.imwrite(str(colour), np.ones((HEIGHT, WIDTH, 3), np.uint8))
    zero = tmp_path / "zero.png"
    cv2.imwrite(str(zero), np.zeros(shape, np.uint16))
    text = tmp_path / "notes.png"
    text.write_text("not an image")
    pickled = tmp_path / "pickled.npy"
    np.save(pickled, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    cases = [(other, "100x100 pixels but the photo is 320x240"), (colour, "one channel"),
             (zero, "no reading"), (text, "cannot decode"), (pickled, "not a NumPy array file"),
             (tmp_path / "missing.png", "cannot read")]
    for path, wanted in cases:
        with pytest.raises(ImageError) as caught:
            load_depth(path, shape)
        message = str(caught.value)
        assert wanted in message and str(path) in message and "\n" not in message, message
    with pytest.raises(ValueError, match="`depth_scale`"):
        load_depth(np.ones(shape), shape, 0.0)
    with pytest.raises(ValueError, match="`depth_scale`"):
        load_depth(np.ones(shape), shape, float("nan"))


def test_depth_files_are_read_in_the_meshes_units(tmp_path):
    raw = np.arange(HEIGHT * WIDTH, dtype=np.uint16).reshape(HEIGHT, WIDTH) % 5000
    png = tmp_path / "d.png"
    cv2.imwrite(str(png), raw)
    npy = tmp_path / "d.npy"
    np.save(npy, raw.astype(np.float32) / 1000.0)
    from_png = load_depth(png, (HEIGHT, WIDTH), 0.001)
    from_npy = load_depth(npy, (HEIGHT, WIDTH), 1.0)
    assert np.isnan(from_png[raw == 0]).all() and np.isnan(from_npy[raw == 0]).all()
    np.testing.assert_allclose(from_png[raw > 0], raw[raw > 0] * 0.001)
    np.testing.assert_allclose(from_npy[raw > 0], raw[raw > 0] / 1000.0, rtol=1e-6)


def test_cli_depth(bracket, tmp_path, capsys):
    photo = tmp_path / "photo.png"
    cv2.imwrite(str(photo), bracket["photo"][:, :, ::-1])
    mask = tmp_path / "mask.png"
    cv2.imwrite(str(mask), bracket["mask"].astype(np.uint8) * 255)
    k = ",".join(str(v) for v in K)
    base = ["query", str(photo), "--db", str(bracket["db"]), "--mask", str(mask), "-k", "1"]
    assert main([*base, "--depth", str(bracket["png"])]) == 2  # no intrinsics
    assert "--intrinsics" in capsys.readouterr().err
    assert main([*base, "--intrinsics", k, "--depth", str(bracket["png"]), "--depth-scale",
                 repr(bracket["scale"]), "--json"]) == 0
    pose = json.loads(capsys.readouterr().out)["results"][0]["pose"]
    assert pose["depth_pixels"] > 500 and _error(pose["translation"], bracket["t"]) < 0.02
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.ones((50, 60), np.uint16))
    assert main([*base, "--intrinsics", k, "--depth", str(small)]) == 1
    err = capsys.readouterr().err.strip()
    assert str(small) in err and "60x50 pixels" in err and "\n" not in err
