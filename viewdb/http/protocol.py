"""uvicorn's HTTP/1.1 protocol (h11) with a deadline for each request's header.

uvicorn closes an idle keep-alive connection after a few seconds, but any byte received
cancels that timer and a fresh connection has none: a client that trickles a header one
line at a time (slowloris) holds a connection for as long as it likes. Here a connection
must deliver a whole request header within :attr:`HttpConfig.header_timeout
<viewdb.config.HttpConfig.header_timeout>` seconds of opening, or of the end of the
previous response; otherwise it is closed. ``viewdb serve`` runs uvicorn with this class
(``http="viewdb.http.protocol:DeadlineH11Protocol"``).
"""

from __future__ import annotations

import asyncio
import logging
import os

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from ..config import HttpConfig

__all__ = ["ENV_HEADER_TIMEOUT", "DeadlineH11Protocol"]

log = logging.getLogger("viewdb.http")

#: The environment variable a worker process reads the header timeout from.
ENV_HEADER_TIMEOUT = "VIEWDB_HEADER_TIMEOUT"


class DeadlineH11Protocol(H11Protocol):
    """:class:`H11Protocol` closing a connection whose request header is not complete in
    time (``VIEWDB_HEADER_TIMEOUT`` seconds, default ``HttpConfig().header_timeout``)."""

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self.header_timeout = float(os.environ.get(ENV_HEADER_TIMEOUT, HttpConfig().header_timeout))
        self._header_deadline: asyncio.TimerHandle | None = None
        self._arm()

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        if self.conn.their_state is not h11.IDLE:  # the header is in: the app has the request
            self._disarm()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if not self.transport.is_closing():
            self._arm()  # the next request on this connection gets its own deadline

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        super().connection_lost(exc)

    def _arm(self) -> None:
        self._disarm()
        self._header_deadline = self.loop.call_later(self.header_timeout, self._expired)

    def _disarm(self) -> None:
        deadline = getattr(self, "_header_deadline", None)
        if deadline is not None:
            deadline.cancel()
            self._header_deadline = None

    def _expired(self) -> None:
        self._header_deadline = None
        if self.conn.their_state is h11.IDLE and not self.transport.is_closing():
            log.info("closed a connection that sent no complete request header in %g s",
                     self.header_timeout)
            self.transport.close()
