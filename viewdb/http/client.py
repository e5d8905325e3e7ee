"""A client of ``viewdb serve``: the server half of the plans over HTTP (stdlib only).

>>> with viewdb.open("client.db", read_only=True) as client, \\
...         viewdb.RemoteServer("http://127.0.0.1:8765") as server:      # doctest: +SKIP
...     result = client.query("photo.jpg", plan="cs1", server=server)

One persistent (keep-alive) connection per :class:`RemoteServer`, used by one request at
a time (a lock serialises threads sharing it). A connection the server closed while idle
is reopened once transparently; every request is a pure read, so that is safe.
"""

from __future__ import annotations

import http.client
import json
import threading
import time
import urllib.parse
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import QueryError, ServerError
from ..pose.estimate import PoseEstimate, QueryView
from ..recognition.server_tier import Exchange
from ..search.plans import Candidate, RefineRequest, ServerReply, WalkRequest
from ..typed import Intrinsics
from .wire import ColourReply, ColourRequest, FitReply, FitRequest, PoseReply, PoseRequest

__all__ = ["RemoteServer"]


class RemoteServer:
    """The server tier (:class:`~viewdb.recognition.server_tier.ServerTier`) at ``url``
    (``http://host:port``, optionally with a path prefix).

    ``token`` is sent as ``Authorization: Bearer <token>``. Errors are
    :class:`~viewdb.errors.ServerError` naming the URL: cannot connect, timed out, or the
    server's own one-line reason with its HTTP status.
    """

    def __init__(self, url: str, *, token: str | None = None, timeout: float = 120.0) -> None:
        parts = urllib.parse.urlsplit(url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ServerError("is not a server URL (expected http://host:port)", url)
        try:
            port = parts.port
        except ValueError as exc:
            raise ServerError(f"has a bad port: {exc}", url) from exc
        self.url = url.rstrip("/")
        self.remote = True
        self._https = parts.scheme == "https"
        self._host, self._port = parts.hostname, port
        self._prefix = parts.path.rstrip("/")
        self._headers = {"Content-Type": "application/json", "Accept": "application/json"}
        if token:
            self._headers["Authorization"] = f"Bearer {token}"
        self.timeout = timeout
        self._conn: http.client.HTTPConnection | None = None
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        with self._lock:
            if self._conn is not None:
                self._conn.close()
                self._conn = None

    def __enter__(self) -> RemoteServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"RemoteServer({self.url!r})"

    # ------------------------------------------------------------------ transport
    def _connection(self) -> http.client.HTTPConnection:
        if self._conn is None:
            cls = http.client.HTTPSConnection if self._https else http.client.HTTPConnection
            self._conn = cls(self._host, self._port, timeout=self.timeout)
        return self._conn

    def request(self, method: str, path: str, body: Any = None) -> tuple[Any, Exchange]:
        """Send one request (``body`` as JSON) and return the decoded JSON reply and what
        the exchange cost; ``server_ms`` is taken from the reply's ``stats`` if present."""
        data = None if body is None else json.dumps(body, separators=(",", ":"),
                                                    allow_nan=False).encode()
        with self._lock:
            start = time.perf_counter()
            status, raw = self._send(method, self._prefix + path, data)
            wall = (time.perf_counter() - start) * 1e3
        try:
            reply = json.loads(raw) if raw else None
        except ValueError:
            reply = None
        if not 200 <= status < 300:
            reason = reply.get("error") if isinstance(reply, dict) else None
            raise ServerError(f"server refused the request ({status}): "
                              f"{reason or raw[:200].decode(errors='replace') or 'no reason given'}",
                              self.url + path, status)
        if reply is None:
            raise ServerError(f"server sent a reply that is not JSON ({len(raw)} bytes)", self.url + path)
        stats = reply.get("stats") if isinstance(reply, dict) else None
        server_ms = float(stats.get("server_ms", 0.0)) if isinstance(stats, dict) else 0.0
        return reply, Exchange(len(data or b""), len(raw), wall, server_ms)

    def _send(self, method: str, path: str, data: bytes | None) -> tuple[int, bytes]:
        for attempt in (0, 1):
            reused = self._conn is not None
            conn = self._connection()
            try:
                conn.request(method, path, body=data, headers=self._headers)
                response = conn.getresponse()
                raw = response.read()
                if response.will_close:
                    self._drop()
                return response.status, raw
            except (http.client.RemoteDisconnected, BrokenPipeError, ConnectionResetError) as exc:
                self._drop()
                if reused and attempt == 0:
                    continue  # the server closed an idle keep-alive connection: retry once
                raise ServerError(f"the server closed the connection ({_reason(exc)})", self.url) from exc
            except TimeoutError as exc:
                self._drop()
                raise ServerError(f"no reply within {self.timeout:g} s", self.url) from exc
            except (OSError, http.client.HTTPException) as exc:
                self._drop()
                raise ServerError(f"cannot connect: {_reason(exc)}", self.url) from exc
        raise AssertionError("unreachable")  # pragma: no cover

    def _drop(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    # ------------------------------------------------------------------ the server tier
    def health(self) -> dict[str, Any]:
        reply, _ = self.request("GET", "/health")
        return dict(reply)

    def info(self) -> dict[str, Any]:
        reply, _ = self.request("GET", "/info")
        return dict(reply)

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

    def fits(
        self, query: QueryView, views: Sequence[tuple[str, float, float]]
    ) -> tuple[list[float | None], Exchange]:
        if not views:
            return [], Exchange(0, 0, 0.0, 0.0, trips=0)
        reply, exchange = self.request("POST", "/fits", FitRequest.from_query(query, views).to_dict())
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
        reply, exchange = self.request(
            "POST", "/pose", PoseRequest.from_query(query, matches, intrinsics, curves, rerank).to_dict())
        poses = _parse_reply(PoseReply.from_dict, reply, self.url).poses
        if len(poses) != len(matches):
            raise ServerError(f"server posed {len(poses)} matches, not {len(matches)}", self.url)
        return poses, exchange


def _parse_reply(parse: Any, reply: Any, url: str) -> Any:
    try:
        return parse(reply)
    except QueryError as exc:
        raise ServerError(f"server sent a malformed reply: {exc.message}", url) from exc


def _reason(exc: BaseException) -> str:
    text = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return " ".join(str(text).split())
