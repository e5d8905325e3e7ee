"""Sharded catalogues on a local Ray: shard actors answer real queries exactly as the single
file does, over HTTP too; a dead shard fails the query (503) until its restarted actor is
readmitted, a damaged one is refused."""

import contextlib
import json
import os
import shutil
import signal
import socket
import sqlite3
import threading
import time
import urllib.error
import urllib.request

import numpy as np
import pytest

import viewdb
from viewdb.bench.photos import composite_photo
from viewdb.search.plans import RefineRequest
from viewdb.shards.layout import split_catalogue

ray = pytest.importorskip("ray")


@pytest.fixture(scope="module")
def three_shards(tiered_db, tmp_path_factory):
    return split_catalogue(tiered_db, 3, tmp_path_factory.mktemp("ray") / "shards")


def _matches(result):
    return [(m.object, m.distance, m.azimuth, m.elevation, m.mirrored) for m in result.results]


def test_shard_actors_answer_curves_and_photos_as_the_single_file(local_ray, tiered_db, three_shards):
    from viewdb.shards.cluster import ShardedServerTier

    tier = ShardedServerTier(three_shards.folder)
    try:
        rng = np.random.default_rng(3)
        with viewdb.open(tiered_db, read_only=True) as db:
            arrays, _ = db.search_tier("full")
            for _ in range(12):
                q = np.clip(arrays.curves[rng.integers(len(arrays.curves))] + rng.normal(0, 0.05, 128), 0, None)
                k = int(rng.integers(1, 7))
                for plan, cs2 in (("server", "shortlist"), ("cs1", "shortlist"), ("cs2", "shortlist"),
                                  ("cs2", "walk")):
                    here = db.recognise(q, k, plan=plan, cs2=cs2, shortlist=3)
                    there = db.recognise(q, k, plan=plan, server=tier, cs2=cs2, shortlist=3)
                    assert [c.to_dict() for c in there.results] == [c.to_dict() for c in here.results]
            for name, h, v in (("car", 200, 15), ("mug", 37, 22), ("chair", 110, 40), ("arrow", 300, -20)):
                img, _ = composite_photo(db.render(name, h, v), turn=20, scale=0.8, background=200)
                here = db.query(img, k=3, pose_top=1)
                there = db.query(img, k=3, pose_top=1, server=tier)
                assert [m.object for m in there.results][0] == name
                assert [m.to_dict()["object"] for m in there.results] == [m.to_dict()["object"] for m in here.results]
                for a, b in zip(here.results, there.results, strict=True):
                    assert a.distance == b.distance
                    assert json.dumps(a.to_dict(), sort_keys=True) == json.dumps(b.to_dict(), sort_keys=True)
    finally:
        tier.close()


def test_the_colour_channel_over_shards_answers_as_the_single_file(local_ray, tiered_db, three_shards):
    """Each shard ranks its own objects' colours; merged, they are the single file's
    answer, and a box-prompted query (the channel, then the exact search of what it
    names) answers alike."""
    from viewdb.recognition.colour import colour_signature
    from viewdb.shards.cluster import ShardedServerTier

    tier = ShardedServerTier(three_shards.folder)
    try:
        with viewdb.open(tiered_db, read_only=True) as db:
            for name, h, v in (("mug", 47, 22), ("car", 200, 15), ("chair", 110, 40)):
                img, mask = composite_photo(db.render(name, h, v), turn=20, scale=0.8, background=200)
                signature = colour_signature(img, mask)
                for n in (1, 3, 6):
                    assert tier.colour_ranking(signature, n)[0] == db.server_tier().colour_ranking(signature, n)[0]
                rows, cols = np.nonzero(mask)
                box = [int(cols.min()) - 2, int(rows.min()) - 2, int(cols.max()) + 3, int(rows.max()) + 3]
                here = db.query(img, boxes=[box], k=3, pose_top=1)
                there = db.query(img, boxes=[box], k=3, pose_top=1, server=tier)
                assert json.dumps(there.to_dict()["objects"][0]["results"], sort_keys=True) == \
                    json.dumps(here.to_dict()["objects"][0]["results"], sort_keys=True)
    finally:
        tier.close()


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _post(url, body, headers=None):
    req = urllib.request.Request(url, json.dumps(body).encode(), {"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            reply = r.status, json.loads(r.read())
            out_headers = dict(r.headers)
    except urllib.error.HTTPError as exc:
        reply = exc.code, json.loads(exc.read())
        out_headers = dict(exc.headers)
    if headers is not None:
        headers.clear()
        headers.update({k.lower(): v for k, v in out_headers.items()})
    return reply


def _health(url):
    with urllib.request.urlopen(url + "/health", timeout=30) as r:
        return json.loads(r.read())


@contextlib.contextmanager
def _serving(folder, monkeypatch):
    """The sharded catalogue in ``folder`` served on loopback in this process: (url, catalogue)."""
    import uvicorn

    from viewdb.http.app import ENV_RAY, create_app
    from viewdb.shards.serving import open_sharded

    monkeypatch.setenv(ENV_RAY, "auto")
    catalogue = open_sharded(folder)
    port = _free_port()
    server = uvicorn.Server(uvicorn.Config(create_app(folder, ui=False), port=port, log_level="critical"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        deadline = time.monotonic() + 60
        while not server.started and time.monotonic() < deadline:
            time.sleep(0.05)
        yield f"http://127.0.0.1:{port}", catalogue
    finally:
        server.should_exit = True
        thread.join(30)
        catalogue.close()


def test_a_killed_shard_fails_queries_with_503_and_a_damaged_shard_is_refused(
        local_ray, tiered_db, three_shards, tmp_path, monkeypatch):
    with _serving(three_shards.folder, monkeypatch) as (url, catalogue):
        with viewdb.open(tiered_db, read_only=True) as db:
            arrays, _ = db.search_tier("full")
            body = RefineRequest(arrays.curves[5], 6, 5, []).to_dict()
            status, reply = _post(url + "/refine", body)
            assert status == 200
            assert [c["object"] for c in reply["results"]] == [h.object for h in db.search(arrays.curves[5], 5)[0]]
        ray.kill(catalogue.server_tier().actors[1])  # for good: Ray does not restart it
        status, reply = _post(url + "/refine", body)
        assert status == 503 and "shard 1" in reply["error"] and "restart the server" in reply["error"]
        assert "results" not in reply

    folder = tmp_path / "damaged"
    shutil.copytree(three_shards.folder, folder)
    with sqlite3.connect(folder / "shard-002.viewdb") as conn:
        conn.execute("UPDATE curves SET samples = x'00' WHERE view_id = (SELECT MIN(view_id) FROM curves)")
    from viewdb.shards.cluster import ShardedServerTier

    with pytest.raises(viewdb.StorageError, match=r"shard 2 refused: .*shard-002\.viewdb: fails check"):
        ShardedServerTier(folder)


def test_a_killed_shard_actor_is_restarted_and_answers_the_same_again(
        local_ray, tiered_db, three_shards, monkeypatch):
    with _serving(three_shards.folder, monkeypatch) as (url, catalogue):
        with viewdb.open(tiered_db, read_only=True) as db:
            arrays, _ = db.search_tier("full")
            body = RefineRequest(arrays.curves[7], 6, 5, []).to_dict()
            expected = [h.object for h in db.search(arrays.curves[7], 5)[0]]
        status, before = _post(url + "/refine", body)
        assert status == 200 and [c["object"] for c in before["results"]] == expected
        assert [s["up"] for s in _health(url)["shards"]] == [True, True, True]

        actor = catalogue.server_tier().actors[1]
        pid = ray.get(actor.pid.remote())
        os.kill(pid, signal.SIGKILL)  # a crash: Ray restarts the actor, which reopens its file

        # the watcher marks the shard down well before its actor has reopened and checked it
        deadline = time.monotonic() + 10
        while (health := _health(url))["shards"][1]["up"] and time.monotonic() < deadline:
            time.sleep(0.05)
        assert health["status"] == "degraded" and health["shards"][1]["up"] is False
        assert health["shards"][1]["restarting"] is True
        assert [s["up"] for s in health["shards"]][::2] == [True, True]

        seen = []
        headers = {}
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            status, reply = _post(url + "/refine", body, headers)
            seen.append(status)
            if status == 200:
                break
            assert status == 503 and "shard 1 is down" in reply["error"], reply
            assert "results" not in reply and int(headers["retry-after"]) >= 1
            time.sleep(0.1)
        assert seen[0] == 503 and seen[-1] == 200, seen
        assert reply["results"] == before["results"]  # every field of every candidate
        assert ray.get(actor.pid.remote()) != pid
        health = _health(url)
        assert health["status"] == "ok" and health["shards"][1]["recoveries"] == 1
