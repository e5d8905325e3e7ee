"""Ingest through the library API: counts, idempotence, failures, transactions, read-back."""

import shutil
import sqlite3

import numpy as np
import pytest

import viewdb
from tests.conftest import sample
from viewdb.camera import grid_views
from viewdb.catalogue.describe import describe_view, perspective_grid
from viewdb.catalogue.features import distance_curve
from viewdb.config import BuildConfig
from viewdb.storage import store as store_module


def test_small_db_stores_exactly_the_skim_plan(small_db):
    with viewdb.open(small_db, create=False) as db:
        objects = db.objects()
        assert [o.name for o in objects] == ["car", "l_bracket", "marked_cube", "mug"]
        for o in objects:
            assert o.views_grid == 36 and o.skimmed and o.symmetry is not None
            plan = db.view_plan(o.name)
            assert set(db.views(o.name)) == set(plan.kept)
            assert o.views_stored + o.empty_views == plan.views_stored < 36
            assert set(plan.mapping) == set(grid_views(60))
        rows = db.info().rows
    assert rows["views"] == rows["curves"] == rows["fourier_points"] == rows["sift_features"]


def test_stored_features_match_a_fresh_render_from_the_stored_mesh(small_db):
    with viewdb.open(small_db, create=False) as db:
        h, v = db.views("mug")[-1]
        stored = db.view("mug", h, v)
        assert not stored.regenerated
        fresh = describe_view(db.render("mug", h, v), db.config)
    np.testing.assert_array_equal(stored.curve, fresh.curve)
    np.testing.assert_array_equal(stored.fourier, fresh.fourier)
    np.testing.assert_array_equal(stored.descriptors, fresh.sift.descriptors)
    np.testing.assert_array_equal(stored.points3d, fresh.sift.points3d)
    assert stored.keypoints.shape[0] > 10  # the mug is textured


def test_render_from_db_equals_render_from_file(small_db):
    with viewdb.open(small_db, create=False) as db:
        from_db = db.render("car", 75, 15)
    from_file = viewdb.render_model(sample("car"), 75, 15, image_size=128)
    assert (from_db.mask != from_file.mask).sum() <= 2
    assert np.abs(from_db.color.astype(int) - from_file.color.astype(int)).mean() < 1.0


def test_reingest_is_a_noop_and_a_changed_file_replaces(tmp_path):
    src = tmp_path / "cone.off"
    shutil.copy(sample("cone"), src)
    path = tmp_path / "db.db"
    with viewdb.open(path, gap=90, image_size=64) as db:
        assert db.ingest([src]).counts()["added"] == 1
        first = db.objects()[0]
        again = db.ingest([src])
        assert again.counts() == {"added": 0, "replaced": 0, "unchanged": 1, "upgraded": 0, "failed": 0}
        assert db.objects()[0].created_at == first.created_at
        src.write_text(src.read_text().replace("OFF", "OFF\n# changed", 1))
        assert db.ingest([src]).counts()["replaced"] == 1
        assert len(db.objects()) == 1
        assert db.objects()[0].content_hash != first.content_hash


def test_renders_are_kept_read_only_and_forgotten_when_their_object_is_replaced(tmp_path):
    src = tmp_path / "shape.off"
    shutil.copy(sample("cone"), src)
    path = tmp_path / "db.db"
    with viewdb.open(path, gap=90, image_size=64) as db:
        db.ingest([src])
        first = db.render("shape", 30, 20)
        assert db.render("shape", 390, 20) is first  # the same view, kept
        with pytest.raises(ValueError):
            first.mask[0, 0] = True  # shared, so read-only
        shutil.copy(sample("pyramid"), src)  # another mesh under the same name
        assert db.ingest([src]).counts()["replaced"] == 1
        again = db.render("shape", 30, 20)
        assert again is not first and (again.mask != first.mask).any()


def test_a_bad_file_fails_alone_and_the_rest_go_in(tmp_path):
    bad = tmp_path / "broken.obj"
    bad.write_text("this is not an obj file\nf 1 2 3\n")
    path = tmp_path / "db.db"
    with viewdb.open(path, gap=90, image_size=64) as db:
        report = db.ingest([sample("cone"), bad, tmp_path / "missing.stl", sample("pyramid")])
        assert report.counts() == {"added": 2, "replaced": 0, "unchanged": 0, "upgraded": 0, "failed": 2}
        errors = [o.error for o in report.failed]
        assert any(str(bad) in e for e in errors) and any("missing.stl" in e for e in errors)
        assert [o.name for o in db.objects()] == ["cone", "pyramid"]


def test_a_failed_write_leaves_no_half_object(tmp_path, monkeypatch):
    path = tmp_path / "db.db"
    with viewdb.open(path, gap=90, image_size=64) as db:
        db.ingest([sample("cone")])
        real = store_module.encode_array
        calls = {"n": 0}

        def failing(arr):
            calls["n"] += 1
            if calls["n"] > 5:  # after the object and its views rows are inserted
                raise viewdb.StorageError("disk on fire")
            return real(arr)

        monkeypatch.setattr(store_module, "encode_array", failing)
        report = db.ingest([sample("pyramid")])
        assert report.counts()["failed"] == 1
    with sqlite3.connect(path) as conn:
        assert [r[0] for r in conn.execute("SELECT name FROM objects")] == ["cone"]
        n_views = conn.execute("SELECT count(*) FROM views").fetchone()[0]
        assert 0 < n_views == conn.execute("SELECT count(*) FROM curves").fetchone()[0]
        assert {r[0] for r in conn.execute("SELECT DISTINCT object_id FROM index_groups")} == {
            r[0] for r in conn.execute("SELECT id FROM objects")}
    with viewdb.open(path, create=False) as db:
        assert db.check().ok, db.check().problems  # R-trees hold exactly the cone's groups


def test_parallel_ingest_stores_the_same_as_serial(tmp_path):
    files = [sample(n) for n in ("cone", "pyramid", "chair")]
    a, b = tmp_path / "a.db", tmp_path / "b.db"
    with viewdb.open(a, gap=90, image_size=64) as db:
        db.ingest(files, jobs=1)
    ticks = []
    with viewdb.open(b, gap=90, image_size=64) as db:
        report = db.ingest(files, jobs=2, progress=ticks.append)
        assert report.counts()["added"] == 3
    per_object = 16 + len(perspective_grid(BuildConfig(gap=90)))  # the 90° grid, then pinholes
    assert ticks[-1].views_done == ticks[-1].views_total == 3 * per_object
    with viewdb.open(a) as da, viewdb.open(b) as dbb:
        for name in ("cone", "pyramid", "chair"):
            for h, v in da.views(name):
                x, y = da.view(name, h, v), dbb.view(name, h, v)
                np.testing.assert_array_equal(x.curve, y.curve)
                np.testing.assert_array_equal(x.descriptors, y.descriptors)


def test_unknown_object_and_view_raise_not_found(small_db):
    with viewdb.open(small_db, create=False) as db:
        with pytest.raises(viewdb.NotFound, match="no object named 'nope'"):
            db.views("nope")
        with pytest.raises(viewdb.NotFound):
            db.view("nope", 0, 0)
        off_grid = db.view("car", 7, 7)  # any view can be had: rendered on demand
        assert off_grid.regenerated and off_grid.stored_as is None


def test_curve_of_stored_view_is_the_curve_of_its_silhouette(small_db):
    with viewdb.open(small_db, create=False) as db:
        h, v = db.views("l_bracket")[3]
        view = db.render("l_bracket", h, v)
        stored = db.view("l_bracket", h, v)
    np.testing.assert_allclose(
        stored.curve, distance_curve(view.mask, db.config.features.curve_samples), atol=1e-6
    )


def test_a_write_failing_inside_the_r_tree_rolls_back_everything(tmp_path, monkeypatch):
    from viewdb.storage.spatial import FourierIndex

    path = tmp_path / "db.db"
    with viewdb.open(path, gap=90, image_size=64) as db:
        db.ingest([sample("cone")])
        with sqlite3.connect(path) as conn:
            pages_before = conn.execute("SELECT tier, page, data FROM rtree_pages ORDER BY 1, 2").fetchall()
        real = FourierIndex.insert_box

        def failing(self, *args):
            real(self, *args)  # one entry goes into the tree (and its pages), then it fails
            raise viewdb.StorageError("disk on fire")

        monkeypatch.setattr(FourierIndex, "insert_box", failing)
        assert db.ingest([sample("pyramid")]).counts()["failed"] == 1
        monkeypatch.setattr(FourierIndex, "insert_box", real)
        with sqlite3.connect(path) as conn:
            assert conn.execute("SELECT tier, page, data FROM rtree_pages ORDER BY 1, 2").fetchall() == pages_before
            assert [r[0] for r in conn.execute("SELECT name FROM objects")] == ["cone"]
        assert db.ingest([sample("pyramid")]).counts()["added"] == 1  # and it goes in later
        assert db.check().ok, db.check().problems
        q = distance_curve(db.render("pyramid", 30, 20).mask, db.config.features.curve_samples)
        assert db.search(q, k=1)[0][0].object == "pyramid"


def test_a_non_manifold_open_mesh_is_ingested_and_searchable(tmp_path):
    # three fins on one edge (an edge shared by three triangles) and an open fan: neither
    # closed nor manifold, but it has a silhouette, which is all recognition needs
    obj = tmp_path / "fins.obj"
    obj.write_text(
        "v 0 -1 0\nv 0 1 0\nv 1 0 0\nv -0.5 0 0.87\nv -0.5 0 -0.87\nv 0.3 0.2 0.9\n"
        "f 1 2 3\nf 1 2 4\nf 1 2 5\nf 2 3 6\n"
    )
    import trimesh

    assert not trimesh.load(str(obj), process=False).is_watertight
    with viewdb.open(tmp_path / "x.db", gap=90, image_size=64) as db:
        report = db.ingest([obj])
        assert not report.failed, report.failed
        curve = db.search_tier("full")[0].curves[0]
        hits, _ = db.search(curve, k=1)
        assert hits[0].object == "fins" and hits[0].distance == pytest.approx(0, abs=1e-9)
        assert db.check().ok


def test_query_refuses_keywords_that_say_otherwise_than_options(small_db, tmp_path):
    options = viewdb.QueryOptions(k=3, rotations=4)
    missing = tmp_path / "no-such-photo.png"
    with viewdb.open(small_db, create=False) as db:
        with pytest.raises(viewdb.QueryError) as refused:
            db.query(missing, options=options, k=4, colour=False)
        message = str(refused.value)
        assert "k=4 (options.k=3)" in message and "colour=False (options.colour=True)" in message
        assert "rotations" not in message  # left at its default: not a conflict
        with pytest.raises(viewdb.QueryError, match=r"fast_shortlist=9"):
            db.query(missing, options=options, fast_shortlist=9)
        with pytest.raises(viewdb.QueryError, match=r"intrinsics=array"):
            db.query(missing, options=options, intrinsics=np.eye(3))
        # the same value twice, or a keyword at its default, says nothing new: the photo is read
        with pytest.raises(viewdb.ImageError):
            db.query(missing, options=options, k=3, rotations=4)
        with pytest.raises(viewdb.ImageError):
            db.query(missing, options=options, plan="fast")
