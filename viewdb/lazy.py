"""Third-party modules imported on first use.

``trimesh = lazy_module("trimesh")`` at the top of a module binds a stand-in that imports
trimesh the first time one of its attributes is read (``trimesh.load(...)``,
``isinstance(x, trimesh.Scene)``, an annotation resolved by ``typing.get_type_hints``)
and hands every attribute over from the real module. Importing the module that holds it
costs nothing, so ``import viewdb`` and ``viewdb --help`` do not pay for libraries a
command never uses (trimesh alone takes about as long to import as the rest of viewdb).
"""

from __future__ import annotations

import importlib
import types
from typing import Any

__all__ = ["lazy_module"]


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
