"""A sharded catalogue on Ray: one actor per shard, an exact scatter-gather search.

:class:`ShardedServerTier` is a :class:`~viewdb.recognition.server_tier.ServerTier`, so
the query pipeline, ``viewdb serve`` and remote clients use it as they use one file.
Each shard of the manifest (:mod:`viewdb.shards.layout`) is a Ray actor holding a
:class:`~viewdb.shards.shard.Shard`, its full tier's curves in memory. When the tier
starts, every actor opens and checks its file; a shard that is missing, fails ``check``
or holds objects the placement rule puts elsewhere is refused, naming its file.

A search (``server`` and ``cs1``, :meth:`ShardedServerTier.refine`) runs in two rounds:
the first ``ShardConfig.first_round`` shards (the shard of the client's best candidate
first), then every other shard at once, bounded by the k-th distance the first round
found (and by the client's bounds, as in CS1). The merge (:mod:`viewdb.shards.gather`)
gives exactly the single file's answer. A shard that dies or does not answer within
``ShardConfig.timeout`` fails the whole query with
:class:`~viewdb.errors.ShardUnavailable` (HTTP 503 with ``Retry-After``): never a partial
answer.

A dead shard comes back by itself: Ray restarts its actor (``ShardConfig.max_restarts``),
whose constructor reopens and checks the file, and the watcher of
:mod:`viewdb.shards.health` readmits it once it answers with the same objects in the same
versions. Ray's restarts rather than a supervisor of our own: the actor handle stays valid
(calls in flight on other threads need no swap), Ray places the new actor wherever the
cluster has room (another node if this one is lost), and the constructor is the one path
that opens a shard, at start and after a death alike. Until readmitted, queries needing the
shard fail at once with 503.

Re-ranking and pose calls go to the shard of each object, in parallel.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from ..config import ShardConfig
from ..errors import NotFound, QueryError, ShardUnavailable, StorageError, ViewDBError
from ..pose.estimate import PoseEstimate, QueryView
from ..pose.intrinsics import Intrinsics
from ..ray_cluster import actor_state, connect
from ..ray_cluster import ray_module as _ray
from ..recognition.server_tier import Exchange
from ..search.colour_index import ColourMatch, merge_colour_matches
from ..search.plans import Candidate, RefineRequest, ServerReply, WalkRequest
from .gather import scatter_gather
from .health import ShardHealth
from .layout import Manifest, read_manifest, shard_of

__all__ = ["ShardedServerTier", "connect"]

T = TypeVar("T")


class _Host:
    """What runs in a shard's actor: the shard, or the error that stopped it opening."""

    def __init__(self, path: str, index: int, check: bool) -> None:
        from .shard import Shard

        self.shard: Shard | None = None
        self.error: str | None = None
        try:
            self.shard = Shard(path, index, check)
        except ViewDBError as exc:
            self.error = str(exc)
        except Exception as exc:  # noqa: BLE001 - any failure refuses the shard, naming it
            self.error = f"{path}: cannot be opened ({type(exc).__name__}: {exc})"

    def call(self, method: str, *args: Any) -> Any:
        if self.shard is None:
            raise StorageError(self.error or "failed to open")
        return getattr(self.shard, method)(*args)

    def describe(self) -> dict[str, Any]:
        return {"error": self.error} if self.shard is None else self.shard.describe()

    def pid(self) -> int:
        """The actor's process id (what a fault-injection test kills)."""
        return os.getpid()


class ShardedServerTier:
    """The server tier of a sharded catalogue (module doc)."""

    remote = False

    def __init__(self, folder: str | Path, *, ray_address: str | None = "auto",
                 config: ShardConfig | None = None) -> None:
        self.config = config or ShardConfig()
        self.manifest: Manifest = read_manifest(folder)
        connect(ray_address)
        ray = _ray()
        actor = ray.remote(_Host).options(num_cpus=self.config.actor_cpus,
                                          max_restarts=self.config.max_restarts, max_task_retries=0)
        self.health = ShardHealth(self.manifest.files, self.config.retry_after)
        #: What each shard described when the tier opened (None until then).
        self._described: list[dict[str, Any]] | None = None
        self.actors = [actor.remote(str(f), i, self.config.check_at_start)
                       for i, f in enumerate(self.manifest.files)]
        try:
            described = self._gather([a.describe.remote() for a in self.actors], range(len(self.actors)))
            self._adopt(described)
            self._described = described
        except BaseException:
            self.close()
            raise
        self.health.watch(lambda i: actor_state(self.actors[i]), self._readmit, self.config.probe_interval)

    def _adopt(self, described: list[dict[str, Any]]) -> None:
        n = self.manifest.shards
        self.owner: dict[str, int] = {}
        self.versions: dict[str, str] = {}
        for i, d in enumerate(described):
            path = self.manifest.files[i]
            if d.get("error"):
                raise StorageError(f"shard {i} refused: {d['error']}", self.manifest.folder)
            misplaced = [name for name in d["versions"] if shard_of(name, n) != i]
            if misplaced or len(d["versions"]) != self.manifest.objects[i]:
                raise StorageError(f"does not hold the objects the manifest places in shard {i} "
                                   f"(e.g. {(misplaced or ['a different count'])[0]!r})", path)
            self.owner.update(dict.fromkeys(d["versions"], i))
            self.versions.update(d["versions"])
        first = described[0]
        if any(d["samples"] != first["samples"] or d["config"] != first["config"] for d in described):
            raise StorageError("holds shards built with different settings", self.manifest.folder)
        self.samples: int = first["samples"]
        self.build: dict[str, Any] = first["config"]

    def _readmit(self, shard: int) -> str | None:
        """None if shard ``shard``'s (restarted) actor answers holding what it held when
        the catalogue was opened; else why it cannot be readmitted."""
        ray = _ray()
        try:
            now = ray.get(self.actors[shard].describe.remote(), timeout=self.config.readmit_timeout)
        except Exception as exc:  # noqa: BLE001 - not answering yet is a reason, not an error
            return f"its restarted actor does not answer yet ({type(exc).__name__})"
        if now.get("error"):
            return f"its restarted actor refused the file: {now['error']}"
        assert self._described is not None
        was = self._described[shard]
        if any(now[key] != was[key] for key in ("versions", "samples", "config")):
            return "its file changed while it was down: restart the server"
        return None

    def shard_health(self) -> list[dict[str, Any]]:
        """Each shard's state (up, recoveries, and why it is down), in shard order."""
        return [{"shard": i, **s.to_dict()} for i, s in enumerate(self.health.snapshot())]

    def close(self) -> None:
        ray = _ray()
        self.health.stop()
        for a in getattr(self, "actors", []):
            ray.kill(a)
        self.actors = []

    # ------------------------------------------------------------------ Ray calls
    def _each(self, shards: Sequence[int], call: Callable[[int], Any]) -> list[Any]:
        """``call(shard)`` (a Ray call) on each of ``shards`` and their answers; none is
        sent if one of them is down (:class:`ShardUnavailable` at once)."""
        self.health.require(shards)
        sent = time.monotonic()
        return self._gather([call(s) for s in shards], shards, sent)

    def _gather(self, refs: list[Any], shards: Sequence[int], sent: float | None = None) -> list[Any]:
        """The results of one round of calls (``shards``: the shard of each; ``sent``: when
        they were sent), or :class:`ShardUnavailable` naming the first shard that failed
        to answer."""
        ray = _ray()
        try:
            return list(ray.get(refs, timeout=self.config.timeout))
        except ray.exceptions.RayTaskError as exc:
            cause = getattr(exc, "cause", None)
            if isinstance(cause, ViewDBError):
                raise cause from None
            raise
        except (ray.exceptions.RayActorError, ray.exceptions.GetTimeoutError,
                ray.exceptions.ObjectLostError) as exc:
            dead = self._dead(refs, shards)
            reason = f"did not answer ({type(exc).__name__})"
            restarts = self.config.max_restarts != 0 and actor_state(self.actors[dead]) != "DEAD"
            if self._described is not None:  # open: the watcher readmits it once restarted
                self.health.down(dead, reason, final=not restarts, sent=sent)
            raise ShardUnavailable(
                f"shard {dead} {reason}; no partial answer is given: "
                + (f"it is being restarted, retry in {self.config.retry_after:g} s" if restarts
                   else "restart the server"),
                self.manifest.files[dead], retry_after=self.config.retry_after if restarts else None,
            ) from None

    def _dead(self, refs: list[Any], shards: Sequence[int]) -> int:
        ray = _ray()
        for ref, shard in zip(refs, shards, strict=True):
            try:
                ray.get(ref, timeout=0)
            except Exception:  # noqa: BLE001 - any failure names the shard
                return int(shard)
        return int(shards[0])

    def _by_shard(self, names: Sequence[str]) -> dict[int, list[int]]:
        """Positions of ``names`` grouped by the shard holding each (NotFound for a name
        the catalogue lacks)."""
        out: dict[int, list[int]] = {}
        for i, name in enumerate(names):
            shard = self.owner.get(name)
            if shard is None:
                raise NotFound(f"no object named {name!r}", self.manifest.folder)
            out.setdefault(shard, []).append(i)
        return out

    def _routed(self, names: Sequence[str], call: Callable[[Any, list[int]], Any]) -> list[Any]:
        """``call(actor, positions)`` on each shard holding some of ``names`` (in
        parallel); the answers put back in the order of ``names``."""
        groups = self._by_shard(names)
        shards = list(groups)
        answers = self._each(shards, lambda s: call(self.actors[s], groups[s]))
        out: list[Any] = [None] * len(names)
        for s, answer in zip(shards, answers, strict=True):
            for position, value in zip(groups[s], answer, strict=True):
                out[position] = value
        return out

    @staticmethod
    def _timed(call: Callable[[], T]) -> tuple[T, Exchange]:
        start = time.perf_counter()
        answer = call()
        ms = (time.perf_counter() - start) * 1e3
        return answer, Exchange(0, 0, ms, ms, trips=0)

    # ------------------------------------------------------------------ the plans
    def refine(self, request: RefineRequest) -> tuple[ServerReply, Exchange]:
        """CS1 (and ``server`` with no client candidates) over every shard, exactly the
        single file's answer (module doc)."""
        return self._timed(lambda: self._refine(request))

    def _refine(self, request: RefineRequest) -> ServerReply:
        if len(request.curve) != self.samples:
            raise QueryError(f"query curve must be {self.samples} finite samples")

        body = request.to_dict()

        def run(shards: list[int], bound: float, client: dict[int, list[Candidate]]) -> list[Any]:
            return self._each(shards, lambda s: self.actors[s].call.remote(
                "refine", {**body, "client": [c.to_dict() for c in client.get(s, [])]}, bound))

        return scatter_gather(request, self.owner, self.versions, self.manifest.shards,
                              self.config.first_round, run)

    def walk(self, request: WalkRequest) -> tuple[ServerReply, Exchange]:
        """CS2: each shard walks from the client's candidates of its objects; the best k."""
        return self._timed(lambda: self._walk(request))

    def _walk(self, request: WalkRequest) -> ServerReply:
        mine = [c for c in request.client if c.object in self.owner]
        groups = self._by_shard([c.object for c in mine])
        shards = list(groups)
        body = request.to_dict()
        replies = self._each(shards, lambda s: self.actors[s].call.remote(
            "walk", {**body, "client": [mine[i].to_dict() for i in groups[s]]}))
        found: list[Candidate] = []
        dtw = 0.0
        for reply in replies:
            parsed = ServerReply.from_dict(reply)
            found += parsed.results
            dtw += parsed.stats.get("dtw", 0.0)
        return ServerReply(sorted(found, key=lambda c: (c.distance, c.object))[: request.k], {"dtw": dtw})

    # ------------------------------------------------------------------ re-ranking and pose
    def colours(
        self, views: Sequence[tuple[str, float, float]]
    ) -> tuple[list[NDArray[np.float32] | None], Exchange]:
        return self._timed(lambda: self._routed(
            [v[0] for v in views], lambda a, at: a.call.remote("colours", [views[i] for i in at])))

    def colour_ranking(
        self, signature: NDArray[np.float32], n: int
    ) -> tuple[list[ColourMatch], Exchange]:
        """The colour channel over every shard: each shard's nearest ``n``, merged."""
        def ask() -> list[ColourMatch]:
            shards = list(range(len(self.actors)))
            parts = self._each(shards, lambda s: self.actors[s].call.remote("colour_ranking", signature, n))
            return merge_colour_matches([[ColourMatch.from_dict(m) for m in part] for part in parts], n)
        return self._timed(ask)

    def looks(self, look: NDArray[np.float32]) -> tuple[dict[str, float], Exchange]:
        """The look distances of the model every shard holds (fitted over all of them when
        they were written); none unless every shard holds a valid one for the same
        catalogue."""
        def ask() -> dict[str, float]:
            shards = list(range(len(self.actors)))
            parts = self._each(shards, lambda s: self.actors[s].call.remote("looks", look))
            keys = {None if part is None else part[0] for part in parts}
            return dict(parts[0][1]) if len(keys) == 1 and None not in keys else {}
        return self._timed(ask)

    def fits(
        self, query: QueryView, views: Sequence[tuple[str, float, float]]
    ) -> tuple[list[float | None], Exchange]:
        return self._timed(lambda: self._routed(
            [v[0] for v in views], lambda a, at: a.call.remote("fits", query, [views[i] for i in at])))

    def poses(
        self, query: QueryView, matches: Sequence[Candidate],
        intrinsics: Intrinsics | None = None,
        curves: Sequence[NDArray[np.float64] | None] | None = None,
        rerank: bool = False,
    ) -> tuple[list[tuple[PoseEstimate | None, str | None]], Exchange]:
        def call(actor: Any, at: list[int]) -> Any:
            return actor.call.remote("poses", query, [matches[i].to_dict() for i in at], intrinsics,
                                     None if curves is None else [curves[i] for i in at], rerank)

        return self._timed(lambda: self._routed([m.object for m in matches], call))
