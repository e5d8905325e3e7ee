"""viewdb's public surface: ``viewdb.__all__`` is sorted, its names exist, and it names
every viewdb type a public method returns."""

from __future__ import annotations

import inspect
import types
import typing

import pytest

import viewdb


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
