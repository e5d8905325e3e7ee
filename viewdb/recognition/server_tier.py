"""The server half of the plans, as the query pipeline sees it: one protocol, two tiers.

The pipeline (:mod:`viewdb.recognition.pipeline`) hands everything that needs the full
catalogue (the server half of a plan, the re-rankings' colours and fits, the poses) to an
object of this shape. :class:`viewdb.recognition.local_tier.LocalServerTier` answers from
a full file in this process; :class:`viewdb.http.RemoteServer` talks HTTP to ``viewdb
serve``, which answers from its own ``LocalServerTier``. Each call returns, beside its
answer, an :class:`Exchange`: what went (or would go) over the wire and how long it took.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..pose.estimate import PoseEstimate, QueryView
from ..pose.intrinsics import Intrinsics
from ..search.colour_index import ColourMatch
from ..search.plans import Candidate, RefineRequest, ServerReply, WalkRequest

__all__ = ["Exchange", "ServerTier"]


@dataclass(frozen=True)
class Exchange:
    """One round trip: request and reply body bytes, the client's wall-clock time for the
    whole call and the time the server reports it spent answering."""

    sent: int
    received: int
    wall_ms: float
    server_ms: float
    #: Round trips it counts as (0: answered in this process without a message, e.g. a
    #: local ``server`` plan or a local re-ranking).
    trips: int = 1
    #: ``(width, height, sent width, sent height)`` when the query image was scaled down
    #: to the server's pixel cap before it was sent; None when sent as it is (or not at all).
    scaled: tuple[int, int, int, int] | None = None


class ServerTier(Protocol):
    """The server half of CS1/CS2, the re-rankings and the pose, behind some transport."""

    #: Whether the tier is reached over a network (its ``Exchange`` times include one).
    remote: bool

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

    def colour_ranking(
        self, signature: NDArray[np.float32], n: int
    ) -> tuple[list[ColourMatch], Exchange]:
        """The colour channel (:mod:`viewdb.search.colour_index`): the ``n`` objects whose
        stored views' colours lie nearest ``signature`` (a photo's colour signature),
        nearest first, each with its nearest view."""
        ...

    def looks(self, look: NDArray[np.float32]) -> tuple[dict[str, float], Exchange]:
        """Each coloured object's look distance to ``look`` (a cut-out's box's
        :func:`~viewdb.catalogue.look.look_features`), from the file's look model
        (:meth:`~viewdb.storage.stored_catalogue.StoredCatalogue.look_model`); none
        without a valid one."""
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
        rerank: bool = False,
    ) -> tuple[list[tuple[PoseEstimate | None, str | None]], Exchange]:
        """``(pose, None)`` or ``(None, why not)`` per match, from the segmented query
        (and per match the query's curve at the turn that matched, or None); ``rerank``
        (with intrinsics): fitted so they can be ranked by silhouette IoU
        (:func:`viewdb.pose.matched.pose_matches`)."""
        ...
