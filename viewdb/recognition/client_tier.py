"""The client tier: the client half of CS1 and CS2 (the paper's mobile side), the k-NN on
the sparse tier of a file in this process, a client file from ``export-client`` or any
full file."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..search.plans import Candidate
from ..search.shifts import ShiftWindow
from ..storage.stored_catalogue import StoredCatalogue

__all__ = ["ClientTier"]


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
        return self.catalogue.nearest_objects(curve, k, band, "sparse", shifts, bounded=True)[0]
