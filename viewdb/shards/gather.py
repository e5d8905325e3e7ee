"""The merge of a scatter-gather search: bounds handed to shards, answers combined.

Pure functions (no Ray, no files), so the rule that makes a sharded answer equal the
single file's is in one place:

* a client's (or earlier turns') candidates bound the search only for objects the
  catalogue holds in the same version (:func:`client_bounds`), as a single file's
  :func:`~viewdb.search.plans.refine` does;
* the k-th distance of the answers gathered so far bounds every later shard
  (:func:`kth_distance`): those answers are real views' exact distances, so the global
  k-th distance is at most it, and a shard left out nothing that could enter the answer;
* the answer is the k best by ``(distance, object name)`` (:func:`top_k`), the order
  of :func:`~viewdb.search.knn.knn`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

from ..search.plans import Candidate, RefineRequest, ServerReply, usable_client

__all__ = ["client_bounds", "kth_distance", "scatter_gather", "top_k"]

#: ``run(shards, bound, client)``: one round's replies (``ServerReply.to_dict`` shape),
#: one per shard, each shard's exact search bounded by ``bound`` and by its client
#: candidates ``client[shard]`` (:func:`~viewdb.search.plans.refine`).
RoundRunner = Callable[[list[int], float, dict[int, list[Candidate]]], list[dict[str, Any]]]


def client_bounds(
    request: RefineRequest, owners: Mapping[str, int], versions: Mapping[str, str],
) -> tuple[float, dict[int, list[Candidate]]]:
    """The upper bound of the k-th distance the usable client candidates give
    (:func:`~viewdb.search.plans.usable_client`: of objects the catalogue holds,
    ``owners``: name → shard, in the same version, at an allowed shift), and those
    candidates by shard."""
    usable = usable_client(request, lambda name: name in owners, versions)
    upper = usable[request.k - 1].distance if len(usable) >= request.k else math.inf
    known: dict[int, list[Candidate]] = {}
    for c in usable:
        known.setdefault(owners[c.object], []).append(c)
    return upper, known


def top_k(found: Iterable[Candidate], k: int) -> list[Candidate]:
    """The ``k`` best candidates by ``(distance, object)``, one per object."""
    best: dict[str, Candidate] = {}
    for c in found:
        if c.object not in best or c.distance < best[c.object].distance:
            best[c.object] = c
    return sorted(best.values(), key=lambda c: (c.distance, c.object))[:k]


def kth_distance(found: Sequence[Candidate], k: int) -> float:
    """The k-th smallest distance of ``found`` (one per object; inf if fewer than k)."""
    ranked = top_k(found, k)
    return ranked[k - 1].distance if len(ranked) >= k else math.inf


def scatter_gather(
    request: RefineRequest, owners: Mapping[str, int], versions: Mapping[str, str], shards: int,
    first_round: int, run: RoundRunner,
) -> ServerReply:
    """The exact k nearest objects over ``shards`` shards in two rounds: the first
    ``first_round`` shards (the shard of the client's best candidate first), then the
    rest, bounded by the k-th distance gathered so far and the client's bounds."""
    upper, known = client_bounds(request, owners, versions)
    best = min(request.client, key=lambda c: c.distance, default=None)
    start = owners.get(best.object, 0) if best is not None else 0
    order = [(start + i) % shards for i in range(shards)]
    found: list[Candidate] = []
    stats: dict[str, float] = {"shards": float(shards), "rounds": 0.0}
    for r, round_shards in enumerate(x for x in (order[:first_round], order[first_round:]) if x):
        bound = min(upper, kth_distance(found, request.k))
        for reply in run(round_shards, bound, known):
            parsed = ServerReply.from_dict(reply)
            found += parsed.results
            for key, value in parsed.stats.items():
                stats[key] = stats.get(key, 0.0) + value
                if key == "dtw":
                    stats[f"dtw_round{r + 1}"] = stats.get(f"dtw_round{r + 1}", 0.0) + value
        stats["rounds"] += 1
    return ServerReply(top_k(found, request.k), stats)
