"""A parallel ingest killed by SIGTERM or SIGKILL leaves no worker behind: each worker
(about 300 MB) and multiprocessing's resource tracker die with the ingest."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import sample_files


def _session(sid: int) -> dict[int, str]:
    """pid -> command line of every live process in session ``sid``."""
    out = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            fields = stat[stat.rindex(")") + 2:].split()
            if int(fields[3]) == sid and fields[0] != "Z":  # field 6 (session), state not zombie
                out[int(entry.name)] = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()[:120]
        except (OSError, ValueError):
            continue
    return out


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc to find the workers")
@pytest.mark.parametrize("how", [signal.SIGTERM, signal.SIGKILL])
def test_killing_a_parallel_ingest_leaves_no_worker_behind(tmp_path, how):
    files = [str(p) for p in sample_files()]
    proc = subprocess.Popen(
        [sys.executable, "-m", "viewdb_cli.main", "ingest", *files, "--db", str(tmp_path / "k.db"),
         "--gap", "20", "--no-skim", "--image-size", "96", "--jobs", "2"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
    )
    sid = proc.pid
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and len(_session(sid)) < 4 and proc.poll() is None:
            time.sleep(0.2)  # the parent, 2 workers and the resource tracker
        assert proc.poll() is None and len(_session(sid)) >= 4, _session(sid)
        time.sleep(2.0)  # the workers are rendering
        os.kill(proc.pid, how)
        proc.wait(timeout=30)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and _session(sid):
            time.sleep(0.2)
        left = _session(sid)
        assert not left, f"processes left behind after {how.name} of the ingest: {left}"
    finally:
        for pid in _session(sid):  # never leave them running behind a failed test
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        if proc.poll() is None:
            proc.kill()
            proc.wait()
