"""The colour channel: every coloured object's stored colour signatures, ranked against a
photo's.

An object cut from a box in clutter has an uncertain outline: a strip of a neighbour, a
limb lost behind another object. Its colours survive such a cut far better than its
outline does (docs/results/real-clutter.md), so a query of a prompted object also asks
which objects' colours it shows. The index holds, for each stored view on a coarse grid
of directions of each coloured object, the square root of its normalised colour signature
(:func:`viewdb.catalogue.appearance.colour_signature`); an object's colour distance to a
photo is its nearest view's Bhattacharyya distance,
``sqrt(1 − Σ sqrt(p q))``, the same number
:func:`viewdb.recognition.colour.colour_distance` gives for the two signatures. Ranking
every object is one matrix product.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import QueryError

__all__ = ["ColourIndex", "ColourMatch", "merge_colour_matches"]


@dataclass(frozen=True)
class ColourMatch:
    """An object whose stored colours lie nearest a photo's: its nearest view's direction
    and Bhattacharyya distance (0: the same colours, 1: none shared)."""

    object: str
    distance: float
    azimuth: float
    elevation: float

    def to_dict(self) -> dict[str, Any]:
        return {"object": self.object, "distance": self.distance, "azimuth": self.azimuth,
                "elevation": self.elevation}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ColourMatch:
        return cls(str(data["object"]), float(data["distance"]), float(data["azimuth"]),
                   float(data["elevation"]))


def _roots(signatures: NDArray[np.floating]) -> NDArray[np.float64]:
    """Each row's square roots after normalising it to sum 1 (an empty row stays zero)."""
    flat = np.asarray(signatures, dtype=np.float64).reshape(len(signatures), -1)
    if np.any(flat < 0) or not np.all(np.isfinite(flat)):
        raise QueryError("a colour signature must be finite and not negative")
    sums = flat.sum(axis=1, keepdims=True)
    return np.sqrt(np.divide(flat, sums, out=np.zeros_like(flat), where=sums > 0))


class ColourIndex:
    """The stored views' colour signatures of a set of objects (module doc)."""

    def __init__(self, names: Sequence[str], views: NDArray[np.floating],
                 signatures: NDArray[np.floating]) -> None:
        """Row ``i``: object ``names[i]``'s view ``views[i]`` (azimuth, elevation) and its
        signature ``signatures[i]`` (any shape, e.g. ``BINS × BINS``)."""
        if not (len(names) == len(views) == len(signatures)):
            raise QueryError("a colour index needs one name and one view per signature")
        order = sorted(range(len(names)), key=lambda i: names[i])
        self.names = [names[i] for i in order]
        self.views = np.asarray(views, dtype=np.float64).reshape(-1, 2)[order]
        self.roots = _roots(np.asarray(signatures)[order]) if len(order) else np.zeros((0, 0))
        self.objects = sorted(set(self.names))
        starts = [i for i in range(len(self.names)) if i == 0 or self.names[i] != self.names[i - 1]]
        self._starts = np.asarray(starts, dtype=np.intp)
        self._ends = np.append(self._starts[1:], len(self.names)).astype(np.intp)

    def __len__(self) -> int:
        return len(self.names)

    def distances(self, signature: NDArray[np.floating]) -> NDArray[np.float64]:
        """Each stored view's Bhattacharyya distance to ``signature`` (1 where either is empty)."""
        if not len(self.names):
            return np.zeros(0)
        query = _roots(np.asarray(signature)[None])[0]
        if query.shape != self.roots.shape[1:]:
            raise QueryError(f"a signature of {query.size} bins; the index's have {self.roots.shape[1]}")
        overlap = self.roots @ query
        empty = ~self.roots.any(axis=1) | (not query.any())
        return np.where(empty, 1.0, np.sqrt(np.clip(1.0 - overlap, 0.0, 1.0)))

    def nearest(self, signature: NDArray[np.floating], n: int) -> list[ColourMatch]:
        """The ``n`` objects whose nearest view's colours lie nearest ``signature``, nearest
        first (ties by name), each with that view."""
        if n < 1:
            raise QueryError(f"the colour channel's n must be at least 1, got {n}")
        if not len(self.names):
            return []
        d = self.distances(signature)
        best = np.minimum.reduceat(d, self._starts)
        out = []
        for k in sorted(range(len(best)), key=lambda j: (best[j], self.objects[j]))[:n]:
            row = self._starts[k] + int(np.argmin(d[self._starts[k]:self._ends[k]]))
            out.append(ColourMatch(self.objects[k], float(best[k]), float(self.views[row, 0]),
                                   float(self.views[row, 1])))
        return out


def merge_colour_matches(parts: Sequence[Sequence[ColourMatch]], n: int) -> list[ColourMatch]:
    """The ``n`` nearest of several indexes' answers (a sharded catalogue's shards)."""
    return sorted((m for part in parts for m in part), key=lambda m: (m.distance, m.object))[:n]
