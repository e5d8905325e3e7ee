"""One search route: the k nearest objects of one tier, each with its best view, as
candidates.

Every k-NN over a file's tier runs through :func:`nearest_candidates`: the client half of
CS1/CS2 and a file's own search (:func:`~viewdb.recognition.client_tier.nearest_objects`),
the server half of the plans (:class:`~viewdb.recognition.local_tier.LocalServerTier`)
and each shard of a sharded catalogue (:class:`~viewdb.shards.shard.Shard`). Each opens
a read snapshot of a file's tiers (a :class:`TierSnapshot`; storage only reads) and hands
it over; the
search (:func:`~viewdb.search.plans.refine`, with the request's bounds and options), the
raised distances of a compact client file and the views' directions on the candidates
are done here, the same way for all of them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from .fast import FastIndex
from .knn import Neighbour, SearchStats, TierSource
from .plans import Candidate, RefineRequest, neighbours_to_candidates, refine
from .quantised import distance_bound, upper_distance

__all__ = ["SnapshotTier", "TierSnapshot", "nearest_candidates", "raised_distances"]


class SnapshotTier(TierSource, Protocol):
    """A tier as a read snapshot opens it: a search source whose curves may be quantised
    (a compact client file), each view with its proven error norms."""

    #: The stored curves are quantised (:mod:`viewdb.search.quantised`).
    quantised: bool

    def view_errors(self, view_id: int) -> NDArray[np.float64]:
        """The quantisation error norms (L2, L-infinity) of a view's stored curve."""
        ...


class TierSnapshot(Protocol):
    """One read snapshot of a file's tiers (:class:`~viewdb.storage.tiers.TierReader` inside
    its ``snapshot``): the tiers searched, and what the answer needs beside them."""

    def tier(self, name: str) -> SnapshotTier:
        """Tier ``name`` (``"full"`` or ``"sparse"``)."""
        ...

    def view_projections(self, view_ids: Sequence[int]) -> Mapping[int, tuple[float, float, float | None]]:
        """``view id -> (azimuth, elevation, camera distance or None)``."""
        ...

    def object_versions(self) -> Mapping[str, str]:
        """``object name -> version`` (content hash and curve settings) of every object."""
        ...

    def fast_index(self, name: str) -> FastIndex | None:
        """The ``fast`` plan's index of tier ``name`` (None: none valid; search exactly)."""
        ...


def nearest_candidates(
    snapshot: TierSnapshot, request: RefineRequest, tier: str = "full", *,
    upper: float = math.inf, versioned: bool = False, bounded: bool = False,
) -> tuple[list[Candidate], SearchStats]:
    """The ``request.k`` nearest objects of ``tier`` in ``snapshot``, each with its best view:
    :func:`~viewdb.search.plans.refine` with the request's curve (or stack, or shifts),
    client bounds (those of the objects the snapshot holds in the same version),
    ``shortlist`` and ``fast`` options, as candidates best first.

    ``upper``: a further upper bound of the k-th distance (a sharded catalogue's other
    shards; objects farther may be left out). ``versioned``: each candidate carries its
    object's version (what a client sends, so a server can tell a stale file's bounds).
    ``bounded``: on a tier of quantised curves each distance is raised by its view's proven
    error (:func:`raised_distances`), an upper bound of the exact one, as a CS1 client
    must send; exact curves have nothing to add."""
    source = snapshot.tier(tier)
    # the versions tell which client candidates bound (none to tell without them)
    versions = snapshot.object_versions() if request.client or versioned else None
    index = snapshot.fast_index(tier) if request.fast is not None else None
    found, stats = refine(source, request, versions, upper, index)
    if bounded and source.quantised:
        found = raised_distances(found, source, len(request.curve), request.band)
    projections = snapshot.view_projections([n.view for n in found])
    return neighbours_to_candidates(found, projections, versions if versioned else None,
                                    shifted=request.shifts is not None,
                                    stacked=request.curves is not None), stats


def raised_distances(
    found: list[Neighbour], source: SnapshotTier, samples: int, band: int,
) -> list[Neighbour]:
    """``found`` with each distance raised by its view's quantisation bound (upper bounds
    of the exact distances, :func:`~viewdb.search.quantised.upper_distance`), best first."""
    raised = [replace(n, distance=upper_distance(
        n.distance, float(distance_bound(source.view_errors(n.view), samples, band)))) for n in found]
    return sorted(raised, key=lambda n: (n.distance, n.object))
