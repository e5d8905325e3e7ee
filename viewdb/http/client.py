"""A client of ``viewdb serve``: the server half of the plans over HTTP (httpx).

>>> with viewdb.open("client.db", read_only=True) as client, \\
...         viewdb.RemoteServer("http://127.0.0.1:8765") as server:      # doctest: +SKIP
...     result = client.query("photo.jpg", plan="cs1", server=server)

One keep-alive connection per :class:`RemoteServer` (httpx, which brings the timeouts,
connection pooling and TLS), used by one request at a time (a lock serialises threads
sharing it). A connection the server closed while idle is reopened once transparently;
every request is a pure read, so that is safe.

The client does not trust the server (:class:`~viewdb.config.HttpConfig`): connecting,
each read and the whole exchange have their own time limits (a server that sends one
header line a second is cut off at the total), a reply over ``max_reply_bytes`` is
refused while it streams in (never held whole), a compressed reply is refused (no
decompression bomb), and JSON nested deeper than ``max_json_depth`` is refused. Every
failure is a :class:`~viewdb.errors.ServerError` naming the URL.

The client meets the server's limits: a query image over the server's pixel cap (its
``/info``, asked once) is scaled down before ``/pose`` and ``/fits`` (intrinsics with it),
and the query's ``transfer`` says so (``image_width``, ``sent_width`` …).
"""

from __future__ import annotations

import json
import socket
import threading
import time
import urllib.parse
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import httpx
import numpy as np

from ..config import HttpConfig
from ..errors import QueryError, ServerError
from ..pose.estimate import PoseEstimate, QueryView
from ..recognition.server_tier import Exchange
from ..search.colour_index import ColourMatch
from ..search.plans import Candidate, RefineRequest, ServerReply, WalkRequest
from ..typed import Intrinsics
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
    shrink_query,
)

__all__ = ["RemoteServer", "is_token", "json_depth"]


class RemoteServer:
    """The server tier (:class:`~viewdb.recognition.server_tier.ServerTier`) at ``url``
    (``http://host:port`` or ``https://``, optionally with a path prefix).

    ``token`` is sent as ``Authorization: Bearer <token>``. ``config`` sets the time and
    size limits (:class:`~viewdb.config.HttpConfig`: ``connect_timeout``,
    ``read_timeout``, ``total_timeout``, ``max_reply_bytes``, ``max_json_depth``);
    ``timeout``, if given, is the read timeout. Errors are
    :class:`~viewdb.errors.ServerError` naming the URL: cannot connect, timed out, a reply
    too large or malformed, or the server's own one-line reason with its HTTP status.
    """

    def __init__(self, url: str, *, token: str | None = None, timeout: float | None = None,
                 config: HttpConfig | None = None) -> None:
        try:
            parts = urllib.parse.urlsplit(url)
        except ValueError as exc:  # "http://[::1": an unclosed IPv6 address
            raise ServerError(f"is not a server URL ({exc})", url) from exc
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ServerError("is not a server URL (expected http://host:port)", url)
        if token and not is_token(token):
            raise ServerError("the bearer token must be printable ASCII without spaces", url)
        try:
            parts.port  # noqa: B018 - raises for a bad port
        except ValueError as exc:
            raise ServerError(f"has a bad port: {exc}", url) from exc
        try:
            self.config = config or HttpConfig()
            if timeout is not None:
                self.config = replace(self.config, read_timeout=timeout)
        except ValueError as exc:
            raise ServerError(str(exc), url) from exc
        self.url = url.rstrip("/")
        self.remote = True
        headers = {"Content-Type": "application/json", "Accept": "application/json",
                   "Accept-Encoding": "identity"}
        if token:
            headers["Authorization"] = f"Bearer {token}"
        cfg = self.config
        self._client = httpx.Client(
            base_url=self.url, headers=headers, follow_redirects=False, trust_env=False,
            timeout=httpx.Timeout(connect=cfg.connect_timeout, read=cfg.read_timeout,
                                  write=cfg.read_timeout, pool=cfg.connect_timeout),
            limits=httpx.Limits(max_connections=1, max_keepalive_connections=1),
        )
        self._lock = threading.Lock()
        #: The socket of the connection last opened (the pool holds one): the total
        #: timeout's watchdog shuts it down to end a read that would go on.
        self._socket: socket.socket | None = None
        #: This attempt opened a connection; the watchdog fired.
        self._connected = self._timed_out = False
        #: The most pixels the server decodes (its /info), once known.
        self._max_pixels: int | None = None

    @property
    def timeout(self) -> float:
        """The read timeout in seconds."""
        return self.config.read_timeout

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        with self._lock:
            self._client.close()

    def __enter__(self) -> RemoteServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"RemoteServer({self.url!r})"

    # ------------------------------------------------------------------ transport
    def request(self, method: str, path: str, body: Any = None) -> tuple[Any, Exchange]:
        """Send one request (``body`` as JSON) and return the decoded JSON reply and what
        the exchange cost; ``server_ms`` is taken from the reply's ``stats`` if present."""
        data = None if body is None else json.dumps(body, separators=(",", ":"),
                                                    allow_nan=False).encode()
        with self._lock:
            start = time.perf_counter()
            status, raw = self._send(method, path, data)
            wall = (time.perf_counter() - start) * 1e3
        reply = self._decode(raw, path)
        if not 200 <= status < 300:
            reason = reply.get("error") if isinstance(reply, dict) else None
            if not isinstance(reason, str):
                reason = raw[:200].decode(errors="replace") or "no reason given"
            raise ServerError(f"server refused the request ({status}): {reason[:300]}",
                              self.url + path, status)
        if reply is None:
            raise ServerError(f"server sent a reply that is not JSON ({len(raw)} bytes)", self.url + path)
        stats = reply.get("stats") if isinstance(reply, dict) else None
        server_ms = stats.get("server_ms", 0.0) if isinstance(stats, dict) else 0.0
        if isinstance(server_ms, bool) or not isinstance(server_ms, int | float) or not 0 <= server_ms < 1e9:
            server_ms = 0.0
        return reply, Exchange(len(data or b""), len(raw), wall, float(server_ms))

    def _decode(self, raw: bytes, path: str) -> Any:
        """The reply's JSON (None if it is not JSON); refused if nested too deep."""
        if not raw:
            return None
        try:
            reply = json.loads(raw)
        except RecursionError:
            reply = _TOO_DEEP
        except ValueError:
            return None
        if reply is _TOO_DEEP or json_depth(reply) > self.config.max_json_depth:
            raise ServerError(f"server sent JSON nested more than {self.config.max_json_depth} deep",
                              self.url + path)
        return reply

    def _send(self, method: str, path: str, data: bytes | None) -> tuple[int, bytes]:
        for attempt in (0, 1):
            self._connected = self._timed_out = False
            try:
                return self._exchange(method, path, data)
            except httpx.HTTPError as exc:
                if self._timed_out:
                    raise ServerError(f"no complete reply within {self.config.total_timeout:g} s "
                                      "(total timeout)", self.url + path) from None
                idle_closed = isinstance(exc, httpx.RemoteProtocolError | httpx.ReadError | httpx.WriteError)
                if idle_closed and not self._connected and attempt == 0:
                    continue  # the server closed an idle keep-alive connection: retry once
                raise self._failure(exc, path) from exc
        raise AssertionError("unreachable")  # pragma: no cover

    def _exchange(self, method: str, path: str, data: bytes | None) -> tuple[int, bytes]:
        """One request under the total timeout: a watchdog shuts the connection's socket
        down at the deadline, which ends whatever read is waiting; the reply is read in
        chunks and refused as soon as it is over the size limit."""
        cfg = self.config
        watchdog = threading.Timer(cfg.total_timeout, self._expire)
        watchdog.daemon = True
        watchdog.start()
        try:
            with self._client.stream(method, path, content=data,
                                     extensions={"trace": self._trace}) as response:
                encoding = response.headers.get("content-encoding", "identity").strip().lower()
                if encoding not in ("", "identity"):
                    raise ServerError(f"server sent a {encoding[:40]!r}-encoded reply; only plain "
                                      "replies are accepted", self.url + path)
                declared = response.headers.get("content-length", "")
                if declared.isdigit() and int(declared) > cfg.max_reply_bytes:
                    raise self._too_large(path)
                chunks, size = [], 0
                for chunk in response.iter_raw():
                    size += len(chunk)
                    if size > cfg.max_reply_bytes:
                        raise self._too_large(path)
                    chunks.append(chunk)
                return response.status_code, b"".join(chunks)
        finally:
            watchdog.cancel()

    def _trace(self, event: str, info: dict[str, Any]) -> None:
        """httpx's trace hook: remember the socket of each new connection."""
        if event == "connection.connect_tcp.complete":
            self._connected = True
            stream = info.get("return_value")
            sock = stream.get_extra_info("socket") if stream is not None else None
            self._socket = sock if isinstance(sock, socket.socket) else None

    def _expire(self) -> None:
        self._timed_out = True
        sock = self._socket
        if sock is not None:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass  # already closed

    def _too_large(self, path: str) -> ServerError:
        return ServerError(f"server sent a reply over {self.config.max_reply_bytes:,} bytes",
                           self.url + path)

    def _failure(self, exc: httpx.HTTPError, path: str) -> ServerError:
        cfg = self.config
        if isinstance(exc, httpx.ConnectTimeout):
            return ServerError(f"cannot connect within {cfg.connect_timeout:g} s", self.url)
        if isinstance(exc, httpx.TimeoutException):
            return ServerError(f"no reply within {cfg.read_timeout:g} s", self.url + path)
        if isinstance(exc, httpx.ConnectError):
            return ServerError(f"cannot connect: {_reason(exc)}", self.url)
        if isinstance(exc, httpx.RemoteProtocolError | httpx.ReadError | httpx.WriteError):
            return ServerError(f"the server closed the connection or broke the protocol ({_reason(exc)})",
                               self.url + path)
        return ServerError(f"request failed: {_reason(exc)}", self.url + path)

    # ------------------------------------------------------------------ the server's limits
    def max_pixels(self) -> int | None:
        """The most pixels of a query image the server decodes (``limits.max_pixels`` of
        its ``/info``, asked once); None if it does not say."""
        if self._max_pixels is None:
            limits = self.info().get("limits")
            cap = limits.get("max_pixels") if isinstance(limits, dict) else None
            if isinstance(cap, int) and not isinstance(cap, bool) and cap > 0:
                self._max_pixels = cap
        return self._max_pixels

    def _fitted(
        self, query: QueryView, intrinsics: Intrinsics | None = None,
    ) -> tuple[QueryView, Intrinsics | None, tuple[int, int, int, int] | None]:
        """``query`` (and ``intrinsics``) scaled down to the server's pixel cap if larger
        (:func:`~viewdb.http.wire.shrink_query`), and the sizes before and after, if scaled."""
        height, width = query.mask.shape
        try:
            cap = self.max_pixels()
        except ServerError:  # no /info: sent as it is (the server refuses it if too large)
            cap = None
        if cap is None or width * height <= cap:
            return query, intrinsics, None
        small, scaled = shrink_query(query, cap, intrinsics)
        return small, scaled, (width, height, small.mask.shape[1], small.mask.shape[0])

    # ------------------------------------------------------------------ the server tier
    def health(self) -> dict[str, Any]:
        reply, _ = self.request("GET", "/health")
        return _object(reply, self.url)

    def info(self) -> dict[str, Any]:
        reply, _ = self.request("GET", "/info")
        return _object(reply, self.url)

    def refine(self, request: RefineRequest) -> tuple[ServerReply, Exchange]:
        reply, exchange = self.request("POST", "/refine", request.to_dict())
        return _parse_reply(ServerReply.from_dict, reply, self.url), exchange

    def walk(self, request: WalkRequest) -> tuple[ServerReply, Exchange]:
        reply, exchange = self.request("POST", "/walk", request.to_dict())
        return _parse_reply(ServerReply.from_dict, reply, self.url), exchange

    def colours(
        self, views: Sequence[tuple[str, float, float]]
    ) -> tuple[list[np.ndarray | None], Exchange]:
        if not views:
            return [], Exchange(0, 0, 0.0, 0.0, trips=0)
        reply, exchange = self.request("POST", "/colours", ColourRequest(list(views)).to_dict())
        signatures = _parse_reply(ColourReply.from_dict, reply, self.url).signatures
        if len(signatures) != len(views):
            raise ServerError(f"server sent {len(signatures)} colour signatures, not {len(views)}", self.url)
        return signatures, exchange

    def colour_ranking(self, signature: np.ndarray, n: int) -> tuple[list[ColourMatch], Exchange]:
        """The server's colour channel; a server that predates it (404) names no object,
        and the query takes the outline's path."""
        body = ColourRankingRequest(signature, n).to_dict()
        try:
            reply, exchange = self.request("POST", "/colour-ranking", body)
        except ServerError as exc:
            if exc.status == 404:
                return [], Exchange(0, 0, 0.0, 0.0)
            raise
        return _parse_reply(ColourRankingReply.from_dict, reply, self.url).matches, exchange

    def looks(self, look: np.ndarray) -> tuple[dict[str, float], Exchange]:
        """The server's look distances; a server that predates them (404) has none."""
        try:
            reply, exchange = self.request("POST", "/looks", LookRequest(look).to_dict())
        except ServerError as exc:
            if exc.status == 404:
                return {}, Exchange(0, 0, 0.0, 0.0)
            raise
        return _parse_reply(LookReply.from_dict, reply, self.url).distances, exchange

    def fits(
        self, query: QueryView, views: Sequence[tuple[str, float, float]]
    ) -> tuple[list[float | None], Exchange]:
        if not views:
            return [], Exchange(0, 0, 0.0, 0.0, trips=0)
        query, _, scaled = self._fitted(query)
        reply, exchange = self.request("POST", "/fits", FitRequest.from_query(query, views).to_dict())
        exchange = replace(exchange, scaled=scaled)
        fits = _parse_reply(FitReply.from_dict, reply, self.url).fits
        if len(fits) != len(views):
            raise ServerError(f"server sent {len(fits)} shape fits, not {len(views)}", self.url)
        return fits, exchange

    def poses(
        self, query: QueryView, matches: Sequence[Candidate],
        intrinsics: Intrinsics | None = None,
        curves: Sequence[np.ndarray | None] | None = None, rerank: bool = False,
    ) -> tuple[list[tuple[PoseEstimate | None, str | None]], Exchange]:
        if not matches:
            return [], Exchange(0, 0, 0.0, 0.0, trips=0)
        query, intrinsics, scaled = self._fitted(query, intrinsics)
        reply, exchange = self.request(
            "POST", "/pose", PoseRequest.from_query(query, matches, intrinsics, curves, rerank).to_dict())
        exchange = replace(exchange, scaled=scaled)
        poses = _parse_reply(PoseReply.from_dict, reply, self.url).poses
        if len(poses) != len(matches):
            raise ServerError(f"server posed {len(poses)} matches, not {len(matches)}", self.url)
        return poses, exchange


_TOO_DEEP = object()


def is_token(token: str) -> bool:
    """Whether ``token`` can travel in an ``Authorization: Bearer`` header: printable
    ASCII without spaces (anything else cannot be sent, or would split the header)."""
    return bool(token) and all(33 <= ord(c) <= 126 for c in token)


def json_depth(value: Any) -> int:
    """How deeply arrays and objects nest in a decoded JSON value (a scalar is 0),
    without recursion."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        item, depth = stack.pop()
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else None
        if children is None:
            continue
        deepest = max(deepest, depth)
        stack.extend((child, depth + 1) for child in children if isinstance(child, dict | list))
    return deepest


def _object(reply: Any, url: str) -> dict[str, Any]:
    if not isinstance(reply, dict):
        raise ServerError("server sent a reply that is not a JSON object", url)
    return reply


def _parse_reply(parse: Any, reply: Any, url: str) -> Any:
    try:
        return parse(reply)
    except QueryError as exc:
        raise ServerError(f"server sent a malformed reply: {exc.message}", url) from exc


def _reason(exc: BaseException) -> str:
    text = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return " ".join(str(text).split())[:200]
