"""Distributed ingest on a local Ray: the objects are described by Ray tasks and written by
the calling process. A Ray ingest stores what a local one stores (same views, same
curves, ``check`` passes), and a Ray worker SIGKILLed mid-object loses nothing: Ray runs
its task again and the file comes out complete."""

import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import viewdb
from tests.conftest import TIERED_DB_MODELS, sample, tiered_config

pytest.importorskip("ray")

#: The process title of a Ray worker while it describes an object.
TASK_TITLE = b"ray::_describe_file"


def _descends_from(pid: int, ancestor: int) -> bool:
    """Whether process ``pid`` is ``ancestor`` or one of its descendants (so only this
    test's own Ray workers are ever touched, not those of other Ray clusters)."""
    while pid > 1:
        if pid == ancestor:
            return True
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except OSError:
            return False
        pid = int(stat.rsplit(")", 1)[1].split()[1])
    return False


def _describing_workers() -> list[int]:
    """Our Ray workers describing an object right now."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            title = Path(f"/proc/{entry}/cmdline").read_bytes()
        except OSError:
            continue
        if title.startswith(TASK_TITLE) and _descends_from(int(entry), os.getpid()):
            found.append(int(entry))
    return found


class _WorkerKiller(threading.Thread):
    """SIGKILLs the first Ray worker seen describing an object."""

    def __init__(self):
        super().__init__(daemon=True)
        self.killed: int | None = None
        self.stop = threading.Event()

    def run(self):
        while not self.stop.is_set() and self.killed is None:
            for pid in _describing_workers():
                os.kill(pid, signal.SIGKILL)
                self.killed = pid
                break
            time.sleep(0.02)


def _stored(path):
    """Every object's views and curves, and the full tier's arrays."""
    with viewdb.open(path, read_only=True) as db:
        assert db.check().ok, db.check().problems
        views = {o.name: {(h, v): db.view(o.name, h, v).curve for h, v in db.views(o.name)}
                 for o in db.objects()}
        arrays, _ = db.search_tier("full")
        return views, arrays


def _tier_curves(arrays):
    """Each object's curves in the searched tier, as a sorted list of their bytes."""
    return {name: sorted(row.tobytes() for row in arrays.curves[arrays.owner == i])
            for i, name in enumerate(arrays.names)}


def test_ray_ingest_with_a_killed_worker_stores_what_a_local_ingest_does(local_ray, tiered_db, tmp_path):
    path = tmp_path / "ray.db"
    files = [sample(n) for n in TIERED_DB_MODELS]
    killer = _WorkerKiller()
    killer.start()
    progress = []
    try:
        with viewdb.open(path, config=tiered_config()) as db:
            report = db.ingest(files, ray="auto", progress=progress.append)
    finally:
        killer.stop.set()
        killer.join()
    assert killer.killed is not None, "no Ray worker was seen describing an object"
    with pytest.raises(ProcessLookupError):
        os.kill(killer.killed, 0)  # it really died
    assert not report.failed, report.failed
    assert report.counts()["added"] == len(files)
    assert progress[-1].written == len(files) and progress[-1].views_done == progress[-1].views_total
    assert progress[-1].objects_per_second > 0

    mine, here = _stored(path)
    theirs, there = _stored(tiered_db)
    assert mine.keys() == theirs.keys() == set(TIERED_DB_MODELS)
    for name, views in theirs.items():
        assert mine[name].keys() == views.keys(), name
        for at, curve in views.items():
            np.testing.assert_array_equal(mine[name][at], curve)
    assert _tier_curves(here) == _tier_curves(there)

    with viewdb.open(path) as db:  # idempotent: nothing is described again
        again = db.ingest(files, ray="auto")
    assert again.counts()["unchanged"] == len(files)


def test_ray_ingest_reports_bad_files_and_goes_on(local_ray, tmp_path):
    bad = tmp_path / "broken.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2 3\n")  # parses, but has no area
    with viewdb.open(tmp_path / "r.db", gap=90, image_size=64) as db:
        report = db.ingest([sample("cone"), bad, tmp_path / "missing.ply"], ray="auto")
        assert report.counts() == {"added": 1, "replaced": 0, "unchanged": 0, "upgraded": 0, "failed": 2}
        errors = {Path(o.path).name: o.error for o in report.failed}
        assert errors["missing.ply"].endswith("no such file")
        assert str(bad) in errors["broken.obj"] and "\n" not in errors["broken.obj"]
        assert [o.name for o in db.objects()] == ["cone"]


def test_ray_ingest_into_new_shards_serves_and_exports_as_the_single_file(local_ray, tiered_db, tmp_path):
    from tests.test_shard_writing import _rows
    from viewdb.shards.cluster import ShardedServerTier
    from viewdb.shards.writing import export_client_from_shards, open_shards

    folder = tmp_path / "shards"
    with open_shards(folder, count=3, config=tiered_config()) as shards:
        report = shards.ingest([sample(n) for n in TIERED_DB_MODELS], ray="auto")
    assert report.counts()["added"] == len(TIERED_DB_MODELS)

    tier = ShardedServerTier(folder)  # opens, checks and places every shard, or refuses
    try:
        rng = np.random.default_rng(5)
        with viewdb.open(tiered_db, read_only=True) as db:
            arrays, _ = db.search_tier("full")
            for _ in range(6):
                q = np.clip(arrays.curves[rng.integers(len(arrays.curves))] + rng.normal(0, 0.05, 128), 0, None)
                for plan in ("server", "cs1"):
                    here = db.recognise(q, 4, plan=plan)
                    there = db.recognise(q, 4, plan=plan, server=tier)
                    assert [c.to_dict() for c in there.results] == [c.to_dict() for c in here.results]
    finally:
        tier.close()

    mine, theirs = tmp_path / "mine.db", tmp_path / "theirs.db"
    export_client_from_shards(folder, mine)
    with viewdb.open(tiered_db, read_only=True) as db:
        db.export_client(theirs)
    (a, schema_a), (b, schema_b) = _rows(mine), _rows(theirs)
    assert schema_a == schema_b and a.keys() == b.keys()
    timing = {10, 11}  # objects.ingest_seconds and created_at differ between two ingests
    for table in b:
        if table == "settings":  # the index's generation is a fresh token on every write
            a[table] = [r for r in a[table] if r[0] != "index_generation"]
            b[table] = [r for r in b[table] if r[0] != "index_generation"]
        if table == "objects":
            a[table] = [tuple(v for i, v in enumerate(r) if i not in timing) for r in a[table]]
            b[table] = [tuple(v for i, v in enumerate(r) if i not in timing) for r in b[table]]
        assert a[table] == b[table], table
