"""viewdb over HTTP: the server tier as an ASGI app (:mod:`viewdb.http.app`, run by
:func:`viewdb.http.serve.run_server`, i.e. ``viewdb serve``) and :class:`RemoteServer`,
the client that calls it. Only the client is imported here (stdlib only); the app needs
FastAPI and uvicorn."""

from .client import RemoteServer

__all__ = ["RemoteServer"]
