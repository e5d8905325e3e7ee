"""Colour signatures: which colours an object shows, to tell apart equal outlines.

A silhouette cannot tell an apple from a lemon, a bowl seen from below from an orange, or
two boxes of the same size. Their colours can. A *colour signature* is the object's
chromaticity histogram: each pixel's share of red and of green in its sum,
``r = R / (R + G + B)`` and ``g = G / (R + G + B)``, in
:data:`BINS` × :data:`BINS` bins over [0, 1], smoothed by one bin and normalised to sum 1.
Chromaticity does not change when light scales all three channels alike, so the light's
strength and the shading of a face matter little (pixels too dark to have a colour are
left out); the pixels next to the outline are left out too, since they mix the object
with the background.

The query engine re-ranks its results by their outline distance times
``1 + COLOUR_WEIGHT * colour distance`` (:func:`reranked_score`), where the colour
distance is the Bhattacharyya distance between the photo's signature and that of the
result's matched view, stored with the view's appearance at ingest
(:mod:`viewdb.catalogue.appearance`, where :func:`colour_signature` lives) or rendered from
the mesh for a view without one (0 = the same colours, 1 = none shared); for a mirrored
match, the view from the opposite side, the side the photo shows
(:func:`viewdb.recognition.verify.physical_view`).
A photo without colour (greyscale, or every pixel nearly neutral: :func:`has_colour`)
is not re-ranked. A mesh whose file gives no colour (no texture, no vertex or face
colours, only a neutral grey material: :func:`carries_colour`) has no signature: a grey
render says nothing about the real object's paint, so such a result counts as mismatched
as the pool's others on average (:func:`rerank`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from ..catalogue.appearance import BINS, carries_colour, colour_signature
from ..catalogue.features import mask_box

__all__ = [
    "BINS", "COLOUR_WEIGHT", "carries_colour", "colour_distance", "colour_signature", "core_signature",
    "has_colour", "reranked_score", "rerank", "rerank_by_colour",
]

#: How much a full colour mismatch (distance 1) lengthens the outline distance: × (1 + w).
COLOUR_WEIGHT = 1.0
#: A photo has colour when at least this share of its pixels are at least
#: :data:`CHROMA_MIN` away from neutral grey in the a*b* plane.
COLOURED_SHARE = 0.01
CHROMA_MIN = 12.0
#: :func:`has_colour` reads about this many pixels of a larger photo, evenly spread.
HAS_COLOUR_PIXELS = 1 << 20
#: A cut-out's core must keep at least this many pixels, else its whole mask is used.
CORE_MIN_PIXELS = 50


def colour_distance(a: NDArray[np.float32], b: NDArray[np.float32]) -> float:
    """Bhattacharyya distance of two signatures: 0 for equal ones, 1 for disjoint or empty."""
    if not a.any() or not b.any():
        return 1.0
    return float(np.clip(cv2.compareHist(a, b, cv2.HISTCMP_BHATTACHARYYA), 0.0, 1.0))


def core_signature(rgb: NDArray[np.uint8], mask: NDArray[np.bool_], share: float) -> NDArray[np.float32]:
    """The :func:`colour_signature` of a cut-out's core: ``mask`` eroded (a disc) by
    ``share`` × the square root of its area, so the rim where a cut in clutter takes in
    its neighbours counts for nothing; the whole mask when the core would keep fewer than
    :data:`CORE_MIN_PIXELS` pixels, or ``share`` is 0."""
    mask = np.asarray(mask, bool)
    radius = int(round(share * math.sqrt(np.count_nonzero(mask))))
    box = mask_box(mask, radius + 2)  # what the erosions see, not the whole photo
    if box is not None:
        rgb, mask = rgb[box], mask[box]
    if radius > 0:
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
        core = cv2.erode(mask.astype(np.uint8), disc).astype(bool)
        if np.count_nonzero(core) >= CORE_MIN_PIXELS:
            mask = core
    return colour_signature(rgb, mask)


def has_colour(rgb: NDArray[np.uint8]) -> bool:
    """Whether the image shows any colour (not greyscale or nearly so)."""
    if rgb.ndim != 3 or rgb.shape[2] < 3:
        return False
    # a share of pixels: every step-th row and column of a large photo tells it as well
    step = max(1, math.ceil(math.sqrt(rgb.shape[0] * rgb.shape[1] / HAS_COLOUR_PIXELS)))
    lab = cv2.cvtColor(np.ascontiguousarray(rgb[::step, ::step, :3]), cv2.COLOR_RGB2LAB).astype(np.float32)
    chroma = np.hypot(lab[:, :, 1] - 128.0, lab[:, :, 2] - 128.0)
    return float(np.mean(chroma >= CHROMA_MIN)) >= COLOURED_SHARE


def reranked_score(distance: float, colour: float, weight: float = COLOUR_WEIGHT) -> float:
    """The outline distance lengthened by the colour mismatch: ``d × (1 + weight × colour)``."""
    return distance * (1.0 + weight * colour)


def rerank(
    distances: Sequence[float], query: NDArray[np.float32],
    signatures: Sequence[NDArray[np.float32] | None], weight: float = COLOUR_WEIGHT,
) -> tuple[list[int], list[float | None], list[float]]:
    """The order of results (indices) by score, ties kept in the given order; each one's
    colour distance (None: its mesh has no colour) and score (:func:`reranked_score`). A
    result without a signature is scored with the mean colour distance of those with one;
    when none has one the scores are the distances."""
    colours = [None if s is None else colour_distance(query, s) for s in signatures]
    order, scores = rerank_by_colour(distances, colours, weight)
    return order, colours, scores


def rerank_by_colour(
    distances: Sequence[float], colours: Sequence[float | None], weight: float = COLOUR_WEIGHT,
) -> tuple[list[int], list[float]]:
    """:func:`rerank` from colour distances already measured: the order and the scores."""
    known = [c for c in colours if c is not None]
    neutral = float(np.mean(known)) if known else 0.0
    scores = [reranked_score(d, neutral if c is None else c, weight)
              for d, c in zip(distances, colours, strict=True)]
    order = sorted(range(len(distances)), key=lambda i: (scores[i], i))
    return order, scores
