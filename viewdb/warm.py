"""Compile the query path's kernels before a user's first query.

The k-NN search runs numba kernels (in :mod:`viewdb.search`) that are compiled on first
use and cached on disk (``cache=True``: next to the sources, or in ``NUMBA_CACHE_DIR``).
Compiling them takes tens of seconds; loading them from the cache takes milliseconds.
:func:`warm_up` makes sure the cache holds every kernel a query uses, with the argument
types a query passes, by doing what a user does on a throw-away catalogue: it ingests two
generated meshes into a database in a temporary folder and queries a photo of one of
them with every plan, with and without pose and with a gravity hint (the search over
circular shifts), draws a result over the photo (the overlay's scan conversion,
:mod:`viewdb.recognition.raster`) and re-ranks by silhouette fits through intrinsics (their
scan conversion, :mod:`viewdb.catalogue.coverage`). ``install.sh`` runs it, so an installed
viewdb never compiles during a query; :func:`kernel_report` tells what a process compiled,
and :func:`compiling` tells a caller each kernel as it starts compiling (``viewdb query``
says so on a terminal, so a fresh install's first query does not wait in silence).

>>> report = warm_up()                                   # doctest: +SKIP
>>> report.compiled, report.cached                        # doctest: +SKIP
(26, 0)
"""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import ViewDBError

__all__ = ["KernelReport", "compiling", "kernel_report", "warm_up"]

@dataclass(frozen=True)
class KernelReport:
    """What the numba kernels of this process did so far."""

    #: Kernel signatures compiled in this process (not found in the cache).
    compiled: int
    #: Kernel signatures loaded from the cache.
    cached: int
    #: ``module.kernel`` of each compiled signature.
    compiled_names: tuple[str, ...] = ()


def kernel_report() -> KernelReport:
    """Count the kernel signatures (numba dispatchers of any imported viewdb module) this
    process compiled, and those it loaded from the cache."""
    compiled: list[str] = []
    cached = 0
    seen: set[int] = set()
    for module_name, module in sorted(sys.modules.items()):
        if module_name != "viewdb" and not module_name.startswith("viewdb."):
            continue
        for value in list(vars(module).values()):
            stats = getattr(value, "stats", None)
            if stats is None or not hasattr(stats, "cache_misses") or id(value) in seen:
                continue  # not a kernel, or one imported from another kernel module
            seen.add(id(value))
            kernel = f"{value.py_func.__module__}.{value.py_func.__name__}"
            compiled += [kernel] * sum(stats.cache_misses.values())
            cached += sum(stats.cache_hits.values())
    return KernelReport(len(compiled), cached, tuple(sorted(compiled)))


@contextmanager
def compiling(callback: Callable[[str], None]) -> Iterator[None]:
    """For the block, ``callback("module.kernel")`` as each viewdb kernel starts compiling:
    one numba did not find in its cache (a fresh install's first query, or a changed
    source). Kernels loaded from the cache are not heard."""
    from .jit import njit  # noqa: F401  # numba imported as the kernels import it (jit.py)

    # isort: split
    from numba.core import event

    class Heard(event.Listener):
        def on_start(self, ev: event.Event) -> None:
            func = getattr(ev.data.get("dispatcher"), "py_func", None)
            module = getattr(func, "__module__", None) or ""
            if func is not None and (module == "viewdb" or module.startswith("viewdb.")):
                callback(f"{module}.{func.__name__}")

        def on_end(self, ev: event.Event) -> None:
            pass

    with event.install_listener("numba:compile", Heard()):
        yield


def _meshes(folder: Path) -> list[Path]:
    """Two small meshes of different shapes (an L-shaped block and a slab), as GLB files."""
    import trimesh

    blocks = [trimesh.creation.box((1.0, 0.3, 0.3)),
              trimesh.creation.box((0.3, 0.8, 0.3)).apply_translation((-0.35, 0.4, 0.0))]
    shapes = {"warm_l": trimesh.util.concatenate(blocks),
              "warm_slab": trimesh.creation.box((1.0, 0.6, 0.15))}
    paths = []
    for name, mesh in shapes.items():
        path = folder / f"{name}.glb"
        mesh.export(path)
        paths.append(path)
    return paths


def warm_up(progress: Callable[[str], None] | None = None) -> KernelReport:
    """Run every plan's query, with and without pose and with a gravity hint, draw an
    overlay and fit silhouettes through intrinsics, on a catalogue built in a temporary
    folder, so that each kernel a query (and the web page) uses is compiled (or found)
    in the cache.
    Returns what the kernels did; ``progress`` hears each step."""
    from .api import open as open_db

    say = progress or (lambda _step: None)
    with tempfile.TemporaryDirectory(prefix="viewdb-warm-") as tmp:
        folder = Path(tmp)
        say("ingesting two generated meshes")
        with open_db(folder / "warm.db", gap=45, image_size=96, client_gap=90) as db:
            report = db.ingest(_meshes(folder))
            if report.failed:
                raise ViewDBError(f"warm-up ingest failed: {report.failed[0].error}")
            view = db.render("warm_l", 37.0, 22.0)
            photo = np.full((*view.mask.shape, 3), 200, np.uint8)
            photo[view.mask] = view.color[view.mask]
            for plan in ("server", "cs1", "cs2", "fast"):
                for pose in (False, True):
                    say(f"querying (plan {plan}, {'with' if pose else 'without'} pose)")
                    db.query(photo, plan=plan, pose=pose, k=2)
                say(f"querying (plan {plan}, with a gravity hint)")
                db.query(photo, plan=plan, pose=False, k=2, roll=0.0)
            say("drawing a result over its photo")
            db.query(photo, k=1).overlay()  # the scan conversion's kernel
            say("fitting silhouettes through a calibrated camera")
            side = float(view.mask.shape[1])
            db.query(photo, k=2, intrinsics=(side, side, side / 2.0, side / 2.0), rerank=True)
    return kernel_report()
