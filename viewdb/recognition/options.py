"""How a query runs: one value instead of a long parameter list."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..config import DEFAULT_PLAN, RecognitionConfig
from ..errors import QueryError
from ..pose.estimate import PoseConfig
from ..pose.intrinsics import Intrinsics, parse_intrinsics
from ..search.plans import MAX_BAND, MAX_K, PLANS
from ..search.shifts import ShiftWindow

__all__ = ["QueryOptions"]


@dataclass(frozen=True)
class QueryOptions:
    """The options of :meth:`viewdb.ViewDB.query` (see there); checked when made.

    ``intrinsics`` may be given as anything :func:`viewdb.pose.intrinsics.parse_intrinsics`
    reads (``(fx, fy, cx, cy)``, a 3×3 matrix, ``"fx,fy,cx,cy"``, a JSON/YAML file); it is
    kept parsed.
    """

    #: How many objects the answer has.
    k: int = 5
    #: ``fast`` (approximate shortlist, exact distances; ``recognition.fast_shortlist``),
    #: ``server`` (exact), ``cs1`` (exact, client-bounded) or ``cs2`` (heuristic).
    plan: str = DEFAULT_PLAN
    #: Sakoe–Chiba band of the DTW distance, in samples. 5 ranks the 240 synthetic photos
    #: as well in less time but puts a real photo's sugar box third
    #: (docs/results/synthetic-photos.md#the-dtw-band).
    band: int = 6
    #: In-plane turns of the silhouette searched (evenly spaced; 1 = upright only). 8, not
    #: 12: as accurate on the synthetic and the real photos, a fifth quicker
    #: (docs/results/real-clutter.md#recognition-and-pose-from-the-box).
    rotations: int = 8
    #: Instead of ``rotations``: one search over these circular shifts of the upright
    #: curve (:class:`~viewdb.search.shifts.ShiftWindow`; ``ShiftWindow()``: every turn).
    shifts: ShiftWindow | None = None
    #: A gravity hint: the in-plane turn (degrees, clockwise on screen, as a match's
    #: ``inplane``) that makes the photo upright (0: upright); one search over the shifts
    #: within ``recognition.roll_tolerance`` of it.
    roll: float | None = None
    #: Pose the results (needs the meshes: a full file or a server).
    pose: bool = True
    #: Pose only the best this many results (None: all k). The common question is "what is
    #: this and how does it sit": the top result's pose; each further one costs as much.
    pose_top: int | None = 1
    #: The camera, for a perspective pose in its OpenCV frame and the mesh's units.
    intrinsics: Intrinsics | str | Path | Sequence[Any] | None = None
    #: With intrinsics: re-rank the k results by the IoU of their perspective silhouette fit.
    rerank: bool = False
    #: Re-rank the plan's pool by colour when the photo has colour.
    colour: bool = True
    #: Re-rank the plan's pool by how well each matched view fits the photo's shape.
    verify: bool = True
    #: The pose's tunables (default :class:`~viewdb.pose.estimate.PoseConfig`).
    pose_config: PoseConfig | None = None
    recognition: RecognitionConfig = field(default_factory=RecognitionConfig)

    def __post_init__(self) -> None:
        if isinstance(self.k, bool) or not isinstance(self.k, int):
            raise QueryError(f"k must be an integer, got {self.k!r}")
        if not 1 <= self.k <= MAX_K:
            raise QueryError(f"k must be in [1, {MAX_K}], got {self.k}")
        if self.plan not in PLANS:
            raise QueryError(f"plan must be one of {', '.join(PLANS)}, got {self.plan!r}")
        if isinstance(self.band, bool) or not isinstance(self.band, int):
            raise QueryError(f"band must be an integer, got {self.band!r}")
        if not 0 <= self.band <= MAX_BAND:
            raise QueryError(f"band must be in [0, {MAX_BAND}], got {self.band}")
        if self.rotations < 1:
            raise QueryError(f"rotations must be at least 1, got {self.rotations}")
        if self.shifts is not None and not isinstance(self.shifts, ShiftWindow):
            raise QueryError(f"shifts must be a ShiftWindow, got {self.shifts!r}")
        if self.roll is not None and (isinstance(self.roll, bool) or not isinstance(self.roll, (int, float))
                                      or not math.isfinite(self.roll)):
            raise QueryError(f"roll must be a finite number of degrees, got {self.roll!r}")
        if self.roll is not None and self.shifts is not None:
            raise QueryError("give either shifts or a roll, not both")
        if self.pose_top is not None and self.pose_top < 0:
            raise QueryError(f"pose_top must be at least 0, got {self.pose_top}")
        if self.intrinsics is not None:
            object.__setattr__(self, "intrinsics", parse_intrinsics(self.intrinsics))

    @property
    def camera(self) -> Intrinsics | None:
        """The parsed intrinsics (None: orthographic pose)."""
        return self.intrinsics  # type: ignore[return-value]

    @property
    def rerank_by_iou(self) -> bool:
        """Whether the results are re-ranked by their perspective silhouette fit."""
        return self.rerank and self.pose and self.intrinsics is not None

    @property
    def posed(self) -> int:
        """How many of the k results get a pose (re-ranking by IoU needs every one)."""
        if not self.pose:
            return 0
        if self.pose_top is None or self.rerank_by_iou:
            return self.k
        return min(self.k, self.pose_top)
