"""Retrieval: the k objects a distance curve shows, by plan, over a client and a server tier.

``server``: the server tier's exact k-NN (CS1 with no client candidates). ``cs1``: the
client tier's k-NN on its sparse tier bounds the server's exact refinement (Algorithm 3;
the same answer as ``server``). ``cs2`` (heuristic): the client's shortlist, its nearest
``shortlist`` objects on the sparse tier, bounds the server's exact search over those
objects alone (``cs2="shortlist"``, the default), or the server walks the grid from the
client's views (``cs2="walk"``, Algorithm 4). ``fast`` (approximate): the server tier's
exact search over the objects its approximate index shortlists
(:mod:`viewdb.search.fast`). A query searches several curves (in-plane turns, a
completed silhouette): ``server``, ``cs1`` and ``fast`` in one search over the stack of
them (a ``(T, N)`` curve: each view's distance is the smallest over the rows, each
result's ``curve_index`` the row that matched), or one search per curve, where
:func:`merge` keeps each object's best and each search is bounded by the objects found
so far (``prior``), which leaves the merged answer unchanged. Both give the same answer.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..config import CS2_SEARCHES, RecognitionConfig
from ..errors import QueryError
from ..search.plans import MAX_K, PLANS, Candidate, RefineRequest, WalkRequest
from ..search.shifts import ShiftWindow
from .client_tier import ClientTier
from .server_tier import ServerTier

__all__ = ["Recognition", "best_of", "merge", "recognise_curve"]


@dataclass(frozen=True)
class Recognition:
    """What one curve's search found: the objects, best first, and what it cost."""

    plan: str
    results: list[Candidate]
    #: The client half's answer (CS1/CS2; empty for ``server``).
    client_results: list[Candidate]
    client_ms: float
    server_ms: float
    server_stats: dict[str, float]
    #: JSON bytes the client sent and received (would send, for a local server tier).
    bytes_sent: int
    bytes_received: int
    #: With a remote server: the round trip's wall time beyond the server's own time.
    network_ms: float = 0.0
    #: Round trips to the server tier (0 for a local ``server`` plan).
    round_trips: int = 0


def best_of(mine: Sequence[Candidate], prior: Sequence[Candidate], k: int) -> list[Candidate]:
    """The k best of two candidate lists, one per object (its smaller distance)."""
    best: dict[str, Candidate] = {}
    for c in (*mine, *prior):
        if c.object not in best or c.distance < best[c.object].distance:
            best[c.object] = c
    return sorted(best.values(), key=lambda c: (c.distance, c.object))[:k]


def recognise_curve(
    curve: NDArray[np.floating], k: int, band: int, plan: str, server: ServerTier,
    client: ClientTier | None, prior: Sequence[Candidate] = (), shifts: ShiftWindow | None = None,
    *, cs2: str = RecognitionConfig().cs2, shortlist: int = RecognitionConfig().cs2_shortlist,
    fast_shortlist: int = RecognitionConfig().fast_shortlist,
) -> Recognition:
    """The k objects ``curve`` shows by ``plan`` (module doc). ``client`` runs the client
    half of ``cs1``/``cs2`` (unused by ``server``). ``prior``: the best objects already
    found for the same photo by other curves; their distances bound the search as a CS1
    client's do (``server``, ``cs1``). ``shifts``: both halves search the smallest distance
    over these circular shifts of the curve (:class:`~viewdb.search.shifts.ShiftWindow`).
    A ``(T, N)`` ``curve`` (``server``, ``cs1``, ``cs2`` by shortlist): both halves search
    the smallest distance over its rows.

    ``cs2``: how that plan's server half searches: ``"shortlist"``, exactly over the
    client's nearest ``shortlist`` objects (and those of ``prior``), or ``"walk"``.
    ``fast``: the server tier searches exactly the ``fast_shortlist`` objects its
    approximate index finds (:mod:`viewdb.search.fast`); no client half."""
    if plan not in PLANS:
        raise QueryError(f"plan must be one of {', '.join(PLANS)}, got {plan!r}")
    if cs2 not in CS2_SEARCHES:
        raise QueryError(f"cs2 must be one of {', '.join(CS2_SEARCHES)}, got {cs2!r}")
    if plan not in ("server", "fast") and client is None:
        raise QueryError(f"the {plan} plan needs a client tier")
    q = np.asarray(curve, dtype=np.float64)
    walks = plan == "cs2" and cs2 == "walk"
    if q.ndim == 2 and walks:
        raise QueryError("the cs2 walk takes one curve at a time, not a stack")
    listed = plan == "cs2" and not walks
    asked = max(k, min(shortlist, MAX_K)) if listed else k
    start = time.perf_counter()
    mine = [] if client is None or plan in ("server", "fast") else client.candidates(q, asked, band, shifts)
    client_ms = (time.perf_counter() - start) * 1e3
    if walks:
        assert client is not None
        reply, exchange = server.walk(WalkRequest(q, band, k, client.client_gap, mine))
    else:
        bounds = best_of(mine, prior, MAX_K if listed else k)
        fast = max(fast_shortlist, k) if plan == "fast" else None
        request = (RefineRequest.of_stack(q, band, k, bounds, listed, fast) if q.ndim == 2
                   else RefineRequest(q, band, k, bounds, shifts, shortlist=listed, fast=fast))
        reply, exchange = server.refine(request)
    return Recognition(plan, reply.results, mine, client_ms, exchange.server_ms, reply.stats,
                       exchange.sent, exchange.received, max(exchange.wall_ms - exchange.server_ms, 0.0),
                       exchange.trips)


def merge(per_curve: Sequence[tuple[float, list[Candidate]]], k: int) -> list[tuple[Candidate, float]]:
    """Each object's best candidate over several curves' results, with the in-plane angle
    of the curve that found it, best first; the first ``k``."""
    best: dict[str, tuple[Candidate, float]] = {}
    for angle, found in per_curve:
        for c in found:
            if c.object not in best or c.distance < best[c.object][0].distance:
                best[c.object] = (c, angle)
    return sorted(best.values(), key=lambda x: (x[0].distance, x[0].object))[:k]
