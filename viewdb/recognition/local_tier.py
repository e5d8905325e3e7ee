"""The server tier in this process: the server half of the plans, the re-rankings' colours
and fits, and the poses, answered from a full catalogue.

It is what ``viewdb serve`` runs behind HTTP, and what a local query uses, so a query
takes the same path whether its server is a file here or a URL. Its :class:`Exchange`
reports what the messages would weigh as JSON on the wire (``count_bytes``; a local
``server`` plan exchanges nothing) and the time spent.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from ..config import SearchConfig
from ..errors import PoseError, QueryError, RenderError
from ..pose.estimate import PoseConfig, PoseEstimate, QueryView
from ..pose.intrinsics import Intrinsics
from ..pose.matched import appearance_view, pose_matches
from ..pose.shape_pose import shape_fit
from ..search.colour_index import ColourMatch
from ..search.plans import Candidate, RefineRequest, ServerReply, WalkRequest, walk
from ..search.route import nearest_candidates
from ..storage.stored_catalogue import StoredCatalogue
from .server_tier import Exchange

__all__ = ["LocalServerTier"]

T = TypeVar("T")


class LocalServerTier:
    """The server tier of a full :class:`~viewdb.storage.stored_catalogue.StoredCatalogue`."""

    remote = False

    def __init__(self, catalogue: StoredCatalogue, *, count_bytes: bool = True,
                 pose_config: PoseConfig | None = None) -> None:
        """``count_bytes``: report what the plans' messages would weigh as JSON, and count
        each as a round trip (False for a local ``server`` plan, which exchanges nothing);
        ``pose_config``: the pose's tunables (default :class:`~viewdb.pose.estimate.PoseConfig`)."""
        self.catalogue = catalogue
        self.count_bytes = count_bytes
        self.pose_config = pose_config

    def _full_tier_only(self) -> None:
        if self.catalogue.role == "client":
            raise QueryError(
                "is a client database (no full tier): query the full database (`db`), "
                "or give a `server`", self.catalogue.path,
            )

    def _exchange(self, call: Callable[[], T], request: Any = None,
                  reply: Callable[[T], Any] | None = None) -> tuple[T, Exchange]:
        start = time.perf_counter()
        answer = call()
        ms = (time.perf_counter() - start) * 1e3
        if request is None or reply is None or not self.count_bytes:
            return answer, Exchange(0, 0, ms, ms, trips=0)
        return answer, Exchange(len(json.dumps(request)), len(json.dumps(reply(answer))), ms, ms)

    # ------------------------------------------------------------------ the plans
    def refine(self, request: RefineRequest) -> tuple[ServerReply, Exchange]:
        """The server half of CS1 (Algorithm 3): exact, the same answer as the ``server``
        plan whenever the client's candidates come from this file's sparse tier (or a
        client file exported from it); candidates of objects this file lacks, or holds in
        another version (a stale client file), are not used as bounds."""
        return self._exchange(lambda: self._refine(request), request.to_dict(), ServerReply.to_dict)

    def _refine(self, request: RefineRequest) -> ServerReply:
        self._full_tier_only()
        q = self.catalogue.query_curve(request.curve, request.k, "full")
        curves = (None if request.curves is None
                  else np.stack([self.catalogue.query_curve(c, request.k, "full") for c in request.curves]))
        with self.catalogue.tier_reader().snapshot() as reader:
            found, stats = nearest_candidates(reader, replace(request, curve=q, curves=curves))
        return ServerReply(found, stats.to_dict())

    def walk(self, request: WalkRequest) -> tuple[ServerReply, Exchange]:
        """The server half of CS2 (Algorithm 4): the neighbour walk from the client's views.
        Candidates of objects this file lacks (a stale client file) are left out."""
        return self._exchange(lambda: self._walk(request), request.to_dict(), ServerReply.to_dict)

    def _walk(self, request: WalkRequest) -> ServerReply:
        self._full_tier_only()
        q = self.catalogue.query_curve(request.curve, request.k, "full")
        with self.catalogue.tier_reader().snapshot() as reader:
            known = reader.object_versions()
        client = [c for c in request.client if c.object in known]
        config, reach = self.catalogue.config, SearchConfig().walk_perspective
        found, stats = walk(replace(request, curve=q, client=client), self.catalogue.grid_curve, config.gap,
                            perspective_near=self.catalogue.perspective_near if reach >= 0 else None,
                            perspective_radius=reach * config.perspective_gap)
        return ServerReply(found, stats)

    # ------------------------------------------------------------------ re-ranking
    def colours(
        self, views: Sequence[tuple[str, float, float]]
    ) -> tuple[list[NDArray[np.float32] | None], Exchange]:
        """The colour signatures of views ``(object, azimuth, elevation)``, from their
        stored appearance (or their render: :meth:`StoredCatalogue.appearance`); None for
        an object whose mesh has no colour."""
        return self._exchange(lambda: self.view_colours(views))

    def view_colours(
        self, views: Sequence[tuple[str, float, float]]
    ) -> list[NDArray[np.float32] | None]:
        return [self.catalogue.appearance(name, azimuth, elevation).colour()
                for name, azimuth, elevation in views]

    def colour_ranking(
        self, signature: NDArray[np.float32], n: int
    ) -> tuple[list[ColourMatch], Exchange]:
        """The ``n`` objects of this file whose stored colours lie nearest ``signature``
        (:meth:`StoredCatalogue.colour_index`)."""
        self._full_tier_only()
        return self._exchange(lambda: self.catalogue.colour_index().nearest(signature, n),
                              {"signature": np.asarray(signature).tolist(), "n": n},
                              lambda found: [m.to_dict() for m in found])

    def looks(self, look: NDArray[np.float32]) -> tuple[dict[str, float], Exchange]:
        """Each coloured object's look distance (:meth:`StoredCatalogue.look_model`; none
        without a valid model)."""
        self._full_tier_only()

        def distances() -> dict[str, float]:
            model = self.catalogue.look_model()
            return {} if model is None else model.distances(look)
        return self._exchange(distances, {"look": np.asarray(look).tolist()}, dict)

    def fits(
        self, query: QueryView, views: Sequence[tuple[str, float, float]]
    ) -> tuple[list[float | None], Exchange]:
        """How well each view ``(object, azimuth, elevation)`` explains the segmented
        query's shape (in [0, 1]; None: no silhouette), compared with its stored appearance
        (:func:`viewdb.pose.matched.appearance_view`)."""
        return self._exchange(lambda: self.view_fits(query, views))

    def view_fits(self, query: QueryView, views: Sequence[tuple[str, float, float]]) -> list[float | None]:
        config = PoseConfig()
        fits: list[float | None] = []
        for name, azimuth, elevation in views:
            try:
                view = appearance_view(self.catalogue, name, azimuth, elevation, config)
                fits.append(shape_fit(query, view, config))
            except (PoseError, RenderError):
                fits.append(None)
        return fits

    # ------------------------------------------------------------------ pose
    def poses(
        self, query: QueryView, matches: Sequence[Candidate],
        intrinsics: Intrinsics | None = None,
        curves: Sequence[NDArray[np.float64] | None] | None = None,
        rerank: bool = False,
    ) -> tuple[list[tuple[PoseEstimate | None, str | None]], Exchange]:
        """``(pose, None)`` or ``(None, why not)`` per match (:func:`viewdb.pose.matched.pose_matches`)."""
        return self._exchange(lambda: pose_matches(self.catalogue, query, matches, intrinsics,
                                                   self.pose_config, curves, rerank=rerank))
