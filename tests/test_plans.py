"""The three query plans: CS1 equals server exactly; CS2 searches the client's shortlist
exactly, or walks to real views; the client file holds the sparse tier only and is enough
for the client half."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import viewdb
import viewdb.http  # the wire messages (a subpackage, not imported by viewdb itself)
from tests.conftest import mixed_query_curves
from viewdb.catalogue.features import mirror_curve
from viewdb.search.bounds import dtw
from viewdb.search.knn import brute_force_knn


@pytest.fixture(scope="module")
def client_file(tiered_db, tmp_path_factory):
    out = tmp_path_factory.mktemp("client") / "client.db"
    with viewdb.open(tiered_db, create=False) as db:
        db.export_client(out, client_gap=60)
    return out


_queries = mixed_query_curves


def _same(a, b):
    assert [c.object for c in a] == [c.object for c in b]
    np.testing.assert_allclose([c.distance for c in a], [c.distance for c in b], rtol=0, atol=1e-9)


def test_cs1_equals_server_with_its_own_sparse_tier_and_with_a_client_file(tiered_db, client_file):
    rng = np.random.default_rng(11)
    with viewdb.open(tiered_db, create=False) as db, viewdb.open(client_file, create=False) as client:
        arrays, _ = db.search_tier("full")
        for q in _queries(db, rng, 16):
            for k, band in ((1, 6), (3, 2), (5, 0)):
                server = db.recognise(q, k, band=band, plan="server")
                _same(server.results, brute_force_knn(q, arrays, k, band))
                for side in (None, client):
                    cs1 = db.recognise(q, k, band=band, plan="cs1", client=side)
                    _same(cs1.results, server.results)
                    assert cs1.bytes_sent > 0 and cs1.bytes_received > 0


@settings(max_examples=40)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.integers(0, 8))
def test_cs1_equals_server_on_random_perturbations(tiered_db, client_file, seed, k, band):
    rng = np.random.default_rng(seed)
    with viewdb.open(tiered_db, create=False) as db, viewdb.open(client_file, create=False) as client:
        arrays, _ = db.search_tier("full")
        q = arrays.curves[rng.integers(len(arrays.curves))]
        q = q * rng.uniform(0.9, 1.1) + rng.normal(0, rng.choice([0.0, 0.02, 0.2]), 128)
        server = db.recognise(q, k, band=band, plan="server")
        _same(db.recognise(q, k, band=band, plan="cs1", client=client).results, server.results)


def _perspective_views(path):
    """``(object, azimuth, elevation, distance) -> curve`` of every perspective view of a file."""
    import sqlite3

    from viewdb.storage.codecs import decode_array

    with sqlite3.connect(path) as raw:
        rows = raw.execute("SELECT o.name, p.azimuth, p.elevation, p.distance, p.samples FROM perspective_views p"
                           " JOIN objects o ON o.id = p.object_id").fetchall()
    return {(n, h, v, d): decode_array(b, np.float32, (None,)).astype(np.float64) for n, h, v, d, b in rows}


def test_cs2_walks_to_real_views_never_better_than_exact(tiered_db, client_file):
    rng = np.random.default_rng(12)
    perspective = _perspective_views(tiered_db)
    keys = list(perspective)
    with viewdb.open(tiered_db, create=False) as db, viewdb.open(client_file, create=False) as client:
        agree = ended_on_perspective = 0
        queries = _queries(db, rng, 12)
        # and outlines as a camera from close by sees them: stored perspective views, jittered
        queries += [perspective[keys[i]] + rng.normal(0, 0.01, 128) for i in rng.choice(len(keys), 8, replace=False)]
        for q in queries:
            server = {c.object: c.distance for c in db.recognise(q, 6, plan="server").results}
            cs2 = db.recognise(q, 3, plan="cs2", client=client, cs2="walk")
            assert cs2.client_results and len(cs2.results) <= 3
            assert {c.object for c in cs2.results} <= {c.object for c in cs2.client_results}
            for c in cs2.results:
                # a real view (of the full grid, or a perspective one) at the reported
                # distance, never below the exact
                if c.camera_distance is None:
                    curve = db.view(c.object, c.azimuth, c.elevation).curve
                else:
                    curve = perspective[(c.object, c.azimuth, c.elevation, c.camera_distance)]
                    ended_on_perspective += 1
                target = mirror_curve(curve) if c.mirrored else curve
                assert dtw(q, target, 6) == pytest.approx(c.distance, abs=1e-5)
                assert c.object not in server or c.distance >= server[c.object] - 1e-9
            top = db.recognise(q, 1, plan="server").results[0].object
            agree += cs2.results[0].object == top
        assert agree >= len(queries) // 2  # a heuristic, but not a coin toss
        assert ended_on_perspective  # the walk's perspective finish was reached


def test_cs2_searches_the_client_shortlist_exactly(tiered_db, client_file):
    rng = np.random.default_rng(13)
    with viewdb.open(tiered_db, create=False) as db, viewdb.open(client_file, create=False) as client:
        arrays, _ = db.search_tier("full")
        names = [o.name for o in db.objects()]
        for q in _queries(db, rng, 10):
            for k, shortlist, band in ((1, 1, 6), (2, 2, 4), (3, 2, 6), (2, len(names), 5)):
                cs2 = db.recognise(q, k, band=band, plan="cs2", client=client, shortlist=shortlist)
                listed = {c.object for c in cs2.client_results}
                assert len(listed) == min(max(k, shortlist), len(names))
                # the brute force over the listed objects alone
                everything = brute_force_knn(q, arrays, len(names), band)
                _same(cs2.results, [nb for nb in everything if nb.object in listed][:k])
                if len(listed) == len(names):
                    _same(cs2.results, db.recognise(q, k, band=band, plan="server").results)


def test_a_shortlist_request_goes_over_the_wire_and_bad_ones_are_refused():
    from viewdb.http import RefineRequest

    c = viewdb.Candidate("mug", 0.5, 10.0, 20.0, False)
    request = RefineRequest.of_stack(np.ones((2, 128)), 6, 3, [c], shortlist=True)
    again = RefineRequest.from_dict(json.loads(json.dumps(request.to_dict())), 128)
    assert again.shortlist and again.client == [c] and again.curves.shape == (2, 128)
    assert not RefineRequest.from_dict(RefineRequest(np.ones(128), 6, 3, [c]).to_dict()).shortlist
    with pytest.raises(viewdb.QueryError, match="shortlist must be true or false"):
        RefineRequest.from_dict({**request.to_dict(), "shortlist": "yes"})


def test_client_file_holds_the_sparse_tier_only(tiered_db, client_file):
    with viewdb.open(client_file, create=False) as client, viewdb.open(tiered_db, create=False) as db:
        assert client.role == "client" and client.config.client_gap == 60
        assert client.check().ok, client.check().problems
        info = client.info()
        assert info.rows["sift_features"] == 0 and info.tiers["full"]["views"] == 0
        assert info.tiers["sparse"]["views"] == info.rows["views"] > 0
        assert [o.name for o in client.objects()] == [o.name for o in db.objects()]
        assert client_file.stat().st_size < 0.25 * db.info().file_bytes
        # its sparse tier is the 60° client grid of the full file
        from viewdb.search.grouping import tier_members

        for o in db.objects():
            stored = db.views(o.name)
            want = tier_members(stored, db.config.gap, 60, o.symmetry, o.skimmed)["sparse"]
            assert sorted(client.views(o.name)) == sorted(stored[i] for i in want)
        with pytest.raises(viewdb.ViewDBError, match="client database"):
            client.ingest([])
        with pytest.raises(viewdb.QueryError, match="client database"):
            client.server_tier().refine(viewdb.http.RefineRequest(np.ones(128), 6, 1, []))


def test_export_refuses_to_overwrite_and_leaves_nothing_when_it_fails(tiered_db, tmp_path, monkeypatch):
    out = tmp_path / "c.db"
    out.write_bytes(b"precious")
    with viewdb.open(tiered_db, create=False) as db:
        with pytest.raises(viewdb.ViewDBError, match="already exists"):
            db.export_client(out)
        assert out.read_bytes() == b"precious"
        with pytest.raises(viewdb.ViewDBError, match="client gap must be a multiple"):
            db.export_client(tmp_path / "d.db", client_gap=45)
        from viewdb.storage import export as export_module

        def boom(*args, **kwargs):
            raise viewdb.StorageError("disk on fire")

        monkeypatch.setattr(export_module, "write_groups", boom)
        with pytest.raises(viewdb.StorageError):
            db.export_client(tmp_path / "e.db")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.db"]


@settings(max_examples=80)
@given(st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=5),
    max_leaves=20,
))
def test_malformed_requests_get_a_query_error(data):
    for cls in (viewdb.http.RefineRequest, viewdb.http.WalkRequest):
        try:
            cls.from_dict(data)
        except viewdb.QueryError:
            pass


def test_requests_round_trip_through_json():
    req = viewdb.http.RefineRequest(np.linspace(0.5, 1.5, 128), 6, 3,
                               [viewdb.Candidate("mug", 0.25, 30.0, 60.0, True)])
    back = viewdb.http.RefineRequest.from_dict(json.loads(json.dumps(req.to_dict())))
    assert back.client == req.client and back.k == 3 and np.array_equal(back.curve, req.curve)
    for bad in ({**req.to_dict(), "curve": [1.0] * 127 + [float("nan")]},
                {**req.to_dict(), "k": 0}, {**req.to_dict(), "band": -1},
                {**req.to_dict(), "client": [{"object": "", "distance": 1, "azimuth": 0, "elevation": 0}]}):
        with pytest.raises(viewdb.QueryError):
            viewdb.http.RefineRequest.from_dict(json.loads(json.dumps(bad)))


@settings(max_examples=25)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(0, 8), st.sampled_from(["server", "cs1"]))
def test_curves_bounded_by_earlier_curves_merge_to_the_unbounded_merge(tiered_db, seed, k, band, plan):
    # how a photo's in-plane turns are searched: each with the merged results so far as
    # `prior`; the merged answer must be that of searching every curve alone
    rng = np.random.default_rng(seed)
    with viewdb.open(tiered_db, create=False) as db:
        arrays, _ = db.search_tier("full")
        base = arrays.curves[rng.integers(len(arrays.curves))]
        curves = [np.roll(base, int(s)) + rng.normal(0, 0.03, 128) for s in rng.integers(0, 128, 5)]
        merged: dict[str, float] = {}
        unbounded: dict[str, float] = {}
        for q in curves:
            prior = sorted((viewdb.Candidate(o, d, 0.0, 0.0, False) for o, d in merged.items()),
                           key=lambda c: (c.distance, c.object))[:k]
            for c in db.recognise(q, k, band=band, plan=plan, prior=prior).results:
                merged[c.object] = min(merged.get(c.object, np.inf), c.distance)
            for nb in brute_force_knn(q, arrays, k, band):
                unbounded[nb.object] = min(unbounded.get(nb.object, np.inf), nb.distance)
        top = lambda d: sorted(d.items(), key=lambda x: (x[1], x[0]))[:k]  # noqa: E731
        got, want = top(merged), top(unbounded)
        assert [o for o, _ in got] == [o for o, _ in want]
        np.testing.assert_allclose([d for _, d in got], [d for _, d in want], rtol=0, atol=1e-9)


def test_a_stale_client_file_cannot_make_cs1_wrong(tmp_path):
    # the client file is exported, then the full file replaces an object with another
    # shape under the same name: the client's distances for it no longer bound anything
    from tests.conftest import sample

    full, client = tmp_path / "full.db", tmp_path / "client.db"
    with viewdb.open(full, gap=30, image_size=96, client_gap=90) as db:
        db.ingest([sample(n) for n in ("arrow", "car", "mug", "chair")])
        db.export_client(client)
    moved = tmp_path / "arrow.off"  # same name, the cone's shape
    moved.write_bytes(sample("cone").read_bytes())
    with viewdb.open(full, create=False) as db, viewdb.open(client, create=False) as side:
        old_arrow = side.search_tier("sparse")[0]
        rows = [i for i, o in enumerate(old_arrow.owner) if old_arrow.names[o] == "arrow"]
        assert db.ingest([moved]).counts()["replaced"] == 1
        assert db.object("arrow").content_hash != side.object("arrow").content_hash
        checked = 0
        for row in rows[:6]:
            q = old_arrow.curves[row]  # a view of the old arrow: the stale client's best match
            mine, _ = side.client_candidates(q, 3)
            assert mine[0].object == "arrow" and mine[0].version.startswith(side.object("arrow").content_hash)
            server = db.recognise(q, 3, plan="server")
            cs1 = db.recognise(q, 3, plan="cs1", client=side)
            _same(cs1.results, server.results)
            checked += 1
        assert checked


def test_candidates_of_objects_the_server_lacks_are_not_bounds(tiered_db):
    with viewdb.open(tiered_db, create=False) as db:
        arrays, _ = db.search_tier("full")
        rng = np.random.default_rng(5)
        for _ in range(5):
            q = arrays.curves[rng.integers(len(arrays.curves))] + rng.normal(0, 0.03, 128)
            strangers = [viewdb.Candidate(f"gone{i}", 1e-6 * i, 0.0, 0.0, False) for i in range(3)]
            reply = db.server_tier().refine(viewdb.http.RefineRequest(q, 6, 3, strangers))[0]
            _same(reply.results, brute_force_knn(q, arrays, 3, 6))


def test_cs2_walk_leaves_out_candidates_of_objects_the_server_lacks(tiered_db, client_file):
    rng = np.random.default_rng(6)
    with viewdb.open(tiered_db, create=False) as db, viewdb.open(client_file, create=False) as client:
        for q in _queries(db, rng, 4):
            mine, _ = client.client_candidates(q, 3)
            gap = client.config.client_gap
            want = db.server_tier().walk(viewdb.http.WalkRequest(q, 6, 3, gap, mine))[0]
            assert want.results
            strangers = [viewdb.Candidate(f"gone{i}", 1e-6 * i, c.azimuth, c.elevation, False)
                         for i, c in enumerate(mine)]
            mixed = db.server_tier().walk(viewdb.http.WalkRequest(q, 6, 3, gap, strangers[:1] + mine + strangers[1:]))[0]
            assert mixed.results == want.results
            assert db.server_tier().walk(viewdb.http.WalkRequest(q, 6, 3, gap, strangers))[0].results == []


@pytest.mark.parametrize("other", [{"image_size": 80}, {"gap": 45}])
def test_a_client_built_with_other_settings_is_stale(tmp_path, other):
    # the same meshes, exported from a file whose curves were made otherwise: the client's
    # distances are of other curves (or of views the server lacks), so they bound nothing
    from tests.conftest import sample
    from viewdb.search.plans import RefineRequest, usable_client

    meshes = [sample(n) for n in ("arrow", "car", "mug")]
    built = {}
    for name, settings_ in (("same", {}), ("other", other)):
        opts = {"gap": 30, "image_size": 96, "client_gap": 90} | settings_
        with viewdb.open(tmp_path / f"{name}.db", **opts) as db:
            db.ingest(meshes)
            db.export_client(tmp_path / f"{name}_client.db")
        built[name] = tmp_path / f"{name}_client.db"
    with viewdb.open(tmp_path / "same.db", create=False) as db:
        server = db._catalogue.tier_reader()
        with server.snapshot() as reader:
            versions = reader.object_versions()
        q = db.search_tier("full")[0].curves[7]
        usable = {}
        for name, path in built.items():
            with viewdb.open(path, read_only=True) as side:
                mine, _ = side.client_candidates(q, 3)
                assert side.object("arrow").content_hash == db.object("arrow").content_hash
            usable[name] = usable_client(RefineRequest(q, 6, 3, mine), lambda n: True, versions)
        assert len(usable["same"]) == 3  # the same settings: every bound is used
        assert usable["other"] == []
        server_ans = db.recognise(q, 3, plan="server").results
        with viewdb.open(built["other"], read_only=True) as side:
            _same(db.recognise(q, 3, plan="cs1", client=side).results, server_ans)


# ---------------------------------------------------------------- CS2's perspective finish
def _fake_object(rng):
    """Curves of one object's grid views (30°) and of perspective views at some directions."""
    from viewdb.camera import grid_views

    grid = {hv: 1 + 0.3 * rng.standard_normal(128) for hv in grid_views(30)}
    perspective = {(h, v, d): 1 + 0.3 * rng.standard_normal(128)
                   for h, v in grid_views(30) for d in (2.0, 4.0) if rng.random() < 0.5}
    return grid, perspective


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from([0.0, 30.0, 45.0]))
def test_cs2_walk_ends_on_the_best_perspective_view_near_where_it_stopped(seed, radius):
    from viewdb.camera import camera_direction
    from viewdb.search.plans import WalkRequest, walk

    rng = np.random.default_rng(seed)
    grid, perspective = _fake_object(rng)
    q = 1 + 0.3 * rng.standard_normal(128)
    asked: list[tuple[float, float, float]] = []

    def near(name, h, v, r):
        asked.append((h, v, r))
        here = camera_direction(h, v)
        return [(ph, pv, d, c) for (ph, pv, d), c in perspective.items()
                if camera_direction(ph, pv) @ here >= np.cos(np.radians(r)) - 1e-9]

    start = [viewdb.Candidate("thing", 0.0, 90.0, 30.0, False)]
    request = WalkRequest(q, 6, 1, 90.0, start)
    plain, _ = walk(request, lambda n, h, v: grid[(h, v)], 30.0)
    finished, stats = walk(request, lambda n, h, v: grid[(h, v)], 30.0, perspective_near=near,
                           perspective_radius=radius)
    [(h, v, r)] = asked  # once, where the plain walk stopped
    assert (h, v, r) == (plain[0].azimuth, plain[0].elevation, radius)
    # brute force over the walked view and the perspective views near it, both orientations
    options = [(plain[0].distance, plain[0].azimuth, plain[0].elevation, None)]
    for ph, pv, d, c in near("thing", h, v, r):
        options.append((min(dtw(q, c, 6), dtw(q, mirror_curve(c), 6)), ph, pv, d))
    best = min(options, key=lambda o: o[0])
    assert finished[0].distance == pytest.approx(best[0]) and finished[0].distance <= plain[0].distance
    if finished[0].distance < plain[0].distance:
        assert (finished[0].azimuth, finished[0].elevation, finished[0].camera_distance) == best[1:]
    else:
        assert finished[0] == plain[0]
