"""Internal edges for the shape pose: Canny edges inside the query's silhouette and inside
a candidate's shaded render, compared under an outline alignment by a symmetric oriented
chamfer distance (:meth:`QueryDetail.cost`). They tell apart poses whose outlines agree
(a chair from the front and from the back)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from ..catalogue.appearance import edge_interior, grey_of, internal_edges, margin_pixels
from ..config import PoseConfig
from ..errors import PoseError
from .views import CandidateView

__all__ = ["QueryDetail", "ViewDetail", "view_detail"]


@dataclass(frozen=True, eq=False)
class _Detail:
    """Internal edges of an image (a window of it): the edge pixels ``(x, y)`` with their
    directions (gradient angle modulo π, y down), and per pixel whether it is inside the
    silhouette away from its outline, the distance to the nearest edge pixel and that
    pixel's direction."""

    points: NDArray[np.float64]
    theta: NDArray[np.float64]
    interior: NDArray[np.bool_]
    distance: NDArray[np.float32]
    nearest_theta: NDArray[np.float32]


def _with_distances(ys: NDArray[np.intp], xs: NDArray[np.intp], theta: NDArray[np.float64],
                    interior: NDArray[np.bool_]) -> _Detail:
    """A :class:`_Detail` of edge pixels at rows ``ys``, columns ``xs`` (row-major order,
    as distanceTransformWithLabels numbers them) of a window with ``interior``."""
    if len(xs) == 0:
        far = np.full(interior.shape, np.inf, np.float32)
        return _Detail(np.zeros((0, 2)), np.zeros(0), interior, far, np.zeros(interior.shape, np.float32))
    edges = np.full(interior.shape, 255, np.uint8)
    edges[ys, xs] = 0
    distance, labels = cv2.distanceTransformWithLabels(edges, cv2.DIST_L2, 5,
                                                       labelType=cv2.DIST_LABEL_PIXEL)
    nearest = theta.astype(np.float32)[labels - 1]
    return _Detail(np.stack([xs, ys], axis=1).astype(np.float64), theta, interior,
                   np.asarray(distance, dtype=np.float32), nearest)


def _detail(grey: NDArray[np.uint8], mask: NDArray[np.uint8], image_size: int, config: PoseConfig) -> _Detail:
    """Canny edges of ``grey`` inside ``mask`` eroded by ``config.edge_margin`` of
    ``image_size`` (the outline's own edges are left to the outline distance;
    :func:`viewdb.catalogue.appearance.internal_edges`)."""
    interior = edge_interior(mask, margin_pixels(config.edge_margin, image_size))
    ys, xs, theta = internal_edges(grey, interior, config.edge_thresholds)
    return _with_distances(ys, xs, theta, interior)


def _lookup(
    detail: _Detail, pts: NDArray[np.float64]
) -> tuple[NDArray[np.bool_], NDArray[np.intp], NDArray[np.intp]]:
    """Which points (n, 2) fall inside ``detail``'s interior, and their nearest pixels."""
    h, w = detail.interior.shape
    x, y = np.rint(pts[:, 0]).astype(np.intp), np.rint(pts[:, 1]).astype(np.intp)
    ok = (x >= 0) & (x < w) & (y >= 0) & (y < h)
    x, y = np.where(ok, x, 0), np.where(ok, y, 0)
    return ok & detail.interior[y, x], x, y


@dataclass(frozen=True, eq=False)
class ViewDetail:
    detail: _Detail
    #: The window's top-left corner in the view (x, y).
    corner: NDArray[np.float64]
    #: sqrt of the view's silhouette area, in its pixels.
    norm: float


def view_detail(cand: CandidateView, area: float, config: PoseConfig) -> ViewDetail | None:
    """The candidate's internal edges, in a window around its silhouette (padded by the
    truncation distance, so query edges near its border still find theirs): found in its
    shaded render, or read from its stored appearance (found in the same render at ingest,
    directions quantised; :mod:`viewdb.catalogue.appearance`). None without either."""
    if cand.color is None and cand.appearance is None:
        return None
    mask = np.asarray(cand.mask, dtype=bool)
    norm = math.sqrt(area)
    pad = int(math.ceil(config.detail_truncation * norm)) + 2
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    y0, x0 = max(0, int(rows[0]) - pad), max(0, int(cols[0]) - pad)
    y1, x1 = min(mask.shape[0], int(rows[-1]) + 1 + pad), min(mask.shape[1], int(cols[-1]) + 1 + pad)
    window = np.ascontiguousarray(mask[y0:y1, x0:x1].astype(np.uint8))
    if cand.color is None:
        assert cand.appearance is not None
        stored = cand.appearance
        interior = edge_interior(window, margin_pixels(config.edge_margin, cand.image_size))
        xs = stored.edge_points[:, 0].astype(np.intp) - x0
        ys = stored.edge_points[:, 1].astype(np.intp) - y0
        keep = interior[ys, xs]  # a wider margin than the stored edges' leaves some out
        detail = _with_distances(ys[keep], xs[keep], stored.theta()[keep], interior)
        return ViewDetail(detail, np.array([x0, y0], np.float64), norm)
    color = np.asarray(cand.color)
    if color.dtype != np.uint8 or color.shape[:2] != mask.shape or color.ndim not in (2, 3):
        raise PoseError(f"candidate ({cand.azimuth}, {cand.elevation}): colour {color.dtype} "
                        f"{color.shape} is not uint8 RGB or grey of its mask's size {mask.shape}")
    detail = _detail(np.ascontiguousarray(grey_of(color)[y0:y1, x0:x1]), window, cand.image_size, config)
    return ViewDetail(detail, np.array([x0, y0], np.float64), norm)


class QueryDetail:
    """The query's internal edges, cropped to the object, at the levels of an image
    pyramid: a view of scale ``lam`` (query pixels per view pixel) is compared with the
    level nearest its resolution, so edges are found at about the same scale in both."""

    def __init__(self, color: NDArray[np.uint8], mask: NDArray[np.bool_], area: float,
                 config: PoseConfig) -> None:
        self.config = config
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        y0, x0 = max(0, int(rows[0]) - 4), max(0, int(cols[0]) - 4)
        y1, x1 = int(rows[-1]) + 5, int(cols[-1]) + 5
        self.offset = np.array([x0, y0], np.float64)
        grey = np.ascontiguousarray(grey_of(color)[y0:y1, x0:x1])
        m = np.ascontiguousarray(mask[y0:y1, x0:x1].astype(np.uint8) * 255)
        self.levels = [(grey, m)]
        while min(grey.shape) >= 32 and len(self.levels) < 8:
            grey = np.asarray(cv2.pyrDown(grey), dtype=np.uint8)
            m = np.asarray(cv2.pyrDown(m), dtype=np.uint8)
            self.levels.append((grey, np.where(m > 127, 255, 0).astype(np.uint8)))
        self._details: dict[tuple[int, int], _Detail] = {}
        # is there any detail inside, at about the resolution of a 256-pixel view?
        k = int(np.clip(round(math.log2(max(math.sqrt(area) / 128.0, 1.0))), 0, len(self.levels) - 1))
        self.active = len(self.level(k, 256).points) >= config.min_detail_edges * math.sqrt(area) / 2**k

    def level(self, k: int, image_size: int) -> _Detail:
        if (k, image_size) not in self._details:
            self._details[k, image_size] = _detail(*self.levels[k], image_size, self.config)
        return self._details[k, image_size]

    def cost(self, similarity: NDArray[np.float64], lam: float, angle: float, cand: CandidateView,
             view: ViewDetail) -> float:
        """Symmetric oriented chamfer distance between the query's internal edges and the
        view's under an outline alignment (``similarity``, the 2×3 map of view pixels to
        query pixels, of scale ``lam`` turned by ``angle`` degrees counter-clockwise on
        screen), where both interiors overlap, over the view's sqrt(area): each edge pixel
        costs ``(1 − o) · min(d, τ) + o · τ · Δθ / 90°`` for the distance ``d`` (view pixels)
        to the nearest edge pixel of the other image and their difference in direction
        ``Δθ`` (90° when ``d ≥ τ``: no match), with ``o = detail_orientation`` and
        ``τ = detail_truncation · sqrt(area)``; so an edge pixel costs at most ``τ``, and an
        image without edges there costs ``τ``."""
        truncation, orientation = self.config.detail_truncation, self.config.detail_orientation
        k = int(np.clip(round(math.log2(lam)), 0, len(self.levels) - 1))
        f = 2.0**k
        query = self.level(k, cand.image_size)
        # view window pixels -> level-k pixels of the query crop
        a = similarity.copy()
        a[:, 2] += a[:, :2] @ view.corner - self.offset
        a /= f
        a[:, 2] += 0.5 / f - 0.5  # pyrDown keeps pixel centres at 2^k (x + 1/2) - 1/2
        inv = cv2.invertAffineTransform(a)
        per_view_px = lam / f
        turn = math.radians(angle)  # a view direction θ is θ − turn in the query
        tau = truncation * view.norm

        def directed(d: NDArray[np.floating], dtheta: NDArray[np.float64]) -> float:
            if len(d) == 0:
                return tau
            dtheta = np.mod(dtheta, np.pi)
            dtheta = np.where(d < tau, np.minimum(dtheta, np.pi - dtheta), np.pi / 2)
            return float(((1.0 - orientation) * np.minimum(d, tau)
                          + orientation * tau * dtheta / (np.pi / 2)).mean())

        v = view.detail
        inside, x, y = _lookup(query, v.points @ a[:, :2].T + a[:, 2])
        to_query = directed(query.distance[y, x][inside] / per_view_px,
                            v.theta[inside] - turn - query.nearest_theta[y, x][inside])
        inside, x, y = _lookup(v, query.points @ inv[:, :2].T + inv[:, 2])
        to_view = directed(v.distance[y, x][inside].astype(np.float64),
                           query.theta[inside] + turn - v.nearest_theta[y, x][inside])
        return (to_query + to_view) / 2.0 / view.norm
