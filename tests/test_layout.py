"""The package's shape: no import cycles among viewdb's modules, and a public surface
(``viewdb.__all__``) that is sorted and names every viewdb type a public method returns."""

from __future__ import annotations

import ast
import inspect
import types
import typing
from pathlib import Path

import pytest

import viewdb

ROOT = Path(viewdb.__file__).resolve().parent


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path, modules: set[str], name: str | None = None) -> set[str]:
    """Every viewdb module ``path`` imports: at the top, inside functions and under
    ``TYPE_CHECKING`` alike (``from .x import y`` counts ``.x``, and ``.x.y`` if that is a
    module)."""
    name = name or _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            targets = [module] + [f"{module}.{a.name}" for a in node.names]
        else:
            continue
        for target in targets:
            while target and target not in modules:
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def _graph() -> dict[str, set[str]]:
    paths = sorted(ROOT.rglob("*.py"))
    modules = {_module_name(p) for p in paths}
    graph = {_module_name(p): _imports(p, modules) for p in paths}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_the_import_scan_sees_imports_in_functions_and_under_type_checking(tmp_path):
    graph = _graph()
    # viewdb.api imports the pipeline at the top; storage.tiers imports the symmetry
    # module inside a function
    assert "viewdb.recognition.pipeline" in graph["viewdb.api"]
    assert "viewdb.catalogue.symmetry" in graph["viewdb.storage.tiers"]
    probe = tmp_path / "probe.py"
    probe.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from viewdb import api\n"
                     "def f():\n    import viewdb.config\n")
    assert _imports(probe, set(graph), "viewdb.probe") >= {"viewdb.api", "viewdb.config"}


def test_no_import_cycle_among_viewdb_modules():
    assert _cycles(_graph()) == []


def test_all_is_sorted_and_names_exist():
    assert viewdb.__all__ == sorted(viewdb.__all__)
    assert len(set(viewdb.__all__)) == len(viewdb.__all__)
    for name in viewdb.__all__:
        assert hasattr(viewdb, name), name


def _viewdb_types(hint: object) -> set[type]:
    """The viewdb classes a type hint mentions (through unions, lists, tuples, dicts)."""
    out: set[type] = set()
    if isinstance(hint, type) and hint.__module__.startswith("viewdb"):
        out.add(hint)
    for arg in typing.get_args(hint):
        out |= _viewdb_types(arg)
    return out


def _public_callables() -> list[tuple[str, object]]:
    found: list[tuple[str, object]] = []
    for name in viewdb.__all__:
        obj = getattr(viewdb, name)
        if isinstance(obj, types.FunctionType):
            found.append((name, obj))
        elif isinstance(obj, type) and obj.__module__.startswith("viewdb"):
            for attr, member in vars(obj).items():
                if attr.startswith("_") and attr != "__call__":
                    continue
                if isinstance(member, property):
                    member = member.fget
                if isinstance(member, (types.FunctionType, classmethod, staticmethod)):
                    found.append((f"{name}.{attr}", getattr(member, "__func__", member)))
    return found


@pytest.mark.parametrize("qualname,func", _public_callables(), ids=lambda x: x if isinstance(x, str) else "")
def test_every_viewdb_type_a_public_callable_returns_is_exported(qualname, func):
    module = inspect.getmodule(func)
    namespace = dict(vars(module)) if module else {}
    try:
        hints = typing.get_type_hints(func, globalns=namespace)
    except NameError as exc:  # an annotation that names an import under TYPE_CHECKING
        pytest.fail(f"{qualname}: cannot resolve its return annotation ({exc})")
    import viewdb.http

    exported = set(viewdb.__all__) | set(viewdb.http.__all__)  # wire messages live under viewdb.http
    missing = {t.__name__ for t in _viewdb_types(hints.get("return"))} - exported
    assert not missing, f"{qualname} returns {sorted(missing)}, which viewdb.__all__ lacks"


def test_the_plans_wire_messages_live_under_viewdb_http():
    import viewdb.http

    for name in ("RefineRequest", "WalkRequest", "ServerReply", "PoseRequest", "RemoteServer"):
        assert name in viewdb.http.__all__
    for name in ("RefineRequest", "WalkRequest", "ServerReply", "PoseRequest"):
        assert name not in viewdb.__all__
