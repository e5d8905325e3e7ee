"""What the R-trees index: the Fourier coordinates of views, grouped per object.

Following the paper's Fig. 4, each object's views sit under *that object's* MBRs and the
R-tree groups those MBRs. One MBR around all of an object's views is loose (its views
spread over much of the space, so nearly every object would be opened by a search);
instead the views of one object are split into small **groups** of nearby points (a k-d
split: halve the widest coordinate at its median until a group holds at most
``group_views`` views), and each group's MBR is an R-tree entry. A group never mixes
objects, so a search that reaches a group knows its object.

A **tier** is a set of views: ``full`` is every stored view (the server grid), ``sparse``
the views that stand for the client grid (:func:`tier_views`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from ..catalogue.skimming import skim_plan
from ..catalogue.symmetry import SymmetryType
from .bounds import fourier_coordinates

__all__ = [
    "DIMENSION",
    "INDEXED_COEFFICIENTS",
    "MBR_PADDING",
    "group_points",
    "indexed_coordinates",
    "padded_mbr",
    "tier_members",
    "tier_views",
]

#: Fourier coefficients indexed: X_1..X_3 (X_0 is the curve's mean, always 1).
INDEXED_COEFFICIENTS = (1, 2, 3)
#: R-tree dimension: real and imaginary parts of the indexed coefficients.
DIMENSION = 2 * len(INDEXED_COEFFICIENTS)
#: Every stored MBR is widened by this much (absolute) on each side, so a point computed
#: again at query time (another BLAS path, last-bit differences) still lies inside it.
MBR_PADDING = 1e-9

_projections: dict[int, NDArray[np.float64]] = {}


def _projection(n: int) -> NDArray[np.float64]:
    """Rows of the orthonormal DFT matrix giving the indexed coordinates, (DIMENSION, n)."""
    p = _projections.get(n)
    if p is None:
        m = max(INDEXED_COEFFICIENTS) + 1
        full = fourier_coordinates(m, n)
        rows = [k for k in INDEXED_COEFFICIENTS] + [m + k for k in INDEXED_COEFFICIENTS]
        p = _projections[n] = np.ascontiguousarray(full[rows])
    return p


def indexed_coordinates(curves: NDArray[np.floating]) -> NDArray[np.float64]:
    """The indexed Fourier coordinates of curves (n, N) → (n, DIMENSION), float64."""
    c = np.asarray(curves, dtype=np.float64)
    if c.ndim == 1:
        c = c[None, :]
    return c @ _projection(c.shape[1]).T


def indexed_rows(m: int) -> NDArray[np.int64]:
    """Positions of the indexed coordinates in a ``2m`` Fourier coordinate vector."""
    return np.array([k for k in INDEXED_COEFFICIENTS] + [m + k for k in INDEXED_COEFFICIENTS])


def padded_mbr(points: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The MBR of ``points`` (n, d), widened by :data:`MBR_PADDING`."""
    return points.min(axis=0) - MBR_PADDING, points.max(axis=0) + MBR_PADDING


def group_points(points: NDArray[np.float64], group_views: int) -> list[NDArray[np.int64]]:
    """Split row indices of ``points`` into groups of at most ``group_views`` close points.

    Deterministic: the widest coordinate of a group is split at its median (stable order)
    until each group is small enough. Every index appears in exactly one group.
    """
    if group_views < 1:
        raise ValueError(f"group_views must be at least 1, got {group_views}")
    pts = np.asarray(points, dtype=np.float64)
    out: list[NDArray[np.int64]] = []
    stack = [np.arange(len(pts), dtype=np.int64)] if len(pts) else []
    while stack:
        idx = stack.pop()
        if len(idx) <= group_views:
            out.append(idx)
            continue
        sub = pts[idx]
        axis = int(np.argmax(sub.max(axis=0) - sub.min(axis=0)))
        order = idx[np.argsort(sub[:, axis], kind="stable")]
        half = len(order) // 2
        stack.append(order[half:])
        stack.append(order[:half])
    return out


def tier_views(
    stored: Iterable[tuple[float, float]],
    client_gap: float,
    mapping: Mapping[tuple[float, float], tuple[tuple[float, float], bool]] | None = None,
) -> list[tuple[float, float]]:
    """The stored views that stand for the client grid of ``client_gap`` degrees.

    The client grid's rings are 0, g, 2g, ... < 360 (``g`` = ``client_gap``; when ``g``
    does not divide 360 the last step is shorter). A client-grid view is either stored
    itself or, for a skimmed object, has the same (or the mirrored) silhouette as the
    stored view ``mapping`` gives for it; searches try every curve and its mirror, so that
    stored view stands for it. Views without a silhouette are not stored and have no
    stand-in. Returned in ``stored`` order.
    """
    stored = list(stored)
    have = set(stored)
    # 0, g, 2g, ... < 360: a gap that does not divide 360 (50°) leaves a shorter last step
    steps = math.ceil(360.0 / client_gap - 1e-9)
    wanted = set()
    for i in range(steps):
        for j in range(steps):
            view = (float(i * client_gap), float(j * client_gap))
            if mapping is not None and view in mapping:
                view = mapping[view][0]
            if view in have:
                wanted.add(view)
    return [v for v in stored if v in wanted]


def tier_members(
    positions: Sequence[tuple[float, float]],
    gap: float,
    client_gap: float,
    symmetry: SymmetryType | None = None,
    skimmed: bool = False,
) -> dict[str, list[int]]:
    """Positions (indices into ``positions``, an object's stored views) of each tier's views.

    ``full`` is every stored view; ``sparse`` is :func:`tier_views` of the client grid,
    through the object's skim plan when it was skimmed.
    """
    mapping = skim_plan(symmetry, gap).mapping if skimmed and symmetry is not None else None
    sparse = set(tier_views(positions, client_gap, mapping))
    return {
        "full": list(range(len(positions))),
        "sparse": [i for i, p in enumerate(positions) if p in sparse],
    }
