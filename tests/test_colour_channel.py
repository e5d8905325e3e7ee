"""The colour channel (viewdb.search.colour_index): every coloured object's stored colours
ranked against a cut-out's, checked against brute force, read from a real file, and used
by a box-prompted query."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import viewdb
from viewdb.bench.photos import composite_photo
from viewdb.config import RecognitionConfig
from viewdb.errors import QueryError
from viewdb.recognition.colour import colour_distance
from viewdb.recognition.options import QueryOptions
from viewdb.search.colour_index import ColourIndex, ColourMatch, merge_colour_matches
from viewdb.storage.appearances import decode_record, decode_signature, encode_record


@st.composite
def _catalogue(draw):
    """Signatures of a few objects' views (some empty), and a query signature."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    objects = draw(st.integers(1, 6))
    names, views, sigs = [], [], []
    for o in range(objects):
        for v in range(draw(st.integers(1, 5))):
            names.append(f"obj{o}")
            views.append((30.0 * v, 30.0 * o))
            sig = rng.random((16, 16)) * (rng.random((16, 16)) < 0.2)
            sigs.append(sig if draw(st.booleans()) or v else np.zeros((16, 16)))
    query = rng.random((16, 16)) * (rng.random((16, 16)) < 0.3)
    return names, np.asarray(views), np.asarray(sigs), query


def _brute_force(names, sigs, query):
    """Each object's best view distance by :func:`colour_distance` (normalised signatures)."""
    def norm(s):
        s = np.asarray(s, np.float32)
        return s / s.sum() if s.sum() > 0 else s

    best = {}
    for name, sig in zip(names, sigs, strict=True):
        best[name] = min(best.get(name, 2.0), colour_distance(norm(query), norm(sig)))
    return best


@settings(max_examples=60, deadline=None)
@given(data=_catalogue(), n=st.integers(1, 8))
def test_the_index_ranks_objects_as_brute_force_does(data, n):
    names, views, sigs, query = data
    found = ColourIndex(names, views, sigs).nearest(query, n)
    best = _brute_force(names, sigs, query)
    assert len(found) == min(n, len(best)) and len({m.object for m in found}) == len(found)
    assert [m.distance for m in found] == pytest.approx(sorted(best.values())[:len(found)], abs=1e-5)
    for m in found:
        assert m.distance == pytest.approx(best[m.object], abs=1e-5)
        # the view named is one of the object's with that distance
        rows = [i for i, name in enumerate(names) if name == m.object and tuple(views[i]) == (m.azimuth, m.elevation)]
        assert rows and min(_brute_force([names[i] for i in rows], sigs[rows], query).values()) == \
            pytest.approx(m.distance, abs=1e-5)


@settings(max_examples=40, deadline=None)
@given(data=_catalogue(), n=st.integers(1, 8), cut=st.integers(0, 6))
def test_merged_shards_answer_as_one_index(data, n, cut):
    names, views, sigs, query = data
    whole = ColourIndex(names, views, sigs).nearest(query, n)
    parts = []
    for keep in (lambda name: int(name[3:]) < cut, lambda name: int(name[3:]) >= cut):
        rows = [i for i, name in enumerate(names) if keep(name)]
        parts.append(ColourIndex([names[i] for i in rows], views[rows], sigs[rows]).nearest(query, n))
    merged = merge_colour_matches(parts, n)
    assert [m.object for m in merged] == [m.object for m in whole]
    assert [m.distance for m in merged] == pytest.approx([m.distance for m in whole])


def test_bad_queries_are_refused():
    index = ColourIndex(["a"], np.zeros((1, 2)), np.ones((1, 16, 16)))
    with pytest.raises(QueryError, match="at least 1"):
        index.nearest(np.ones((16, 16)), 0)
    with pytest.raises(QueryError, match="bins"):
        index.nearest(np.ones((8, 8)), 1)
    with pytest.raises(QueryError, match="not negative"):
        index.nearest(-np.ones((16, 16)), 1)
    assert ColourIndex([], np.zeros((0, 2)), np.zeros((0, 256))).nearest(np.ones((16, 16)), 3) == []
    assert ColourMatch.from_dict(ColourMatch("a", 0.5, 10.0, 20.0).to_dict()) == ColourMatch("a", 0.5, 10.0, 20.0)


def test_a_signature_is_read_without_the_rest_of_its_record(tiered_db):
    with viewdb.open(tiered_db, read_only=True) as db:
        catalogue = db._catalogue
        for name in ("mug", "l_bracket"):
            record = catalogue.appearance(name, 30.0, 60.0)
            data = encode_record(record)
            decoded = decode_record(data, 30.0, 60.0, record.mask.shape[0])
            if decoded.signature is None:
                assert decode_signature(data) is None
            else:
                assert np.array_equal(decode_signature(data), decoded.signature)
        with pytest.raises(viewdb.StorageError, match="lengths"):  # bytes after a record without one
            decode_signature(encode_record(catalogue.appearance("l_bracket", 0.0, 0.0)) + b"xx")
        with pytest.raises(viewdb.StorageError, match="colour signature"):  # a damaged signature
            decode_signature(encode_record(catalogue.appearance("mug", 0.0, 0.0))[:-4])


def test_the_file_s_index_holds_the_coloured_objects_grid_views(tiered_db):
    """Read from a real file: the coloured objects only, on the colour grid, each row the
    signature the view's appearance record holds."""
    with viewdb.open(tiered_db, read_only=True) as db:
        catalogue = db._catalogue
        index = catalogue.colour_index()
        coloured = {o.name for o in db.objects() if catalogue.appearance(o.name, 0.0, 0.0).colour() is not None}
        assert set(index.objects) == coloured and "mug" in coloured and "l_bracket" not in coloured
        assert all(h % 30 == 0 and v % 30 == 0 for h, v in index.views)
        for row in range(0, len(index), max(1, len(index) // 12)):
            name, (h, v) = index.names[row], index.views[row]
            sig = catalogue.appearance(name, h, v).colour()
            assert np.allclose(index.roots[row] ** 2, sig.ravel(), atol=1e-6)
            best = index.nearest(sig, 1)[0]
            assert best.distance == pytest.approx(0.0, abs=1e-6)


def _box(mask, pad=3):
    rows, cols = np.nonzero(mask)
    return [int(cols.min()) - pad, int(rows.min()) - pad, int(cols.max()) + 1 + pad, int(rows.max()) + 1 + pad]


def test_a_boxed_object_is_ranked_by_its_colours_first(tiered_db):
    """A box around the mug in a photo with colour: the colour channel names the mug,
    the result carries its colour distance, and its pose is that of its best view."""
    with viewdb.open(tiered_db, read_only=True) as db:
        img, mask = composite_photo(db.render("mug", 47, 22), turn=30, scale=0.8, background=190)
        answer = db.query(img, boxes=[_box(mask)], k=3, pose_top=1)
        top = answer.objects[0].results
        assert top[0].object == "mug" and top[0].colour is not None and top[0].pose is not None
        assert [m.colour_score for m in top] == sorted(m.colour_score for m in top)
        # without the channel the same box is re-ranked from the outline's deeper pool
        off = db.query(img, boxes=[_box(mask)], options=QueryOptions(
            k=3, pose=False, recognition=RecognitionConfig(colour_pool=0)))
        assert off.objects[0].results[0].shape_fit is not None
        assert all(m.shape_fit is None for m in top)


def test_a_grey_photo_falls_back_to_the_outline(small_db):
    """A photo without colour: the outline's pool, re-ranked by shape fit."""
    with viewdb.open(small_db, read_only=True) as db:
        img, mask = composite_photo(db.render("l_bracket", 47, 22), turn=30, scale=0.8, background=190)
        grey = cv2.cvtColor(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)
        answer = db.query(grey, boxes=[_box(mask)], k=2, pose=False).objects[0].results
        assert all(m.colour is None for m in answer) and all(m.shape_fit is not None for m in answer)


def test_a_server_that_predates_the_channel_names_no_object():
    """A server without ``/colour-ranking`` (404) names nothing, so the query takes the
    outline's path; any other refusal is still an error."""
    import json
    import threading
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    class Old(BaseHTTPRequestHandler):
        def do_POST(self):  # noqa: N802 - the stdlib's name
            self.rfile.read(int(self.headers.get("Content-Length", 0)))
            status = 404 if self.path == "/colour-ranking" else 503
            body = json.dumps({"error": "Not Found", "status": status}).encode()
            self.send_response(status)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):
            pass

    httpd = ThreadingHTTPServer(("127.0.0.1", 0), Old)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        with viewdb.RemoteServer(f"http://127.0.0.1:{httpd.server_address[1]}") as remote:
            assert remote.colour_ranking(np.ones((16, 16), np.float32) / 256, 3)[0] == []
            with pytest.raises(viewdb.ServerError) as refused:
                remote.colours([("mug", 0.0, 0.0)])
            assert refused.value.status == 503
    finally:
        httpd.shutdown()
        httpd.server_close()


def test_a_catalogue_without_colour_takes_the_outline_s_deeper_path(tmp_path):
    """No coloured mesh in the file: the channel names nothing, so a box in a photo with
    colour is searched as deep as ``prompt_pool`` and re-ranked by shape fit."""
    from tests.conftest import sample

    path = tmp_path / "grey.db"
    with viewdb.open(path, gap=60, image_size=96) as db:
        assert not db.ingest([sample("l_bracket"), sample("box_long"), sample("cone")]).failed
    with viewdb.open(path, read_only=True) as db:
        assert len(db._catalogue.colour_index()) == 0
        img, mask = composite_photo(db.render("l_bracket", 47, 22), turn=30, scale=0.8, background=190)
        img[mask] = (200, 40, 30)  # a red part: a photo with colour
        answer = db.query(img, boxes=[_box(mask)], k=2, pose=False).objects[0].results
        assert all(m.shape_fit is not None for m in answer)


@st.composite
def _ranking_and_looks(draw):
    """A colour ranking (nearest first, ties by name) and look distances for some of its
    objects and for others the ranking left out."""
    count = draw(st.integers(0, 12))
    distances = sorted(draw(st.lists(st.floats(0.0, 1.0), min_size=count, max_size=count)))
    matches = [ColourMatch(f"obj{i:02d}", d, 0.0, 0.0) for i, d in enumerate(distances)]
    looked = [m.object for m in matches if draw(st.booleans())] + [f"other{i}" for i in range(draw(st.integers(0, 3)))]
    looks = {name: draw(st.floats(0.0, 5.0)) for name in looked}
    return matches, looks


@settings(max_examples=200, deadline=None)
@given(data=_ranking_and_looks(), pool=st.integers(0, 14), weight=st.sampled_from([0.0, 0.2, 1.0]),
       reference=st.sampled_from([0.0, 0.02, 0.5]))
def test_the_channel_names_the_objects_whose_colour_and_look_are_least(data, pool, weight, reference):
    """named_by_look keeps the colour_pool objects of the ranking with the least colour
    distance + look_weight × (look distance − the look_reference quantile), in the
    ranking's order: no object left out scores less than one kept."""
    from viewdb.recognition.pipeline import named_by_look

    matches, looks = data
    recognition = RecognitionConfig(colour_pool=pool, look_weight=weight, look_reference=reference)
    named = named_by_look(matches, looks, recognition)
    base = float(np.quantile(list(looks.values()), reference)) if looks else 0.0

    def score(m):
        return m.distance + (weight * (looks.get(m.object, base) - base) if looks else 0.0)

    assert len(named) == min(pool, len(matches))
    assert named == [m for m in matches if m in named]  # a subset, in the ranking's order
    left = [m for m in matches if m not in named]
    for kept in named:
        for out in left:
            assert (score(kept), kept.object) <= (score(out), out.object)
    if not looks or weight == 0:
        assert named == matches[:pool]
