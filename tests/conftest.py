"""Shared fixtures: sample models, small databases built once per session."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

# the tests take the sample models from here, as ``tests.conftest.sample``
from benchmarks.support.samples import sample, sample_files  # noqa: F401

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

# No per-example deadline: the first example of a test may compile numba kernels or
# create the GL context, and CI machines are shared; speed is measured in benchmarks.
settings.register_profile("viewdb", deadline=None)
settings.load_profile("viewdb")

ROOT = Path(__file__).resolve().parent.parent
SHARED_MODELS = ROOT.parent / "shared" / "models"


def copy_db(src: Path, dst: Path) -> Path:
    """A copy of the SQLite file ``src`` at ``dst`` (SQLite's online backup), ``dst``."""
    import sqlite3

    a, b = sqlite3.connect(src), sqlite3.connect(dst)
    a.backup(b)
    a.close()
    b.close()
    return dst


def pytest_report_header(config: pytest.Config) -> list[str]:
    import cv2
    import numpy
    import sqlalchemy
    import trimesh

    return [
        f"viewdb deps: numpy {numpy.__version__}, opencv {cv2.__version__}, "
        f"trimesh {trimesh.__version__}, sqlalchemy {sqlalchemy.__version__}, "
        f"PYOPENGL_PLATFORM={os.environ.get('PYOPENGL_PLATFORM')}"
    ]


SMALL_DB_MODELS = ("marked_cube", "car", "mug", "l_bracket")


def _build_small_db(tmp_path_factory: pytest.TempPathFactory, skim: bool) -> Path:
    import viewdb

    path = tmp_path_factory.mktemp("db") / ("small.db" if skim else "small_full.db")
    with viewdb.open(path, gap=60, image_size=128) as db:
        report = db.ingest([sample(n) for n in SMALL_DB_MODELS], skim=skim)
    assert not report.failed, report.failed
    return path


@pytest.fixture(scope="session")
def small_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four sample models ingested (skimmed) on a 60° grid of 36 views, built once."""
    return _build_small_db(tmp_path_factory, skim=True)


@pytest.fixture(scope="session")
def small_db_full(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same four models with every grid view stored (--no-skim)."""
    return _build_small_db(tmp_path_factory, skim=False)


@pytest.fixture(scope="module")
def local_ray():
    """A private local Ray of two CPUs for one test module (skipped without Ray)."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield ray
    ray.shutdown()


TIERED_DB_MODELS = ("marked_cube", "car", "mug", "l_bracket", "chair", "arrow")


def tiered_config():
    """The build configuration of :func:`tiered_db`."""
    from viewdb.config import BuildConfig, IndexConfig, RenderConfig

    return BuildConfig(gap=30, render=RenderConfig(image_size=96), index=IndexConfig(client_gap=90))


@pytest.fixture(scope="session")
def tiered_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Six sample models (skimmed) on a 30° server grid with a 90° client grid, so the
    sparse tier is a real subset of the full one; built once."""
    import viewdb

    path = tmp_path_factory.mktemp("db") / "tiered.db"
    with viewdb.open(path, config=tiered_config()) as db:
        report = db.ingest([sample(n) for n in TIERED_DB_MODELS])
    assert not report.failed, report.failed
    return path


def mixed_query_curves(db, rng, count):
    """Query curves for plan tests, half of each kind: a stored curve with noise (mirrored
    half the time), and the silhouette of a random object at a random off-grid angle."""

    from viewdb.catalogue.features import distance_curve, mirror_curve

    arrays, _ = db.search_tier("full")
    out = []
    for i in range(count):
        if i % 2:
            q = arrays.curves[rng.integers(len(arrays.curves))] + rng.normal(0, 0.03, 128)
            out.append(mirror_curve(q) if rng.random() < 0.5 else q)
        else:
            name = arrays.names[rng.integers(len(arrays.names))]
            out.append(distance_curve(db.render(name, *rng.uniform(0, 360, 2)).mask, 128))
    return out
