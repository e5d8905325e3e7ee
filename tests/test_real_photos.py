"""The YCB-Video benchmark on a subset (``-m slow``): queried with the frame's boxes, the
right object ranks first among a small catalogue and its pose is close to the ground truth."""

import importlib.util
import sys
from pathlib import Path

import pytest

import viewdb

pytestmark = pytest.mark.slow

BENCH = Path(__file__).resolve().parent.parent / "benchmarks" / "real_photos.py"


def _bench():
    spec = importlib.util.spec_from_file_location("real_photos", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_ycb_objects_rank_first_on_a_subset(tmp_path):
    bench = _bench()
    if not (bench.YCB / "gt.json").is_file() or not bench.MODELS.is_dir():
        pytest.skip("../shared/real/ycb_video_2frames or ../shared/models not present")
    db_path = tmp_path / "cat.db"
    bench.build(db_path, gap=30, subset=12, extras=False, jobs=2)
    objects = ["002_master_chef_can", "004_sugar_box", "010_potted_meat_can"]
    with viewdb.open(db_path, create=False) as db:
        rows = bench.run_ycb(db, 5, "server", tmp_path / "overlays", objects, progress=lambda m: None)
    assert sorted(r["object"] for r in rows) == sorted(objects)
    for r in rows:  # queried with the frame's boxes alone: a box's cut-out is coarser than a label's
        assert r["rank_same"] == 1, r
        assert r["pose"]["rotation_deg"] < 12.0, r
        assert r["pose"]["translation_mm"] < 40.0, r
    assert (tmp_path / "overlays" / "ycb_000002.png").is_file()
