"""The server half of the plans as seen from a client: what a remote server must offer.

:meth:`viewdb.ViewDB.query` with ``server=...`` runs the client half of a plan on a client
file and hands the rest to an object of this shape; :class:`viewdb.http.RemoteServer`
is the one that talks HTTP to ``viewdb serve``. Each call returns, beside its answer, an
:class:`Exchange`: what went over the wire and how long it took.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..pose.estimate import PoseEstimate, QueryView
from ..search.plans import Candidate, RefineRequest, ServerReply, WalkRequest
from ..typed import Intrinsics

__all__ = ["Exchange", "ServerTier"]


@dataclass(frozen=True)
class Exchange:
    """One round trip: request and reply body bytes, the client's wall-clock time for the
    whole call and the time the server reports it spent answering."""

    sent: int
    received: int
    wall_ms: float
    server_ms: float


class ServerTier(Protocol):
    """The server half of CS1/CS2 and the pose, behind some transport."""

    def refine(self, request: RefineRequest) -> tuple[ServerReply, Exchange]:
        """CS1 (an empty ``client`` list makes it the ``server`` plan's exact k-NN)."""
        ...

    def walk(self, request: WalkRequest) -> tuple[ServerReply, Exchange]:
        """CS2's neighbour walk."""
        ...

    def colours(
        self, views: Sequence[tuple[str, float, float]]
    ) -> tuple[list[NDArray[np.float32] | None], Exchange]:
        """The colour signatures (:func:`viewdb.recognition.colour.colour_signature`) of stored views
        ``(object, azimuth, elevation)``, rendered from the server's meshes (None: the
        object's mesh has no colour)."""
        ...

    def fits(
        self, query: QueryView, views: Sequence[tuple[str, float, float]]
    ) -> tuple[list[float | None], Exchange]:
        """How well each stored view ``(object, azimuth, elevation)``, rendered from the
        server's meshes, fits the segmented query's shape (:mod:`viewdb.recognition.verify`; None: the
        view has no silhouette)."""
        ...

    def poses(
        self, query: QueryView, matches: Sequence[Candidate],
        intrinsics: Intrinsics | None = None,
        curves: Sequence[NDArray[np.float64] | None] | None = None,
    ) -> tuple[list[tuple[PoseEstimate | None, str | None]], Exchange]:
        """``(pose, None)`` or ``(None, why not)`` per match, from the segmented query
        (and per match the query's curve at the turn that matched, or None)."""
        ...
