"""The web page of ``viewdb serve`` and the endpoints behind it.

``POST /query``  a photo (multipart field ``photo``) and options (``plan``, ``k``,
                 ``pose_top``, each defaulting as in the library; for
                 several objects ``box`` and ``point``, each repeatable, or ``all`` and
                 ``max_objects``, as ``viewdb query``'s options): the
                 whole query runs on the server (:meth:`viewdb.ViewDB.query` on the full
                 file); the reply is the ``viewdb query --json`` document plus, to show
                 it, the photo as the server decoded it (shrunk, JPEG) and per posed
                 result its overlay (:mod:`viewdb.recognition.overlay`, a transparent PNG
                 laid over that photo; the best posed result's, the others' from
                 ``POST /overlay``) and the URL of its matched view's picture (with
                 prompts: for each entry of ``objects``)
``POST /overlay`` one result's overlay (JSON: the result as ``POST /query`` gave it and
                 the photo's size): a transparent PNG
``GET /objects`` every object with its symmetry, views stored and grid, and a picture
``GET /objects/{name}/views``  the views the file stores of one object (a turntable)
``GET /objects/{name}/views/{azimuth}/{elevation}.png``  a view rendered from the stored
                 mesh, RGBA with a transparent background; rendered once per worker and
                 kept (:attr:`viewdb.config.WebConfig.view_cache`); with ``?v=`` the
                 object's content hash (as the URLs above give it) the browser may keep
                 it for good, since a changed mesh gets another URL
``GET /``        the page (``static/``), unless the server runs with ``--no-ui``

The endpoints need the bearer token as every other one does; the page asks for it once
(when an endpoint answers 401) and keeps it in the browser.
"""

from __future__ import annotations

import base64
import json
import math
import tempfile
import time
from collections import OrderedDict
from collections.abc import Awaitable, Callable
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar
from urllib.parse import quote

import cv2
import numpy as np
from fastapi import APIRouter, FastAPI, Request
from fastapi.responses import FileResponse, Response
from fastapi.staticfiles import StaticFiles
from numpy.typing import NDArray
from starlette.datastructures import UploadFile
from starlette.exceptions import HTTPException

from ..api import ViewDB
from ..camera import normalise_angle
from ..config import LIMITS, OverlayConfig, SegmentationConfig, WebConfig, finite
from ..errors import ImageError, QueryError, ViewDBError
from ..pose.intrinsics import Intrinsics, check_intrinsics
from ..recognition.depth_image import decode_depth
from ..recognition.image import DEFAULTS as IMAGE_LIMITS
from ..recognition.image import load_image
from ..recognition.options import QueryOptions
from ..recognition.overlay import OverlayPose, overlay_layer, resized_photo
from ..recognition.regions import Prompts
from ..recognition.verify import physical_view
from ..search.plans import PLANS, Candidate
from . import models

__all__ = ["STATIC", "add_page", "web_router"]

T = TypeVar("T")
#: The library's query defaults, which are the page's.
QUERY_DEFAULTS = QueryOptions()
Runner = Callable[[Callable[[ViewDB], T]], Awaitable[tuple[T, float]]]

#: The page's files (package data).
STATIC = Path(__file__).resolve().parent / "static"

#: The page loads nothing from elsewhere and runs no inline script.
_PAGE_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data: blob:; "
                               "style-src 'self'; script-src 'self'; connect-src 'self'; "
                               "frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
}


def add_page(app: FastAPI) -> None:
    """Serve the page at ``/`` and its files under ``/static/`` (no token needed)."""

    @app.get("/", include_in_schema=False)
    async def page() -> FileResponse:
        return FileResponse(STATIC / "index.html", media_type="text/html", headers=_PAGE_HEADERS)

    app.mount("/static", StaticFiles(directory=STATIC), name="static")


# ------------------------------------------------------------------ helpers
def _finite(value: Any) -> Any:
    """``value`` with every non-finite float replaced by None (JSON has no NaN)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not allowed in JSON")


def _data_url(kind: str, data: bytes) -> str:
    return f"data:{kind};base64,{base64.b64encode(data).decode('ascii')}"


def _encode(image: NDArray[np.uint8], ext: str, params: list[int] | None = None) -> bytes:
    """RGB(A) → PNG or JPEG bytes."""
    code = cv2.COLOR_RGBA2BGRA if image.ndim == 3 and image.shape[2] == 4 else cv2.COLOR_RGB2BGR
    ok, buf = cv2.imencode(ext, cv2.cvtColor(image, code), params or [])
    if not ok:
        raise ViewDBError(f"cannot encode a {ext} image")
    return bytes(buf)


def _angle(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise HTTPException(422, f"{what} must be a number of degrees, got {text!r}") from None
    if not math.isfinite(value):
        raise HTTPException(422, f"{what} must be a finite number of degrees, got {text!r}")
    return normalise_angle(value)


def view_url(name: str, azimuth: float, elevation: float, content_hash: str) -> str:
    """The picture of a view, relative to the server's root (the page's base)."""
    return (f"objects/{quote(name, safe='')}/views/{azimuth:g}/{elevation:g}.png"
            f"?v={content_hash[:12]}")


def _upload_name(upload: UploadFile) -> str:
    name = Path(upload.filename or "photo").name
    printable = "".join(c if c.isprintable() else " " for c in name)
    return " ".join(printable.split())[:120] or "photo"


def _int_field(form: Any, name: str, default: int, low: int, high: int) -> int:
    raw = form.get(name)
    if raw is None or raw == "":
        return default
    try:
        value = int(str(raw))
    except ValueError:
        raise HTTPException(422, f"{name} must be a whole number, got {str(raw)[:40]!r}") from None
    if not low <= value <= high:
        raise HTTPException(422, f"{name} must be between {low} and {high}, got {value}")
    return value


# ------------------------------------------------------------------ the query
def _decode(data: bytes, name: str, max_pixels: int = IMAGE_LIMITS.max_pixels
            ) -> tuple[NDArray[np.uint8], NDArray[np.uint8] | None]:
    """The uploaded photo as RGB (+ alpha), upright (its EXIF orientation applied); an
    :class:`ImageError` names the upload, not a temporary file."""
    with tempfile.TemporaryDirectory(prefix="viewdb-upload-") as folder:
        path = Path(folder) / "photo"
        path.write_bytes(data)
        try:
            loaded = load_image(path, max_pixels=max_pixels)
        except ImageError as exc:
            raise ImageError(exc.message, name) from exc
    return loaded.rgb, loaded.alpha


def _drawing(config: WebConfig) -> OverlayConfig:
    return OverlayConfig(max_side=config.display_side, min_side=config.display_min_side)


def _colour(rank: int | None, drawing: OverlayConfig) -> tuple[int, int, int]:
    return drawing.colours[((rank or 1) - 1) % len(drawing.colours)]


def draw_layer(db: ViewDB, result: dict[str, Any], shape: tuple[int, int], config: WebConfig,
               intrinsics: Intrinsics | None = None) -> bytes | None:
    """One result's overlay (a transparent PNG the size the photo is shown at), in the
    colour of its rank; None when it has no pose. A pinhole pose is drawn through the
    query's ``intrinsics``."""
    pose = OverlayPose.from_json(result)
    if pose is None:
        return None
    drawing = _drawing(config)
    drawing = replace(drawing, colours=(_colour(pose.rank, drawing),))
    return _encode(overlay_layer(shape, [pose], db.mesh, intrinsics=intrinsics, placement=db.placement,
                                 config=drawing), ".png")


def answer_query(db: ViewDB, data: bytes, name: str, plan: str, k: int, config: WebConfig,
                 max_pixels: int = IMAGE_LIMITS.max_pixels, pose_top: int | None = QUERY_DEFAULTS.pose_top,
                 prompts: dict[str, Any] | None = None) -> dict[str, Any]:
    """What ``POST /query`` answers (see the module doc); runs on the worker's thread.
    A photo of more than ``max_pixels`` pixels is refused from its header; the best
    ``pose_top`` results are posed, as the library poses them (the page asks again, with a
    larger ``pose_top``, for a result that was not posed).
    ``prompts``: the query's ``boxes``, ``points``, ``every`` and ``max_objects``, and its
    ``intrinsics``, ``depth`` and ``depth_scale``."""
    rgb, alpha = _decode(data, name, max_pixels)
    image = rgb if alpha is None else np.dstack([rgb, alpha])
    try:
        result = db.query(image, k=k, plan=plan, pose_top=pose_top, **(prompts or {})).to_dict()
    except ImageError as exc:
        raise ImageError(exc.message, name) from exc
    result["image"] = name
    start = time.perf_counter()
    drawing = _drawing(config)
    shown = resized_photo(rgb, drawing)
    quality = [cv2.IMWRITE_JPEG_QUALITY, config.photo_quality]
    result["photo"] = {"width": int(shown.shape[1]), "height": int(shown.shape[0]),
                       "source_width": int(rgb.shape[1]), "source_height": int(rgb.shape[0]),
                       "src": _data_url("image/jpeg", _encode(shown, ".jpg", quality))}
    hashes = {o.name: o.content_hash for o in db.objects()}
    camera = (prompts or {}).get("intrinsics")
    if camera is not None:
        result["intrinsics"] = [float(v) for v in camera]
    for entries in [result["results"], *(o["results"] for o in result.get("objects") or [])]:
        _dress(db, entries, rgb.shape[:2], hashes, config, drawing, camera)
    result["timing_ms"]["overlay"] = round((time.perf_counter() - start) * 1e3, 3)
    return _finite(result)


def _dress(db: ViewDB, entries: list[dict[str, Any]], shape: tuple[int, int], hashes: dict[str, str],
           config: WebConfig, drawing: OverlayConfig, intrinsics: Intrinsics | None) -> None:
    """Each result of one object with its colour, thumbnail and (the best posed one's) overlay."""
    drawn = False
    for entry in entries:
        entry["colour"] = "#{:02x}{:02x}{:02x}".format(*_colour(entry.get("rank"), drawing))
        entry["overlay"] = None
        if not drawn and entry.get("pose"):  # the best posed result's; the others on request
            png = draw_layer(db, entry, shape, config, intrinsics)
            entry["overlay"] = None if png is None else _data_url("image/png", png)
            drawn = True
        view = entry["view"]
        h, v = physical_view(Candidate(entry["object"], entry["distance"], view["azimuth"],
                                       view["elevation"], bool(view["mirrored"])))
        entry["thumbnail"] = view_url(entry["object"], h, v, hashes.get(entry["object"], ""))


def _prompt_fields(form: Any) -> dict[str, Any]:
    """The ``box``, ``point``, ``all`` and ``max_objects`` fields of the form, parsed."""
    try:
        prompts = Prompts.of([str(b) for b in form.getlist("box")], [str(p) for p in form.getlist("point")],
                             str(form.get("all") or "").lower() in ("1", "true", "yes", "on"),
                             _int_field(form, "max_objects", 0, 0, 1000) or None)
    except QueryError as exc:
        raise HTTPException(422, exc.message) from None
    if prompts is None:
        return {}
    return {"boxes": list(prompts.boxes), "points": list(prompts.points), "every": prompts.every,
            "max_objects": prompts.max_objects}


async def _camera_fields(form: Any) -> dict[str, Any]:
    """The ``intrinsics`` (``fx,fy,cx,cy``), ``depth`` (a file) and ``depth_scale`` fields
    of the form, parsed (:meth:`viewdb.ViewDB.query`'s keywords)."""
    out: dict[str, Any] = {}
    text = str(form.get("intrinsics") or "").strip()
    if text:  # numbers only: never a path on the server
        try:
            out["intrinsics"] = check_intrinsics([float(v) for v in text.split(",")])
        except ValueError:
            raise HTTPException(422, "intrinsics must be fx,fy,cx,cy (four numbers), "
                                     f"got {text[:60]!r}") from None
        except ViewDBError as exc:
            raise HTTPException(422, f"intrinsics: {exc.message}") from None
    upload = form.get("depth")
    if isinstance(upload, UploadFile):
        name = _upload_name(upload)
        try:
            out["depth"] = decode_depth(await upload.read(), name)
        except ImageError as exc:
            raise HTTPException(422, str(exc)) from None
        if "intrinsics" not in out:
            raise HTTPException(422, "depth needs intrinsics (fx,fy,cx,cy): it sets a perspective "
                                     "pose's distance")
    elif upload is not None and str(upload) != "":
        raise HTTPException(422, "depth must be a file (a 16-bit PNG or TIFF, a float TIFF or a .npy)")
    raw = str(form.get("depth_scale") or "").strip()
    if raw:
        try:
            out["depth_scale"] = finite(float(raw), "depth_scale", LIMITS.min_depth_scale,
                                        LIMITS.max_depth_scale)
        except ValueError:
            raise HTTPException(422, f"depth_scale must be a positive number, got {raw[:40]!r}") from None
    return out


def _overlay_intrinsics(data: dict[str, Any]) -> Intrinsics | None:
    """A ``POST /overlay`` body's ``intrinsics`` (those ``POST /query`` answered with), checked."""
    values = data.get("intrinsics")
    if values is None:
        return None
    try:
        return check_intrinsics(values)
    except ViewDBError as exc:
        raise HTTPException(422, exc.message) from None


def _overlay_request(data: Any, max_pixels: int = IMAGE_LIMITS.max_pixels
                     ) -> tuple[dict[str, Any], tuple[int, int]]:
    """The result and photo size of a ``POST /overlay`` body, checked."""
    if not isinstance(data, dict) or not isinstance(data.get("result"), dict):
        raise HTTPException(422, "expected {\"result\": <one result of POST /query>, \"width\": int, "
                                 "\"height\": int}")
    size = []
    for key in ("height", "width"):
        value = data.get(key)
        if not isinstance(value, int) or isinstance(value, bool) or not 16 <= value <= 100_000:
            raise HTTPException(422, f"{key} must be the photo's {key} in pixels (16 to 100000), "
                                     f"got {value!r}")
        size.append(value)
    if size[0] * size[1] > max_pixels:
        raise HTTPException(422, f"a photo of {size[1]}x{size[0]} pixels is larger than any query accepts")
    result = data["result"]
    if not isinstance(result.get("object"), str) or not isinstance(result.get("pose"), dict):
        raise HTTPException(422, "the result needs its object's name and its pose")
    try:
        OverlayPose.from_json(result)
    except (KeyError, TypeError, ValueError, OverflowError) as exc:  # 1e400 parses as inf
        why = " ".join(str(exc).split())[:160]
        raise HTTPException(422, f"the result's pose is not a pose: {why}") from exc
    return result, (size[0], size[1])


# ------------------------------------------------------------------ the router
def web_router(run: Runner[Any], guarded: list[Any], config: WebConfig | None = None, *,
               max_pixels: int = IMAGE_LIMITS.max_pixels) -> APIRouter:
    """The endpoints of the page (see the module doc), behind ``guarded`` (the token);
    photos of more than ``max_pixels`` pixels are refused from their header."""
    config = config or WebConfig()
    router = APIRouter(dependencies=guarded)
    errors = {code: {"model": models.ErrorModel, "description": what} for code, what in (
        (400, "the body is not JSON"), (401, "missing or wrong bearer token"), (404, "no such object"),
        (413, "the photo is over the server's limit"),
        (422, "the photo is not an image, shows no object, or an option is out of range"),
    )}
    _photo_routes(router, run, config, errors, max_pixels)
    _object_routes(router, run, config, errors)
    return router


def _photo_routes(router: APIRouter, run: Runner[Any], config: WebConfig, errors: dict[Any, Any],
                  max_pixels: int) -> None:
    """``POST /query`` and ``POST /overlay``: a photo's answer and one result's overlay."""

    @router.post("/query", responses={200: {"model": models.WebQueryReplyModel}, **errors},
                 openapi_extra=models.multipart_body(models.WebQueryFormModel),
                 summary="Recognise the object in a photo and pose it, with pictures to show it")
    async def query(request: Request) -> dict[str, Any]:
        form = await request.form(max_files=2, max_fields=10 + 2 * SegmentationConfig().max_prompts)
        try:
            upload = form.get("photo")
            if not isinstance(upload, UploadFile):
                raise HTTPException(422, "no photo: send the image as the multipart form field 'photo'")
            plan = str(form.get("plan") or QUERY_DEFAULTS.plan)
            if plan not in PLANS:
                raise HTTPException(422, f"plan must be server, cs1, cs2 or fast, got {plan[:40]!r}")
            k = _int_field(form, "k", min(QUERY_DEFAULTS.k, config.max_k), 1, config.max_k)
            pose_top = _int_field(form, "pose_top", QUERY_DEFAULTS.pose_top or k, 0, config.max_k)
            prompts = _prompt_fields(form)
            camera = await _camera_fields(form)
            name = _upload_name(upload)
            data = await upload.read()
        finally:
            await form.close()
        if not data:
            raise HTTPException(422, f"{name}: empty file, not an image")
        try:
            out, _ = await run(lambda db: answer_query(db, data, name, plan, k, config, max_pixels,
                                                       pose_top, {**prompts, **camera}))
        except ImageError as exc:
            raise HTTPException(422, str(exc)) from exc
        return out

    @router.post("/overlay", responses={200: {"content": {"image/png": {}}, "description": "the overlay"},
                                        **errors},
                 openapi_extra=models.json_body(models.OverlayRequestModel), response_class=Response,
                 summary="One result's overlay, to lay over the photo as POST /query shows it")
    async def overlay(request: Request) -> Response:
        try:
            data = json.loads(await request.body() or b"null", parse_constant=_no_constant)
        except (ValueError, RecursionError) as exc:
            raise HTTPException(400, f"body is not valid JSON: {exc}") from exc
        result, shape = _overlay_request(data, max_pixels)
        camera = _overlay_intrinsics(data)
        png, _ = await run(lambda db: draw_layer(db, result, shape, config, camera))
        return Response(png, media_type="image/png")


def _object_routes(router: APIRouter, run: Runner[Any], config: WebConfig, errors: dict[Any, Any]) -> None:
    """``GET /objects``, an object's stored views, and a view's picture (cached)."""
    pictures: OrderedDict[tuple[str, str, float, float], bytes] = OrderedDict()

    @router.get("/objects", responses={200: {"model": models.ObjectsReplyModel}, **errors},
                summary="Every object, with its symmetry, views stored and a picture")
    async def objects() -> dict[str, Any]:
        def listing(db: ViewDB) -> dict[str, Any]:
            h, v = config.picture_view
            out = []
            for info in db.objects():
                entry = info.to_dict()
                entry.pop("source", None)  # a path on the server
                entry["thumbnail"] = view_url(info.name, h, v, info.content_hash)
                out.append(entry)
            return {"gap": db.config.gap, "objects": out}

        found, _ = await run(listing)
        return _finite(found)

    @router.get("/objects/{name}/views", responses={200: {"model": models.ViewsReplyModel}, **errors},
                summary="The views the file stores of one object")
    async def views(name: str) -> dict[str, Any]:
        def stored(db: ViewDB) -> dict[str, Any]:
            info = db.object(name)
            return {"object": name, "gap": db.config.gap,
                    "views": [{"azimuth": h, "elevation": v, "src": view_url(name, h, v, info.content_hash)}
                              for h, v in sorted(db.views(name), key=lambda x: (x[1], x[0]))]}

        found, _ = await run(stored)
        return found

    @router.get("/objects/{name}/views/{azimuth}/{elevation}.png",
                responses={200: {"content": {"image/png": {}}, "description": "the view, RGBA"}, **errors},
                response_class=Response, summary="A view of an object rendered from its stored mesh")
    async def picture(request: Request, name: str, azimuth: str, elevation: str) -> Response:
        h, v = _angle(azimuth, "azimuth"), _angle(elevation, "elevation")

        def make(db: ViewDB) -> tuple[bytes, str]:
            version = db.object(name).content_hash
            key = (name, version, h, v)
            if key in pictures:
                pictures.move_to_end(key)
                return pictures[key], version
            view = db.render(name, h, v)
            rgba = np.dstack([view.color, view.mask.astype(np.uint8) * 255])
            png = pictures[key] = _encode(rgba, ".png")
            while len(pictures) > config.view_cache:
                pictures.popitem(last=False)
            return png, version

        (png, version), _ = await run(make)
        tag = f'"{version[:16]}-{h:g}-{v:g}"'
        forever = request.query_params.get("v") == version[:12]
        headers = {"ETag": tag, "Cache-Control": "private, max-age=31536000, immutable" if forever
                   else "private, no-cache"}
        if request.headers.get("if-none-match") == tag:
            return Response(status_code=304, headers=headers)
        return Response(png, media_type="image/png", headers=headers)
