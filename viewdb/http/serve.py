"""Running the server: validate the database, bind the socket, start uvicorn workers.

The socket is bound here, before any worker starts, so ``port=0`` picks a free port and
the caller learns the real URL (``ready``) before the first request can arrive; with
``workers > 1`` uvicorn's supervisor hands the socket to that many worker processes, each
of which builds the app (:func:`viewdb.http.app.app_from_env`) and opens the database
read-only.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..api import open as open_db
from ..config import HttpConfig
from ..errors import ServerError, ViewDBError
from .app import (
    DEFAULT_MAX_BODY,
    DEFAULT_MAX_IMAGE_BODY,
    ENV_BODY_TIMEOUT,
    ENV_DB,
    ENV_MAX_BODY,
    ENV_MAX_IMAGE_BODY,
    ENV_MAX_PIXELS,
    ENV_RAY,
    ENV_TOKEN,
    ENV_UI,
)
from .client import is_token
from .protocol import ENV_HEADER_TIMEOUT

__all__ = ["bind", "run_server"]


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``(host, port)``; port 0 picks a free one."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise ServerError(f"cannot resolve host: {exc.strerror}", f"{host}:{port}") from exc
    family, kind, proto, _, address = infos[0]
    sock = socket.socket(family, kind, proto)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(2048)
        sock.set_inheritable(True)
    except OSError as exc:
        sock.close()
        raise ServerError(f"cannot listen: {exc.strerror or exc}", f"{host}:{port}") from exc
    return sock


def run_server(
    db: str | Path,
    *,
    host: str = "127.0.0.1",
    port: int = 8765,
    workers: int = 1,
    token: str | None = None,
    max_body: int = DEFAULT_MAX_BODY,
    max_image_body: int = DEFAULT_MAX_IMAGE_BODY,
    log_level: str = "warning",
    ready: Callable[[str, int], None] | None = None,
    ui: bool = True,
    http: HttpConfig | None = None,
    ray: str | None = None,
) -> None:
    """Serve the full database ``db`` (or, given a folder of shards, the sharded catalogue
    on the Ray cluster ``ray``: ``"auto"`` or ``HOST:PORT``) until interrupted.
    ``ready(url, objects)`` is called once the socket listens (before the workers start
    answering). ``ui``: serve the web page at ``/``. ``http`` sets the header and body
    timeouts and the largest image decoded (:class:`~viewdb.config.HttpConfig`)."""
    import uvicorn
    from uvicorn.supervisors import Multiprocess

    if workers < 1:
        raise ViewDBError(f"workers must be at least 1, got {workers}")
    if token and not is_token(token):
        raise ViewDBError("the bearer token must be printable ASCII without spaces (a client could "
                          "not send it)")
    http = http or HttpConfig()
    if Path(db).is_dir():
        objects = _open_shards(Path(db), workers, ray or "auto")
    else:
        with open_db(db, read_only=True) as vdb:  # refuse a bad file before binding anything
            if vdb.role != "full":
                raise ViewDBError("is a client file (export-client); serve the full database", db)
            objects = len(vdb.objects())
    os.environ[ENV_DB] = str(Path(db).resolve())
    os.environ[ENV_MAX_BODY] = str(int(max_body))
    os.environ[ENV_MAX_IMAGE_BODY] = str(int(max_image_body))
    os.environ[ENV_HEADER_TIMEOUT] = repr(float(http.header_timeout))
    os.environ[ENV_BODY_TIMEOUT] = repr(float(http.body_timeout))
    os.environ[ENV_MAX_PIXELS] = str(int(http.max_pixels))
    os.environ[ENV_UI] = "1" if ui else "0"
    if token:
        os.environ[ENV_TOKEN] = token
    else:
        os.environ.pop(ENV_TOKEN, None)
    sock = bind(host, port)
    try:
        bound_host, bound_port = sock.getsockname()[:2]
        shown = f"[{bound_host}]" if ":" in bound_host else bound_host
        config = uvicorn.Config("viewdb.http.app:app_from_env", factory=True, workers=workers,
                                log_level=log_level, access_log=log_level in ("debug", "info"),
                                timeout_graceful_shutdown=10,
                                http="viewdb.http.protocol:DeadlineH11Protocol")
        if ready is not None:
            ready(f"http://{shown}:{bound_port}", objects)
        if workers > 1:
            supervisor = _supervisor(Multiprocess)(config, sockets=[sock])
            supervisor.run()
            stopped_by = supervisor.stopped_by
        else:  # uvicorn re-raises the signal that stopped it (SIGINT: KeyboardInterrupt)
            server = uvicorn.Server(config)
            server.run(sockets=[sock])
            stopped_by = "signal" if server.started else None
    finally:
        sock.close()
    if stopped_by is None:
        raise ServerError("the server failed to start (see the log above)", db)
    if stopped_by == "int":
        raise KeyboardInterrupt  # Ctrl-C, as with one worker


def _open_shards(folder: Path, workers: int, ray: str) -> int:
    """Open (and check) a sharded catalogue before binding; its object count."""
    from ..shards.serving import open_sharded

    if workers != 1:
        raise ViewDBError("a sharded catalogue is served by one worker (its shards answer in "
                          "parallel on Ray); serve it with `workers` 1", folder)
    os.environ[ENV_RAY] = ray
    return len(open_sharded(folder, ray).objects())


def _supervisor(base: type[Any]) -> type[Any]:
    """uvicorn's multi-process supervisor, remembering which signal stopped it (it
    returns normally for both; and without one when a worker could not start)."""

    class Supervisor(base):  # type: ignore[misc, valid-type]
        stopped_by: str | None = None

        def handle_int(self) -> None:
            self.stopped_by = "int"
            super().handle_int()

        def handle_term(self) -> None:
            self.stopped_by = "term"
            super().handle_term()

    return Supervisor
