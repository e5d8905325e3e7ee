"""Shape verification: re-rank the plan's best objects by how well each one's matched
view, rendered from its mesh, explains the photo's shape.

The outline distance (DTW of centroid distance curves) sees only the outline, sampled
from one point; look-alike outlines of different objects (a remote control and a
riser, a sugar box and a bathtub, a toilet and a piano from the side) come within the
grid's discretisation of each other, and then the wrong one is often first while the
right one is in the top few. What is *inside* the outline tells them apart.

So the query engine renders each of its best objects' matched view (for a match of the
mirrored curve, the view from the opposite side: an orthographic silhouette seen from
behind is the mirror image, :func:`physical_view`) and fits it to the photo as the
pose's shape method does (:func:`viewdb.pose.shape_pose.shape_fit`: the outline aligned by
centroid, area and in-plane angle, then the internal edges — creases, shading, texture
— compared under that alignment; a fit in [0, 1]). The results are ranked by

    score × (1 + SHAPE_WEIGHT × (1 − fit))

where ``score`` is the outline distance, or the colour re-ranked score
(:mod:`viewdb.recognition.colour`) when there was one. The fit alone ranks worse than the outline
distance (the views are on a grid, the photo is not); the product keeps the outline's
order among equally fitting objects and lets a much better fit overtake a slightly
closer outline.
"""

from __future__ import annotations

from collections.abc import Sequence

from ..camera import normalise_angle
from ..search.plans import Candidate

__all__ = ["SHAPE_WEIGHT", "physical_view", "rerank_by_fit", "verified_score"]

#: How much a complete misfit (fit 0) lengthens the score: × (1 + w). Chosen on the
#: synthetic photos of ``benchmarks/photo_accuracy.py`` (seeds 1–4), confirmed on unseen
#: ones (seeds 5–6); see the README's results.
SHAPE_WEIGHT = 8.0


def physical_view(match: Candidate) -> tuple[float, float]:
    """The grid direction ``(azimuth, elevation)`` whose orthographic view shows the
    silhouette ``match`` matched: its own, or for a mirrored match the opposite one
    (``(h + 180°, −v)``: seen from behind, an orthographic silhouette is mirrored left to
    right). A perspective match is fitted by the orthographic view of its direction."""
    if not match.mirrored:
        return match.azimuth, match.elevation
    return normalise_angle(match.azimuth + 180.0), normalise_angle(-match.elevation)


def verified_score(score: float, fit: float | None, weight: float = SHAPE_WEIGHT) -> float:
    """``score × (1 + weight × (1 − fit))``; no fit (the view has no silhouette to fit)
    counts as a complete misfit."""
    return score * (1.0 + weight * (1.0 - (0.0 if fit is None else fit)))


def rerank_by_fit(
    scores: Sequence[float], fits: Sequence[float | None], weight: float = SHAPE_WEIGHT
) -> tuple[list[int], list[float]]:
    """The order of results (indices) by :func:`verified_score`, ties kept in the given
    order, and each one's verified score."""
    verified = [verified_score(s, f, weight) for s, f in zip(scores, fits, strict=True)]
    order = sorted(range(len(verified)), key=lambda i: (verified[i], i))
    return order, verified
