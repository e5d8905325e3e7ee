"""The remote client does not trust its server: against hostile fake servers on loopback it
fails in one line, in bounded time and memory, and never with a traceback."""

from __future__ import annotations

import gzip
import json
import socket
import threading
import time
from collections.abc import Callable

import numpy as np
import pytest

import viewdb
from viewdb.config import HttpConfig
from viewdb.http.client import json_depth

REQUEST = viewdb.http.RefineRequest(np.ones(128), 6, 3, [])
OK_BODY = json.dumps({"results": [], "stats": {"server_ms": 1.0}}).encode()


class FakeServer:
    """A loopback server answering every request with ``respond(conn)``; it stops by
    itself (each connection and the whole server are bounded in time)."""

    def __init__(self, respond: Callable[[socket.socket], None]) -> None:
        self.respond = respond
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.url = f"http://127.0.0.1:{self.sock.getsockname()[1]}"
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._serve, daemon=True)

    def __enter__(self) -> FakeServer:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join(10)
        self.sock.close()

    def _serve(self) -> None:
        deadline = time.monotonic() + 60
        while not self.stop.is_set() and time.monotonic() < deadline:
            try:
                conn, _ = self.sock.accept()
            except TimeoutError:
                continue
            threading.Thread(target=self._handle, args=(conn,), daemon=True).start()

    def _handle(self, conn: socket.socket) -> None:
        with conn:
            conn.settimeout(5)
            try:
                data = b""
                while b"\r\n\r\n" not in data:
                    chunk = conn.recv(65536)
                    if not chunk:
                        return
                    data += chunk
                head, _, body = data.partition(b"\r\n\r\n")
                length = next((int(line.split(b":")[1]) for line in head.split(b"\r\n")
                               if line.lower().startswith(b"content-length:")), 0)
                while len(body) < length:
                    body += conn.recv(65536)
                self.respond(conn)
            except OSError:
                pass  # the client hung up: that is what most of these tests want

    def sending(self) -> bool:
        return not self.stop.is_set()


def _headers(extra: str = "", length: int | None = None) -> bytes:
    size = "" if length is None else f"Content-Length: {length}\r\n"
    return f"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\n{size}{extra}\r\n".encode()


def _refine(server_url: str, config: HttpConfig | None = None) -> tuple[BaseException, float]:
    start = time.monotonic()
    with viewdb.RemoteServer(server_url, config=config) as remote:
        with pytest.raises(viewdb.ServerError) as info:
            remote.refine(REQUEST)
    assert "\n" not in str(info.value) and server_url in str(info.value)
    return info.value, time.monotonic() - start


def test_an_endless_stream_of_brackets_is_cut_off_at_the_size_limit():
    def flood(conn: socket.socket) -> None:
        conn.sendall(_headers("Connection: close\r\n"))  # no length: the body runs to the close
        block = b"[" * 65536
        for _ in range(64 * 16):  # 64 MB at most: a client without a limit reads it all
            conn.sendall(block)

    with FakeServer(flood) as fake:
        error, seconds = _refine(fake.url, HttpConfig(max_reply_bytes=1 << 20))
    assert "over 1,048,576 bytes" in str(error) and seconds < 30


def test_the_default_limit_holds_too_and_deep_nesting_is_refused():
    deep = b"[" * 5000 + b"]" * 5000

    def nested(conn: socket.socket) -> None:
        conn.sendall(_headers(length=len(deep)) + deep)

    with FakeServer(nested) as fake:
        error, _ = _refine(fake.url)
    assert "nested more than 32 deep" in str(error)
    assert json_depth({"a": [[1, {"b": []}]]}) == 5 and json_depth(3) == 0


def test_a_declared_length_over_the_limit_is_refused_without_reading():
    def huge(conn: socket.socket) -> None:
        conn.sendall(_headers(length=10**12) + b"[")
        time.sleep(3)

    with FakeServer(huge) as fake:
        error, seconds = _refine(fake.url)
    assert "over 16,777,216 bytes" in str(error) and seconds < 2


def test_a_server_sending_one_header_line_a_second_is_cut_off_at_the_total_timeout():
    def trickle(conn: socket.socket) -> None:
        conn.sendall(b"HTTP/1.1 200 OK\r\n")
        for i in range(40):
            conn.sendall(f"X-Slow-{i}: yes\r\n".encode())
            time.sleep(0.5)

    with FakeServer(trickle) as fake:
        error, seconds = _refine(fake.url, HttpConfig(total_timeout=2.0))
    assert "total timeout" in str(error) and seconds < 6


def test_a_silent_server_hits_the_read_timeout():
    def silent(conn: socket.socket) -> None:
        time.sleep(4)

    with FakeServer(silent) as fake:
        error, seconds = _refine(fake.url, HttpConfig(read_timeout=1.0))
    assert "no reply within 1 s" in str(error) and seconds < 3.5


def test_a_compressed_reply_is_refused():
    body = gzip.compress(OK_BODY)

    def zipped(conn: socket.socket) -> None:
        conn.sendall(_headers("Content-Encoding: gzip\r\n", len(body)) + body)

    with FakeServer(zipped) as fake:
        error, _ = _refine(fake.url)
    assert "'gzip'-encoded" in str(error)


@pytest.mark.parametrize("reply", [
    b'{"results": [{"object": "a", "distance": "0.5", "azimuth": 0, "elevation": 0}], "stats": {}}',
    b'{"results": "nope"}',
    b'[1, 2, 3]',
    b'not json at all',
    b'{"results": [{"object": "a", "distance": 1e999, "azimuth": 0, "elevation": 0}]}',
])
def test_malformed_replies_are_one_line_errors(reply):
    def answer(conn: socket.socket) -> None:
        conn.sendall(_headers(length=len(reply)) + reply)

    with FakeServer(answer) as fake:
        error, _ = _refine(fake.url)
    assert "malformed" in str(error) or "not JSON" in str(error)


def test_junk_stats_are_left_out_not_fatal():
    body = json.dumps({"results": [], "stats": {"server_ms": "soon", "dtw": 1e300,
                                                "x": [1], "groups": True}}).encode()

    def answer(conn: socket.socket) -> None:
        conn.sendall(_headers(length=len(body)) + body)

    with FakeServer(answer) as fake, viewdb.RemoteServer(fake.url) as remote:
        reply, exchange = remote.refine(REQUEST)
    assert reply.results == [] and exchange.server_ms == 0.0 and reply.stats == {"dtw": 1e300}


def test_an_error_reply_with_a_strange_error_field_is_still_one_line():
    body = json.dumps({"error": {"nested": ["x"] * 3}, "status": 500}).encode()

    def answer(conn: socket.socket) -> None:
        conn.sendall(f"HTTP/1.1 500 Oops\r\nContent-Length: {len(body)}\r\n\r\n".encode() + body)

    with FakeServer(answer) as fake:
        error, _ = _refine(fake.url)
    assert error.status == 500 and "(500)" in str(error)


def test_limits_are_checked():
    with pytest.raises(ValueError, match="total_timeout"):
        HttpConfig(total_timeout=float("nan"))
    with pytest.raises(viewdb.ServerError, match="read_timeout"):
        viewdb.RemoteServer("http://127.0.0.1:1", timeout=-1)
