"""One shard of a sharded catalogue, answering in the process that holds it.

A :class:`Shard` opens its file read-only, refuses it if ``check`` finds a problem, loads
its full tier's curves into memory and answers the server half of the plans for its own
objects: the bounded exact search (:meth:`Shard.refine`), CS2's walk, the colours, fits
and poses. It knows nothing of Ray: :mod:`viewdb.shards.cluster` wraps it in an actor.
Replies are plain dicts and lists (what crosses between processes).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import StorageError
from ..pose.estimate import QueryView
from ..pose.intrinsics import Intrinsics
from ..search.plans import Candidate, RefineRequest, ServerReply, WalkRequest
from ..search.route import nearest_candidates

__all__ = ["Shard"]


class Shard:
    """Shard ``index`` of a sharded catalogue: the file at ``path`` (module doc)."""

    def __init__(self, path: str | Path, index: int, check: bool = True) -> None:
        from ..api import open as open_db

        self.path, self.index = Path(path), index
        self.db = open_db(self.path, create=False, read_only=True)
        try:
            if self.db.role != "full":
                raise StorageError("is a client file, not a shard of a full catalogue", self.path)
            if check:
                report = self.db.check()
                if not report.ok:
                    raise StorageError(f"fails check: {report.problems[0]}", self.path)
            self.tier = self.db.server_tier()
            self.samples = self.db.config.features.curve_samples
            with self.tier.catalogue.tier_reader().snapshot() as reader:
                self.versions = dict(reader.object_versions())
                full = reader.tier("full")
                full.rows(np.arange(full.n_groups, dtype=np.int64))  # every curve in memory
            if full.n_groups:  # the search kernels compiled (or loaded) before the first query
                self.refine(RefineRequest(np.ones(self.samples), 6, 1, []).to_dict(), math.inf)
        except BaseException:
            self.db.close()
            raise

    def describe(self) -> dict[str, Any]:
        """The shard's objects (name → content hash), curve length and build settings."""
        return {"index": self.index, "path": str(self.path), "versions": self.versions,
                "samples": self.samples, "config": self.db.config.to_dict()}

    def info(self) -> dict[str, Any]:
        """``viewdb info`` of the shard file, as JSON."""
        return self.db.info().to_dict()

    def refine(self, request: dict[str, Any], upper: float) -> dict[str, Any]:
        """CS1's server half on this shard (:func:`~viewdb.search.route.nearest_candidates`; the
        request as JSON, its client candidates those of this shard's objects), further
        bounded by ``upper``, an upper bound of the k-th distance over every shard: every
        object of this shard that ranks among its k best and is no farther than ``upper``
        is in the reply with its exact distance; farther objects may be left out."""
        parsed = RefineRequest.from_dict(request, self.samples)
        with self.tier.catalogue.tier_reader().snapshot() as reader:
            if reader.tier("full").n_groups == 0:
                return ServerReply([], {}).to_dict()
            found, stats = nearest_candidates(reader, parsed, upper=upper)
        return ServerReply(found, stats.to_dict()).to_dict()

    def walk(self, request: dict[str, Any]) -> dict[str, Any]:
        """CS2's walk from the client candidates of this shard's objects."""
        reply, _ = self.tier.walk(WalkRequest.from_dict(request, self.samples))
        return reply.to_dict()

    def colours(self, views: Sequence[tuple[str, float, float]]) -> list[NDArray[np.float32] | None]:
        return self.tier.view_colours(views)

    def colour_ranking(self, signature: NDArray[np.float32], n: int) -> list[dict[str, Any]]:
        """The colour channel on this shard's objects (as JSON)."""
        found, _ = self.tier.colour_ranking(signature, n)
        return [m.to_dict() for m in found]

    def looks(self, look: NDArray[np.float32]) -> tuple[str, dict[str, float]] | None:
        """Each coloured object's look distance by this shard's look model, and the key of
        the catalogue the model serves; None without a valid model."""
        found = self.tier.catalogue.shard_look()
        return None if found is None else (found[0], found[1].distances(look))

    def fits(self, query: QueryView, views: Sequence[tuple[str, float, float]]) -> list[float | None]:
        return self.tier.view_fits(query, views)

    def poses(self, query: QueryView, matches: Sequence[dict[str, Any]], intrinsics: Intrinsics | None,
              curves: Sequence[NDArray[np.float64] | None] | None, rerank: bool) -> list[Any]:
        found, _ = self.tier.poses(query, [Candidate.from_dict(m) for m in matches], intrinsics,
                                   curves, rerank)
        return found

    def memory(self) -> dict[str, int | None]:
        """The bytes of the full tier held in memory, and this process's resident set
        (None where ``/proc`` is not there to say)."""
        with self.tier.catalogue.tier_reader().snapshot() as reader:
            full = reader.tier("full")
            held = sum(a.nbytes for a in full.rows(np.zeros(0, np.int64)))
        try:
            with open("/proc/self/status", encoding="ascii") as f:
                rss = next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmRSS:"))
        except (OSError, StopIteration, ValueError):
            rss = None
        return {"tier_bytes": held, "rss_bytes": rss}

    def ping(self) -> int:
        return self.index

    def close(self) -> None:
        self.db.close()
