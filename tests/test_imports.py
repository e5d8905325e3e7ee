"""viewdb's imports: no cycles among its modules, and every import keeps to the floors that
``docs/architecture.md`` draws (a module imports from its own floor and those below)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

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


ARCHITECTURE = ROOT.parent / "docs" / "architecture.md"
FLOOR_LINE = re.compile(r"^\d+\. (.+)$")


def _floors(text: str) -> dict[str, int]:
    """Each unit of ``viewdb`` (a subpackage, a top-level module, or ``__init__``) and its
    floor, from the numbered list under the ``## Floors`` heading of the architecture page."""
    section = text.split("## Floors", 1)[1].split("\n## ", 1)[0]
    floors: dict[str, int] = {}
    level = 0
    for line in section.splitlines():
        match = FLOOR_LINE.match(line.strip())
        if match:
            floors.update(dict.fromkeys(re.findall(r"`([^`]+)`", match.group(1)), level))
            level += 1
    return floors


def _unit(module: str) -> str:
    """``viewdb.search.knn`` -> ``search``; ``viewdb.api`` -> ``api``; ``viewdb`` -> ``__init__``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _climbing(graph: dict[str, set[str]], floors: dict[str, int]) -> list[str]:
    """Every import in ``graph`` that reaches a floor above its own module's."""
    return sorted(f"{a} -> {b}" for a, targets in graph.items() for b in targets
                  if floors[_unit(b)] > floors[_unit(a)])


def test_the_floors_are_read_from_the_page_in_order():
    floors = _floors("intro\n## Floors\n\ntext `x`\n\n1. `a`, `b`\n2. `c`\n3. `d`\n\n## Next\n4. `e`\n")
    assert floors == {"a": 0, "b": 0, "c": 1, "d": 2}


def test_an_import_that_climbs_a_floor_is_found():
    floors = {"errors": 0, "search": 1, "api": 2, "__init__": 3}
    graph = {"viewdb.search.knn": {"viewdb.errors", "viewdb.search.bounds", "viewdb.api"},
             "viewdb.api": {"viewdb.search.knn"}, "viewdb.errors": set(), "viewdb": {"viewdb.api"}}
    assert _climbing(graph, floors) == ["viewdb.search.knn -> viewdb.api"]


def test_every_unit_of_the_package_has_a_floor_on_the_page():
    floors = _floors(ARCHITECTURE.read_text(encoding="utf-8"))
    units = {_unit(m) for m in _graph()}
    assert units == set(floors), (f"not on the page: {sorted(units - set(floors))}; "
                                  f"on the page but not in viewdb/: {sorted(set(floors) - units)}")


def test_no_import_climbs_above_its_floor():
    floors = _floors(ARCHITECTURE.read_text(encoding="utf-8"))
    offenders = _climbing(_graph(), floors)
    assert not offenders, "imports above their floor (docs/architecture.md, Floors):\n" + "\n".join(offenders)


BENCHMARKS = ROOT.parent / "benchmarks"


def _leans_on_tests(source: str) -> list[str]:
    """What in a benchmark's ``source`` reaches into the tests or edits ``sys.path``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [f"import {a.name}" for a in node.names if a.name.split(".")[0] == "tests"]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "tests":
            found.append(f"from {node.module} import ...")
        elif (isinstance(node, ast.Attribute) and node.attr == "path" and isinstance(node.value, ast.Name)
              and node.value.id == "sys"):
            found.append(f"line {node.lineno}: sys.path")
    return found


def test_the_benchmark_scan_finds_test_imports_and_path_edits():
    source = "import sys\nsys.path.insert(0, '..')\nfrom tests.serving import X\nimport tests.conftest\nimport os\n"
    assert sorted(_leans_on_tests(source)) == ["from tests.serving import ...", "import tests.conftest",
                                               "line 2: sys.path"]
    assert _leans_on_tests("from support.serving import ServerProcess\nimport sys\nsys.argv\n") == []


def test_benchmarks_stand_on_their_own():
    offenders = {str(p.relative_to(BENCHMARKS)): found for p in sorted(BENCHMARKS.rglob("*.py"))
                 if (found := _leans_on_tests(p.read_text(encoding="utf-8")))}
    assert not offenders, f"benchmarks that lean on tests/ or edit sys.path: {offenders}"
