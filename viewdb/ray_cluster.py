"""Joining a Ray cluster: the one home of ``import ray``.

Ray is an optional extra (``pip install 'viewdb[ray]'``). Only the modules that run work
on Ray (the sharded search in :mod:`viewdb.shards.cluster`, the distributed ingest in
:mod:`viewdb.catalogue.distributed`) call :func:`ray_module`, and only when asked to, so
``import viewdb`` and ``viewdb --help`` never import Ray.
"""

from __future__ import annotations

from typing import Any

from .errors import ViewDBError

__all__ = ["actor_state", "connect", "ray_module"]


def ray_module() -> Any:
    """The ``ray`` module, or a clear error saying how to install it."""
    try:
        import ray
    except ImportError:
        raise ViewDBError("this needs Ray: pip install 'viewdb[ray]'") from None
    return ray


def connect(address: str | None = "auto") -> Any:
    """Join a Ray cluster and return the ``ray`` module. ``address``: ``"auto"`` joins the
    one running on this machine, or starts a local one if none is; ``"HOST:PORT"`` joins
    that head node. A process already connected stays so."""
    ray = ray_module()
    if ray.is_initialized():
        return ray
    options = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
    if address in (None, "auto"):
        try:
            ray.init(address="auto", **options)
        except ConnectionError:
            ray.init(**options)
        return ray
    try:
        ray.init(address=address, **options)
    except (ConnectionError, ValueError, RuntimeError) as exc:
        raise ViewDBError(f"cannot join the Ray cluster at {address}: {str(exc).splitlines()[0]}") from None
    return ray


def actor_state(actor: Any) -> str | None:
    """Ray's record of ``actor`` (a handle): ``"ALIVE"``, ``"RESTARTING"``, ``"DEAD"``,
    ``"PENDING_CREATION"`` …, or None when it cannot be read. Read from Ray's control
    store directly (about a millisecond; no dashboard needed)."""
    try:
        from ray._private import state

        return str(state.actors(actor_id=actor._actor_id.hex())["State"])
    except Exception:  # noqa: BLE001 - an unreadable record is "unknown", never an error
        return None
