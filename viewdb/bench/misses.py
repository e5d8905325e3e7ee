"""Why a photo was not recognised: each miss (the right object not ranked first) sorted into
one cause, for ``benchmarks/miss_analysis.py``.

The causes, tested in this order (the first that holds is the miss's cause):

``twin``
    what won has a near-identical mesh to the right object (:mod:`viewdb.bench.twins`): no
    silhouette tells them apart, only colour may.
``segmentation``
    the automatic mask differs from the photo's true silhouette (its holes filled, as the
    query fills them) by an IoU below :attr:`~viewdb.bench.config.MissConfig.min_iou`.
``recall``
    the right object is not among the search's shortlist (the best
    :attr:`~viewdb.bench.config.MissConfig.shortlist` objects by outline distance alone,
    before the colour and shape re-rankings), so no re-ranking can bring it back.
``re-ranking``
    it was on the shortlist, but the outline distance and the re-rankings put another first.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from ..recognition.results import QueryMatch

__all__ = ["CAUSES", "Miss", "cause_of", "filled", "iou", "outline_rank"]

#: The causes in the order they are tested (module doc).
CAUSES = ("twin", "segmentation", "recall", "re-ranking")


def filled(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """``mask`` with its holes filled: every pixel not 4-connected to the image's border
    through pixels off the mask."""
    m = np.asarray(mask, bool)
    h, w = m.shape
    pad = np.zeros((h + 2, w + 2), np.uint8)
    pad[1:-1, 1:-1] = m
    flood = np.zeros((h + 4, w + 4), np.uint8)
    cv2.floodFill(pad, flood, (0, 0), 2, flags=4)
    return np.asarray(pad[1:-1, 1:-1] != 2)


def iou(a: NDArray[np.bool_], b: NDArray[np.bool_]) -> float:
    """Intersection over union of two masks of one size (1 for two empty masks)."""
    a, b = np.asarray(a, bool), np.asarray(b, bool)
    if a.shape != b.shape:
        raise ValueError(f"masks of different sizes: {a.shape} and {b.shape}")
    union = int(np.count_nonzero(a | b))
    return 1.0 if union == 0 else int(np.count_nonzero(a & b)) / union


def outline_rank(name: str, shortlist: Sequence[QueryMatch]) -> int | None:
    """The rank of object ``name`` in the search's shortlist (None: not on it)."""
    for m in shortlist:
        if m.object == name:
            return m.rank
    return None


def cause_of(twin: bool, mask_iou: float, rank_in_shortlist: int | None, min_iou: float) -> str:
    """A miss's cause (module doc)."""
    if twin:
        return "twin"
    if mask_iou < min_iou:
        return "segmentation"
    if rank_in_shortlist is None:
        return "recall"
    return "re-ranking"


@dataclass(frozen=True)
class Miss:
    """One photo whose right object was not first, and what the query saw."""

    seed: int
    index: int
    #: The right object and what won.
    object: str
    winner: str
    cause: str
    #: IoU of the automatic mask with the true silhouette (holes filled).
    iou: float
    #: The right object's rank in the final answer (None: not in it).
    rank: int | None
    #: Its rank on the search's shortlist by outline alone (None: not on it).
    outline_rank: int | None
    #: Outline distances (best over the in-plane turns) of the right object (from its
    #: nearest stored view when it is not on the shortlist) and of the winner.
    distance: float
    winner_distance: float
    #: Final scores (outline distance lengthened by the re-rankings; None: the right object
    #: was not re-ranked, being outside the re-ranked pool).
    score: float | None
    winner_score: float
    #: Colour distances and shape fits (None where not measured).
    colour: float | None
    winner_colour: float | None
    fit: float | None
    winner_fit: float | None
    #: Twin distance of the two meshes (:mod:`viewdb.bench.twins`).
    twin_distance: float
    #: The right object's rank when queried with the true silhouette (None: not in the answer).
    mask_rank: int | None
