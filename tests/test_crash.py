"""Crash safety and concurrency of the database file (issue: reliability).

* SIGKILL at random moments of an ingest (the whole process group, workers included):
  afterwards the file opens, ``check`` passes (which covers the R-trees of both tiers),
  every object is whole or absent, and re-running the ingest completes the catalogue.
* Readers in other processes keep searching while an ingest writes (WAL).
* Two writers at once serialise (or one is told the database is busy); never corruption.

The default run kills a few times; ``VIEWDB_CRASH_RUNS=200 pytest -m slow tests/test_crash.py``
runs the long version.
"""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import viewdb
from tests.conftest import sample_files

INGEST = [sys.executable, "-m", "viewdb_cli.main", "ingest"]


def _ingest_cmd(db, files, jobs=1, extra=()):
    return [*INGEST, *map(str, files), "--db", str(db), "--gap", "45", "--image-size", "64",
            "--jobs", str(jobs), *extra]


def _assert_whole(db):
    with viewdb.open(db, create=False) as vdb:
        report = vdb.check()
        assert report.ok, report.problems
        rows = vdb.info().rows
        for o in vdb.objects():
            assert o.views_stored + o.empty_views == vdb.view_plan(o.name).views_stored
        assert rows["views"] == rows["curves"] == rows["fourier_points"] == rows["sift_features"]
        return len(vdb.objects())


def _kill_runs(tmp_path, runs, seed):
    """Kill ``runs`` ingests at random moments; a catalogue that gets complete is set aside
    and the next kills hit a fresh file. Returns the objects present after each kill."""
    rng = np.random.default_rng(seed)
    files = sample_files()
    generation = 0
    counts = []
    previous = 0
    for i in range(runs):
        db = tmp_path / f"killed{generation}.db"
        # the whole grid at 30° (144 views per object): long enough that kills land mid-ingest
        cmd = _ingest_cmd(db, files, jobs=1 + i % 2, extra=("--no-skim",))
        cmd[cmd.index("--gap") + 1] = "30"
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True)
        time.sleep(rng.uniform(0.5, 6.0))
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
        if db.exists():
            try:
                counts.append(_assert_whole(db))
            except viewdb.StorageError as exc:  # killed before the file's creation committed
                assert "unfinished database" in str(exc), exc
                counts.append(0)
            assert counts[-1] >= previous  # progress is kept between kills
            previous = counts[-1]
            if counts[-1] == len(files):
                generation, previous = generation + 1, 0
    # re-running completes the catalogue
    cmd[cmd.index("--jobs") + 1] = "2"
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert _assert_whole(db) == len(files)
    return counts


def test_sigkill_at_random_moments_leaves_whole_objects(tmp_path):
    counts = _kill_runs(tmp_path, runs=4, seed=1)
    assert counts and min(counts) < len(sample_files())  # kills landed mid-ingest


@pytest.mark.slow
def test_sigkill_many_times(tmp_path):
    runs = int(os.environ.get("VIEWDB_CRASH_RUNS", "50"))
    counts = _kill_runs(tmp_path, runs=runs, seed=2)
    print(f"{runs} kills; objects present after each: {counts}")


def _reader_script(db, seconds, total):
    return (
        "import sys, time, numpy as np, viewdb\n"
        f"db = viewdb.open({str(db)!r}, create=False)\n"
        "rng = np.random.default_rng(0); n = 0; seen = set()\n"
        f"end = time.time() + {seconds}; limit = time.time() + 300\n"
        "first = len(db.objects())\n"
        "# search for a while, and on until a new object has arrived (a loaded machine ingests slowly)\n"
        f"while time.time() < limit and (time.time() < end\n"
        f"                               or first < {total} and max(seen, default=first) <= first):\n"
        "    q = 1 + 0.2 * np.cos(np.linspace(0, 6.283, 128, endpoint=False) * rng.integers(1, 4)"
        " + rng.uniform(0, 6.283))\n"
        "    hits, _ = db.search(q, k=3)\n"
        "    assert hits and all(h.distance >= 0 for h in hits)\n"
        "    seen.add(len(db.objects())); n += 1\n"
        "print(n, max(seen))\n"
    )


def test_readers_keep_searching_while_an_ingest_writes(tmp_path):
    db = tmp_path / "busy.db"
    files = sample_files()
    first = subprocess.run(_ingest_cmd(db, files[:2]), capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    writer = subprocess.Popen(_ingest_cmd(db, files[2:]), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    reader = subprocess.run([sys.executable, "-c", _reader_script(db, 8, len(files))], capture_output=True,
                            text=True, timeout=300)
    _, werr = writer.communicate(timeout=600)
    assert writer.returncode == 0, werr
    assert reader.returncode == 0, reader.stderr
    searches, most = map(int, reader.stdout.split())
    assert searches > 10 and most > 2  # it searched throughout and saw new objects arrive
    assert _assert_whole(db) == len(files)


def test_two_writers_serialise_or_one_is_told_the_db_is_busy(tmp_path):
    db = tmp_path / "two.db"
    files = sample_files()
    half = len(files) // 2
    subprocess.run(_ingest_cmd(db, files[:1]), check=True, capture_output=True, timeout=300)
    a = subprocess.Popen(_ingest_cmd(db, files[:half]), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    b = subprocess.Popen(_ingest_cmd(db, files[half:]), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    results = [p.communicate(timeout=600) + (p.returncode,) for p in (a, b)]
    for _, err, code in results:
        assert code == 0 or "database is busy" in err, err
        assert "Traceback" not in err
    assert _assert_whole(db) >= 1
