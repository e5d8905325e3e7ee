"""Third-party modules imported on first use.

``trimesh = lazy_module("trimesh")`` at the top of a module binds a stand-in that imports
trimesh the first time one of its attributes is read (``trimesh.load(...)``,
``isinstance(x, trimesh.Scene)``, an annotation resolved by ``typing.get_type_hints``)
and hands every attribute over from the real module. Importing the module that holds it
costs nothing, so ``import viewdb`` and ``viewdb --help`` do not pay for libraries a
command never uses (trimesh alone takes about as long to import as the rest of viewdb).

A core install (``pip install viewdb``) queries prebuilt files; building, serving and Ray
come with extras. :func:`missing_extra` names the extra when one of their modules is
missing, so the CLI can say what to install instead of printing a traceback.
"""

from __future__ import annotations

import importlib
import types
from typing import Any

__all__ = ["EXTRAS", "lazy_module", "missing_extra"]

#: The extra (``pip install 'viewdb[EXTRA]'``) that installs each third-party module a
#: core install lacks.
EXTRAS = {
    **dict.fromkeys(("trimesh", "pyrender", "OpenGL", "fast_simplification"), "ingest"),
    **dict.fromkeys(("fastapi", "starlette", "uvicorn", "multipart", "python_multipart"), "serve"),
    "ray": "ray",
    "matplotlib": "bench",
}


class _LazyModule(types.ModuleType):
    """Stands in for module ``__name__`` until an attribute is read."""

    def __getattr__(self, attr: str) -> Any:
        # only called for names the stand-in itself lacks: every public one
        return getattr(importlib.import_module(self.__name__), attr)

    def __repr__(self) -> str:
        return f"<lazy module {self.__name__!r}>"


def lazy_module(name: str) -> Any:
    """A stand-in for module ``name`` that imports it when an attribute is first read
    (an ``ImportError`` surfaces then, not at definition)."""
    return _LazyModule(name)


def missing_extra(exc: BaseException) -> str | None:
    """What to install, in one line, when ``exc`` failed to import a module that only an
    extra installs (:data:`EXTRAS`); None for any other error."""
    name = getattr(exc, "name", None) if isinstance(exc, ImportError) else None
    extra = EXTRAS.get((name or "").split(".")[0])
    if extra is None:
        return None
    return f"this needs {name}, which is not installed: pip install 'viewdb[{extra}]'"
