"""Ctrl-C during an ingest: exit code 130, one clean line, and no half-written object."""

import os
import signal
import sqlite3
import subprocess
import sys
import time

import pytest

import viewdb
from benchmarks.support.serving import deliverable_sigint
from tests.conftest import sample_files
from tests.interrupting import ctrl_c_in, sigint_raises


def _interrupt_an_ingest(db, files, jobs):
    """Start an ingest, send SIGINT once an object is committed; ``(returncode, stderr)``,
    or None when the ingest was over before the interrupt could act on it (it ended
    first, or it exits 0 with every object in: the signal came as it was exiting)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "viewdb_cli.main", "ingest", *files, "--db", str(db), "--gap", "20", "--no-skim",
         "--image-size", "96", "--jobs", str(jobs)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=deliverable_sigint, env={**os.environ, "PYTHONFAULTHANDLER": "1"},
    )
    try:
        return _interrupt(proc, db, files)
    finally:
        if proc.poll() is None:  # never leave an ingest running behind a failed test
            proc.kill()
            proc.communicate()


def _interrupt(proc, db, files):
    """Wait until at least one object is committed, then interrupt (see above)."""
    deadline = time.time() + 120
    seen, problems = 0, []
    while time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
        conn = None
        try:
            conn = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=5)
            seen = conn.execute("SELECT count(*) FROM objects").fetchone()[0]
        except sqlite3.Error as exc:
            problems.append(str(exc))
        finally:
            if conn is not None:
                conn.close()
        if seen >= 1:
            break
    if proc.poll() is not None:
        proc.communicate()
        print(f"the ingest ended before it could be interrupted (objects seen {seen}; "
              f"poll errors {sorted(set(problems))[:3]})")
        return None
    os.kill(proc.pid, signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the ingest did not stop within 60 s of SIGINT\n{_post_mortem(proc)}")
    if proc.returncode == 0:
        with viewdb.open(db, create=False) as vdb:
            if len(vdb.objects()) == len(files):
                print(f"the ingest finished as the interrupt came (objects seen {seen})")
                return None
    return proc.returncode, err


def _post_mortem(proc: subprocess.Popen[str]) -> str:
    """How a stuck child handles SIGINT (its /proc masks: bit 1 is SIGINT) and where each
    of its threads is (faulthandler's dump on SIGABRT)."""
    try:
        status = open(f"/proc/{proc.pid}/status").read().splitlines()
        masks = [line for line in status if line.startswith(("SigPnd", "ShdPnd", "SigBlk", "SigIgn", "SigCgt"))]
    except OSError as exc:
        masks = [f"no /proc status: {exc}"]
    proc.send_signal(signal.SIGABRT)
    try:
        out, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    return "\n".join([*masks, "stdout:", out[-2000:], "stderr:", err[-8000:]])


@pytest.mark.parametrize("jobs", [1, 2])
def test_sigint_mid_ingest_exits_130_and_leaves_whole_objects(tmp_path, jobs):
    files = [str(p) for p in sample_files()]
    # a timing test: retried (fresh file) only when the interrupt could not land mid-ingest
    for attempt in range(3):
        db = tmp_path / f"ctrlc{attempt}.db"
        outcome = _interrupt_an_ingest(db, files, jobs)
        if outcome is not None:
            break
    assert outcome is not None, "three ingests were over before they could be interrupted"
    returncode, err = outcome
    assert returncode == 130, err
    assert err.strip().splitlines()[-1] == "viewdb: interrupted", err
    assert "Traceback" not in err
    with viewdb.open(db, create=False) as vdb:
        objects = vdb.objects()
        assert 1 <= len(objects) < len(files)
        rows = vdb.info().rows
        for o in objects:
            assert o.views_stored + o.empty_views == vdb.view_plan(o.name).views_stored
    assert rows["views"] == rows["curves"] == rows["fourier_points"] == rows["sift_features"]
    # re-running completes the catalogue
    with viewdb.open(db) as vdb:
        report = vdb.ingest(files)
        assert not report.failed
        assert len(vdb.objects()) == len(files)


@pytest.mark.parametrize("nth", [1, 5, 9])
def test_ctrl_c_inside_the_r_tree_while_an_object_is_written_stops_the_ingest(tmp_path, nth):
    """The interrupt comes inside an R-tree page callback (C++ between it and the ingest):
    it must stop the ingest, not be lost or count the object as failed."""
    files = [str(p) for p in sample_files()][:3]
    db = tmp_path / "held.db"
    with viewdb.open(db, gap=30, image_size=64) as vdb:
        with sigint_raises(), ctrl_c_in("storeByteArray", nth) as calls:
            with pytest.raises(KeyboardInterrupt):
                vdb.ingest(files)
        assert calls[0] >= nth  # raised once the native call that took it was over
        objects = vdb.objects()
        assert len(objects) < len(files)
        rows = vdb.info().rows
        for o in objects:
            assert o.views_stored + o.empty_views == vdb.view_plan(o.name).views_stored
        assert rows["views"] == rows["curves"] == rows["fourier_points"] == rows["sift_features"]
        report = vdb.ingest(files)
        assert not report.failed
        assert len(vdb.objects()) == len(files)
