"""A real ``viewdb serve`` in a subprocess on a free loopback port, and raw HTTP requests
(the tests and the HTTP benchmarks)."""

from __future__ import annotations

import http.client
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any


def deliverable_sigint() -> None:
    """Run in the child before exec: SIGINT at its default disposition and unblocked,
    whatever this process inherited. A parent that ignores SIGINT (a shell's background
    job, nohup) passes SIG_IGN on, and Python then installs no Ctrl-C handler; a parent
    that blocks it (some CI runners) passes the blocked mask on, and the signal stays
    pending. Either way a user's viewdb would rightly not be interrupted, so its children
    get what a terminal gives a foreground process."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})

class ServerProcess:
    """``viewdb serve --db DB --port 0 ...`` started on enter (returns once /health
    answers), stopped with SIGINT on exit (as Ctrl-C would)."""

    def __init__(self, db: str | Path, *, workers: int = 1, token: str | None = None,
                 extra: tuple[str, ...] = (), startup_timeout: float = 180.0) -> None:
        self.db = Path(db)
        self.workers = workers
        self.token = token
        self.extra = extra
        self.startup_timeout = startup_timeout
        self.url = ""
        self.proc: subprocess.Popen[str] | None = None
        self.returncode: int | None = None
        self._log = tempfile.TemporaryFile(mode="w+")
        self._final_log = ""
        self.pids: set[int] = set()

    def __enter__(self) -> ServerProcess:
        cmd = [sys.executable, "-m", "viewdb_cli.main", "serve", "--db", str(self.db), "--port", "0",
               "--workers", str(self.workers), *self.extra]
        if self.token:
            cmd += ["--token", self.token]
        env = {k: v for k, v in os.environ.items() if k != "VIEWDB_TOKEN"}
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self._log, text=True, env=env,
                                     preexec_fn=deliverable_sigint)
        line: list[str] = []
        reader = threading.Thread(target=lambda: line.append(self.proc.stdout.readline()), daemon=True)
        reader.start()
        reader.join(self.startup_timeout)
        found = re.search(r"http://[\d.]+:\d+", line[0]) if line else None
        if found is None:
            self.stop()
            raise RuntimeError(f"server did not start: {line}; log: {self.log()}")
        self.url = found.group(0)
        deadline = time.monotonic() + self.startup_timeout
        while time.monotonic() < deadline:
            try:
                self.pids |= self._health_pids()
                if len(self.pids) >= self.workers:  # every worker is up
                    return self
            except OSError:
                pass
            if self.proc.poll() is not None:
                break
            time.sleep(0.1)
        self.stop()
        raise RuntimeError(f"server never became healthy; log: {self.log()}")

    def _health_pids(self) -> set[int]:
        """Worker pids answering /health on a few parallel fresh connections."""
        n = max(2, 4 * self.workers)
        with ThreadPoolExecutor(n) as pool:
            replies = list(pool.map(lambda _: request(self.url, "GET", "/health", token=self.token,
                                                      timeout=5), range(n)))
        return {r["pid"] for status, r in replies if status == 200}

    def worker_pids(self) -> set[int]:
        return self._health_pids()

    def log(self) -> str:
        if self._log.closed:
            return self._final_log
        self._log.seek(0)
        return self._log.read()[-4000:]

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self) -> int | None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc is not None:
            self.returncode = self.proc.returncode
            if self.proc.stdout:
                self.proc.stdout.close()
        return self.returncode

    def __exit__(self, *exc: object) -> None:
        self.stop()
        self._final_log = self.log()
        self._log.close()


def request(url: str, method: str, path: str, body: bytes | str | Any = None, *,
            headers: dict[str, str] | None = None, token: str | None = None,
            chunked: bool = False, timeout: float = 60.0) -> tuple[int, Any]:
    """One request on a fresh connection: ``(status, decoded JSON reply or raw bytes)``.
    ``body``: bytes/str as is, anything else as JSON (NaN allowed, as a careless client
    would send); ``chunked`` sends it without a Content-Length."""
    parts = urllib.parse.urlsplit(url)
    conn = http.client.HTTPConnection(parts.hostname, parts.port, timeout=timeout)
    if body is not None and not isinstance(body, (bytes, str)):
        body = json.dumps(body)
    if isinstance(body, str):
        body = body.encode()
    hdrs = {"Content-Type": "application/json", **(headers or {})}
    if token:
        hdrs["Authorization"] = f"Bearer {token}"
    try:
        if chunked:
            conn.request(method, path, body=iter([body[i:i + 65536] for i in range(0, len(body), 65536)]),
                         headers=hdrs, encode_chunked=True)
        else:
            conn.request(method, path, body=body, headers=hdrs)
        response = conn.getresponse()
        raw = response.read()
    finally:
        conn.close()
    try:
        return response.status, json.loads(raw)
    except ValueError:
        return response.status, raw


def multipart(fields: dict[str, str | list[str]], files: dict[str, tuple[str, bytes, str]]
              ) -> tuple[bytes, dict[str, str]]:
    """A multipart/form-data body and its headers: ``fields`` name → text (a list: the
    field repeated), ``files`` name → (file name, bytes, content type), as a browser's
    form upload sends them."""
    boundary = f"viewdb{os.urandom(12).hex()}"
    parts = []
    for name, values in fields.items():
        for value in values if isinstance(values, list) else [values]:
            parts.append(f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"\r\n\r\n{value}\r\n'
                         .encode())
    for name, (filename, data, kind) in files.items():
        head = (f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"; filename="{filename}"\r\n'
                f"Content-Type: {kind}\r\n\r\n").encode()
        parts.append(head + data + b"\r\n")
    parts.append(f"--{boundary}--\r\n".encode())
    return b"".join(parts), {"Content-Type": f"multipart/form-data; boundary={boundary}"}
