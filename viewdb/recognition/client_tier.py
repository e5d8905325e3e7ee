"""The client tier: the client half of CS1 and CS2 (the paper's mobile side), the k-NN on
the sparse tier of a file in this process, a client file from ``export-client`` or any
full file; and :func:`nearest_objects`, a file's own k-NN on one of its tiers, which it
runs on (:meth:`viewdb.ViewDB.search` runs it on either tier).

Like the server half (:class:`~viewdb.recognition.local_tier.LocalServerTier`), it checks
the query, opens a read snapshot of the file's tiers and hands it to the search route
(:func:`~viewdb.search.route.nearest_candidates`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import QueryError
from ..search.knn import SearchStats
from ..search.plans import Candidate, RefineRequest
from ..search.route import nearest_candidates
from ..search.shifts import ShiftWindow
from ..storage.stored_catalogue import StoredCatalogue

__all__ = ["ClientTier", "nearest_objects"]


class ClientTier:
    """The sparse tier of ``catalogue``."""

    def __init__(self, catalogue: StoredCatalogue) -> None:
        self.catalogue = catalogue

    @property
    def client_gap(self) -> float:
        """The sparse tier's grid gap (what CS2's walk starts from)."""
        return self.catalogue.config.client_gap

    def candidates(
        self, curve: NDArray[np.floating], k: int, band: int = 6, shifts: ShiftWindow | None = None
    ) -> list[Candidate]:
        """The k nearest objects on the sparse tier (over ``shifts`` of the curve, or the
        smallest distance over the rows of a ``(T, N)`` stack of curves), each with its
        version (content hash and curve settings, so a server can tell a stale client
        file's bounds). A compact client file's distances are raised by their curves' proven
        quantisation error, so each is an upper bound of the exact one and CS1 stays exact."""
        return nearest_objects(self.catalogue, curve, k, band, "sparse", shifts, bounded=True)[0]


def nearest_objects(
    catalogue: StoredCatalogue, curve: NDArray[np.floating], k: int, band: int = 6,
    tier: str = "full", shifts: ShiftWindow | None = None, *, bounded: bool = False,
) -> tuple[list[Candidate], SearchStats]:
    """Algorithm 2 on one tier of ``catalogue``, in one read snapshot (handed to the search
    route, :func:`~viewdb.search.route.nearest_candidates`): the ``k`` nearest objects, each
    with its best view (and the object's content hash as its ``version``); over the
    circular ``shifts`` of the curve in one search (each with the shift that matched).
    A ``(T, N)`` stack of curves (no ``shifts``): the smallest distance over its rows,
    in one search (:func:`~viewdb.search.knn.knn_stack`; each with the row that
    matched as its ``curve_index``).

    The distances are those of the stored curves. ``bounded``: each is raised by its
    view's proven quantisation error (a compact client file; nothing to add for exact
    curves), so it bounds the distance to the exact curve from above, as a CS1 client
    must send (:mod:`viewdb.search.quantised`)."""
    stacked = np.ndim(curve) == 2
    if stacked and (shifts is not None or len(curve) == 0):
        raise QueryError("a stack of curves needs at least one curve and no shifts")
    if stacked:
        q = np.stack([catalogue.query_curve(c, k, tier) for c in curve])
        request = RefineRequest(q[0], band, k, [], curves=q)
    else:
        request = RefineRequest(catalogue.query_curve(curve, k, tier), band, k, [], shifts)
    with catalogue.tier_reader().snapshot() as reader:
        if reader.tier(tier).n_groups == 0:
            raise QueryError("the database holds no views", catalogue.path)
        return nearest_candidates(reader, request, tier, versioned=True, bounded=bounded)
