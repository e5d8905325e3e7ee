"""Scan conversion with a depth buffer: which triangle each pixel shows (the overlay's
face-index image, :mod:`viewdb.recognition.overlay`).

A pixel shows the nearest triangle whose projection holds its centre (pixel centres on
integers). A centre on a triangle's right or bottom edge is left to its neighbour (a
GPU's rule): row ``y`` is crossed where ``y_min <= y < y_max``, and in it the pixels
``left <= x < right``, the corners first put on a GPU's sub-pixel grid
(:data:`viewdb.catalogue.coverage.SUBPIXELS`). Depth is linear across a triangle's
projection (the plane ``a·x + b·y + c`` through its corners); between equally near
triangles the later one wins.

The loops run in a numba kernel (compiled once, cached on disk, ``nogil``); the
vectorised set-up (which triangles can show, their planes) stays in NumPy.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..catalogue.coverage import snapped
from ..jit import njit

__all__ = ["face_ids"]


def face_ids(tri: NDArray[np.float64], planes: NDArray[np.float64], faces: NDArray[np.int64],
             shape: tuple[int, int]) -> NDArray[np.int32]:
    """The index (from ``faces``) of the triangle seen at each pixel of an image of
    ``shape`` (−1: none). ``tri`` (n, 3, 2): the corners ``(x, y)`` in pixels;
    ``planes`` (n, 3): ``(a, b, c)`` with the depth ``a·x + b·y + c``; ``faces`` (n,)
    the index each triangle reports."""
    h, w = shape
    ids = np.full(h * w, -1, dtype=np.int32)
    if len(tri):
        tri = snapped(tri)  # a GPU's grid
        y0 = np.clip(np.ceil(tri[:, :, 1].min(axis=1)), 0, h).astype(np.int64)
        y1 = np.clip(np.ceil(tri[:, :, 1].max(axis=1)) - 1, -1, h - 1).astype(np.int64)
        _scan(np.ascontiguousarray(tri, dtype=np.float64), np.ascontiguousarray(planes, dtype=np.float64),
              np.ascontiguousarray(faces, dtype=np.int32), y0, y1, w, ids, np.full(h * w, np.inf))
    return ids.reshape(h, w)


@njit(cache=True, nogil=True)
def _scan(tri, planes, faces, y0, y1, w, ids, zbuf):  # pragma: no cover - compiled
    for f in range(tri.shape[0]):
        a, b, c = planes[f, 0], planes[f, 1], planes[f, 2]
        for row in range(y0[f], y1[f] + 1):
            y = float(row)
            left, right = np.inf, -np.inf
            for k in range(3):
                px, py = tri[f, k, 0], tri[f, k, 1]
                qx, qy = tri[f, (k + 1) % 3, 0], tri[f, (k + 1) % 3, 1]
                dy = qy - py
                if dy != 0 and (py - y) * (qy - y) <= 0:
                    x = px + (y - py) * (qx - px) / dy
                    left = min(left, x)
                    right = max(right, x)
            if not left <= right:
                continue
            x0 = int(min(max(np.ceil(left), 0.0), float(w)))
            x1 = int(min(max(np.ceil(right) - 1.0, -1.0), float(w - 1)))
            z0 = a * float(x0) + b * y + c
            base = row * w
            for x in range(x0, x1 + 1):
                z = z0 + a * float(x - x0)
                if z <= zbuf[base + x]:
                    zbuf[base + x] = z
                    ids[base + x] = faces[f]
