"""``viewdb serve`` over real HTTP on loopback: remote queries equal local ones exactly;
bad input gets a 4xx with a one-line JSON error and the server stays up.

One server (two worker processes, a bearer token) is shared by the whole module.
"""

from __future__ import annotations

import base64
import io
import json
import shutil
import struct
import zlib

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from PIL import Image

import viewdb
from benchmarks.support.serving import ServerProcess, multipart, request
from tests.conftest import mixed_query_curves
from viewdb.bench.photos import composite_photo
from viewdb.catalogue.look import LOOK_DIMS, look_features
from viewdb.http import models
from viewdb.http.wire import (
    ColourRankingReply,
    ColourReply,
    FitReply,
    LookReply,
    PoseReply,
    PoseRequest,
    decode_query,
    encode_query,
)
from viewdb.pose.estimate import QueryView
from viewdb.recognition.colour import colour_signature
from viewdb.search.plans import MAX_K
from viewdb.storage.ann_file import ann_file_path
from viewdb_cli.main import main

TOKEN = "s3cret-token"
#: Short header and body deadlines for the slow-client tests.
HEADER_TIMEOUT, BODY_TIMEOUT = 2.0, 3.0


@pytest.fixture(scope="module")
def files(tiered_db, tmp_path_factory):
    """The served copy of the full db (checked unchanged at the end) and a client file."""
    folder = tmp_path_factory.mktemp("http")
    served = folder / "served.db"
    shutil.copy(tiered_db, served)
    # and the fast plan's index, which the ingest wrote next to it (a copy is the same file)
    shutil.copy(ann_file_path(tiered_db, "full"), ann_file_path(served, "full"))
    client = folder / "client.db"
    with viewdb.open(tiered_db, create=False) as db:
        db.export_client(client)
    return served, client


@pytest.fixture(scope="module")
def server(files):
    served, _ = files
    before = served.read_bytes(), served.stat().st_mtime_ns
    srv = ServerProcess(served, workers=2, token=TOKEN,
                        extra=("--header-timeout", str(HEADER_TIMEOUT), "--body-timeout", str(BODY_TIMEOUT)))
    with srv:
        yield srv
        assert srv.alive(), srv.log()
        assert srv.worker_pids() <= srv.pids, "a worker was restarted (crashed)"
    assert srv.returncode == 130, (srv.returncode, srv.log())  # Ctrl-C: "interrupted"
    assert (served.read_bytes(), served.stat().st_mtime_ns) == before


@pytest.fixture
def remote(server):
    with viewdb.RemoteServer(server.url, token=TOKEN) as r:
        yield r


def photo(db, name, h, v, turn):
    return composite_photo(db.render(name, h, v), turn=turn, scale=0.85, background=190)[0]


_curves = mixed_query_curves


# ----------------------------------------------------------------------------- exactness
def test_remote_queries_equal_local_ones_for_every_plan(tiered_db, files, remote):
    _, client_path = files
    with viewdb.open(tiered_db, create=False) as full, viewdb.open(client_path, read_only=True) as client:
        # the mug and the car are coloured, the bracket grey (no colour re-ranking)
        # (pose_top 1: the server poses the first result only)
        cases = [("mug", 47, 22, 30, "cs1", True, True, None), ("car", 200, 15, -40, "cs2", True, True, 1),
                 ("l_bracket", 120, 40, 10, "server", False, False, None)]
        for name, h, v, turn, plan, pose, coloured, top in cases:
            img = photo(full, name, h, v, turn)
            kw = dict(k=2, plan=plan, rotations=6, pose=pose, pose_top=top)
            local = full.query(img, client=client if plan != "server" else None, **kw)
            there = client.query(img, server=remote, **kw)
            assert there.to_dict()["results"] == local.to_dict()["results"], plan
            assert len(there.results) == 2
            if pose:
                assert there.results[0].pose is not None
                assert (there.results[1].pose is None) == (top == 1)
            t, x = there.timing_ms, there.transfer
            # the search (one stack of the 6 turns; cs2 too, over its shortlist), the
            # colour signatures (a photo with colour), the shape fits, the pose
            assert any(m.colour is not None for m in there.results) == coloured
            assert all(m.shape_fit is not None for m in there.results)
            assert x["round_trips"] == 1 + coloured + 1 + pose and x["bytes_sent"] > 0 and x["bytes_received"] > 0
            assert t["server"] > 0 and t["network"] >= 0 and t["total"] >= t["segment"]
            if plan == "server":
                assert t["client"] < 1.0  # nothing runs on the client's tier
            if pose:
                assert t["pose_server"] > 0


def test_a_box_prompted_query_over_http_equals_the_local_one(tiered_db, files, remote):
    """A box prompt's colour channel (``/colour-ranking``, then the exact search of the
    objects it names) answers over HTTP as in this process."""
    _, client_path = files
    with viewdb.open(tiered_db, create=False) as full, viewdb.open(client_path, read_only=True) as client:
        img = photo(full, "mug", 47, 22, 30)
        rows, cols = np.nonzero(np.abs(img.astype(int) - 190).sum(axis=2) > 30)
        box = [int(cols.min()) - 3, int(rows.min()) - 3, int(cols.max()) + 4, int(rows.max()) + 4]
        for plan in ("server", "cs1"):
            local = full.query(img, boxes=[box], k=3, plan=plan, pose=False,
                               client=client if plan != "server" else None)
            there = client.query(img, boxes=[box], k=3, plan=plan, pose=False, server=remote)
            assert there.to_dict()["objects"][0]["results"] == local.to_dict()["objects"][0]["results"], plan
            assert there.objects[0].results[0].object == "mug"
            assert there.objects[0].results[0].colour is not None
        ranked, _ = remote.colour_ranking(colour_signature(img, full.query(
            img, boxes=[box], pose=False).objects[0].region.mask), 4)
        here, _ = full.server_tier().colour_ranking(colour_signature(
            img, full.query(img, boxes=[box], pose=False).objects[0].region.mask), 4)
        assert ranked == here and ranked[0].object == "mug"
        look = look_features(img[box[1]:box[3], box[0]:box[2]])
        theirs, _ = remote.looks(look)
        ours, _ = full.server_tier().looks(look)
        assert theirs == pytest.approx(ours) and "mug" in ours and min(ours.values()) == 0.0


def test_refine_and_walk_over_http_equal_the_local_server_half(tiered_db, files, remote):
    _, client_path = files
    rng = np.random.default_rng(5)
    with viewdb.open(tiered_db, create=False) as full, viewdb.open(client_path, read_only=True) as client:
        for curve in _curves(full, rng, 24):
            k, band = int(rng.integers(1, 6)), int(rng.integers(0, 10))
            for plan, cs2 in (("server", "shortlist"), ("cs1", "shortlist"), ("cs2", "shortlist"), ("cs2", "walk"),
                              ("fast", "shortlist")):
                shortlist = int(rng.integers(1, 8))
                local = full.recognise(curve, k, band=band, plan=plan, client=client, cs2=cs2, shortlist=shortlist,
                                       fast_shortlist=shortlist)
                there = client.recognise(curve, k, band=band, plan=plan, server=remote, cs2=cs2, shortlist=shortlist,
                                         fast_shortlist=shortlist)
                assert there.results == local.results, (plan, k, band)
                if plan == "fast":  # the server's own index shortlisted
                    assert there.server_stats["fast_index"] == 1.0
                    # fewer when the index's nearest views name fewer objects, never fewer than k
                    assert k <= there.server_stats["shortlisted"] <= min(max(shortlist, k), len(full.objects()))
                    assert there.server_stats["shortlisted"] == local.server_stats["shortlisted"]
                if plan not in ("server", "fast"):
                    assert there.client_results == local.client_results
                    assert there.bytes_sent > 0 and there.bytes_received > 0


def test_shift_searches_over_http_equal_the_local_ones(tiered_db, files, remote):
    _, client_path = files
    rng = np.random.default_rng(8)
    with viewdb.open(tiered_db, create=False) as full, viewdb.open(client_path, read_only=True) as client:
        for curve in _curves(full, rng, 6):
            for window in (viewdb.ShiftWindow(), viewdb.ShiftWindow(int(rng.integers(128)), 9, 2)):
                for plan in ("server", "cs1", "cs2"):
                    local = full.recognise(curve, 3, plan=plan, client=client, shifts=window)
                    there = client.recognise(curve, 3, plan=plan, server=remote, shifts=window)
                    assert there.results == local.results, (plan, window)
                    assert all(c.shift is not None for c in there.results)
        img = photo(full, "l_bracket", 120, 40, 35)
        for options in ({"shifts": viewdb.ShiftWindow(step=4)}, {"roll": 35.0}):
            kw = dict(k=2, plan="cs1", pose=False, colour=False, verify=False, **options)
            local = full.query(img, client=client, **kw)
            there = client.query(img, server=remote, **kw)
            assert there.to_dict()["results"] == local.to_dict()["results"], options
            assert there.transfer["round_trips"] == 1  # one search, not one per turn


def test_turn_stacks_over_http_equal_separate_turns_locally(tiered_db, files, remote):
    """The query's turns go to the server as one stack (one /refine) and come back with the
    local answer of one search per turn, for server and cs1."""
    _, client_path = files
    with viewdb.open(tiered_db, create=False) as full, viewdb.open(client_path, read_only=True) as client:
        for name, h, v, turn in (("mug", 47, 22, 30), ("l_bracket", 120, 40, 10), ("chair", 250, 65, -100)):
            img = photo(full, name, h, v, turn)
            for plan in ("server", "cs1"):
                kw = dict(k=3, plan=plan, pose=False, colour=False, verify=False)
                separate = viewdb.QueryOptions(**kw, recognition=viewdb.RecognitionConfig(turn_search="separate"))
                local = full.query(img, client=client if plan == "cs1" else None, options=separate)
                there = client.query(img, server=remote, **kw)
                assert there.to_dict()["results"] == local.to_dict()["results"], (name, plan)
                assert there.transfer["round_trips"] == 1
                old = client.query(img, server=remote, options=separate)  # an older client: a request per turn
                assert old.to_dict()["results"] == local.to_dict()["results"]
                assert old.transfer["round_trips"] == viewdb.QueryOptions().rotations


def test_a_stack_of_more_curves_than_the_limit_is_refused(server):
    body = {**_valid(), "client": [], "curves": [[1.0] * 128] * 73}
    del body["curve"]
    status, reply = request(server.url, "POST", "/refine", body, token=TOKEN)
    assert status == 422 and "curves" in reply["error"], reply
    status, reply = request(server.url, "POST", "/refine", {**body, "curves": body["curves"][:72]}, token=TOKEN)
    assert status == 200 and len(reply["results"]) == 3
    assert all(0 <= c["curve_index"] < 72 for c in reply["results"])
    status, info = request(server.url, "GET", "/info", token=TOKEN)
    assert info["limits"]["max_curves"] == 72


def test_walk_names_each_object_once_however_often_the_client_does(server):
    cand = {"object": "car", "distance": 0.5, "azimuth": 30.0, "elevation": 30.0, "mirrored": False}
    other = {**cand, "object": "mug"}
    body = {**_valid("walk"), "k": 5, "client": [cand, {**cand, "azimuth": 120.0}, cand, other, cand]}
    got, reply = request(server.url, "POST", "/walk", body, token=TOKEN)
    assert got == 200, reply
    names = [r["object"] for r in reply["results"]]
    assert sorted(names) == ["car", "mug"]


def test_health_shows_the_pid_only_to_a_caller_with_the_token(server):
    got, anonymous = request(server.url, "GET", "/health")
    assert got == 200 and anonymous["status"] == "ok" and "pid" not in anonymous
    got, known = request(server.url, "GET", "/health", token=TOKEN)
    assert got == 200 and isinstance(known["pid"], int)


@pytest.mark.parametrize("path", ["/openapi.json", "/docs", "/redoc"])
def test_the_schema_pages_are_public_by_design(server, path):
    """Documented (viewdb.http.app, docs/reliability.md): they describe the API, hold no data."""
    got, _ = request(server.url, "GET", path)
    assert got == 200


def test_a_client_trickling_its_header_is_cut_off_and_others_are_served(server):
    import socket
    import time
    from urllib.parse import urlsplit

    parts = urlsplit(server.url)
    start = time.monotonic()
    with socket.create_connection((parts.hostname, parts.port), timeout=HEADER_TIMEOUT + 10) as sock:
        sock.sendall(b"POST /refine HTTP/1.1\r\nHost: x\r\n")
        closed = False
        for i in range(int((HEADER_TIMEOUT + 6) / 0.25)):
            try:
                sock.sendall(f"X-Slow-{i}: yes\r\n".encode())
            except (BrokenPipeError, ConnectionResetError):
                closed = True
                break
            sock.settimeout(0.25)
            try:
                if sock.recv(1024) == b"":
                    closed = True
                    break
            except TimeoutError:
                pass
            assert request(server.url, "GET", "/health", timeout=5)[0] == 200 if i == 2 else True
    assert closed, "the server kept a connection whose header never ended"
    assert time.monotonic() - start < HEADER_TIMEOUT + 4


def test_a_body_that_does_not_arrive_gets_408(server):
    import socket
    from urllib.parse import urlsplit

    parts = urlsplit(server.url)
    with socket.create_connection((parts.hostname, parts.port), timeout=BODY_TIMEOUT + 10) as sock:
        sock.sendall(f"POST /refine HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\n"
                     "Content-Type: application/json\r\nContent-Length: 5000\r\n\r\n{".encode())
        reply = b""
        while b"\r\n\r\n" not in reply:
            chunk = sock.recv(4096)
            if not chunk:
                break
            reply += chunk
    assert reply.startswith(b"HTTP/1.1 408"), reply[:200]


def test_health_info_and_openapi(server, remote):
    health = remote.health()
    assert health["status"] == "ok" and health["objects"] == 6
    assert server.pids and len(server.pids) == 2  # both workers answer
    info = remote.info()
    assert info["role"] == "full" and info["read_only"] and info["auth"]
    assert len(info["objects"]) == 6 and "path" not in info
    assert info["limits"]["curve_samples"] == 128 and info["limits"]["max_k"] == MAX_K
    status, schema = request(server.url, "GET", "/openapi.json")
    assert status == 200
    assert {"/refine", "/walk", "/pose", "/colours", "/colour-ranking", "/fits", "/info",
            "/health"} <= set(schema["paths"])
    body = schema["paths"]["/refine"]["post"]["requestBody"]["content"]["application/json"]["schema"]
    assert body["$ref"].split("/")[-1] in schema["components"]["schemas"]
    assert "CandidateModel" in schema["components"]["schemas"]


def test_the_documented_models_accept_real_messages():
    req = viewdb.http.RefineRequest(np.linspace(0.5, 1.5, 128), 6, 3, [viewdb.Candidate("mug", 0.25, 30.0, 60.0, True)])
    models.RefineRequestModel.model_validate(json.loads(json.dumps(req.to_dict())))
    walk = viewdb.http.WalkRequest(req.curve, 6, 3, 90.0, req.client)
    models.WalkRequestModel.model_validate(json.loads(json.dumps(walk.to_dict())))
    img = np.zeros((32, 40, 3), np.uint8)
    mask = np.zeros((32, 40), bool)
    mask[5:20, 8:30] = True
    pose = PoseRequest.from_query(QueryView(img, mask), req.client, (100.0, 100.0, 20.0, 16.0))
    models.PoseRequestModel.model_validate(json.loads(json.dumps(pose.to_dict())))
    reply = viewdb.http.ServerReply(req.client, {"dtw": 3.0})
    models.ServerReplyModel.model_validate(reply.to_dict())


def test_the_query_image_round_trips_exactly():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)
    mask = rng.random((37, 53)) < 0.4
    back = decode_query(encode_query(QueryView(img, mask)))
    assert np.array_equal(back.color, img) and np.array_equal(back.mask, mask)


# ----------------------------------------------------------------------------- bad input
def _valid(kind="refine"):
    body = {"curve": [1.0] * 128, "band": 6, "k": 3,
            "client": [{"object": "mug", "distance": 0.5, "azimuth": 30.0, "elevation": 60.0, "mirrored": False}]}
    if kind == "walk":
        body["client_gap"] = 90.0
    return body


def _png(array, mode=None):
    out = io.BytesIO()
    Image.fromarray(array, mode).save(out, format="PNG")
    return base64.b64encode(out.getvalue()).decode()


def _pose_body(image):
    return {"image": image, "matches": _valid()["client"], "intrinsics": None}


def _fit_body(image):
    return {"image": image, "views": [{"object": "mug", "azimuth": 30.0, "elevation": 60.0}]}


@pytest.mark.parametrize("path, body, status, problem", [
    ("/refine", b"{not json", 400, "not valid JSON"),
    ("/refine", b"", 400, "empty body"),
    ("/refine", b"\xff\xfe\x00garbage", 400, "not valid JSON"),
    ("/refine", b"[" * 100_000 + b"]" * 100_000, 400, "not valid JSON"),
    ("/refine", b'{"curve": [NaN], "band": 1, "k": 1, "client": []}', 400, "NaN is not allowed"),
    ("/refine", b'{"curve": [Infinity], "band": 1, "k": 1, "client": []}', 400, "Infinity is not allowed"),
    ("/refine", [1, 2, 3], 422, "must be an object"),
    ("/refine", {**_valid(), "curve": [1.0] * 127}, 422, "128 samples"),
    ("/refine", {**_valid(), "curve": [1.0] * 129}, 422, "128 samples"),
    ("/refine", {**_valid(), "curve": [[1.0] * 128]}, 422, "list of numbers"),
    ("/refine", {**_valid(), "curve": [1.0] * 127 + ["NaN"]}, 422, "list of numbers"),
    ("/refine", json.dumps(_valid()).replace("1.0]", "1e400]"), 422, "finite"),
    ("/refine", {**_valid(), "curve": ["a"] * 128}, 422, "list of numbers"),
    ("/refine", {**_valid(), "k": 0}, 422, "k must be in"),
    ("/refine", {**_valid(), "k": 10**30}, 422, "k must be in"),
    ("/refine", {**_valid(), "k": 2.5}, 422, "k must be an integer"),
    ("/refine", {**_valid(), "band": True}, 422, "band must be an integer"),
    ("/refine", {**_valid(), "band": 65}, 422, "band must be in"),
    ("/refine", {**_valid(), "client": [{"object": "mug"}] * 101}, 422, "at most 100"),
    ("/refine", {**_valid(), "client": [{"object": "mug", "distance": -1, "azimuth": 0, "elevation": 0}]}, 422, ">= 0"),
    ("/refine", {**_valid(), "client": [{"object": 5, "distance": 1, "azimuth": 0, "elevation": 0}]}, 422, "non-empty string"),
    ("/refine", {"curve": [1.0] * 128}, 422, "lacks 'band'"),
    ("/walk", _valid(), 422, "lacks 'client_gap'"),
    ("/walk", {**_valid("walk"), "client_gap": 0}, 422, "client_gap must be in"),
    ("/walk", {**_valid("walk"), "client_gap": "NaN"}, 422, "must be a number"),
    ("/pose", {"matches": []}, 422, "lacks 'image'"),
    ("/pose", _pose_body("!!!not base64!!!"), 422, "not valid base64"),
    ("/pose", _pose_body(base64.b64encode(b"GIF89a....").decode()), 422, "must be a PNG"),
    ("/pose", _pose_body(base64.b64encode(b"\x89PNG\r\n\x1a\n" + b"\x00" * 50).decode()), 422, "not a readable PNG"),
    ("/pose", _pose_body(_png(np.zeros((32, 32, 3), np.uint8))), 422, "must be RGBA"),
    ("/pose", _pose_body(_png(np.zeros((32, 32, 4), np.uint8))), 422, "mask (alpha channel) is empty"),
    ("/pose", _pose_body(_png(np.zeros((4, 4, 4), np.uint8))), 422, "too small"),
    ("/pose", {**_pose_body(_png(np.full((32, 32, 4), 255, np.uint8))), "matches": []}, 422, "must not be empty"),
    ("/pose", {**_pose_body(_png(np.full((32, 32, 4), 255, np.uint8))), "intrinsics": [1, 2, 3]}, 422, "intrinsics"),
    ("/pose", {**_pose_body(_png(np.full((32, 32, 4), 255, np.uint8))), "intrinsics": [0, 1, 2, 3]}, 422, "fx must be a finite number"),
    # numbers a pose would divide or overflow with: refused, never a 500
    ("/pose", {**_pose_body(_png(np.full((32, 32, 4), 255, np.uint8))), "intrinsics": [1e20, 1e20, 128, 128]},
     422, "fx must be a finite number in"),
    ("/pose", {**_pose_body(_png(np.full((32, 32, 4), 255, np.uint8))), "intrinsics": [5e-324, 5e-324, 128, 128]},
     422, "fx must be a finite number in"),
    ("/pose", {**_pose_body(_png(np.full((32, 32, 4), 255, np.uint8))), "intrinsics": [500, 500, 1e300, 0]},
     422, "cx must be a finite number in"),
    ("/pose", {**_pose_body(_png(np.full((32, 32, 4), 255, np.uint8))), "intrinsics": ["500", 500, 1, 0]},
     422, "fx must be a number"),
    ("/pose", {**_pose_body(_png(np.full((32, 32, 4), 255, np.uint8))), "curves": [[1e308] * 128]},
     422, "curve samples must be in [0, 128]"),
    # strings, booleans and absurd values are not curve samples
    ("/refine", {**_valid(), "curve": ["1_0"] * 128}, 422, "list of numbers"),
    ("/refine", {**_valid(), "curve": [True] * 128}, 422, "list of numbers"),
    ("/refine", {**_valid(), "curve": [1e308] * 128}, 422, "curve samples must be in [0, 128]"),
    ("/refine", {**_valid(), "curve": [-1.0] + [1.0] * 127}, 422, "curve samples must be in [0, 128]"),
    ("/refine", {**_valid(), "curve": [10**400] + [1.0] * 127}, 422, "finite"),
    ("/refine", {**_valid(), "client": [{**_valid()["client"][0], "azimuth": "30"}]}, 422, "must be a number"),
    ("/refine", {**_valid(), "client": [{**_valid()["client"][0], "distance": True}]}, 422, "must be a number"),
    ("/walk", {**_valid("walk"), "client_gap": True}, 422, "must be a number"),
    ("/fits", {"views": []}, 422, "lacks 'image'"),
    ("/fits", _fit_body("!!!not base64!!!"), 422, "not valid base64"),
    ("/fits", _fit_body(_png(np.zeros((32, 32, 3), np.uint8))), 422, "must be RGBA"),
    ("/fits", {**_fit_body(_png(np.full((32, 32, 4), 255, np.uint8))), "views": []}, 422, "1 to 100"),
    ("/fits", {**_fit_body(_png(np.full((32, 32, 4), 255, np.uint8))),
               "views": [{"object": "mug", "azimuth": "NaN", "elevation": 0}]}, 422, "must be a number"),
    ("/fits", {**_fit_body(_png(np.full((32, 32, 4), 255, np.uint8))),
               "views": [{"object": "nope", "azimuth": 0, "elevation": 0}]}, 404, "no object named 'nope'"),
])
def test_bad_input_gets_a_4xx_with_a_one_line_json_error(server, path, body, status, problem):
    got, reply = request(server.url, "POST", path, body, token=TOKEN)
    assert got == status, reply
    assert reply["status"] == status and problem in reply["error"] and "\n" not in reply["error"]


def _chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def test_an_image_too_large_is_refused_from_its_header(server):
    # a PNG claiming 20000 x 20000 RGBA pixels: refused before any pixel is decoded
    header = struct.pack(">IIBBBBB", 20000, 20000, 8, 6, 0, 0, 0)
    png = (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header)
           + _chunk(b"IDAT", zlib.compress(b"\x00" * 1000)) + _chunk(b"IEND", b""))
    got, reply = request(server.url, "POST", "/pose", _pose_body(base64.b64encode(png).decode()), token=TOKEN)
    assert got == 422 and "too large" in reply["error"]


def test_the_server_caps_decoded_pixels_below_the_library(server):
    """A 20-megapixel PNG is refused from its header (the server's cap is 16 million, the
    library's for local files 40 million): a 170 KB file of 40 million pixels took a
    worker from 439 to 1,093 MB."""
    header = struct.pack(">IIBBBBB", 5000, 4000, 8, 6, 0, 0, 0)
    png = (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header)
           + _chunk(b"IDAT", zlib.compress(b"\x00" * 1000)) + _chunk(b"IEND", b""))
    body = _pose_body(base64.b64encode(png).decode())
    for path, payload in (("/pose", body), ("/fits", {**_fit_body(body["image"])})):
        got, reply = request(server.url, "POST", path, payload, token=TOKEN)
        assert got == 422 and "image too large: 5000x4000, more than 16,000,000 pixels" in reply["error"]
    form, headers = multipart({}, {"photo": ("big.png", png, "image/png")})
    got, reply = request(server.url, "POST", "/query", form, headers=headers, token=TOKEN)
    assert got == 422 and "too large" in reply["error"] and "big.png" in reply["error"]
    assert request(server.url, "GET", "/info", token=TOKEN)[1]["limits"]["max_pixels"] == 16_000_000


@pytest.mark.parametrize("chunked", [False, True])
def test_huge_payloads_get_413(server, chunked):
    huge = json.dumps({**_valid(), "curve": [1.0] * 600_000}).encode()  # ~3.6 MB
    got, reply = request(server.url, "POST", "/refine", huge, token=TOKEN, chunked=chunked)
    assert got == 413 and "limit" in reply["error"]
    got, reply = request(server.url, "POST", "/refine", b"x", token=TOKEN,
                         headers={"Content-Length": str(10**9)})
    assert got == 413


@pytest.mark.parametrize("headers", [{}, {"Authorization": "Bearer wrong"}, {"Authorization": TOKEN},
                                     {"Authorization": f"Basic {TOKEN}"}, {"Authorization": f"Bearer {TOKEN}x"}])
@pytest.mark.parametrize("method, path", [("POST", "/refine"), ("POST", "/walk"), ("POST", "/pose"),
                                          ("POST", "/fits"), ("GET", "/info")])
def test_a_missing_or_wrong_token_gets_401(server, headers, method, path):
    got, reply = request(server.url, method, path, _valid() if method == "POST" else None, headers=headers)
    assert got == 401 and "token" in reply["error"]


def test_unknown_paths_and_methods_get_json_4xx(server):
    assert request(server.url, "GET", "/nope", token=TOKEN)[0] == 404
    got, reply = request(server.url, "GET", "/refine", token=TOKEN)
    assert got == 405 and reply["status"] == 405


def test_the_remote_client_reports_server_errors_in_one_line(server, files):
    with viewdb.RemoteServer(server.url, token="wrong") as bad:
        with pytest.raises(viewdb.ServerError, match=r"\(401\)") as info:
            bad.info()
        assert info.value.status == 401 and server.url in str(info.value)
    with viewdb.RemoteServer("http://127.0.0.1:1") as nowhere:
        with pytest.raises(viewdb.ServerError, match="cannot connect"):
            nowhere.health()
    with pytest.raises(viewdb.ServerError, match="not a server URL"):
        viewdb.RemoteServer("ftp://x")
    with viewdb.RemoteServer(server.url, token=TOKEN) as r:
        req = viewdb.http.RefineRequest(np.ones(64), 6, 3, [])  # a client file of another build
        with pytest.raises(viewdb.ServerError, match=r"\(422\).*128 samples"):
            r.refine(req)


# ----------------------------------------------------------------------------- CLI
def test_cli_query_against_the_server_equals_the_local_query(tiered_db, files, server, tmp_path, capsys):
    _, client = files
    with viewdb.open(tiered_db, create=False) as full:
        img = photo(full, "car", 150, 20, 15)
    path = tmp_path / "q.png"
    cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    common = [str(path), "--plan", "cs1", "-k", "2", "--rotations", "4", "--no-pose", "--json"]
    assert main(["query", *common, "--client", str(client), "--server", server.url, "--token", TOKEN]) == 0
    there = json.loads(capsys.readouterr().out)
    assert main(["query", *common, "--db", str(tiered_db), "--client", str(client)]) == 0
    local = json.loads(capsys.readouterr().out)
    assert there["results"] == local["results"] and there["results"][0]["object"] == "car"
    # one stack of the 4 turns, the colour signatures (the car is coloured) and the shape fits
    assert there["results"][0]["colour_distance"] is not None
    assert there["results"][0]["shape_fit"] is not None
    assert there["transfer"]["round_trips"] == 1 + 1 + 1 and "network" in there["timing_ms"]


def test_cli_errors_for_remote_queries(files, server, tmp_path, capsys):
    _, client = files
    img = tmp_path / "q.png"
    disc = np.full((64, 64, 3), 200, np.uint8)
    cv2.circle(disc, (30, 34), 18, (40, 60, 90), -1)
    cv2.imwrite(str(img), disc)
    assert main(["query", str(img), "--client", str(client), "--server", "http://127.0.0.1:1"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("viewdb: http://127.0.0.1:1") and "cannot connect" in err and "\n" not in err
    assert main(["query", str(img), "--server", server.url]) == 2  # --client is needed
    capsys.readouterr()
    assert main(["query", str(img)]) == 2  # neither --db nor --server
    capsys.readouterr()
    assert main(["serve", "--db", str(client), "--port", "0"]) == 1  # a client file cannot be served
    assert "client file" in capsys.readouterr().err


# ----------------------------------------------------------------------------- fuzz
JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=10), inner, max_size=6),
    max_leaves=30,
)
KEYS = {"/refine": ("curve", "band", "k", "client"), "/walk": ("curve", "band", "k", "client", "client_gap"),
        "/pose": ("image", "matches", "intrinsics"), "/fits": ("image", "views")}


@st.composite
def mutated(draw):
    """A valid request of some endpoint with one part replaced, dropped or corrupted."""
    path = draw(st.sampled_from(sorted(KEYS)))
    image = _png(np.full((20, 20, 4), 255, np.uint8))
    body = (_pose_body(image) if path == "/pose" else _fit_body(image) if path == "/fits"
            else _valid("walk" if path == "/walk" else "refine"))
    key = draw(st.sampled_from(KEYS[path]))
    how = draw(st.sampled_from(["replace", "drop", "candidate", "curve"]))
    if how == "drop":
        del body[key]
    elif how == "candidate" and path == "/fits":
        body["views"][0][draw(st.sampled_from(["object", "azimuth", "elevation"]))] = draw(JSON)
    elif how == "candidate":
        cands = body["matches" if path == "/pose" else "client"]
        cands[0][draw(st.sampled_from(["object", "distance", "azimuth", "elevation", "mirrored"]))] = draw(JSON)
    elif how == "curve" and path not in ("/pose", "/fits"):
        body["curve"] = draw(st.lists(st.floats(allow_nan=False) | st.integers(), max_size=200))
    else:
        body[key] = draw(JSON)
    return path, body


def _fuzz_one(url, path, body):
    got, reply = request(url, "POST", path, body, token=TOKEN)
    # (an unknown object's view cannot be fitted: 404; a pose of one is an error per match)
    assert got in (200, 400, 413, 422) + ((404,) if path == "/fits" else ()), (got, reply)
    assert isinstance(reply, dict)
    if got == 200:
        if path == "/pose":
            assert len(reply["poses"]) == len(body["matches"])
        elif path == "/fits":
            assert len(FitReply.from_dict(reply).fits) == len(body["views"])
        else:
            viewdb.http.ServerReply.from_dict(reply)
    else:
        assert reply["status"] == got and isinstance(reply["error"], str) and "\n" not in reply["error"]


FUZZ = settings(max_examples=40, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                        HealthCheck.too_slow])
FUZZ_LONG = settings(max_examples=1500, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                               HealthCheck.too_slow])


@FUZZ
@given(path=st.sampled_from(sorted(KEYS)), data=JSON)
def test_fuzz_arbitrary_json_bodies(server, path, data):
    _fuzz_one(server.url, path, data)


@FUZZ
@given(case=mutated())
def test_fuzz_mutated_requests(server, case):
    _fuzz_one(server.url, *case)


@FUZZ
@given(path=st.sampled_from(sorted(KEYS)), raw=st.binary(max_size=300))
def test_fuzz_raw_bytes(server, path, raw):
    got, reply = request(server.url, "POST", path, raw, token=TOKEN)
    assert got in (400, 422), (got, reply)


@pytest.mark.slow
@FUZZ_LONG
@given(path=st.sampled_from(sorted(KEYS)), data=JSON | st.binary(max_size=2000).map(bytes))
def test_fuzz_long_arbitrary_bodies(server, path, data):
    if isinstance(data, bytes):
        got, _ = request(server.url, "POST", path, data, token=TOKEN)
        assert got in (400, 422)
    else:
        _fuzz_one(server.url, path, data)


@pytest.mark.slow
@FUZZ_LONG
@given(case=mutated())
def test_fuzz_long_mutated_requests(server, case):
    _fuzz_one(server.url, *case)


# ------------------------------------------------------------- fuzz: every body model
#: Numbers a careless or hostile client sends where the models say "number".
NASTY_FLOATS = (st.floats(allow_nan=False, allow_infinity=False)
                | st.sampled_from([0.0, -0.0, 5e-324, -5e-324, 1e-300, 1e308, -1e308, 1.7976931348623157e308,
                                   1e20, 1e-20, 360.0, -360.0, 720.5, 128.0, 128.0001, 1.0])
                | st.integers(-10**30, 10**30) | st.sampled_from([10**400, -10**400]))
ANGLES = st.floats(-720, 720) | st.sampled_from([0.0, 30.0, 90.0, 180.0, 359.999999]) | NASTY_FLOATS
OBJECTS = ("car", "mug", "chair", "arrow", "l_bracket", "marked_cube")
NAMES = st.sampled_from(OBJECTS) | st.sampled_from(["nope", "", "\x1b[2J", "é" * 200])


def _plausible_or(plausible, nasty=NASTY_FLOATS):
    """Mostly a plausible value (so the deep code paths run), sometimes a nasty one."""
    return st.one_of(plausible, plausible, plausible, nasty)


def _candidate():
    return st.fixed_dictionaries(
        {"object": _plausible_or(st.sampled_from(OBJECTS), NAMES),
         "distance": _plausible_or(st.floats(0, 5)), "azimuth": _plausible_or(ANGLES),
         "elevation": _plausible_or(ANGLES)},
        optional={"mirrored": st.booleans(), "version": st.text(max_size=140),
                  "camera_distance": _plausible_or(st.sampled_from([3.0, 4.0, 6.0, 1000.0])),
                  "curve_index": _plausible_or(st.integers(0, 71), st.integers(-2, 80))})


def _curve():
    good = st.lists(st.floats(0, 3) | st.sampled_from([0.0, 128.0]), min_size=128, max_size=128)
    nasty = st.lists(st.sampled_from([0.0, 0.5, 1.0, 1.5, 128.0]) | NASTY_FLOATS, min_size=8, max_size=130)
    return _plausible_or(good, nasty)


@st.composite
def _query_png(draw):
    h, w = draw(st.integers(8, 64)), draw(st.integers(8, 64))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    rgba = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    fill = draw(st.sampled_from(["blob", "blob", "blob", "random", "empty", "full"]))
    if fill != "random":
        rgba[:, :, 3] = 255 if fill == "full" else 0
        if fill == "blob":
            cv2.ellipse(rgba, (w // 2, h // 2), (max(2, w // 3), max(2, h // 4)),
                        draw(st.floats(0, 180)), 0, 360, (30, 60, 90, 255), -1)
    return _png(rgba)


INTRINSICS = st.none() | st.tuples(st.floats(1, 1e7), st.floats(1, 1e7), st.floats(-1e7, 1e7),
                                   st.floats(-1e7, 1e7)).map(list) \
    | st.tuples(st.floats(50, 2000), st.floats(50, 2000), st.floats(0, 64), st.floats(0, 64)).map(list) \
    | st.lists(NASTY_FLOATS, min_size=4, max_size=4)


BODY_MODELS = {
    "/refine": st.fixed_dictionaries({
        "band": _plausible_or(st.integers(0, 64), st.integers(-3, 70) | NASTY_FLOATS),
        "k": _plausible_or(st.integers(1, 100), st.integers(-3, 110)), "client": st.lists(_candidate(), max_size=6)},
        optional={"curve": _curve(), "curves": _plausible_or(st.lists(_curve(), min_size=1, max_size=3),
                                                               st.lists(_curve(), max_size=74)),
                  "shortlist": _plausible_or(st.booleans(), st.integers(0, 2) | st.text(max_size=3))}),
    "/walk": st.fixed_dictionaries({
        "curve": _curve(), "band": _plausible_or(st.integers(0, 64), st.integers(-3, 70)),
        "k": _plausible_or(st.integers(1, 100), st.integers(-3, 110)), "client": st.lists(_candidate(), max_size=6),
        "client_gap": _plausible_or(st.sampled_from([30.0, 60.0, 90.0, 180.0]) | st.floats(0.001, 180))}),
    "/pose": st.fixed_dictionaries({
        "image": _query_png(), "matches": st.lists(_candidate(), min_size=1, max_size=2),
        "intrinsics": INTRINSICS,
        "curves": st.none() | st.lists(st.none() | _curve(), min_size=1, max_size=2)}),
    "/colours": st.fixed_dictionaries({"views": st.lists(st.fixed_dictionaries(
        {"object": _plausible_or(st.sampled_from(OBJECTS), NAMES), "azimuth": _plausible_or(ANGLES),
         "elevation": _plausible_or(ANGLES)}), min_size=1, max_size=4)}),
    "/colour-ranking": st.fixed_dictionaries({
        "signature": _plausible_or(st.lists(st.floats(0, 1), min_size=256, max_size=256),
                                   st.lists(NASTY_FLOATS, max_size=260)),
        "n": _plausible_or(st.integers(1, 10), st.integers(-3, 10**6) | st.text(max_size=3))}),
    "/looks": st.fixed_dictionaries({
        "look": _plausible_or(st.lists(st.floats(0, 1), min_size=LOOK_DIMS, max_size=LOOK_DIMS),
                              st.lists(NASTY_FLOATS, max_size=LOOK_DIMS + 4))}),
    "/fits": st.fixed_dictionaries({"image": _query_png(), "views": st.lists(st.fixed_dictionaries(
        {"object": _plausible_or(st.sampled_from(OBJECTS), NAMES), "azimuth": _plausible_or(ANGLES),
         "elevation": _plausible_or(ANGLES)}), min_size=1, max_size=3)}),
}


@st.composite
def _overlay_body(draw):
    pose = {"rotation": draw(st.one_of(st.just(np.eye(3).tolist()), st.lists(
                st.lists(_plausible_or(st.floats(-1, 1)), min_size=3, max_size=3), min_size=3, max_size=3),
                st.lists(NASTY_FLOATS, max_size=4))),
            "translation": draw(st.lists(_plausible_or(st.floats(-5, 5)), min_size=3, max_size=3)
                                | st.lists(NASTY_FLOATS, max_size=4)),
            "scale": draw(_plausible_or(st.floats(0.01, 10)) | st.none()),
            "frame": draw(st.sampled_from(["viewdb", "viewdb", "opencv", "nope"])),
            "units": draw(st.sampled_from(["normalised", "normalised", "mesh", "feet"]))}
    result = {"object": draw(_plausible_or(st.sampled_from(OBJECTS), NAMES)), "pose": pose,
              "rank": draw(_plausible_or(st.integers(1, 10)) | st.none()),
              "score": draw(_plausible_or(st.floats(0, 10)) | st.none())}
    return {"result": result, "width": draw(_plausible_or(st.integers(16, 2000), st.integers(-5, 200_000))),
            "height": draw(_plausible_or(st.integers(16, 2000), st.integers(-5, 200_000)))}


@st.composite
def _query_form(draw):
    """A multipart ``POST /query`` body: a photo (a real one of an object, noise, or bytes
    that are no image) and the options, some of them nonsense."""
    kind = draw(st.sampled_from(["photo", "photo", "noise", "bytes"]))
    if kind == "bytes":
        data = draw(st.binary(min_size=1, max_size=300))
    else:
        h, w = draw(st.integers(16, 96)), draw(st.integers(16, 96))
        rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
        image = (rng.integers(0, 256, (h, w, 3), dtype=np.uint8) if kind == "noise"
                 else np.full((h, w, 3), 200, np.uint8))
        if kind == "photo":
            cv2.ellipse(image, (w // 2, h // 2), (max(3, w // 3), max(3, h // 4)), draw(st.floats(0, 180)),
                        0, 360, (30, 60, 90), -1)
        data = cv2.imencode(draw(st.sampled_from([".png", ".jpg", ".webp", ".bmp"])), image)[1].tobytes()
    fields = {}
    if draw(st.booleans()):
        fields["plan"] = draw(_plausible_or(st.sampled_from(["server", "cs1", "cs2"]), st.text(max_size=20)))
    if draw(st.booleans()):
        fields["k"] = draw(_plausible_or(st.integers(1, 10).map(str),
                                         st.integers(-10**30, 10**30).map(str) | st.text(max_size=12)))
    name = draw(st.sampled_from(["photo.png", "p.jpg", "x", "é\x1b[2J.png", "../../etc/passwd"]))
    return {"fields": fields, "photo": (name, data)}


BODY_MODELS["/overlay"] = _overlay_body()
BODY_MODELS["/query"] = _query_form()

#: The documented model of each endpoint's body: every one is fuzzed.
DOCUMENTED = {"/refine": models.RefineRequestModel, "/walk": models.WalkRequestModel,
              "/pose": models.PoseRequestModel, "/colours": models.ColourRequestModel,
              "/colour-ranking": models.ColourRankingRequestModel, "/looks": models.LookRequestModel,
              "/fits": models.FitRequestModel, "/overlay": models.OverlayRequestModel,
              "/query": models.WebQueryFormModel}


def test_every_body_model_is_fuzzed(server):
    status, schema = request(server.url, "GET", "/openapi.json")
    posts = {path for path, ops in schema["paths"].items() if "post" in ops}
    assert posts == set(BODY_MODELS) == set(DOCUMENTED)


def _body_json(body):
    """JSON as a client would send it (Python's json writes 10**400 as a big integer)."""
    return json.dumps(body, allow_nan=False)


MODEL_FUZZ = settings(max_examples=30, suppress_health_check=[
    HealthCheck.function_scoped_fixture, HealthCheck.too_slow, HealthCheck.large_base_example,
    HealthCheck.data_too_large])


@MODEL_FUZZ
@given(data=st.data())
@pytest.mark.parametrize("path", sorted(BODY_MODELS))
def test_fuzz_every_body_model_gets_a_reply_or_a_4xx_never_a_500(server, path, data):
    body = data.draw(BODY_MODELS[path])
    if path == "/query":
        form, headers = multipart(body["fields"], {"photo": (*body["photo"], "application/octet-stream")})
        got, reply = request(server.url, "POST", path, form, headers=headers, token=TOKEN)
    else:
        got, reply = request(server.url, "POST", path, _body_json(body), token=TOKEN)
    event(f"status {got}")
    assert got < 500, (got, reply)
    if path == "/overlay" and got == 200:
        assert isinstance(reply, bytes) and reply.startswith(b"\x89PNG")
        return
    assert isinstance(reply, dict), reply
    if got != 200:
        assert 400 <= got < 500 and reply["status"] == got
        assert isinstance(reply["error"], str) and "\n" not in reply["error"] and reply["error"]
        return
    if path in ("/refine", "/walk"):
        parsed = viewdb.http.ServerReply.from_dict(reply)
        names = [c.object for c in parsed.results]
        assert len(names) == len(set(names)) and len(names) <= body["k"]
        assert all(c.distance >= 0 for c in parsed.results)
    elif path == "/pose":
        assert len(PoseReply.from_dict(reply).poses) == len(body["matches"])
    elif path == "/colours":
        assert len(ColourReply.from_dict(reply).signatures) == len(body["views"])
    elif path == "/colour-ranking":
        found = ColourRankingReply.from_dict(reply).matches
        assert len(found) <= body["n"] and all(0 <= m.distance <= 1 for m in found)
        assert [m.distance for m in found] == sorted(m.distance for m in found)
    elif path == "/looks":
        distances = LookReply.from_dict(reply).distances
        assert all(d >= 0 for d in distances.values())
    elif path == "/query":
        assert 1 <= len(reply["results"]) and reply["image"] and "\x1b" not in reply["image"]
    else:
        assert len(FitReply.from_dict(reply).fits) == len(body["views"])


@pytest.mark.slow
@settings(MODEL_FUZZ, max_examples=400)
@given(data=st.data())
@pytest.mark.parametrize("path", sorted(BODY_MODELS))
def test_fuzz_every_body_model_long(server, path, data):
    test_fuzz_every_body_model_gets_a_reply_or_a_4xx_never_a_500.hypothesis.inner_test(server, path, data)


def test_the_server_is_still_up_after_all_of_it(server):
    assert server.alive()
    assert server.worker_pids() <= server.pids


def test_the_remote_client_scales_a_photo_to_the_servers_pixel_cap_and_says_so(tiered_db, files):
    """A server decoding at most 50,000 pixels refuses a 600×600 query image; the client
    scales it down before sending (its pose and fits), and the query's JSON says so."""
    from viewdb.http.wire import shrink_query

    served, client_path = files
    with viewdb.open(tiered_db, read_only=True) as full:
        big = cv2.resize(photo(full, "mug", 47, 22, 30), (600, 600), interpolation=cv2.INTER_CUBIC)
        local = full.query(big, k=2, rotations=6, pose_top=1)
    with ServerProcess(served, token=TOKEN, extra=("--max-pixels", "50000")) as srv, \
            viewdb.RemoteServer(srv.url, token=TOKEN) as remote, \
            viewdb.open(client_path, read_only=True) as client:
        mask = np.ones((600, 600), bool)
        got, reply = request(srv.url, "POST", "/fits", _fit_body(base64.b64encode(
            encode_query(QueryView(big, mask))).decode()), token=TOKEN)
        assert got == 422 and "more than 50,000 pixels" in reply["error"]  # as it is: refused
        assert remote.max_pixels() == 50_000
        there = client.query(big, server=remote, k=2, rotations=6, pose_top=1)
    transfer = there.to_dict()["transfer"]
    assert (transfer["image_width"], transfer["image_height"]) == (600, 600)
    assert transfer["sent_width"] * transfer["sent_height"] <= 50_000 and transfer["sent_width"] >= 200
    assert "image_width" not in local.to_dict()["transfer"]
    assert [m.object for m in there.results] == [m.object for m in local.results]
    assert there.results[0].pose is not None and all(m.shape_fit is not None for m in there.results)
    a, b = there.results[0].pose.rotation, local.results[0].pose.rotation
    assert np.degrees(np.arccos(np.clip((np.trace(a.T @ b) - 1) / 2, -1, 1))) < 15  # the same pose

    # intrinsics go with the pixels: the principal point stays on the same spot of the scene
    small, scaled = shrink_query(QueryView(big, mask), 50_000, (800.0, 800.0, 299.5, 299.5))
    h, w = small.mask.shape
    assert w * h <= 50_000 and abs(w - h) <= 1
    assert scaled == pytest.approx((800 * w / 600, 800 * h / 600, (w - 1) / 2, (h - 1) / 2))
