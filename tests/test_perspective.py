"""Perspective views (schema revision 0004): rendering, skimming, storage, upgrade, search."""

from __future__ import annotations

import math
import shutil
import sqlite3

import cv2
import numpy as np
import pytest

import viewdb
from tests.conftest import ROOT, sample
from viewdb.camera import GL_TO_CV, camera_pose, grid_views, sphere_views
from viewdb.catalogue.describe import describe_perspective, perspective_grid
from viewdb.catalogue.features import distance_curve
from viewdb.catalogue.mesh import load_mesh
from viewdb.catalogue.pinhole import get_pinhole_renderer
from viewdb.catalogue.render import get_renderer
from viewdb.config import BuildConfig, IndexConfig, PerspectiveConfig, RenderConfig
from viewdb.errors import FeatureError, QueryError
from viewdb.search.plans import Candidate
from viewdb_cli.main import main

SAMPLES = 128


def rms(a, b) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)))


def euclid(a, b) -> float:
    return float(np.linalg.norm(np.asarray(a, np.float64) - np.asarray(b, np.float64)))


# ---------------------------------------------------------------- configuration
@pytest.mark.parametrize("distances", [(1.0,), (0.5, 3.0), (3.0, 3.0), (-2.0,)])
def test_perspective_distances_must_be_outside_the_bounding_sphere_and_distinct(distances):
    with pytest.raises(ValueError, match="perspective distances"):
        PerspectiveConfig(distances=distances)


@pytest.mark.parametrize("distances", ["none", "3,4,6", ("three",), 4.0])
def test_perspective_distances_that_are_not_numbers_are_refused_in_one_line(tmp_path, distances):
    db = tmp_path / "p.db"
    with pytest.raises(viewdb.ViewDBError, match="sequence of numbers") as info:
        viewdb.open(db, perspective=distances)
    assert str(db) in str(info.value) and "\n" not in str(info.value)
    assert not db.exists()


def test_perspective_gap_must_divide_360():
    with pytest.raises(ValueError, match="perspective gap"):
        PerspectiveConfig(gap=25)


@pytest.mark.parametrize("gap", [5, 10, 15, 20, 30, 40, 45, 60, 90])
@pytest.mark.parametrize("wanted", [10, 20, 30, 60])
def test_the_perspective_grid_is_the_coarsest_server_grid_multiple_needed(gap, wanted):
    config = BuildConfig(gap=gap, perspective=PerspectiveConfig(gap=wanted))
    g = config.perspective_gap
    ratio = g / gap
    assert abs(ratio - round(ratio)) < 1e-9 and abs(360 / g - round(360 / g)) < 1e-9
    assert g >= wanted - 1e-9
    # no smaller multiple of the server gap would do
    smaller = [m * gap for m in range(1, round(ratio)) if m * gap >= wanted and 360 % (m * gap) == 0]
    assert not smaller
    views = perspective_grid(config)
    assert len(views) == len(sphere_views(g)) * len(config.perspective.distances)
    server = set(grid_views(gap))
    assert all((h, v) in server for h, v, _ in views)


def test_a_configuration_from_before_revision_0004_reads_with_the_default_perspective_views():
    data = BuildConfig(gap=30).to_dict()
    del data["perspective"]
    assert BuildConfig.from_dict(data).perspective == PerspectiveConfig()
    off = BuildConfig(perspective=PerspectiveConfig(distances=()))
    assert BuildConfig.from_dict(off.to_dict()).perspective.enabled is False


def test_a_configuration_from_before_the_sphere_layout_keeps_its_square_grid():
    data = BuildConfig(gap=30).to_dict()
    assert data["perspective"].pop("grid") == "sphere"
    assert data["perspective"].pop("tolerance") == 0.01
    old = BuildConfig.from_dict(data)
    assert (old.perspective.grid, old.perspective.tolerance) == ("square", None)
    assert len(perspective_grid(old)) == len(grid_views(old.perspective_gap)) * len(old.perspective.distances)
    assert BuildConfig.from_dict(old.to_dict()) == old  # and keeps it when saved again
    with pytest.raises(ValueError, match="perspective grid"):
        PerspectiveConfig(grid="cube")


# ---------------------------------------------------------------- rendering
def _pinhole_reference(mesh, azimuth, elevation, distance, size):
    """The silhouette by projecting every triangle through the documented camera with
    numpy and filling it with OpenCV (no GL): the oracle for :meth:`perspective_mask`."""
    geometry = mesh.geometry
    pose = camera_pose(azimuth, elevation, distance)
    rot, centre = pose[:3, :3], pose[:3, 3]
    cam = (np.asarray(geometry.vertices, np.float64) - centre) @ rot  # world -> camera
    yfov = 2.0 * math.asin(1.0 / distance) * 1.05
    f = 1.0 / math.tan(yfov / 2.0)
    depth = -cam[:, 2]
    ndc = cam[:, :2] * f / depth[:, None]
    px = np.stack([(ndc[:, 0] + 1) * size / 2, (1 - ndc[:, 1]) * size / 2], axis=1)
    out = np.zeros((size, size), np.uint8)
    shift = 4
    tri = np.round((px[geometry.faces] - 0.5) * (1 << shift)).astype(np.int32)
    for t in tri:  # one by one: fillPoly of many overlapping polygons fills by parity
        cv2.fillConvexPoly(out, t, 1, lineType=cv2.LINE_8, shift=shift)
    return out.astype(bool)


@pytest.mark.parametrize("name, azimuth, elevation, distance", [
    ("chair", 30.0, 20.0, 3.0), ("car", 200.0, -40.0, 2.5), ("l_bracket", 95.0, 65.0, 4.0),
    ("arrow", 300.0, 10.0, 6.0),
])
def test_perspective_silhouettes_follow_the_pinhole_camera_of_the_convention(name, azimuth, elevation, distance):
    mesh = load_mesh(sample(name), name)
    size = 128
    renderer = get_renderer(RenderConfig(image_size=size))
    mask = renderer.perspective_mask(mesh, azimuth, elevation, distance)
    reference = _pinhole_reference(mesh, azimuth, elevation, distance, size)
    # the reference fills every pixel a triangle touches, GL only those whose centre it
    # covers: they agree to within one pixel of the outline
    grown = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    assert (mask & ~reference).sum() <= 0.01 * mask.sum()
    assert (reference & ~grown).sum() <= 0.01 * reference.sum()
    # and OpenGL, through the same camera, covers the same pixels (the mask is scan-converted
    # on the CPU)
    focal = (size / 2) / math.tan(math.asin(1.0 / distance) * 1.05)
    rotation = GL_TO_CV @ camera_pose(azimuth, elevation, distance)[:3, :3].T
    gl, _ = get_pinhole_renderer().render(mesh, rotation, np.array([0.0, 0.0, distance]),
                                          (focal, focal, (size - 1) / 2, (size - 1) / 2), size)
    assert gl.sum() > 100 and (gl ^ mask).sum() <= 2
    # and the orthographic renders of the same renderer are untouched by the pinhole camera
    ortho = renderer.render(mesh, azimuth, elevation, shaded=False).mask
    again = get_renderer(RenderConfig(image_size=size)).render(mesh, azimuth, elevation, shaded=False).mask
    assert np.array_equal(ortho, again)


def test_a_far_pinhole_sees_the_orthographic_outline_and_a_near_one_does_not():
    mesh = load_mesh(sample("chair"), "chair")
    renderer = get_renderer(RenderConfig(image_size=256))
    ortho = distance_curve(renderer.render(mesh, 30.0, 20.0, shaded=False).mask, SAMPLES)
    far = distance_curve(renderer.perspective_mask(mesh, 30.0, 20.0, 300.0), SAMPLES)
    near = distance_curve(renderer.perspective_mask(mesh, 30.0, 20.0, 2.5), SAMPLES)
    assert rms(far, ortho) < 0.01
    assert rms(near, ortho) > 3 * rms(far, ortho) and rms(near, ortho) > 0.02


def test_pinhole_distance_inside_the_bounding_sphere_is_refused():
    mesh = load_mesh(sample("cone"), "cone")
    with pytest.raises(ValueError, match="greater than 1"):
        get_renderer(RenderConfig(image_size=64)).perspective_mask(mesh, 0.0, 0.0, 0.9)


# ---------------------------------------------------------------- skimming
@pytest.mark.parametrize("tolerance", [None, 0.01])
@pytest.mark.parametrize("name", ["cone", "car"])
def test_perspective_skimming_leaves_out_only_views_within_the_tolerance_of_a_kept_one(name, tolerance):
    config = BuildConfig(gap=60, render=RenderConfig(image_size=96),
                         perspective=PerspectiveConfig(distances=(3.0, 5.0), grid="square",
                                                       tolerance=tolerance))
    mesh = load_mesh(sample(name), name)
    kept = describe_perspective(mesh, config)
    renderer = get_renderer(config.render)
    # None: the older files' rule, an RMS difference under the skimming sigma
    limit = config.skim.sigma * math.sqrt(SAMPLES) if tolerance is None else tolerance
    by_distance: dict[float, list] = {}
    for v in kept:
        by_distance.setdefault(v.distance, []).append(v)
    for h, v, d in perspective_grid(config):
        try:
            curve = distance_curve(renderer.perspective_mask(mesh, h, v, d), SAMPLES)
        except FeatureError:
            continue
        mine = [k for k in by_distance[d] if (k.azimuth, k.elevation) == (h, v)]
        if mine:
            assert np.allclose(mine[0].curve, curve, atol=1e-6)
        else:  # left out: some kept view at that distance has the same shape
            assert min(euclid(k.curve, curve) for k in by_distance[d]) < limit
    for d, views in by_distance.items():  # kept views are pairwise distinct shapes
        for i, a in enumerate(views):
            for b in views[:i]:
                assert euclid(a.curve, b.curve) >= limit, (d, a.azimuth, a.elevation, b.azimuth, b.elevation)
    grid = len(perspective_grid(config))
    if name == "cone":  # axisymmetric: its views around the axis repeat
        assert len(kept) < grid / 2
    else:
        assert len(kept) > grid / 2


# ---------------------------------------------------------------- storage and search
def test_perspective_views_are_in_the_full_tier_only_and_pass_the_check(tiered_db):
    with viewdb.open(tiered_db, read_only=True) as db:
        counts = {o.name: o.perspective_views for o in db.objects()}
        assert all(n > 0 for n in counts.values()), counts
        full, full_rows = db.search_tier("full")
        sparse, sparse_rows = db.search_tier("sparse")
        assert sum(1 for vid, _, _ in full_rows if vid < 0) == sum(counts.values())
        assert all(vid > 0 for vid, _, _ in sparse_rows)
        assert db.check().ok
        info = db.info().to_dict()
        assert info["rows"]["perspective_views"] == sum(counts.values())
        assert [o["perspective_views"] for o in info["objects"]] == [counts[o["name"]] for o in info["objects"]]


def _perspective_photo(db, name, azimuth, elevation, distance, inplane=0.0):
    """A close-up photo: the stored object's pinhole silhouette, white on black."""
    mask = get_renderer(db.config.render).perspective_mask(db.mesh(name), azimuth, elevation, distance)
    image = np.where(mask, 255, 0).astype(np.uint8)
    if inplane:
        size = image.shape[0]
        turn = cv2.getRotationMatrix2D(((size - 1) / 2, (size - 1) / 2), inplane, 1.0)
        image = cv2.warpAffine(image, turn, (size, size), flags=cv2.INTER_NEAREST)
    return np.stack([image] * 3, axis=-1)


def test_a_close_up_photo_is_matched_by_its_perspective_view(tiered_db):
    with viewdb.open(tiered_db, read_only=True) as db:
        photo = _perspective_photo(db, "chair", 60.0, 30.0, 3.0)
        result = db.query(photo, k=3, pose=False, colour=False, mask=photo[:, :, 0] > 0)
        top = result.results[0]
        assert top.object == "chair"
        assert top.camera_distance is not None and top.camera_distance in db.config.perspective.distances
        assert top.distance < 0.05
        assert result.to_dict()["results"][0]["view"]["camera_distance"] == top.camera_distance
        orthographic = [m for m in result.results if m.camera_distance is None]
        assert all(m.distance >= top.distance for m in orthographic)


def test_cs1_and_the_server_agree_when_perspective_views_win(tiered_db):
    with viewdb.open(tiered_db, read_only=True) as db:
        for name, h, v, d, turn in [("chair", 60.0, 30.0, 3.0, 0.0), ("car", 150.0, -30.0, 4.0, 30.0),
                                    ("arrow", 270.0, 60.0, 3.0, 90.0)]:
            photo = _perspective_photo(db, name, h, v, d, turn)
            mask = photo[:, :, 0] > 0
            server = db.query(photo, k=4, plan="server", pose=False, colour=False, mask=mask)
            cs1 = db.query(photo, k=4, plan="cs1", pose=False, colour=False, mask=mask)
            assert [(m.object, m.distance, m.camera_distance) for m in server.results] == \
                [(m.object, m.distance, m.camera_distance) for m in cs1.results]
            assert any(m.camera_distance is not None for m in server.results)


def test_replacing_an_object_replaces_its_perspective_views(tmp_path):
    config = BuildConfig(gap=60, render=RenderConfig(image_size=64), index=IndexConfig(client_gap=120))
    path = tmp_path / "r.db"
    model = tmp_path / "thing.off"
    shutil.copy(sample("cone"), model)
    with viewdb.open(path, config=config) as db:
        db.ingest([model])
        before = db.object("thing").perspective_views
    shutil.copy(sample("pyramid"), model)
    with viewdb.open(path, create=False) as db:
        assert db.ingest([model]).counts()["replaced"] == 1
        after = db.object("thing").perspective_views
        assert db.check().ok
    with sqlite3.connect(path) as conn:
        rows = conn.execute("SELECT count(*), count(DISTINCT object_id) FROM perspective_views").fetchone()
    assert rows == (after, 1)
    assert before != after  # an axisymmetric cone skims to fewer views than a pyramid


def test_an_old_file_gains_perspective_views_by_ingesting_its_files_again(tmp_path, capsys):
    path = tmp_path / "old.db"
    shutil.copy(ROOT / "tests" / "data" / "schema_0001.db", path)
    files = [str(sample("cone")), str(sample("pyramid"))]
    with viewdb.open(path, create=False) as db:
        assert [o.perspective_views for o in db.objects()] == [0, 0]
        assert db.check().ok  # migrated, and whole without them
    with sqlite3.connect(path) as conn:
        ortho = conn.execute("SELECT v.id, v.azimuth, v.elevation, c.samples FROM views v"
                             " JOIN curves c ON c.view_id = v.id ORDER BY v.id").fetchall()
    assert main(["ingest", *files, "--db", str(path)]) == 0
    assert "2 upgraded" in capsys.readouterr().out
    with viewdb.open(path, create=False) as db:
        counts = [o.perspective_views for o in db.objects()]
        assert all(n > 0 for n in counts)
        assert db.check().ok
        again = db.ingest(files)
        assert again.counts()["unchanged"] == 2 and again.counts()["upgraded"] == 0
        grid = perspective_grid(db.config)
        assert all(n <= len(grid) for n in counts)
    with sqlite3.connect(path) as conn:
        assert conn.execute("SELECT v.id, v.azimuth, v.elevation, c.samples FROM views v"
                            " JOIN curves c ON c.view_id = v.id ORDER BY v.id").fetchall() == ortho


def test_a_configuration_without_perspective_views_stores_none(tmp_path):
    config = BuildConfig(gap=60, render=RenderConfig(image_size=64),
                         perspective=PerspectiveConfig(distances=()))
    with viewdb.open(tmp_path / "n.db", config=config) as db:
        db.ingest([sample("car")])
        db.ingest([sample("car")])  # nothing to upgrade either
        assert db.object("car").perspective_views == 0
        _, rows = db.search_tier("full")
        assert all(vid > 0 for vid, _, _ in rows)


# ---------------------------------------------------------------- wire
def test_candidates_carry_the_camera_distance_and_reject_bad_ones():
    c = Candidate("chair", 0.1, 60.0, 30.0, False, "abc123", 3.0)
    assert Candidate.from_dict(c.to_dict()) == c
    plain = Candidate("chair", 0.1, 60.0, 30.0, True)
    assert "camera_distance" not in plain.to_dict() and Candidate.from_dict(plain.to_dict()) == plain
    for bad in (1.0, 0.5, "3", float("nan"), True):
        with pytest.raises(QueryError, match="camera_distance"):
            Candidate.from_dict({**c.to_dict(), "camera_distance": bad})


# ---------------------------------------------------------------- choosing them
def test_the_cli_sets_the_perspective_distances_of_a_new_file_and_refuses_another(tmp_path, capsys):
    path = tmp_path / "few.db"
    assert main(["ingest", str(sample("cone")), "--db", str(path), "--gap", "60",
                 "--image-size", "64", "--perspective", "2.5,5"]) == 0
    with viewdb.open(path, create=False) as db:
        assert db.config.perspective.distances == (2.5, 5.0)
        with sqlite3.connect(path) as conn:
            stored = {d for (d,) in conn.execute("SELECT DISTINCT distance FROM perspective_views")}
        assert stored == {2.5, 5.0}
    capsys.readouterr()
    assert main(["ingest", str(sample("pyramid")), "--db", str(path), "--perspective", "none"]) == 1
    assert "was built with --perspective 2.5,5, not none" in capsys.readouterr().err
    with viewdb.open(path, create=False) as db:  # refused before anything was written
        assert [o.name for o in db.objects()] == ["cone"]
    none = tmp_path / "none.db"
    assert main(["ingest", str(sample("cone")), "--db", str(none), "--gap", "60",
                 "--image-size", "64", "--perspective", "none"]) == 0
    with viewdb.open(none, create=False) as db:
        assert not db.config.perspective.enabled and db.object("cone").perspective_views == 0
    for bad, code in (("3,x", 2), ("0.5", 2), ("3,3", 2)):  # out of range: usage errors, as --gap
        assert main(["ingest", str(sample("cone")), "--db", str(tmp_path / "bad.db"),
                     "--perspective", bad]) == code
        assert not (tmp_path / "bad.db").exists()


def test_the_perspective_grid_gap_is_chosen_for_a_new_file_and_kept(tmp_path, capsys):
    """``--perspective-gap`` sets a new file's perspective grid (rounded up to a multiple of
    ``--gap``): a finer one stores more perspective views; another gap for an existing
    file is refused before anything is written; a gap that does not divide 360 is
    refused as ``--gap``'s is."""
    counts = {}
    for pgap in (60, 120):
        path = tmp_path / f"p{pgap}.db"
        assert main(["ingest", str(sample("cone")), "--db", str(path), "--gap", "60",
                     "--image-size", "64", "--perspective", "4", "--perspective-gap", str(pgap)]) == 0
        with viewdb.open(path, create=False, perspective_gap=pgap) as db:
            assert db.config.perspective_gap == pgap
            counts[pgap] = db.object("cone").perspective_views
    assert counts[60] > counts[120] > 0
    with viewdb.open(tmp_path / "p60.db", create=False, perspective_gap=40) as db:  # rounds to 60
        assert db.config.perspective_gap == 60
    capsys.readouterr()
    assert main(["ingest", str(sample("pyramid")), "--db", str(tmp_path / "p60.db"),
                 "--perspective-gap", "120"]) == 1
    assert "was built with --perspective-gap 60, not 120" in capsys.readouterr().err
    with viewdb.open(tmp_path / "p60.db", create=False) as db:
        assert [o.name for o in db.objects()] == ["cone"]
    capsys.readouterr()
    assert main(["ingest", str(sample("cone")), "--db", str(tmp_path / "bad.db"), "--perspective-gap", "7"]) == 1
    assert "perspective gap must divide 360 evenly, got 7" in capsys.readouterr().err  # as --gap 7
    assert not (tmp_path / "bad.db").exists()
