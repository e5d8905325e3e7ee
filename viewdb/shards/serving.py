"""A sharded catalogue where ``viewdb serve`` expects an open database.

:class:`ShardedCatalogue` gives the HTTP server what it uses of a
:class:`~viewdb.ViewDB`: the server tier (:class:`~viewdb.shards.cluster.ShardedServerTier`:
``/refine``, ``/walk``, ``/colours``, ``/fits``, ``/pose``), ``info`` (the shards'
summed), the objects and the build configuration. Remote clients (``viewdb query
--server URL``) therefore work unchanged. What needs one local file (the web page's
whole-photo ``/query``, meshes and renders) is refused with a one-line error.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..config import BuildConfig, ShardConfig
from ..errors import ViewDBError
from ..search.plans import RefineRequest
from .cluster import ShardedServerTier

__all__ = ["ShardedCatalogue", "ShardedInfo", "open_sharded"]

#: Sharded catalogues open in this process, by folder: ``viewdb serve`` opens (and
#: checks) the shards before it binds its socket, and its worker in the same process
#: then serves that one instead of starting the actors again.
_OPEN: dict[Path, ShardedCatalogue] = {}


def open_sharded(folder: str | Path, ray_address: str | None = "auto") -> ShardedCatalogue:
    """The sharded catalogue in ``folder``, opened once per process."""
    key = Path(folder).resolve()
    if key not in _OPEN:
        _OPEN[key] = ShardedCatalogue(key, ray_address)
    return _OPEN[key]


class ShardedInfo:
    """``info`` of a sharded catalogue: the shards' ``info`` merged (sizes and rows
    summed, objects of every shard by name) plus the shard count."""

    def __init__(self, shards: list[dict[str, Any]], folder: Path) -> None:
        first = shards[0]
        self.data = {**first, "path": str(folder), "shards": len(shards),
                     "file_bytes": sum(s["file_bytes"] for s in shards),
                     "rows": {key: sum(s["rows"].get(key, 0) for s in shards) for key in first["rows"]},
                     "tiers": {tier: {key: (value if key == "gap" else
                                            sum(s["tiers"][tier].get(key, 0) for s in shards))
                                      for key, value in first["tiers"][tier].items()}
                               for tier in first["tiers"]},
                     "objects": sorted((o for s in shards for o in s["objects"]), key=lambda o: o["name"])}

    def to_dict(self) -> dict[str, Any]:
        return dict(self.data)


class ShardedCatalogue:
    """The shards in ``folder`` served through Ray (``ray_address``: see
    :func:`~viewdb.shards.cluster.connect`)."""

    role = "full"
    read_only = True

    def __init__(self, folder: str | Path, ray_address: str | None = "auto",
                 config: ShardConfig | None = None) -> None:
        self.path = Path(folder)
        self._tier = ShardedServerTier(folder, ray_address=ray_address, config=config)
        self.config = BuildConfig.from_dict(self._tier.build)

    def server_tier(self) -> ShardedServerTier:
        return self._tier

    def info(self) -> ShardedInfo:
        tier = self._tier
        every = list(range(len(tier.actors)))
        return ShardedInfo(tier._each(every, lambda s: tier.actors[s].call.remote("info")), self.path)

    def shard_health(self) -> list[dict[str, Any]]:
        """Each shard's state (:meth:`ShardedServerTier.shard_health`), for ``/health``."""
        return self._tier.shard_health()

    def objects(self) -> list[str]:
        return sorted(self._tier.owner)

    def search(self, curve: NDArray[np.floating], k: int) -> Any:
        """The exact k nearest objects of a curve over every shard (``server`` plan)."""
        return self._tier.refine(RefineRequest(np.asarray(curve, np.float64), 6, k, []))[0].results

    def close(self) -> None:
        _OPEN.pop(self.path.resolve(), None)
        self._tier.close()

    def __enter__(self) -> ShardedCatalogue:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __getattr__(self, name: str) -> Any:
        raise ViewDBError(f"a sharded catalogue does not serve {name!r} (the web page's photo queries, "
                          "meshes and renders need one file): query it through a `server` from a client file",
                          self.path)
