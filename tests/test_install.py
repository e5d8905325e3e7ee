"""Installs for each use: the wheel in a fresh virtual environment beside the core
dependencies alone queries a prebuilt file, and a client file against a running server,
with the ingest and serve extras' modules not importable there; with the ingest extra
added, it ingests a sample mesh.

The environment is made offline: ``python -m venv`` without the system's packages, the
wheel built here and installed with ``pip --no-deps``, and the core dependencies (the
wheel's own ``Requires-Dist`` without extras, and what they require) taken from this
interpreter's installation through a ``.pth`` file listing only their files. Its first
queries compile the search kernels (the wheel's sources are new to numba's cache): about
2.7 minutes in all on two loaded cores, so the test is marked ``slow`` and ``.ci/run``
runs it on its own after the default run.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement

from benchmarks.support.serving import ServerProcess
from tests.conftest import ROOT

pytestmark = pytest.mark.slow

#: The modules the extras install, none of which a core install may import.
NOT_CORE = ("trimesh", "pyrender", "OpenGL", "fastapi", "starlette", "uvicorn", "fast_simplification")


def _wheel(out: Path) -> Path:
    """The wheel of this tree, built from a copy (setuptools writes into the source tree)."""
    src = out / "viewdb-src"  # (named "src", setuptools took the folder for the project)
    for part in ("viewdb", "cli", "migrations"):
        shutil.copytree(ROOT / part, src / part, ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    for part in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / part, src / part)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q",
                    "-w", str(out), str(src)], check=True, capture_output=True, text=True, timeout=600)
    return next(out.glob("viewdb-*.whl"))


def _requirements(wheel: Path, extras: tuple[str, ...] = ()) -> list[Requirement]:
    """The wheel's ``Requires-Dist``: the core's, and those of ``extras``."""
    with zipfile.ZipFile(wheel) as zf:
        meta = next(n for n in zf.namelist() if n.endswith(".dist-info/METADATA"))
        lines = zf.read(meta).decode().splitlines()
    reqs = [Requirement(line.split(":", 1)[1].strip()) for line in lines if line.startswith("Requires-Dist:")]
    return [r for r in reqs if r.marker is None or any(r.marker.evaluate({"extra": e}) for e in ("", *extras))]


def _closure(reqs: list[Requirement]) -> list[metadata.Distribution]:
    """The installed distributions ``reqs`` need, with what they need in turn (no extras)."""
    found: dict[str, metadata.Distribution] = {}
    todo = [(req, True) for req in reqs]  # the wheel's own were chosen with their extras
    while todo:
        req, chosen = todo.pop()
        if not chosen and req.marker is not None and not req.marker.evaluate({"extra": ""}):
            continue
        key = re.sub(r"[-_.]+", "-", req.name).lower()
        if key in found:
            continue
        dist = metadata.distribution(req.name)
        assert dist.version in req.specifier or not req.specifier, f"{req}: {dist.version} installed"
        found[key] = dist
        todo += [(Requirement(r), False) for r in dist.requires or ()]
    return list(found.values())


def _venv(tmp: Path, wheel: Path, extras: tuple[str, ...] = ()) -> Path:
    """A venv without the system's packages: the wheel installed, the core dependencies
    (and those of ``extras``) visible through one ``.pth`` file of links to their files;
    its ``bin`` folder."""
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=300)
    python = venv / "bin" / "python"
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index",
                    "-q", str(wheel)], check=True, capture_output=True, text=True, timeout=600)
    deps = tmp / "core-deps"
    deps.mkdir()
    site = Path(sysconfig.get_paths()["purelib"])
    for dist in _closure(_requirements(wheel, extras)):
        tops = {Path(str(f)).parts[0] for f in dist.files or () if not str(f).startswith("..")}
        for top in tops - {"__pycache__"}:
            target = Path(str(dist.locate_file(top)))
            if target.exists() and not (deps / top).exists() and target.parent == site:
                (deps / top).symlink_to(target)
    venv_site = next((venv / "lib").glob("python3*/site-packages"))
    (venv_site / "core-deps.pth").write_text(f"{deps}\n")
    return venv / "bin"


def _run(bin_dir: Path, args: list[str], cwd: Path, timeout: float = 1200) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env["PATH"] = f"{bin_dir}:{env.get('PATH', '')}"
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def _answer(stdout: str) -> list[tuple[str, float, dict]]:
    return [(r["object"], round(r["distance"], 9), r["view"]) for r in json.loads(stdout)["results"]]


def test_a_core_install_queries_a_file_and_a_server_without_the_extras(tiered_db, tmp_path):
    import cv2

    import viewdb
    from viewdb.bench.photos import composite_photo

    photo, client = tmp_path / "photo.png", tmp_path / "client.db"
    with viewdb.open(tiered_db, create=False) as db:
        view = db.render("mug", 37.0, 22.0)
        cv2.imwrite(str(photo), cv2.cvtColor(composite_photo(view, turn=20.0, scale=0.8, background=200)[0],
                                             cv2.COLOR_RGB2BGR))
        db.export_client(client)
        here = {plan: db.query(photo, k=3, plan=plan).to_dict()["results"] for plan in ("server", "cs1")}
    expected = {plan: [(r["object"], round(r["distance"], 9), r["view"]) for r in results]
                for plan, results in here.items()}

    bin_dir = _venv(tmp_path, _wheel(tmp_path / "wheel"))
    work = tmp_path / "work"
    work.mkdir()
    probe = _run(bin_dir, ["python", "-c", "import importlib.util, json, viewdb; print(json.dumps("
                           f"[viewdb.__file__, [m for m in {NOT_CORE!r} if importlib.util.find_spec(m)]]))"], work)
    assert probe.returncode == 0, probe.stderr
    where, importable = json.loads(probe.stdout)
    assert str(tmp_path / "venv") in where and importable == []

    local = _run(bin_dir, ["viewdb", "query", str(photo), "--db", str(tiered_db), "-k", "3", "--json"], work)
    assert local.returncode == 0, local.stderr
    assert _answer(local.stdout) == expected["server"]

    with ServerProcess(tiered_db) as server:
        remote = _run(bin_dir, ["viewdb", "query", str(photo), "--client", str(client), "--server", server.url,
                                "-k", "3", "--plan", "cs1", "--json"], work)
    assert remote.returncode == 0, remote.stderr
    assert _answer(remote.stdout) == expected["cs1"]

    refused = _run(bin_dir, ["viewdb", "serve", "--db", str(tiered_db), "--port", "0"], work, timeout=300)
    assert refused.returncode == 1 and "pip install 'viewdb[serve]'" in refused.stderr, refused.stderr


def test_the_ingest_extra_ingests_a_sample_mesh(tmp_path):
    from tests.conftest import sample

    bin_dir = _venv(tmp_path, _wheel(tmp_path / "wheel"), extras=("ingest",))
    work = tmp_path / "work"
    work.mkdir()
    db = tmp_path / "cone.db"
    done = _run(bin_dir, ["viewdb", "ingest", str(sample("cone")), "--db", str(db), "--gap", "90",
                          "--image-size", "64", "--json"], work)
    assert done.returncode == 0, done.stderr
    info = _run(bin_dir, ["viewdb", "info", "--db", str(db), "--json"], work)
    assert [o["name"] for o in json.loads(info.stdout)["objects"]] == ["cone"]
    probe = _run(bin_dir, ["python", "-c", "import importlib.util as u; print(u.find_spec('fastapi') is None)"], work)
    assert probe.stdout.strip() == "True"  # the serve extra stays out
