"""Options a real photo needs: intrinsics files, label maps, and a perspective pose in the
mesh's own units recovered from a pinhole render at a known pose."""

import json

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import viewdb
from tests.conftest import sample
from viewdb.catalogue.pinhole import Window, get_pinhole_renderer
from viewdb.errors import ImageError, QueryError
from viewdb.pose.frames import GL_TO_CV, rotation_angle, view_rotation
from viewdb.pose.silhouette import fibonacci_directions, lift_alignment, ray_rotation, to_mesh_units
from viewdb.recognition.image import load_image
from viewdb.recognition.segmentation import label_mask
from viewdb.recognition.shapes import completed_mask
from viewdb_cli.main import main

K4 = (500.0, 510.0, 160.0, 120.0)


# ---------------------------------------------------------------------- intrinsics
@pytest.mark.parametrize("name, text", [
    ("k.json", json.dumps({"fx": 500, "fy": 510, "cx": 160, "cy": 120})),
    ("k.json", json.dumps({"K": [[500, 0, 160], [0, 510, 120], [0, 0, 1]]})),
    ("k.json", json.dumps([[500, 0, 160], [0, 510, 120], [0, 0, 1]])),
    ("k.yaml", "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [500, 0, 160, 0, 510, 120, 0, 0, 1]\n"),
    ("k.yml", "fx: 500\nfy: 510\ncx: 160\ncy: 120\n"),
    ("k.json", json.dumps({"intrinsics": [500, 510, 160, 120]})),
])
def test_intrinsics_files(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    assert viewdb.parse_intrinsics(path) == K4
    assert viewdb.parse_intrinsics(str(path)) == K4


def test_intrinsics_text_and_arrays():
    assert viewdb.parse_intrinsics("500,510,160,120") == K4
    assert viewdb.parse_intrinsics(np.array([[500, 0, 160], [0, 510, 120], [0, 0, 1]])) == K4
    assert viewdb.parse_intrinsics((500, 510, 160, 120)) == K4


@pytest.mark.parametrize("name, text, problem", [
    ("k.json", "{", "not valid JSON"),
    ("k.yaml", "fx: [1,\n", "not valid YAML"),
    ("k.json", json.dumps({"f": 1}), "no intrinsics found"),
    ("k.json", json.dumps([1, 2, 3]), "got 3 numbers"),
    ("k.json", json.dumps({"fx": 0, "fy": 1, "cx": 1, "cy": 1}), r"fx must be a finite number in \[1, 1e\+07\]"),
    ("k.json", json.dumps({"K": [[500, 0, 160], [0, 510, 120], [0, 1, 1]]}), "last row"),
    ("k.json", json.dumps({"K": [[500, 3, 160], [0, 510, 120], [0, 0, 1]]}), "skew"),
    ("k.json", json.dumps({"fx": "a", "fy": 1, "cx": 1, "cy": 1}), "fx must be a number"),
])
def test_bad_intrinsics_files_name_the_file(tmp_path, name, text, problem):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(QueryError, match=problem) as info:
        viewdb.parse_intrinsics(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_bad_intrinsics_text_and_missing_file(tmp_path):
    with pytest.raises(QueryError, match="four numbers"):
        viewdb.parse_intrinsics("1,2,3")
    with pytest.raises(QueryError, match="not found"):
        viewdb.parse_intrinsics(tmp_path / "missing.json")


# ---------------------------------------------------------------------- label maps
def _labels(tmp_path, dtype=np.uint8):
    labels = np.zeros((60, 80), dtype)
    labels[10:30, 10:30] = 3
    labels[20:50, 40:70] = 7
    path = tmp_path / f"labels_{np.dtype(dtype).name}.png"
    assert cv2.imwrite(str(path), labels)
    return path, labels


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_label_map_picks_one_object(tmp_path, dtype):
    path, labels = _labels(tmp_path, dtype)
    image = load_image(np.zeros((60, 80, 3), np.uint8))
    chosen, others = label_mask(path, 7, image)
    assert (chosen == (labels == 7)).all()
    assert (others == (labels == 3)).all()
    chosen, _ = label_mask(labels, 3, image)  # arrays too
    assert chosen.sum() == 400


def test_label_map_errors(tmp_path):
    path, labels = _labels(tmp_path)
    image = load_image(np.zeros((60, 80, 3), np.uint8))
    with pytest.raises(ImageError, match=r"label 5 is not in the label map \(labels present: 3, 7\)") as info:
        label_mask(path, 5, image)
    assert str(path) in str(info.value)
    with pytest.raises(ImageError, match="label map is 80x60 pixels but the image is 40x60"):
        label_mask(path, 3, load_image(np.zeros((60, 40, 3), np.uint8)))
    with pytest.raises(ImageError, match="not found"):
        label_mask(tmp_path / "none.png", 3, image)
    with pytest.raises(ImageError, match="one channel"):
        label_mask(np.dstack([labels, labels * 0, labels]), 3, image)
    with pytest.raises(ImageError, match="positive"):
        label_mask(labels, 0, image)


def test_completed_mask_fills_an_occluders_bite():
    mask = np.zeros((100, 100), bool)
    mask[20:80, 20:80] = True
    ignore = np.zeros_like(mask)
    ignore[50:90, 50:90] = True  # a square in front of the lower-right corner
    mask &= ~ignore
    done = completed_mask(mask, ignore)
    assert done is not None and done[20:80, 20:80].sum() > mask.sum()
    assert not done[85:, 85:].any()  # the occluder outside the hull stays out
    assert completed_mask(mask, None) is None


# ---------------------------------------------------------------------- pinhole maths
def test_lifting_an_on_axis_alignment_keeps_the_view_rotation():
    k = np.array([[500.0, 0, 160], [0, 500.0, 120], [0, 0, 1]])
    r, t = lift_alignment(30.0, 20.0, 15.0, 1.0, (160.0, 120.0), 256, 1.0, k)
    assert np.allclose(r, GL_TO_CV @ view_rotation(30.0, 20.0, 15.0))
    assert np.allclose(t, [0.0, 0.0, 500.0 * 2.0 / 256.0])
    d = ray_rotation(400.0, 10.0, k) @ [0.0, 0.0, 1.0]
    assert np.allclose(d / d[2], [(400 - 160) / 500, (10 - 120) / 500, 1.0])
    assert len(fibonacci_directions(50)) == 50


@given(u=st.floats(-5000, 5000), w=st.floats(-5000, 5000))
def test_the_ray_rotation_is_the_smallest_rotation_onto_the_ray(u, w):
    """A rotation (orthonormal, det 1) taking the optical axis onto the ray through the
    pixel, by the angle between them (its axis is perpendicular to both)."""
    k = np.array([[500.0, 0, 160], [0, 520.0, 120], [0, 0, 1]])
    r = ray_rotation(u, w, k)
    assert np.allclose(r.T @ r, np.eye(3), atol=1e-12) and np.isclose(np.linalg.det(r), 1.0)
    ray = np.array([(u - 160) / 500, (w - 120) / 520, 1.0])
    ray /= np.linalg.norm(ray)
    assert np.allclose(r @ [0.0, 0.0, 1.0], ray, atol=1e-12)
    assert np.isclose((np.trace(r) - 1.0) / 2.0, ray[2], atol=1e-12)  # cos of its angle


# ---------------------------------------------------------------------- pose in mesh units
@pytest.fixture(scope="module")
def bracket_db(tmp_path_factory):
    path = tmp_path_factory.mktemp("real") / "b.db"
    with viewdb.open(path, gap=30) as db:
        assert not db.ingest([sample("l_bracket"), sample("car")]).failed
    return path


def test_pose_in_mesh_units_from_a_perspective_render(bracket_db, tmp_path):
    """A pinhole render of l_bracket at a known pose (mesh units) is recognised and its
    pose recovered in the mesh's own frame and units through the intrinsics file."""
    width, height = 320, 240
    k = (400.0, 400.0, 171.5, 112.0)
    with viewdb.open(bracket_db, create=False) as db:
        info = db.object("l_bracket")
        r_true = GL_TO_CV @ view_rotation(47.0, 28.0, -20.0)
        t_norm = np.array([0.4, 0.2, 6.0])
        t_true = to_mesh_units(r_true, t_norm, info.centre, info.scale)
        window = Window(0.0, 0.0, float(width), width)
        mask, _ = get_pinhole_renderer().render(db.mesh("l_bracket"), r_true, t_norm, window.intrinsics(*k), width)
        mask = mask[:height]
        image = np.full((height, width, 3), 90, np.uint8)
        image[mask] = (200, 180, 160)
        (tmp_path / "k.json").write_text(json.dumps({"K": [[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1]]}))
        result = db.query(image, k=1, mask=mask, intrinsics=tmp_path / "k.json")
    best = result.results[0]
    assert best.object == "l_bracket"
    pose = best.pose
    assert pose is not None and pose.frame == "opencv" and pose.units == "mesh"
    assert pose.iou is not None and pose.iou > 0.9
    assert rotation_angle(pose.rotation, r_true) < 5.0
    distance = float(np.linalg.norm(t_true))
    assert np.linalg.norm(pose.translation - t_true) < 0.02 * distance, (pose.translation, t_true)
    out = result.to_dict()["results"][0]["pose"]
    assert out["units"] == "mesh" and out["refined"] == "silhouette"


# ---------------------------------------------------------------------- CLI
def test_cli_label_map_and_intrinsics_errors(bracket_db, tmp_path, capsys):
    img = tmp_path / "img.png"
    cv2.imwrite(str(img), np.full((60, 80, 3), 100, np.uint8))
    labels, _ = _labels(tmp_path)
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    assert main(["query", str(img), "--db", str(bracket_db), "--label-map", str(labels), "--label", "5"]) == 1
    err = capsys.readouterr().err.strip()
    assert "label 5 is not in the label map" in err and "\n" not in err
    assert main(["query", str(img), "--db", str(bracket_db), "--mask", str(labels),
                 "--intrinsics", str(bad)]) == 1
    err = capsys.readouterr().err.strip()
    assert str(bad) in err and "not valid JSON" in err and "\n" not in err
    assert main(["query", str(img), "--db", str(bracket_db), "--label-map", str(labels)]) == 2
