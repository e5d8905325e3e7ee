"""The server tier over HTTP: an ASGI app (FastAPI) serving a full database read-only.

Endpoints (the JSON bodies are the messages of :mod:`viewdb.search.plans` and
:mod:`viewdb.http.wire`; the HTTP layer is only transport):

``POST /refine``  CS1's server half (Algorithm 3); with no client candidates, the
                  ``server`` plan's exact k-NN; with ``shortlist``, CS2's (the exact
                  k-NN over the client's shortlisted objects); with ``fast``, the
                  ``fast`` plan's (the exact k-NN over the objects the server's
                  approximate index shortlists)
``POST /walk``    CS2's server half by the paper's neighbour walk (Algorithm 4)
``POST /pose``    the pose of given matches from the segmented query image
``POST /colours`` the colour signatures of stored views (the client re-ranks by colour)
``POST /colour-ranking`` the objects whose stored colours lie nearest a cut-out's
``POST /looks``   each coloured object's look distance to a cut-out's box (the look model)
``POST /fits``    how well stored views fit the segmented query's shape (the client
                  re-ranks by them, :mod:`viewdb.recognition.verify`)
``GET /info``     what the database holds, its build settings and the server's limits
``GET /health``   liveness (no database access, no token; the worker's pid only with it;
                  for a sharded catalogue, which shards are up)
``GET /openapi.json``, ``/docs``, ``/redoc``  the schema and its pages: public even with a
                  token (they describe the API and hold no data)
``POST /query``, ``POST /overlay``, ``GET /objects``, ``GET /objects/{name}/views[/{h}/{v}.png]``
                  the web page's endpoints: the whole query on the server, with pictures
                  (:mod:`viewdb.http.web`)
``GET /``         the web page (no token; not with ``ui=False``, ``viewdb serve --no-ui``)

Bad input never gets a 500: a body that is not JSON is 400, a well-formed one that is
not a valid message 422 (wrong array lengths, NaN, out-of-range numbers), a body over the
limit 413 (refused from its Content-Length before it is read), a body that takes longer
than ``body_timeout`` to arrive 408, a missing or wrong bearer token 401; every error body
is ``{"error": "<one line>", "status": <code>}``. A connection must deliver each request's
header within ``header_timeout`` seconds (:mod:`viewdb.http.protocol`); an image of more
than ``max_pixels`` pixels is refused from its header.

Each worker process opens the database read-only once and answers on one thread of its
own (the renderer's GL context is per thread): requests to one worker are served one
at a time; run several workers (``viewdb serve --workers N``) for parallelism.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import logging
import math
import os
import time
from collections.abc import AsyncIterator, Callable
from concurrent.futures import ThreadPoolExecutor
from contextlib import asynccontextmanager
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from fastapi import APIRouter, Depends, FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.openapi.utils import get_openapi
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from ..api import ViewDB
from ..api import open as open_db
from ..config import HttpConfig, WebConfig
from ..errors import NotFound, QueryError, StorageError, ViewDBError
from ..search.plans import MAX_BAND, MAX_CURVES, MAX_K, RefineRequest, ServerReply, WalkRequest
from . import models, web
from .wire import (
    ColourRankingReply,
    ColourRankingRequest,
    ColourReply,
    ColourRequest,
    FitReply,
    FitRequest,
    LookReply,
    LookRequest,
    PoseReply,
    PoseRequest,
    decode_query,
)

__all__ = ["DEFAULT_MAX_BODY", "DEFAULT_MAX_IMAGE_BODY", "app_from_env", "create_app"]

log = logging.getLogger("viewdb.http")

#: Largest body of a /refine or /walk request (a curve and at most MAX_K candidates).
DEFAULT_MAX_BODY = 256 * 1024
#: Largest body of a /pose request (a base64 PNG).
DEFAULT_MAX_IMAGE_BODY = 32 * 1024 * 1024

#: Environment variables a worker process reads its configuration from.
ENV_DB, ENV_TOKEN = "VIEWDB_DB", "VIEWDB_TOKEN"
#: The Ray cluster a sharded catalogue is served on ("auto" or HOST:PORT).
ENV_RAY = "VIEWDB_RAY"
ENV_MAX_BODY, ENV_MAX_IMAGE_BODY = "VIEWDB_MAX_BODY", "VIEWDB_MAX_IMAGE_BODY"
ENV_BODY_TIMEOUT, ENV_MAX_PIXELS = "VIEWDB_BODY_TIMEOUT", "VIEWDB_MAX_PIXELS"
#: "0": no web page (``viewdb serve --no-ui``).
ENV_UI = "VIEWDB_UI"

T = TypeVar("T")


def _error(status: int, message: str, headers: dict[str, str] | None = None) -> JSONResponse:
    return JSONResponse({"error": " ".join(str(message).split()), "status": status},
                        status_code=status, headers=headers)


#: A refused body up to this size is read and dropped before the 413 goes out, so the
#: client (still sending) gets the reply rather than a reset connection.
DRAIN_BYTES = 16 * 1024 * 1024


async def _drain(receive: Receive, seen: int, deadline: float) -> None:
    while seen <= DRAIN_BYTES:
        try:
            message = await asyncio.wait_for(receive(), max(deadline - time.monotonic(), 0.0))
        except TimeoutError:
            return
        if message["type"] != "http.request":
            return
        seen += len(message.get("body", b""))
        if not message.get("more_body", False):
            return


class BodyLimit:
    """ASGI middleware: 413 for a body over the path's limit, from its Content-Length
    before reading, or while reading a body sent without one (chunked); 408 for a body
    that has not arrived whole ``timeout`` seconds after the request's header."""

    def __init__(self, app: ASGIApp, limits: dict[str, int], default: int,
                 timeout: float = HttpConfig().body_timeout) -> None:
        self.app, self.limits, self.default, self.timeout = app, limits, default, timeout

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        deadline = time.monotonic() + self.timeout
        limit = self.limits.get(scope["path"], self.default)
        declared = dict(scope["headers"]).get(b"content-length")
        close = {"Connection": "close"}
        if declared is not None:
            if not declared.isdigit():
                await _error(400, "Content-Length is not a number", close)(scope, receive, send)
                return
            if int(declared) > limit:
                if int(declared) <= DRAIN_BYTES:
                    await _drain(receive, 0, deadline)
                await _error(413, f"body of {int(declared):,} bytes is over this endpoint's "
                                  f"limit of {limit:,}", close)(scope, receive, send)
                return
        seen = 0
        complete = False

        async def limited() -> Message:
            nonlocal seen, complete
            if complete:  # after the body only a disconnect can come: no deadline
                return await receive()
            try:
                message = await asyncio.wait_for(receive(), max(deadline - time.monotonic(), 0.0))
            except TimeoutError:
                raise HTTPException(408, f"the body did not arrive within {self.timeout:g} s",
                                    headers=close) from None
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                complete = not message.get("more_body", False)
                if seen > limit:
                    if message.get("more_body", False):
                        await _drain(receive, seen, deadline)
                    raise HTTPException(413, f"body is over this endpoint's limit of {limit:,} bytes",
                                        headers=close)
            return message

        await self.app(scope, limited, send)


@dataclass
class _State:
    db: ViewDB
    executor: ThreadPoolExecutor
    curve_samples: int
    objects: int


def _no_constants(name: str) -> Any:
    raise ValueError(f"{name} is not allowed in JSON")


async def _json(request: Request) -> Any:
    body = await request.body()
    if not body:
        raise HTTPException(400, "empty body: expected a JSON object")
    try:
        return json.loads(body, parse_constant=_no_constants)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError and UnicodeDecodeError too
        raise HTTPException(400, f"body is not valid JSON: {exc}") from exc


def _parse(parse: Callable[[], T]) -> T:
    try:
        return parse()
    except QueryError as exc:
        raise HTTPException(422, exc.message) from exc


def _body(model: type[Any]) -> dict[str, Any]:
    """``openapi_extra`` declaring a JSON request body of ``model`` (documented, not
    validated by FastAPI: the message's ``from_dict`` validates)."""
    return {"requestBody": {"required": True, "content": {"application/json": {
        "schema": {"$ref": f"#/components/schemas/{model.__name__}"}}}}}


_ERRORS: dict[int | str, dict[str, Any]] = {
    code: {"model": models.ErrorModel, "description": what} for code, what in (
        (400, "the body is not JSON"), (401, "missing or wrong bearer token"),
        (408, "the body did not arrive in time"), (413, "the body is over the limit"),
        (422, "the JSON is not a valid message"),
    )
}


def create_app(
    db_path: str | Path,
    *,
    token: str | None = None,
    max_body: int = DEFAULT_MAX_BODY,
    max_image_body: int = DEFAULT_MAX_IMAGE_BODY,
    ui: bool = True,
    web_config: WebConfig | None = None,
    http: HttpConfig | None = None,
) -> FastAPI:
    """The ASGI app serving the full database at ``db_path`` (opened read-only at startup).

    ``token``: when given, every endpoint but ``/health``, the schema (``/openapi.json``,
    ``/docs``, ``/redoc``) and the web page needs the header ``Authorization: Bearer
    <token>`` (those are public on purpose: they describe the API and hold no data);
    ``/health`` then shows the worker's pid only to a caller with the token. ``ui``:
    serve the web page at ``/`` (its endpoints are served either way). ``http``: the
    body timeout (408) and the most pixels of an image decoded
    (:class:`~viewdb.config.HttpConfig`).
    """
    http = http or HttpConfig()
    server = _Server(Path(db_path), token, max_body, max_image_body, http.max_pixels)
    app = FastAPI(
        title="viewdb server",
        version=version("viewdb"),
        description="The server tier of viewdb's client-server plans (CS1, CS2) and pose "
                    "estimation, over a full database opened read-only.",
        lifespan=server.lifespan,
    )
    _add_error_handlers(app)
    app.include_router(_routes(server))
    app.include_router(web.web_router(server.run, [Depends(server.authorised)], web_config,
                                      max_pixels=http.max_pixels))
    if ui:
        web.add_page(app)
    app.openapi = lambda: _openapi(app)  # type: ignore[method-assign]
    app.add_middleware(BodyLimit, limits={"/pose": max_image_body, "/fits": max_image_body,
                                          "/query": max_image_body}, default=max_body,
                       timeout=http.body_timeout)
    return app


class _Server:
    """What the routes of one worker share: its open database and the thread that
    answers on it, the token and the limits."""

    def __init__(self, db_path: Path, token: str | None, max_body: int, max_image_body: int,
                 max_pixels: int) -> None:
        self.db_path, self.token = db_path, token
        self.max_body, self.max_image_body, self.max_pixels = max_body, max_image_body, max_pixels
        self._state: _State | None = None

    @asynccontextmanager
    async def lifespan(self, _app: FastAPI) -> AsyncIterator[None]:
        executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="viewdb")
        loop = asyncio.get_running_loop()
        db = await loop.run_in_executor(executor, _open_for_serving, self.db_path)
        self._state = _State(db, executor, db.config.features.curve_samples, len(db.objects()))
        try:
            yield
        finally:
            await loop.run_in_executor(executor, db.close)
            executor.shutdown(wait=True)

    def state(self) -> _State:
        assert self._state is not None
        return self._state

    async def run(self, fn: Callable[[ViewDB], T]) -> tuple[T, float]:
        """``fn(db)`` on the database's thread, and how long it took (ms)."""
        s = self.state()

        def timed() -> tuple[T, float]:
            start = time.perf_counter()
            out = fn(s.db)
            return out, (time.perf_counter() - start) * 1e3

        return await asyncio.get_running_loop().run_in_executor(s.executor, timed)

    def authorised(self, request: Request) -> None:
        """A dependency: 401 unless the request carries the bearer token (if one is set)."""
        if self.token is None:
            return
        given = request.headers.get("authorization", "")
        scheme, _, value = given.partition(" ")
        if scheme.lower() != "bearer" or not hmac.compare_digest(value.strip().encode(), self.token.encode()):
            raise HTTPException(401, "missing or wrong bearer token" if given else
                                "this server needs a bearer token (Authorization: Bearer ...)",
                                headers={"WWW-Authenticate": "Bearer"})


def _add_error_handlers(app: FastAPI) -> None:
    """Every error as ``{"error": "<one line>", "status": <code>}``: the library's errors
    by kind (404, 503, 422), anything unexpected as a logged 500."""

    @app.exception_handler(HTTPException)
    async def http_error(_request: Request, exc: HTTPException) -> JSONResponse:
        return _error(exc.status_code, str(exc.detail), dict(exc.headers or {}))

    @app.exception_handler(RequestValidationError)
    async def validation_error(_request: Request, exc: RequestValidationError) -> JSONResponse:
        first = exc.errors()[0] if exc.errors() else {"msg": "invalid request"}
        return _error(422, f"{'.'.join(str(x) for x in first.get('loc', ()))}: {first['msg']}")

    @app.exception_handler(ViewDBError)
    async def viewdb_error(_request: Request, exc: ViewDBError) -> JSONResponse:
        if isinstance(exc, NotFound):
            return _error(404, exc.message)
        if isinstance(exc, StorageError):
            log.error("database error: %s", exc)
            retry = getattr(exc, "retry_after", None)  # a shard being restarted (ShardUnavailable)
            return _error(503, f"the server's database is unavailable: {exc.message}",
                          None if retry is None else {"Retry-After": str(math.ceil(retry))})
        return _error(422, exc.message)

    @app.exception_handler(Exception)
    async def internal_error(_request: Request, exc: Exception) -> JSONResponse:
        log.exception("internal error")
        return _error(500, f"internal server error ({type(exc).__name__})")


def _reply(r: ServerReply, ms: float) -> dict[str, Any]:
    out = r.to_dict()
    out["stats"]["server_ms"] = ms
    return out


def _routes(server: _Server) -> APIRouter:
    """The endpoints (module docstring), answered by ``server``'s server tier."""
    router = APIRouter()
    guarded = [Depends(server.authorised)]
    state, run = server.state, server.run

    @router.get("/health", summary="Liveness: the worker is up and its database open (no token "
                                    "needed; the worker's pid only with the token)")
    async def health(request: Request) -> dict[str, Any]:
        out: dict[str, Any] = {"status": "ok", "objects": state().objects}
        shards = getattr(state().db, "shard_health", None)  # a sharded catalogue: which shards are up
        if shards is not None:
            out["shards"] = shards()
            if not all(s["up"] for s in out["shards"]):
                out["status"] = "degraded"
        try:
            server.authorised(request)
        except HTTPException:
            return out  # a caller without the token learns nothing about the process
        return {**out, "pid": os.getpid()}

    @router.get("/info", dependencies=guarded, responses=_ERRORS,
                summary="What the database holds, its build settings and this server's limits")
    async def info() -> dict[str, Any]:
        data, _ = await run(lambda db: db.info().to_dict())
        data.pop("path", None)
        return {**data, "viewdb": version("viewdb"), "role": "full", "read_only": True,
                "limits": {"max_k": MAX_K, "max_band": MAX_BAND, "max_curves": MAX_CURVES,
                           "max_body": server.max_body,
                           "max_image_body": server.max_image_body, "max_pixels": server.max_pixels,
                           "curve_samples": state().curve_samples},
                "auth": server.token is not None}

    @router.post("/refine", dependencies=guarded, openapi_extra=_body(models.RefineRequestModel),
                 responses={200: {"model": models.ServerReplyModel}, **_ERRORS},
                 summary="CS1: exact top-k refined from the client's candidates (CS2: over them alone)")
    async def refine(request: Request) -> dict[str, Any]:
        data = await _json(request)
        req = _parse(lambda: RefineRequest.from_dict(data, state().curve_samples))
        found, ms = await run(lambda db: db.server_tier().refine(req)[0])
        return _reply(found, ms)

    @router.post("/walk", dependencies=guarded, openapi_extra=_body(models.WalkRequestModel),
                 responses={200: {"model": models.ServerReplyModel}, **_ERRORS},
                 summary="CS2 by the paper's walk: neighbour walk from the client's views")
    async def walk(request: Request) -> dict[str, Any]:
        data = await _json(request)
        req = _parse(lambda: WalkRequest.from_dict(data, state().curve_samples))
        found, ms = await run(lambda db: db.server_tier().walk(req)[0])
        return _reply(found, ms)

    _image_routes(router, guarded, run, server.max_pixels)
    return router


def _image_routes(router: APIRouter, guarded: list[Any], run: Callable[..., Any], max_pixels: int) -> None:
    """The endpoints that take the segmented query image or stored views' signatures."""

    @router.post("/pose", dependencies=guarded, openapi_extra=_body(models.PoseRequestModel),
                 responses={200: {"model": models.PoseReplyModel}, **_ERRORS},
                 summary="Pose of the given matches from the segmented query image")
    async def pose(request: Request) -> dict[str, Any]:
        data = await _json(request)
        req = _parse(lambda: PoseRequest.from_dict(data))
        query = _parse(lambda: decode_query(req.image, max_pixels))
        poses, ms = await run(lambda db: db.server_tier().poses(
            query, req.matches, req.intrinsics, req.curves, rerank=req.rerank)[0])
        return PoseReply(poses, {"server_ms": ms}).to_dict()

    @router.post("/colours", dependencies=guarded, openapi_extra=_body(models.ColourRequestModel),
                 responses={200: {"model": models.ColourReplyModel}, **_ERRORS},
                 summary="Colour signatures of stored views, to re-rank results by colour")
    async def colours(request: Request) -> dict[str, Any]:
        data = await _json(request)
        req = _parse(lambda: ColourRequest.from_dict(data))
        signatures, ms = await run(lambda db: db.server_tier().colours(req.views)[0])
        return ColourReply(signatures, {"server_ms": ms}).to_dict()

    @router.post("/colour-ranking", dependencies=guarded,
                 openapi_extra=_body(models.ColourRankingRequestModel),
                 responses={200: {"model": models.ColourRankingReplyModel}, **_ERRORS},
                 summary="The objects whose stored colours lie nearest a cut-out's (the colour channel)")
    async def colour_ranking(request: Request) -> dict[str, Any]:
        data = await _json(request)
        req = _parse(lambda: ColourRankingRequest.from_dict(data))
        found, ms = await run(lambda db: db.server_tier().colour_ranking(req.signature, req.n)[0])
        return ColourRankingReply(found, {"server_ms": ms}).to_dict()

    @router.post("/looks", dependencies=guarded, openapi_extra=_body(models.LookRequestModel),
                 responses={200: {"model": models.LookReplyModel}, **_ERRORS},
                 summary="Each coloured object's look distance to a cut-out's box (the look model)")
    async def looks(request: Request) -> dict[str, Any]:
        data = await _json(request)
        req = _parse(lambda: LookRequest.from_dict(data))
        found, ms = await run(lambda db: db.server_tier().looks(req.look)[0])
        return LookReply(found, {"server_ms": ms}).to_dict()

    @router.post("/fits", dependencies=guarded, openapi_extra=_body(models.FitRequestModel),
                 responses={200: {"model": models.FitReplyModel}, **_ERRORS},
                 summary="Shape fits of stored views to the segmented query image, to re-rank results")
    async def fits(request: Request) -> dict[str, Any]:
        data = await _json(request)
        req = _parse(lambda: FitRequest.from_dict(data))
        query = _parse(lambda: decode_query(req.image, max_pixels))
        found, ms = await run(lambda db: db.server_tier().fits(query, req.views)[0])
        return FitReply(found, {"server_ms": ms}).to_dict()


def _openapi(app: FastAPI) -> dict[str, Any]:
    """The schema, with the request bodies' models (the routes only refer to them)."""
    if app.openapi_schema is None:
        schema = get_openapi(title=app.title, version=app.version, description=app.description,
                             routes=app.routes)
        components = schema.setdefault("components", {}).setdefault("schemas", {})
        for model in (models.RefineRequestModel, models.WalkRequestModel, models.PoseRequestModel,
                      models.ColourRequestModel, models.ColourRankingRequestModel, models.LookRequestModel,
                      models.FitRequestModel,
                      models.WebQueryFormModel, models.OverlayRequestModel):
            doc = model.model_json_schema(ref_template="#/components/schemas/{model}")
            components.update(doc.pop("$defs", {}))
            components[model.__name__] = doc
        app.openapi_schema = schema
    return app.openapi_schema


def _open_for_serving(path: Path) -> ViewDB:
    if path.is_dir():  # a sharded catalogue (viewdb shard --out): its shards on Ray
        from ..shards.serving import open_sharded

        return open_sharded(path, os.environ.get(ENV_RAY) or "auto")  # type: ignore[return-value]
    db = open_db(path, read_only=True)
    try:
        if db.role != "full":
            raise ViewDBError("is a client file (export-client); serve the full database", path)
        # compile the search kernels now rather than on the first request
        db.search(np.ones(db.config.features.curve_samples), 1)
    except QueryError:
        pass  # an empty database: nothing to warm up
    except BaseException:
        db.close()
        raise
    return db


def app_from_env() -> FastAPI:
    """The app configured from the environment (``VIEWDB_DB``, ``VIEWDB_TOKEN``,
    ``VIEWDB_MAX_BODY``, ``VIEWDB_MAX_IMAGE_BODY``, ``VIEWDB_UI``, ``VIEWDB_BODY_TIMEOUT``,
    ``VIEWDB_MAX_PIXELS``): the factory each worker of ``viewdb serve`` calls."""
    default = HttpConfig()
    path = os.environ.get(ENV_DB)
    if not path:
        raise ViewDBError(f"set {ENV_DB} to the database to serve")
    return create_app(
        path, token=os.environ.get(ENV_TOKEN) or None,
        max_body=int(os.environ.get(ENV_MAX_BODY, DEFAULT_MAX_BODY)),
        max_image_body=int(os.environ.get(ENV_MAX_IMAGE_BODY, DEFAULT_MAX_IMAGE_BODY)),
        ui=os.environ.get(ENV_UI, "1") != "0",
        http=HttpConfig(body_timeout=float(os.environ.get(ENV_BODY_TIMEOUT, default.body_timeout)),
                        max_pixels=int(os.environ.get(ENV_MAX_PIXELS, default.max_pixels))),
    )
