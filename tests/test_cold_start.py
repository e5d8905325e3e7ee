"""A fresh process does only what its command needs: ``viewdb --help`` and ``import
viewdb`` load none of the heavy libraries, and a query after the warm-up compiles no
kernel (behaviour checked in child processes; the times are measured by
``benchmarks/cold_start.py``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

#: Libraries that take a tenth of a second or more to import, none of which --help needs.
HEAVY = ("numpy", "cv2", "trimesh", "pyrender", "OpenGL", "numba", "sqlalchemy", "alembic", "scipy",
         "fastapi", "uvicorn", "httpx", "rtree", "PIL", "matplotlib")


def _child(code: str, env: dict[str, str] | None = None) -> dict:
    """Run ``code`` in a fresh interpreter; it prints one JSON line last."""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                          env={**os.environ, **(env or {})})
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


LOADED = f"[m for m in {HEAVY!r} if m in sys.modules]"


@pytest.mark.parametrize("argv", [["--help"], ["query", "--help"], ["ingest", "--help"], []])
def test_help_loads_no_heavy_library(argv):
    out = _child(
        "import contextlib, io, json, sys\n"
        "from viewdb_cli.main import main\n"
        "with contextlib.redirect_stdout(io.StringIO()) as text:\n"
        f"    code = main({argv!r})\n"
        f"print(json.dumps({{'code': code, 'text': text.getvalue(), 'loaded': {LOADED}}}))\n"
    )
    assert "Usage" in out["text"] and out["code"] in (0, 2)
    assert out["loaded"] == []


def test_import_viewdb_loads_no_heavy_library_until_a_name_is_used():
    out = _child(
        "import json, sys, viewdb\n"
        f"before = {LOADED}\n"
        "opened = viewdb.open.__module__\n"
        f"print(json.dumps({{'before': before, 'opened': opened, 'after': {LOADED}}}))\n"
    )
    assert out["before"] == []
    assert out["opened"] == "viewdb.api" and "sqlalchemy" in out["after"]


def test_a_lazy_module_is_imported_on_first_attribute():
    out = _child(
        "import json, sys\n"
        "from viewdb.lazy import lazy_module\n"
        "wave = lazy_module('wave')\n"
        "before = 'wave' in sys.modules\n"
        "error = wave.Error\n"
        "print(json.dumps({'before': before, 'after': 'wave' in sys.modules,"
        " 'same': error is sys.modules['wave'].Error}))\n"
    )
    assert out == {"before": False, "after": True, "same": True}


def test_a_missing_lazy_module_fails_when_used_not_when_named():
    from viewdb.lazy import lazy_module

    missing = lazy_module("viewdb_no_such_module")
    with pytest.raises(ModuleNotFoundError):
        missing.anything  # noqa: B018


def test_after_the_warm_up_a_query_compiles_no_kernel(small_db, tmp_path):
    """The warm-up, in a fresh kernel cache, leaves nothing for the first queries of a
    new process to compile: the CLI's query with each plan, with and without pose, with
    a gravity hint and with silhouette fits through intrinsics, on another database."""
    import cv2

    import viewdb

    with viewdb.open(small_db, read_only=True) as db:
        view = db.render("mug", 37.0, 22.0)
    photo = np.full((*view.mask.shape, 3), 200, np.uint8)
    photo[view.mask] = view.color[view.mask]
    path = tmp_path / "photo.png"
    cv2.imwrite(str(path), photo[:, :, ::-1])
    side = float(photo.shape[1])
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "kernels")}
    warmed = _child("import json\nfrom viewdb.warm import warm_up\n"
                    "r = warm_up()\nprint(json.dumps([r.compiled, r.cached]))", env)
    assert warmed[0] > 0  # the fresh cache was filled
    queries = [["query", str(path), "--db", str(small_db), "--json", *extra]
               for extra in ([], ["--no-pose"], ["--plan", "cs1"], ["--plan", "cs2", "--no-pose"],
                             ["--upright", "--no-pose"], ["--plan", "cs1", "--roll", "30", "--no-pose"],
                             ["-k", "2", "--intrinsics", f"{side},{side},{side / 2},{side / 2}", "--rerank"])]
    out = _child(
        "import contextlib, io, json\n"
        "from viewdb_cli.main import main\n"
        "from viewdb.warm import kernel_report\n"
        "codes = []\n"
        f"for argv in {queries!r}:\n"
        "    with contextlib.redirect_stdout(io.StringIO()):\n"
        "        codes.append(main(argv))\n"
        "r = kernel_report()\n"
        "print(json.dumps({'codes': codes, 'compiled': list(r.compiled_names), 'cached': r.cached}))\n",
        env,
    )
    assert out["codes"] == [0] * len(queries)
    assert out["compiled"] == [] and out["cached"] > 0, out["compiled"]


_HEAR_COMPILES = (
    "import json, numpy as np\n"
    "from viewdb.warm import compiling\n"
    "heard = []\n"
    "with compiling(heard.append):\n"
    "    from viewdb.search import bounds\n"
    "    bounds.dtw(np.ones(16), np.ones(16), 2)\n"
    "print(json.dumps(heard))\n"
)


def test_a_kernel_compiling_is_heard_and_one_from_the_cache_is_not(tmp_path):
    cache = {"NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    first = _child(_HEAR_COMPILES, cache)
    assert "viewdb.search.bounds.dtw_kernel" in first and all(k.startswith("viewdb.") for k in first)
    assert _child(_HEAR_COMPILES, cache) == []  # loaded from the cache: nothing to say
