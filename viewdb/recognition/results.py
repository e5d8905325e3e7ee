"""What a search and a query return: an object a curve's k-NN search found
(:class:`SearchHit`), each recognised object with its view, scores and pose
(:class:`QueryMatch`), each object of a photo of several with its matches
(:class:`ObjectResult`), and the whole answer (:class:`QueryResult`, whose ``to_dict`` is
the ``viewdb query --json`` shape of the public contract)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import QueryError
from ..pose.estimate import PoseEstimate
from .regions import Region

__all__ = ["ObjectResult", "QueryMatch", "QueryResult", "SearchHit"]


@dataclass(frozen=True)
class QueryMatch:
    """One recognised object: its best view, the in-plane turn that matched, its pose."""

    rank: int
    object: str
    distance: float
    azimuth: float
    elevation: float
    mirrored: bool
    #: The query's silhouette matched the view after turning it back by this angle.
    inplane: float
    pose: PoseEstimate | None = None
    #: Why there is no pose (e.g. a client file without meshes), if there is none.
    pose_error: str | None = None
    #: Colour distance between the photo and the matched view (:mod:`viewdb.recognition.colour`),
    #: None when the results were not re-ranked by colour or the mesh has no colour.
    colour: float | None = None
    #: What the results are ranked by when re-ranked by colour
    #: (:func:`viewdb.recognition.colour.rerank`); None: by ``distance`` alone.
    colour_score: float | None = None
    #: The matched view is a perspective silhouette from this many bounding radii
    #: (:class:`~viewdb.config.PerspectiveConfig`); None: an orthographic view.
    camera_distance: float | None = None
    #: How well the matched view, rendered, fits the photo's shape (:mod:`viewdb.recognition.verify`,
    #: in [0, 1]); None when the results were not verified or the view has no silhouette.
    shape_fit: float | None = None
    #: What the results are ranked by when verified (:func:`viewdb.recognition.verify.rerank_by_fit`).
    verified_score: float | None = None

    @property
    def score(self) -> float:
        """What the results are ranked by: ``distance``, lengthened by the colour
        mismatch when they were re-ranked by colour, and by the shape misfit when they
        were verified."""
        if self.verified_score is not None:
            return self.verified_score
        return self.distance if self.colour_score is None else self.colour_score

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "rank": self.rank, "object": self.object, "distance": self.distance,
            "view": {"azimuth": self.azimuth, "elevation": self.elevation,
                     "mirrored": self.mirrored, "inplane": self.inplane,
                     "camera_distance": self.camera_distance},
            "colour_distance": self.colour, "shape_fit": self.shape_fit, "score": self.score,
            "pose": None,
        }
        p = self.pose
        if p is not None:
            out["pose"] = {
                "azimuth": p.azimuth, "elevation": p.elevation, "inplane": p.inplane,
                "method": p.method, "inliers": int(p.inliers), "scale": p.scale,
                "score": p.score, "frame": p.frame, "units": p.units, "refined": p.refined,
                "iou": p.iou,
                "rotation": [[float(x) for x in row] for row in p.rotation],
                "translation": [float(x) for x in p.translation],
            }
            if p.depth_pixels is not None:
                out["pose"]["depth_pixels"] = int(p.depth_pixels)
        if self.pose_error is not None:
            out["pose_error"] = self.pose_error
        return out


@dataclass(frozen=True)
class ObjectResult:
    """One object of a photo of several (a prompt's, or one of every object's): where it
    is and what it was recognised as."""

    region: Region
    results: list[QueryMatch]
    #: Its share of the query's time: its curves ("segment"), search, re-rankings, pose.
    timing_ms: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"region": self.region.to_dict(), "segmentation": self.region.segmentation.method,
                "results": [r.to_dict() for r in self.results],
                "timing_ms": {k: round(v, 3) for k, v in self.timing_ms.items()}}


#: Draws a result over its photo: ``(result, top, config) -> RGB image``.
Drawer = Callable[["QueryResult", int, Any], NDArray[np.uint8]]


@dataclass(frozen=True)
class QueryResult:
    """The answer to one query (``to_dict`` is the ``viewdb query --json`` shape).

    A query of several objects (prompts, every object) has them in ``objects`` and an
    empty ``results``; a single-object query has ``objects`` None."""

    image: str
    plan: str
    k: int
    results: list[QueryMatch]
    timing_ms: dict[str, float]
    segmentation: str
    #: What went over the (would-be) wire: bytes each way and round trips (CS1/CS2).
    transfer: dict[str, int] = field(default_factory=dict)
    #: Each object of a query of several, in the prompts' order (every object: largest first).
    objects: list[ObjectResult] | None = None
    #: The photo (RGB) the query saw, for :meth:`overlay`.
    photo: NDArray[np.uint8] | None = field(default=None, repr=False, compare=False)
    #: Draws the overlay (:meth:`overlay`); None when the meshes are not at hand.
    drawer: Drawer | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict[str, Any]:
        out = {
            "image": self.image, "plan": self.plan, "k": self.k,
            "results": [r.to_dict() for r in self.results],
            "timing_ms": {k: round(v, 3) for k, v in self.timing_ms.items()},
            "segmentation": self.segmentation, "transfer": dict(self.transfer),
        }
        if self.objects is not None:
            out["objects"] = [o.to_dict() for o in self.objects]
        return out

    def overlay(self, *, top: int = 1, config: Any = None) -> NDArray[np.uint8]:
        """The photo (RGB uint8) with the posed mesh of each object's best ``top`` results
        drawn over it (:mod:`viewdb.recognition.overlay`; ``config`` an
        :class:`~viewdb.config.OverlayConfig`). The meshes are read from the file the query
        ran on: draw while it is open.

        Raises
        ------
        QueryError
            The query ran without the meshes at hand (a client file with a server).
        """
        if top < 1:
            raise QueryError(f"top must be at least 1, got {top}")
        if self.drawer is None or self.photo is None:
            raise QueryError("an overlay needs the meshes: query the full database file, not a client "
                             "file with a server")
        return self.drawer(self, top, config)


@dataclass(frozen=True)
class SearchHit:
    """One object found by a k-NN search, with its best stored view."""

    object: str
    distance: float
    azimuth: float
    elevation: float
    #: The query matches the stored view's mirror (its reversed curve).
    mirrored: bool
    #: The view is a perspective silhouette from this many bounding radii (None: an
    #: orthographic view).
    camera_distance: float | None = None
    #: The query curve matched started at this sample (a shift search; None: as given).
    shift: int | None = None
