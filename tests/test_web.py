"""The web page of ``viewdb serve`` and its endpoints, over real HTTP on loopback, and in a
real browser (Debian's headless Chromium driven by Selenium).

One server (a bearer token, a small photo limit) and one browser serve the whole module.
"""

from __future__ import annotations

import base64
import http.client
import io
import os
import re
import shutil
import urllib.parse
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

import viewdb
from benchmarks.support.browser import (
    CHROMEDRIVER,
    CHROMIUM,
    choose,
    drag_box,
    gesture,
    js,
    message,
    no_horizontal_scroll,
    on_screen,
    open_with_token,
    screenshot_on_failure,
    start_chromium,
    upload,
    wait,
)
from benchmarks.support.serving import ServerProcess, multipart, request
from viewdb.config import OverlayConfig
from viewdb.http import models
from viewdb.http.app import ENV_DB, ENV_UI, app_from_env
from viewdb.recognition.overlay import OverlayPose, overlay_layer

TOKEN = "web-s3cret"
#: The server's limit on a photo's upload (bytes).
LIMIT = 300_000
#: A pose as the query's JSON gives it.
POSE = {"rotation": np.eye(3).tolist(), "translation": [0.0, 0.0, -3.0], "scale": 1.0, "frame": "viewdb",
        "units": "normalised"}


@pytest.fixture(scope="module")
def served(tiered_db, tmp_path_factory):
    folder = tmp_path_factory.mktemp("web")
    copy = folder / "served.db"
    shutil.copy(tiered_db, copy)
    return copy


@pytest.fixture(scope="module")
def server(served):
    srv = ServerProcess(served, workers=1, token=TOKEN, extra=("--max-image-body", str(LIMIT)))
    with srv:
        yield srv
        assert srv.alive(), srv.log()
        assert srv.worker_pids() <= srv.pids, "the worker was restarted (crashed)"


@pytest.fixture(scope="module")
def db(tiered_db):
    with viewdb.open(tiered_db, read_only=True) as vdb:
        yield vdb


@pytest.fixture(scope="module")
def demo_photo(tiered_db, tmp_path_factory) -> Path:
    """The photo ``viewdb demo`` queries: the mug off the grid, turned, scaled and moved."""
    from viewdb_cli.main import _demo_photo

    path = tmp_path_factory.mktemp("photos") / "demo.png"
    _demo_photo(tiered_db, "mug", path)
    return path


@pytest.fixture(scope="module")
def bad_files(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("bad")
    notes = folder / "notes.txt"
    notes.write_text("not a photo\n" * 20)
    huge = folder / "huge.jpg"
    huge.write_bytes(np.random.default_rng(1).integers(0, 256, LIMIT + 50_000, dtype=np.uint8).tobytes())
    empty_scene = folder / "wall.png"
    cv2.imwrite(str(empty_scene), np.full((160, 200, 3), 128, np.uint8))
    return {"notes": notes, "huge": huge, "wall": empty_scene}


def post_photo(url: str, path: Path, token: str | None = TOKEN, **fields: str | list[str]) -> tuple[int, object]:
    body, headers = multipart(fields, {"photo": (path.name, path.read_bytes(), "application/octet-stream")})
    return request(url, "POST", "/query", body, headers=headers, token=token)


def decode_data_url(url: str) -> np.ndarray:
    head, _, data = url.partition(",")
    assert head in ("data:image/png;base64", "data:image/jpeg;base64"), head
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(data))))


# ====================================================================== HTTP
def test_page_needs_no_token_but_every_endpoint_does(server):
    status, page = request(server.url, "GET", "/")
    assert status == 200 and b"<title>viewdb</title>" in page
    status, script = request(server.url, "GET", "/static/app.js")
    assert status == 200 and b"fetch(" in script
    for method, path in [("GET", "/objects"), ("GET", "/objects/mug/views"), ("GET", "/info"),
                         ("GET", "/objects/mug/views/30/20.png"), ("POST", "/query"), ("POST", "/overlay")]:
        status, reply = request(server.url, method, path, b"" if method == "POST" else None)
        assert status == 401 and "token" in reply["error"], (path, reply)
        status, reply = request(server.url, method, path, b"" if method == "POST" else None, token="wrong")
        assert status == 401, path


def test_query_answers_what_the_library_answers_plus_pictures(server, db, demo_photo):
    for plan in ("server", "cs1"):
        status, answer = post_photo(server.url, demo_photo, plan=plan, k="2")
        assert status == 200, answer
        local = db.query(str(demo_photo), k=2, plan=plan).to_dict()  # the library's defaults pose the top
        shown = [{k: v for k, v in r.items() if k not in ("overlay", "thumbnail", "colour")}
                 for r in answer["results"]]
        assert shown == local["results"], plan
        assert answer["image"] == "demo.png" and answer["plan"] == plan and answer["k"] == 2
        assert set(local["timing_ms"]) | {"overlay"} == set(answer["timing_ms"])
    models.WebQueryReplyModel.model_validate(answer)
    top = answer["results"][0]
    assert top["object"] == "mug"
    # the photo as the server read it, enlarged to be legible, and the mug's overlay on it
    photo = decode_data_url(answer["photo"]["src"])
    layer = decode_data_url(top["overlay"])
    assert photo.shape[:2] == layer.shape[:2] == (answer["photo"]["height"], answer["photo"]["width"])
    assert layer.shape[2] == 4 and min(photo.shape[:2]) >= 512
    grey = np.asarray(Image.open(demo_photo).convert("RGB"))
    mug = cv2.resize((np.abs(grey.astype(int) - 200).sum(axis=2) > 0).astype(np.uint8),
                     photo.shape[1::-1], interpolation=cv2.INTER_NEAREST) > 0
    drawn = layer[:, :, 3] > 0
    assert (drawn & mug).sum() > 0.9 * mug.sum()  # the overlay covers the mug
    # another result is posed when asked for (pose_top reaching it, as in the library), and
    # its overlay drawn on request, as the library draws it
    assert answer["results"][1]["pose"] is None and "pose_error" not in answer["results"][1]
    status, again = post_photo(server.url, demo_photo, k="2", pose_top="2")
    assert status == 200, again
    second = again["results"][1]
    assert second["pose"] == db.query(str(demo_photo), k=2, pose_top=2).to_dict()["results"][1]["pose"]
    assert second["overlay"] is None and second["pose"] is not None
    assert again["results"][0]["pose"] == top["pose"]  # posing another leaves the best one as it was
    size = {"width": answer["photo"]["source_width"], "height": answer["photo"]["source_height"]}
    status, png = request(server.url, "POST", "/overlay", {"result": second, **size}, token=TOKEN)
    assert status == 200
    config = OverlayConfig(max_side=1024, min_side=512, colours=(OverlayConfig().colours[1],))
    mine = overlay_layer(grey.shape, [OverlayPose.from_json(second)], db.mesh, config=config)
    assert np.array_equal(np.asarray(Image.open(io.BytesIO(png))), mine)
    # the thumbnail is the matched view (from the side the photo shows), rendered
    status, png = request(server.url, "GET", "/" + top["thumbnail"], token=TOKEN)
    assert status == 200
    thumb = np.asarray(Image.open(io.BytesIO(png)))
    h, v = (float(x) for x in re.fullmatch(r"objects/mug/views/([^/]+)/([^/]+)\.png\?v=\w+",
                                           top["thumbnail"]).groups())
    view = db.render("mug", h, v)
    assert np.array_equal(thumb[:, :, :3], view.color) and np.array_equal(thumb[:, :, 3] > 0, view.mask)


def test_query_with_boxes_answers_each_object(server, db, tmp_path):
    from viewdb.bench.photos import table_photo

    views = [db.render("car", 40, 20), db.render("mug", 130, 25)]
    photo, masks = table_photo(views, (560, 260),
                               [(10, 20), (300, 40)])
    path = tmp_path / "table.png"
    cv2.imwrite(str(path), photo[:, :, ::-1])
    boxes = []
    for m in masks:
        ys, xs = np.nonzero(m)
        boxes.append(f"{xs.min()},{ys.min()},{xs.max() + 1},{ys.max() + 1}")
    status, answer = post_photo(server.url, path, k="1", box=[boxes[1], boxes[0]])
    assert status == 200, answer
    models.WebQueryReplyModel.model_validate(answer)
    assert answer["results"] == [] and [o["results"][0]["object"] for o in answer["objects"]] == ["mug", "car"]
    local = db.query(str(path), k=1, boxes=[boxes[1], boxes[0]]).to_dict()
    for mine, theirs in zip(local["objects"], answer["objects"], strict=True):
        assert mine["region"] == theirs["region"]
        assert theirs["results"][0]["overlay"].startswith("data:image/png;base64,")
    status, reply = post_photo(server.url, path, box=["1,2,3"])
    assert status == 422 and "box" in reply["error"]
    status, reply = post_photo(server.url, path, box=["600,10,900,100"])
    assert status == 422 and "outside the 560x260 image" in reply["error"] and "\n" not in reply["error"]


def test_the_echoed_file_name_is_one_printable_line(server, demo_photo):
    body, headers = multipart({"k": "1"}, {"photo": ("../é\x1b[2J\nmug\tphoto.png", demo_photo.read_bytes(),
                                                     "application/octet-stream")})
    status, answer = request(server.url, "POST", "/query", body, headers=headers, token=TOKEN)
    assert status == 200, answer
    assert answer["image"] == "é [2J mug photo.png"


def test_view_pictures_are_cached_by_version(server, db):
    path = "/objects/car/views/60/30.png"
    version = db.object("car").content_hash[:12]
    status, first = request(server.url, "GET", f"{path}?v={version}", token=TOKEN)
    assert status == 200 and first[:8] == b"\x89PNG\r\n\x1a\n"
    parts = urllib.parse.urlsplit(server.url)

    def head(query: str, etag: str | None = None) -> http.client.HTTPResponse:
        conn = http.client.HTTPConnection(parts.hostname, parts.port, timeout=60)
        headers = {"Authorization": f"Bearer {TOKEN}", **({"If-None-Match": etag} if etag else {})}
        conn.request("GET", path + query, headers=headers)
        response = conn.getresponse()
        response.read()
        conn.close()
        return response

    fresh = head(f"?v={version}")
    assert "immutable" in fresh.getheader("Cache-Control")
    assert "no-cache" in head("?v=stale").getheader("Cache-Control")
    assert head("", fresh.getheader("ETag")).status == 304
    # any angle, normalised: -300 is 60
    status, same = request(server.url, "GET", "/objects/car/views/-300/390.png", token=TOKEN)
    assert status == 200 and same == first


def test_objects_and_their_stored_views(server, db):
    status, listing = request(server.url, "GET", "/objects", token=TOKEN)
    assert status == 200
    models.ObjectsReplyModel.model_validate(listing)
    mine = {o.name: o for o in db.objects()}
    assert [o["name"] for o in listing["objects"]] == sorted(mine)
    for entry in listing["objects"]:
        info = mine[entry["name"]]
        assert (entry["h_type"], entry["v_type"]) == (info.symmetry.h_type, info.symmetry.v_type)
        assert (entry["views_stored"], entry["views_grid"]) == (info.views_stored, info.views_grid)
        assert "source" not in entry and entry["thumbnail"].endswith(f"?v={info.content_hash[:12]}")
    status, views = request(server.url, "GET", "/objects/mug/views", token=TOKEN)
    assert status == 200
    models.ViewsReplyModel.model_validate(views)
    assert sorted((v["azimuth"], v["elevation"]) for v in views["views"]) == sorted(db.views("mug"))
    status, _ = request(server.url, "GET", "/" + views["views"][0]["src"], token=TOKEN)
    assert status == 200


def _with_depth(url: str, photo: Path, depth: bytes, **fields: str) -> tuple[int, object]:
    body, headers = multipart(fields, {"photo": (photo.name, photo.read_bytes(), "image/png"),
                                       "depth": ("depth.png", depth, "image/png")})
    return request(url, "POST", "/query", body, headers=headers, token=TOKEN)


def test_a_depth_image_and_intrinsics_go_with_the_photo(server, db, demo_photo):
    """The form's ``intrinsics``, ``depth`` and ``depth_scale`` reach the query as the
    library's keywords do: the answer is the library's."""
    height, width = cv2.imread(str(demo_photo)).shape[:2]
    depth = np.full((height, width), 3000, np.uint16)  # a flat wall 3 m away, in millimetres
    depth_png = cv2.imencode(".png", depth)[1].tobytes()
    camera = (500.0, 500.0, width / 2, height / 2)
    status, answer = _with_depth(server.url, demo_photo, depth_png, k="2",
                                 intrinsics=",".join(str(v) for v in camera), depth_scale="0.001")
    assert status == 200, answer
    local = db.query(str(demo_photo), k=2, intrinsics=camera, depth=depth, depth_scale=0.001).to_dict()
    shown = [{k: v for k, v in r.items() if k not in ("overlay", "thumbnail", "colour")}
             for r in answer["results"]]
    assert shown == local["results"]
    top = local["results"][0]
    assert top["pose"]["depth_pixels"] > 0 and answer["intrinsics"] == list(camera)
    assert answer["results"][0]["overlay"] is not None
    # a pinhole pose is drawn on request through the intrinsics the answer carries
    size = {"width": width, "height": height}
    status, png = request(server.url, "POST", "/overlay", {"result": top, **size, "intrinsics": list(camera)},
                          token=TOKEN)
    assert status == 200 and png.startswith(b"\x89PNG")
    status, reply = request(server.url, "POST", "/overlay", {"result": top, **size}, token=TOKEN)
    assert status == 422 and "intrinsics" in reply["error"], reply
    # the form's bad camera fields: one line each, and nothing read from the server's disk
    cases = [(dict(k="2"), "depth needs intrinsics"),
             (dict(intrinsics="/etc/passwd"), "intrinsics must be fx,fy,cx,cy"),
             (dict(intrinsics="1,2,3"), "intrinsics must be four numbers"),
             (dict(intrinsics="500,500,80,60", depth_scale="-1"), "depth_scale must be a positive number")]
    for fields, want in cases:
        status, reply = _with_depth(server.url, demo_photo, depth_png, **fields)
        assert status == 422 and want in reply["error"] and "\n" not in reply["error"], (fields, reply)
    status, reply = _with_depth(server.url, demo_photo, b"not a depth image", intrinsics="500,500,80,60")
    assert status == 422 and "depth.png: cannot decode the depth image" in reply["error"], reply
    small = cv2.imencode(".png", np.full((20, 30), 3000, np.uint16))[1].tobytes()
    status, reply = _with_depth(server.url, demo_photo, small, intrinsics="500,500,80,60")
    assert status == 422 and "the depth image is 30x20 pixels" in reply["error"], reply


def test_bad_input_gets_a_one_line_error_and_the_server_stays_up(server, demo_photo, bad_files):
    cases = [
        (post_photo(server.url, bad_files["notes"]), 422, "notes.txt: not an image file"),
        (post_photo(server.url, bad_files["wall"]), 422, "wall.png: no object found"),
        (post_photo(server.url, bad_files["huge"]), 413, "over this endpoint's limit of 300,000"),
        (post_photo(server.url, demo_photo, plan="cs9"), 422, "plan must be server, cs1, cs2 or fast"),
        (post_photo(server.url, demo_photo, k="0"), 422, "k must be between 1 and 10"),
        (post_photo(server.url, demo_photo, k="many"), 422, "k must be a whole number"),
        (request(server.url, "POST", "/query", b"{}", token=TOKEN), 422, "no photo"),
        (request(server.url, "GET", "/objects/nope/views", token=TOKEN), 404, "no object named 'nope'"),
        (request(server.url, "GET", "/objects/nope/views/0/0.png", token=TOKEN), 404, "no object named"),
        (request(server.url, "GET", "/objects/mug/views/east/0.png", token=TOKEN), 422, "azimuth must be"),
        (request(server.url, "GET", "/objects/mug/views/0/nan.png", token=TOKEN), 422, "elevation must be"),
        (request(server.url, "POST", "/overlay", b"{not json", token=TOKEN), 400, "not valid JSON"),
        (request(server.url, "POST", "/overlay", {"result": {}, "width": 64}, token=TOKEN), 422, "height must be"),
        (request(server.url, "POST", "/overlay", {"result": {"object": "mug", "pose": {"rotation": 1}},
                                                  "width": 64, "height": 64}, token=TOKEN), 422, "not a pose"),
        (request(server.url, "POST", "/overlay", {"result": {"object": "nope", "pose": POSE}, "width": 64,
                                                  "height": 64}, token=TOKEN), 404, "no object named 'nope'"),
    ]
    for (status, reply), want_status, want in cases:
        assert status == want_status and want in reply["error"], (status, reply, want)
        assert "\n" not in reply["error"] and reply["status"] == status
    status, health = request(server.url, "GET", "/health", token=TOKEN)
    assert status == 200 and health["pid"] in server.pids


def test_the_schema_documents_the_endpoints(server):
    status, schema = request(server.url, "GET", "/openapi.json")
    assert status == 200
    paths = schema["paths"]
    assert {"/query", "/overlay", "/objects", "/objects/{name}/views",
            "/objects/{name}/views/{azimuth}/{elevation}.png"} <= set(paths)
    assert "/" not in paths
    body = paths["/query"]["post"]["requestBody"]["content"]["multipart/form-data"]["schema"]
    form = schema["components"]["schemas"][body["$ref"].split("/")[-1]]
    assert {"photo", "plan", "k"} <= set(form["properties"])


def test_no_ui_leaves_out_the_page_only(served, monkeypatch):
    def paths():
        app = app_from_env()
        return {getattr(r, "path", None) for r in app.routes} | set(app.openapi()["paths"])

    monkeypatch.setenv(ENV_DB, str(served))
    assert {"/", "/static", "/query", "/objects"} <= paths()
    monkeypatch.setenv(ENV_UI, "0")
    found = paths()
    assert "/" not in found and "/static" not in found and {"/query", "/objects"} <= found


# ====================================================================== browser
@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    if not (CHROMIUM.exists() and CHROMEDRIVER.exists()):
        why = "needs Debian's chromium and chromium-driver (./install.sh installs them)"
        if os.environ.get("CI"):
            pytest.fail(why)
        pytest.skip(why)
    driver = start_chromium(tmp_path_factory.mktemp("chromium"), (1200, 900))
    try:
        yield driver
    finally:
        driver.quit()


def open_page(driver, url: str) -> None:
    open_with_token(driver, url, TOKEN)


def test_the_page_asks_for_the_token_once(browser, server):
    from selenium.webdriver.common.by import By

    with screenshot_on_failure(browser, "token"):
        browser.get(server.url + "/")
        js(browser, "localStorage.clear()")
        browser.refresh()
        wait(browser, lambda d: d.find_element(By.ID, "token-panel").is_displayed())
        browser.find_element(By.ID, "token").send_keys("wrong")
        browser.find_element(By.CSS_SELECTOR, "#token-form button").click()
        wait(browser, lambda d: "refused" in d.find_element(By.ID, "token-message").text)
        browser.find_element(By.ID, "token").clear()
        browser.find_element(By.ID, "token").send_keys(TOKEN)
        browser.find_element(By.CSS_SELECTOR, "#token-form button").click()
        wait(browser, lambda d: "6 objects" in d.find_element(By.ID, "server").text)
        assert not browser.find_element(By.ID, "token-panel").is_displayed()
        browser.refresh()  # kept: not asked again
        wait(browser, lambda d: "6 objects" in d.find_element(By.ID, "server").text)
        assert not browser.find_element(By.ID, "token-panel").is_displayed()


def test_upload_the_demo_photo_and_see_the_mug_posed(browser, server, demo_photo):
    from selenium.webdriver.common.by import By

    with screenshot_on_failure(browser, "query"):
        browser.set_window_size(1200, 900)
        open_page(browser, server.url)
        upload(browser, demo_photo)
        wait(browser, lambda d: d.find_elements(By.CSS_SELECTOR, ".ranking li"))
        first = browser.find_element(By.CSS_SELECTOR, ".ranking li")
        assert first.get_attribute("data-object") == "mug"
        assert "1. mug" in first.text and "pose: azimuth" in first.text
        wait(browser, lambda d: js(d, "return document.querySelector('#layers img').naturalWidth") > 0)
        wait(browser, lambda d: js(d, "return document.getElementById('photo-img').naturalWidth") > 0)
        # every matched view's thumbnail arrived (fetched with the token)
        wait(browser, lambda d: js(d, "return [...document.querySelectorAll('.ranking img')]"
                                      ".every(i => i.naturalWidth > 0)"))
        assert "round trip" in browser.find_element(By.ID, "timing").text
        # no prompt: one ranking, no object sections, no region outlines
        assert not browser.find_elements(By.CSS_SELECTOR, ".found.several, #marks rect")
        # as the library, the query posed its best result only; choosing another poses it and
        # shows its overlay, drawn on request
        assert len(browser.find_elements(By.CSS_SELECTOR, ".ranking li")) == 5  # the library's k
        second = browser.find_elements(By.CSS_SELECTOR, ".ranking li")[1]
        assert "not posed yet" in second.text
        second.click()
        wait(browser, lambda d: "pose: azimuth" in d.find_elements(By.CSS_SELECTOR, ".ranking li")[1].text)
        second = browser.find_elements(By.CSS_SELECTOR, ".ranking li")[1]
        assert second.get_attribute("aria-selected") == "true"
        wait(browser, lambda d: js(d, "const i = document.querySelector('#layers img');"
                                      "return !i.hidden && i.src.startsWith('blob:') && i.naturalWidth > 0"))
        browser.set_window_size(390, 844)
        wait(browser, lambda d: js(d, "return window.innerWidth") <= 400)
        no_horizontal_scroll(browser)


def test_a_depth_image_chosen_on_the_page_sets_the_pose(browser, server, demo_photo, tmp_path):
    """The camera's intrinsics typed in and a depth image chosen beside the photo: the
    top result's pose comes in the camera's frame, at the depth's distance, and is drawn;
    a depth image of another size is a readable message."""
    from selenium.webdriver.common.by import By

    height, width = cv2.imread(str(demo_photo)).shape[:2]
    depth = tmp_path / "depth.png"
    cv2.imwrite(str(depth), np.full((height, width), 3000, np.uint16))
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.full((20, 30), 3000, np.uint16))
    with screenshot_on_failure(browser, "depth"):
        browser.set_window_size(1200, 900)
        open_page(browser, server.url)
        browser.find_element(By.CSS_SELECTOR, "#camera summary").click()
        browser.find_element(By.ID, "intrinsics").send_keys(f"500,500,{width / 2},{height / 2}")
        browser.find_element(By.ID, "depth").send_keys(str(depth))
        upload(browser, demo_photo)
        wait(browser, lambda d: d.find_elements(By.CSS_SELECTOR, ".ranking li"))
        first = browser.find_element(By.CSS_SELECTOR, ".ranking li")
        assert "1. mug" in first.text and "pose: azimuth" in first.text, first.text
        wait(browser, lambda d: js(d, "return document.querySelector('#layers img').naturalWidth") > 0)
        answer = js(browser, "return state.answer")
        assert answer["intrinsics"] == [500.0, 500.0, width / 2, height / 2]
        assert answer["results"][0]["pose"]["depth_pixels"] > 0
        # a pinhole pose is drawn on request (POST /overlay) through the answer's intrinsics
        js(browser, "const g = state.groups[0]; g.results[0].overlay = null; select(g, 0);")
        wait(browser, lambda d: js(d, "const i = document.querySelector('#layers img');"
                                      "return !i.hidden && i.src.startsWith('blob:') && i.naturalWidth > 0"))
        browser.find_element(By.ID, "depth").clear()
        browser.find_element(By.ID, "depth").send_keys(str(small))
        upload(browser, demo_photo)
        text = message(browser)
        assert "the depth image is 30x20 pixels" in text, text


def test_bad_photos_show_a_message_and_the_server_stays_up(browser, server, bad_files):
    with screenshot_on_failure(browser, "bad-photos"):
        browser.set_window_size(390, 844)
        open_page(browser, server.url)
        for name, wanted in (("notes", "not an image file"), ("huge", "too large"), ("wall", "no object found")):
            upload(browser, bad_files[name])
            text = message(browser)
            assert wanted in text and bad_files[name].name in text, text
            no_horizontal_scroll(browser)
            status, health = request(server.url, "GET", "/health", token=TOKEN)
            assert status == 200 and health["pid"] in server.pids
            js(browser, "document.getElementById('message').className = ''")  # wait for the next one


def test_the_catalogue_shows_every_object_and_turns_one(browser, server):
    from selenium.webdriver.common.by import By

    with screenshot_on_failure(browser, "catalogue"):
        browser.set_window_size(390, 844)
        open_page(browser, server.url)
        browser.find_element(By.CSS_SELECTOR, '.tab[data-tab="catalogue"]').click()
        wait(browser, lambda d: len(d.find_elements(By.CSS_SELECTOR, "#objects li")) == 6)
        cards = {li.get_attribute("data-object"): li.text for li in browser.find_elements(By.CSS_SELECTOR, "#objects li")}
        assert "H2 · V2" in cards["mug"] and "25 of 144 views stored" in cards["mug"]
        wait(browser, lambda d: js(d, "return [...document.querySelectorAll('#objects img')]"
                                      ".every(i => i.naturalWidth > 0)"))
        no_horizontal_scroll(browser)
        browser.find_element(By.CSS_SELECTOR, '#objects li[data-object="mug"] button').click()
        wait(browser, lambda d: js(d, "return document.getElementById('turntable-img').naturalWidth") > 0)
        first = browser.find_element(By.ID, "turntable-view").text
        wait(browser, lambda d: d.find_element(By.ID, "turntable-view").text != first, 30)  # it turns
        assert "mirror" in browser.find_element(By.ID, "turntable-symmetry").text
        no_horizontal_scroll(browser)
        browser.find_element(By.CSS_SELECTOR, "#turntable .dialog-head button").click()


# ---------------------------------------------------------------------- prompts on the page
#: Three sample objects on a table, each seen off the database's grid: (name, azimuth,
#: elevation) and where its render's top-left corner goes in the photo.
TABLE = (("car", 40, 20), ("mug", 130, 25), ("marked_cube", 200, 35))
TABLE_PLACES = [(10, 60), (170, 20), (310, 80)]
TABLE_SIZE = (430, 200)


@pytest.fixture(scope="module")
def table(db, tmp_path_factory) -> dict[str, object]:
    """A photo of three objects: a PNG, the same photo as a JPEG stored on its side with an
    EXIF orientation (6: turn 90° clockwise to show), and each object's true mask."""
    from viewdb.bench.photos import table_photo
    from viewdb.recognition.image import load_image

    photo, masks = table_photo([db.render(n, h, v) for n, h, v in TABLE], TABLE_SIZE, TABLE_PLACES)
    folder = tmp_path_factory.mktemp("table")
    png = folder / "table.png"
    Image.fromarray(photo).save(png)
    turned = folder / "table-on-its-side.jpg"
    exif = Image.Exif()
    exif[0x0112] = 6
    Image.fromarray(photo).transpose(Image.Transpose.ROTATE_90).save(turned, quality=95, exif=exif)
    assert load_image(turned).rgb.shape == photo.shape  # the server reads it upright
    return {"png": png, "turned": turned, "masks": dict(zip((n for n, _, _ in TABLE), masks, strict=True))}


def true_box(mask: np.ndarray) -> tuple[int, int, int, int]:
    ys, xs = np.nonzero(mask)
    return int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1


def box_iou(a, b) -> float:
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    area = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1])
    return w * h / (area - w * h)


def answered_objects(driver) -> list[dict[str, object]]:
    """Each object of the answer the page shows: its region and ranked objects."""
    from selenium.webdriver.common.by import By

    wait(driver, lambda d: d.find_elements(By.CSS_SELECTOR, ".found.several")
         or d.find_element(By.ID, "message").get_attribute("class") == "error")
    assert not driver.find_element(By.ID, "message").is_displayed(), driver.find_element(By.ID, "message").text
    return js(driver, "return state.answer.objects.map(o => ({region: o.region, "
                      "objects: o.results.map(r => r.object)}))")


def test_boxes_dragged_on_a_turned_photo_ask_for_those_objects(browser, server, table):
    from selenium.webdriver.common.by import By

    with screenshot_on_failure(browser, "boxes"):
        browser.set_window_size(1200, 900)
        open_page(browser, server.url)
        surface = choose(browser, table["turned"])
        # the preview shows the photo upright, as the server reads it
        assert (surface["photo_width"], surface["photo_height"]) == TABLE_SIZE
        scale = surface["photo_width"] / surface["width"]  # photo pixels per CSS pixel
        drawn = []
        for name in ("mug", "car"):
            x1, y1, x2, y2 = true_box(table["masks"][name])
            drawn.append((x1 - 8, y1 - 8, x2 + 8, y2 + 8))
            drag_box(browser, surface, drawn[-1])
        assert len(browser.find_elements(By.CSS_SELECTOR, "#marks rect.prompt")) == 2
        browser.find_element(By.ID, "k").clear()
        browser.find_element(By.ID, "k").send_keys("1")
        browser.find_element(By.ID, "go").click()
        found = answered_objects(browser)
        assert [o["objects"] for o in found] == [["mug"], ["car"]]
        slack = 1.5 * scale + 1  # a CSS pixel of the preview, and rounding
        for entry, box, name in zip(found, drawn, ("mug", "car"), strict=True):
            sent = entry["region"]["prompt"]["box"]  # the box the request carried
            assert np.allclose(sent, box, atol=slack), (sent, box)
            cut = entry["region"]["box"]
            assert cut[0] >= box[0] - slack and cut[1] >= box[1] - slack
            assert cut[2] <= box[2] + slack and cut[3] <= box[3] + slack
            assert box_iou(cut, true_box(table["masks"][name])) > 0.7, (name, cut)
        # one section per object, its region outlined, its best result drawn in its pose
        sections = browser.find_elements(By.CSS_SELECTOR, ".found.several")
        assert [s.find_element(By.CSS_SELECTOR, ".ranking li").get_attribute("data-object") for s in sections] \
            == ["mug", "car"]
        assert "from the box" in sections[0].text and "Object 1" in sections[0].text
        assert len(browser.find_elements(By.CSS_SELECTOR, "#marks rect.region")) == 2
        wait(browser, lambda d: js(d, "return [...document.querySelectorAll('#layers img')]"
                                      ".map(i => !i.hidden && i.naturalWidth > 0)") == [True, True])
        wait(browser, lambda d: js(d, "return [...document.querySelectorAll('.ranking img')]"
                                      ".every(i => i.naturalWidth > 0)"))
        # clearing the prompts clears the answer drawn for them
        browser.find_element(By.ID, "clear-prompts").click()
        assert not browser.find_elements(By.CSS_SELECTOR, "#marks rect, #layers img")
        assert not browser.find_element(By.ID, "answers").is_displayed()


def test_a_tap_with_a_finger_asks_for_the_object_under_it_at_phone_width(browser, server, table):
    from scipy.ndimage import distance_transform_edt
    from selenium.webdriver.common.by import By

    with screenshot_on_failure(browser, "tap"):
        browser.set_window_size(390, 844)
        wait(browser, lambda d: js(d, "return window.innerWidth") <= 400)
        open_page(browser, server.url)
        surface = choose(browser, table["png"])
        inside = distance_transform_edt(table["masks"]["mug"])
        y, x = np.unravel_index(int(np.argmax(inside)), inside.shape)  # deep inside the mug
        scrolled = js(browser, "return window.scrollY")
        gesture(browser, [on_screen(surface, x + 0.5, y + 0.5)], kind="touch")
        assert js(browser, "return window.scrollY") == scrolled
        assert len(browser.find_elements(By.CSS_SELECTOR, "#marks circle.prompt")) == 1
        browser.find_element(By.ID, "k").clear()
        browser.find_element(By.ID, "k").send_keys("1")
        browser.find_element(By.ID, "go").click()
        found = answered_objects(browser)
        assert len(found) == 1 and found[0]["objects"] == ["mug"]
        scale = surface["photo_width"] / surface["width"]
        sent = found[0]["region"]["prompt"]["point"]
        assert abs(sent[0] - x) <= scale + 1 and abs(sent[1] - y) <= scale + 1, (sent, (x, y))
        assert box_iou(found[0]["region"]["box"], true_box(table["masks"]["mug"])) > 0.7
        assert "from the point" in browser.find_element(By.CSS_SELECTOR, ".found.several").text
        wait(browser, lambda d: js(d, "return document.querySelector('#layers img').naturalWidth") > 0)
        no_horizontal_scroll(browser)


def test_every_object_ticked_finds_each_one(browser, server, table):
    from selenium.webdriver.common.by import By

    with screenshot_on_failure(browser, "every"):
        browser.set_window_size(1200, 900)
        open_page(browser, server.url)
        surface = choose(browser, table["png"])
        drag_box(browser, surface, true_box(table["masks"]["car"]))
        browser.find_element(By.ID, "every").click()  # prompts or every object, not both
        assert not browser.find_elements(By.CSS_SELECTOR, "#marks rect.prompt")
        browser.find_element(By.ID, "k").clear()
        browser.find_element(By.ID, "k").send_keys("1")
        browser.find_element(By.ID, "go").click()
        found = answered_objects(browser)
        assert len(found) == 3 and all("prompt" not in o["region"] for o in found)
        for name, mask in table["masks"].items():
            assert max(box_iou(o["region"]["box"], true_box(mask)) for o in found) > 0.7, name
        assert "found on its own" in browser.find_element(By.CSS_SELECTOR, ".found.several").text


def test_a_degenerate_box_shows_a_message_and_the_server_stays_up(browser, server, table):
    from selenium.webdriver.common.by import By

    with screenshot_on_failure(browser, "degenerate-box"):
        browser.set_window_size(1200, 900)
        open_page(browser, server.url)
        surface = choose(browser, table["png"])
        start = on_screen(surface, 40, 100)
        gesture(browser, [start, (start[0] + 60, start[1]), (start[0] + 120, start[1])])  # flat: no height
        assert len(browser.find_elements(By.CSS_SELECTOR, "#marks rect.prompt")) == 1
        browser.find_element(By.ID, "go").click()
        text = message(browser)
        assert "table.png" in text and "degenerate" in text and "box" in text, text
        assert not browser.find_element(By.ID, "answers").is_displayed()
        status, health = request(server.url, "GET", "/health", token=TOKEN)
        assert status == 200 and health["pid"] in server.pids
