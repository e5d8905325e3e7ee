"""The sample models in ``sample_models/`` and their generator ``make_samples.py``."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")

SAMPLES = Path(__file__).resolve().parent.parent / "sample_models"
MESH_EXTS = {".obj", ".ply", ".stl", ".off", ".glb"}

#: Models whose visuals must survive a reload, and the trimesh visual kind expected.
EXPECTED_VISUALS = {
    "cube_dice.obj": "texture",
    "bottle.obj": "texture",
    "car.glb": "texture",
    "mug.glb": "texture",
    "arrow.glb": "vertex",
    "torus.ply": "vertex",
    "chair.ply": "vertex",
    "marked_cube.ply": "face",
}


@pytest.fixture(scope="module")
def make_samples():
    spec = importlib.util.spec_from_file_location("make_samples", SAMPLES / "make_samples.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("make_samples", module)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def generated(make_samples, tmp_path_factory):
    """Two independent runs of the generator."""
    a = tmp_path_factory.mktemp("samples_a")
    b = tmp_path_factory.mktemp("samples_b")
    make_samples.main(a)
    make_samples.main(b)
    return a, b


def _geometries(path: Path):
    loaded = trimesh.load(path)
    if isinstance(loaded, trimesh.Scene):
        return list(loaded.geometry.values())
    return [loaded]


def _sample_files(folder: Path):
    return sorted(p for p in folder.iterdir() if p.suffix in MESH_EXTS)


def test_generator_is_deterministic(generated):
    a, b = generated
    names_a = sorted(p.name for p in a.iterdir())
    names_b = sorted(p.name for p in b.iterdir())
    assert names_a == names_b
    assert len(names_a) >= 12
    for name in names_a:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


def test_generator_writes_the_committed_file_set(generated):
    a, _ = generated
    fresh = {p.name for p in a.iterdir()}
    committed = {p.name for p in SAMPLES.iterdir() if p.suffix not in {".py", ".md"} and p.is_file()}
    assert fresh == committed


def test_committed_files_match_generator_geometry(generated):
    """Same face counts and areas as a fresh run (bytes may differ across library versions)."""
    a, _ = generated
    for path in _sample_files(SAMPLES):
        mine = _geometries(path)
        fresh = _geometries(a / path.name)
        assert sum(len(g.faces) for g in mine) == sum(len(g.faces) for g in fresh), path.name
        assert np.isclose(sum(g.area for g in mine), sum(g.area for g in fresh), rtol=1e-5), path.name


def test_expected_formats_present():
    exts = {p.suffix for p in SAMPLES.iterdir()}
    assert MESH_EXTS | {".mtl", ".png"} <= exts
    assert len(_sample_files(SAMPLES)) >= 12


@pytest.mark.parametrize("name", sorted(p.name for p in _sample_files(SAMPLES)))
def test_sample_loads_with_positive_area(name):
    path = SAMPLES / name
    geoms = _geometries(path)
    assert geoms, name
    for g in geoms:
        assert isinstance(g, trimesh.Trimesh)
        assert len(g.faces) > 0 and len(g.faces) <= 5000
        assert g.area > 0
        assert np.all(np.isfinite(g.vertices))
    # centred near the origin
    bounds = np.array([g.bounds for g in geoms])
    lo, hi = bounds[:, 0].min(axis=0), bounds[:, 1].max(axis=0)
    assert np.linalg.norm((lo + hi) / 2) < 1e-3 * np.linalg.norm(hi - lo)
    if path.suffix == ".glb":
        assert isinstance(trimesh.load(path), trimesh.Scene)


@pytest.mark.parametrize("name,kind", sorted(EXPECTED_VISUALS.items()))
def test_visuals_survive_reload(name, kind):
    geoms = _geometries(SAMPLES / name)
    assert [g.visual.kind for g in geoms] == [kind] * len(geoms)
    if kind == "texture":
        for g in geoms:
            assert g.visual.uv is not None and len(g.visual.uv) == len(g.vertices)
            mat = g.visual.material
            image = getattr(mat, "image", None) or getattr(mat, "baseColorTexture", None)
            assert image is not None and max(image.size) <= 256
            # real detail, not a flat colour
            assert np.asarray(image.convert("L"), dtype=float).std() > 10


@pytest.mark.parametrize("process", [True, False])
def test_marked_cube_face_colours(process):
    cube = trimesh.load(SAMPLES / "marked_cube.ply", process=process)
    expected = {
        (0, 0, 1): (255, 0, 0),
        (0, 0, -1): (0, 255, 255),
        (1, 0, 0): (0, 255, 0),
        (-1, 0, 0): (255, 0, 255),
        (0, 1, 0): (0, 0, 255),
        (0, -1, 0): (255, 255, 0),
    }
    normals = np.round(cube.face_normals).astype(int)
    colours = cube.visual.face_colors[:, :3]
    seen = set()
    for n, c in zip(normals, colours, strict=False):
        assert tuple(c) == expected[tuple(n)]
        seen.add(tuple(n))
    assert seen == set(expected)
    if not process:
        # unshared vertices: converting to vertex colours (as a glTF export does) stays pure
        assert len(cube.vertices) == 3 * len(cube.faces)
        assert set(map(tuple, cube.visual.vertex_colors[:, :3])) == set(expected.values())


def test_samples_are_small():
    files = [p for p in SAMPLES.iterdir() if p.is_file() and p.suffix not in {".py", ".md"}]
    assert sum(p.stat().st_size for p in files) < 1_500_000
    for p in files:
        assert p.stat().st_size < 150_000, p.name
