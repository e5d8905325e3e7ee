"""Queries from images, end to end: segmentation, in-plane turns, plans, pose, CLI JSON."""

import json

import cv2
import numpy as np
import pytest

import viewdb
from viewdb.bench.photos import composite_photo
from viewdb.pose.frames import rotation_angle, view_rotation
from viewdb_cli.main import main


def photo(db, name, h, v, turn=0.0, scale=1.0, shift=(0, 0), background=200):
    """An off-grid render turned in-plane by ``turn`` (counter-clockwise), scaled, shifted,
    on a plain background; and the model-to-camera rotation it shows."""
    img, _ = composite_photo(db.render(name, h, v), turn=turn, scale=scale, shift=shift,
                             background=background)
    return img, view_rotation(h, v, turn)


@pytest.fixture(scope="module")
def query_db(tmp_path_factory):
    from tests.conftest import sample

    path = tmp_path_factory.mktemp("q") / "q.db"
    with viewdb.open(path, gap=30, image_size=256) as db:
        report = db.ingest([sample(n) for n in ("cube_dice", "car", "mug", "l_bracket", "chair", "arrow")])
    assert not report.failed
    return path


@pytest.mark.parametrize("name, h, v, turn, scale", [
    ("cube_dice", 37, 22, 25, 0.8), ("car", 200, 15, -30, 0.9),
    # texture-less, and its matched view's front/back twins share an outline ~20° from the
    # truth: found among the object's next nearest views (NEAR_VIEWS; 72° off without them)
    ("chair", 110, 40, 60, 0.7),
    ("l_bracket", 200, 30, 40, 0.8),
])
def test_an_off_grid_turned_scaled_photo_is_recognised_and_posed(query_db, name, h, v, turn, scale):
    with viewdb.open(query_db, create=False) as db:
        img, truth = photo(db, name, h, v, turn, scale, shift=(9, -7))
        result = db.query(img, k=3)
        best = result.results[0]
        assert best.object == name
        assert best.pose is not None
        # symmetric objects: the error is to the nearest same-shape pose
        err = min(rotation_angle(best.pose.rotation, view_rotation(p.azimuth, p.elevation, 0) @
                                 view_rotation(h, v, 0).T @ truth)
                  for p in db.candidate_poses(name, round(h / 30) * 30 % 360, round(v / 30) * 30 % 360)
                  ) if name != "cube_dice" else rotation_angle(best.pose.rotation, truth)
        assert err < 20.0, (best.pose, err)
        assert result.timing_ms["total"] >= result.timing_ms["segment"] > 0


def test_cs1_gives_the_server_answer_for_images(query_db, tmp_path):
    client = tmp_path / "client.db"
    with viewdb.open(query_db, create=False) as db:
        db.export_client(client, client_gap=90)
        with viewdb.open(client, create=False) as side:
            for name, h, v in (("mug", 14, 50), ("arrow", 300, 200), ("l_bracket", 77, 333)):
                img, _ = photo(db, name, h, v, 15, 0.9)
                server = db.query(img, k=3, pose=False)
                cs1 = db.query(img, k=3, plan="cs1", client=side, pose=False)
                assert [(r.object, r.distance) for r in cs1.results] == \
                    [(r.object, pytest.approx(r.distance, abs=1e-9)) for r in server.results]
                assert cs1.transfer["round_trips"] == 1 and cs1.transfer["bytes_sent"] > 0  # one stack of 12 turns
                cs2 = db.query(img, k=3, plan="cs2", client=side, pose=False)
                assert cs2.results and all(r.distance >= server.results[0].distance - 1e-9
                                           for r in cs2.results)


def test_query_json_has_the_contract_shape(query_db, tmp_path, capsys):
    with viewdb.open(query_db, create=False) as db:
        img, _ = photo(db, "mug", 40, 20, 10, 0.9)
    path = tmp_path / "mug.png"
    cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    assert main(["query", str(path), "--db", str(query_db), "-k", "2", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["image"] == str(path) and data["plan"] == "fast" and data["k"] == 2  # the default plan
    assert [r["rank"] for r in data["results"]] == [1, 2]
    r = data["results"][0]
    assert r["object"] == "mug" and isinstance(r["distance"], float)
    assert set(r["view"]) >= {"azimuth", "elevation", "mirrored"}
    pose = r["pose"]
    assert set(pose) >= {"azimuth", "elevation", "inplane", "method", "inliers", "rotation", "translation"}
    assert pose["method"] in ("sift", "shape") and isinstance(pose["inliers"], int)
    assert np.allclose(np.array(pose["rotation"]) @ np.array(pose["rotation"]).T, np.eye(3), atol=1e-6)
    assert len(pose["translation"]) == 3
    assert set(data["timing_ms"]) >= {"segment", "client", "server", "pose", "total"}


def test_pose_top_poses_only_the_best_results(query_db, tmp_path, capsys):
    with viewdb.open(query_db, create=False) as db:
        img, _ = photo(db, "car", 200, 15, -30, 0.9)
        every = db.query(img, k=3, pose_top=None)
        top = db.query(img, k=3)  # the top result only, by default
        assert [m.object for m in top.results] == [m.object for m in every.results]
        assert all(m.pose is not None for m in every.results)
        assert top.results[0].pose is not None and np.allclose(top.results[0].pose.rotation,
                                                               every.results[0].pose.rotation)
        assert [m.pose for m in top.results[1:]] == [None, None]
        assert all(m.pose is None for m in db.query(img, k=3, pose_top=0).results)
        with pytest.raises(viewdb.QueryError, match="pose_top"):
            db.query(img, k=3, pose_top=-1)
    path = tmp_path / "car.png"
    cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    assert main(["query", str(path), "--db", str(query_db), "-k", "2", "--pose-top", "1", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["results"][0]["pose"] is not None and data["results"][1]["pose"] is None


@pytest.mark.parametrize("content, problem", [
    (b"", "empty"), (b"not an image at all", ""), (None, "no object"),
])
def test_bad_images_exit_1_with_one_line(query_db, tmp_path, capsys, content, problem):
    path = tmp_path / "bad.png"
    if content is None:  # a readable image with nothing in it
        cv2.imwrite(str(path), np.full((64, 64, 3), 180, np.uint8))
    else:
        path.write_bytes(content)
    assert main(["query", str(path), "--db", str(query_db)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"viewdb: {path}") and "\n" not in err and problem in err.lower()
    assert main(["query", str(tmp_path / "missing.png"), "--db", str(query_db)]) in (1, 2)
