"""Library functions stay short: none in ``viewdb/`` is longer than 100 lines (nested
functions count towards the function that holds them, and on their own)."""

from __future__ import annotations

import ast
from pathlib import Path

import viewdb

ROOT = Path(viewdb.__file__).resolve().parent
MAX_LINES = 100


def long_functions(source: str, where: str, limit: int = MAX_LINES) -> list[str]:
    """``"where:line name (n lines)"`` for every function or method of ``source`` longer
    than ``limit`` lines, from its ``def`` to its last line (decorators left out)."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            lines = node.end_lineno - node.lineno + 1
            if lines > limit:
                out.append(f"{where}:{node.lineno} {node.name} ({lines} lines)")
    return out


def _body(indent: str, lines: int = 100) -> str:
    return "".join(f"{indent}x{i} = {i}\n" for i in range(lines))


def test_the_scan_finds_long_functions_methods_and_nested_ones():
    source = ("def long():\n" + _body("    ")
              + "class C:\n    async def method(self):\n" + _body("        ")
              + "def outer():\n    def inner():\n" + _body("        ")
              + "def short():\n    return 1\n")
    found = long_functions(source, "probe.py")
    assert sorted(f.split()[1] for f in found) == ["inner", "long", "method", "outer"]
    assert "probe.py:1 long (101 lines)" in found
    assert long_functions("def f():\n" + _body("    ", 99), "ok.py") == []  # exactly 100 lines


def test_no_library_function_is_longer_than_100_lines():
    offenders = []
    for path in sorted(ROOT.rglob("*.py")):
        offenders += long_functions(path.read_text(encoding="utf-8"), str(path.relative_to(ROOT.parent)))
    assert not offenders, f"functions over {MAX_LINES} lines:\n" + "\n".join(offenders)
