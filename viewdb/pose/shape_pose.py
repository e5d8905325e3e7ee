"""The shape pose: the query's outer contour aligned to each candidate view's (centroid,
area, in-plane angle by the symmetric chamfer distance), alignments that fit about equally
well told apart by their internal edges (:mod:`viewdb.pose.edges`); and :func:`shape_fit`,
how well one view explains the query's shape."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from ..camera import normalise_angle
from ..catalogue.features import largest_contour
from ..config import PoseConfig
from ..errors import FeatureError, PoseError
from ..jit import njit
from .edges import QueryDetail, ViewDetail, view_detail
from .frames import (
    CAMERA_DISTANCE,
    GL_TO_CV,
    angle_gap,
    query_normalised,
    rotation_to_view,
    rotation_z,
    view_rotation,
)
from .views import CandidateView, PoseEstimate, QueryView

__all__ = ["Outline", "ShapeResult", "align_shape", "candidate_outline", "outline_of", "shape_fit",
           "shape_pose"]


@dataclass(frozen=True, eq=False)
class Outline:
    """A silhouette's outer contour (pixels, y down), its area, centroid and edge distances."""

    points: NDArray[np.float64]
    area: float
    centroid: NDArray[np.float64]
    distance: NDArray[np.float32]


def outline_of(mask: NDArray[np.bool_], samples: int) -> Outline:
    poly = largest_contour(mask)  # raises FeatureError when there is no usable region
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area2 = float(cross.sum())
    centroid = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (3.0 * area2)
    # equally spaced points along the polygon
    seg = np.hypot(xn - x, yn - y)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.linspace(0.0, cum[-1], samples, endpoint=False)
    closed = np.vstack([poly, poly[:1]])
    pts = np.stack([np.interp(s, cum, closed[:, 0]), np.interp(s, cum, closed[:, 1])], axis=1)
    edges = np.full(mask.shape, 255, np.uint8)
    ring = np.rint(closed).astype(np.int32).reshape(-1, 1, 2)
    cv2.polylines(edges, [ring], isClosed=True, color=0, thickness=1)
    dist = cv2.distanceTransform(edges, cv2.DIST_L2, 5)  # within 2 % of exact, 10x faster
    return Outline(pts, abs(area2) / 2.0, centroid, np.asarray(dist, dtype=np.float32))


def candidate_outline(cand: CandidateView, samples: int) -> Outline:
    """:func:`outline_of` the candidate's silhouette; kept with its stored appearance
    record when the silhouette is the record's (a query fits the same views repeatedly)."""
    stored = cand.appearance
    if stored is not None and stored.mask is cand.mask:
        return stored.derived(("outline", samples), lambda: outline_of(stored.mask, samples))
    return outline_of(np.asarray(cand.mask, dtype=bool), samples)


def _chamfer(query: Outline, view: Outline, lam: float, angles: NDArray[np.float64]) -> NDArray[np.float64]:
    """Symmetric mean chamfer distance (query pixels) for each in-plane angle, with the view
    scaled by ``lam`` and its centroid put on the query's: the mean distance-map value of
    the query at the view's turned outline points and of the view at the query's turned
    back (both :func:`_mean_sampled`)."""
    radians = np.radians(np.asarray(angles, dtype=np.float64))
    d1 = np.empty(len(radians))
    d2 = np.empty(len(radians))
    _mean_sampled(np.ascontiguousarray(view.points - view.centroid), float(query.centroid[0]),
                  float(query.centroid[1]), lam, query.distance, radians, d1)
    _mean_sampled(np.ascontiguousarray(query.points - query.centroid), float(view.centroid[0]),
                  float(view.centroid[1]), 1.0 / lam, view.distance, -radians, d2)
    return (d1 + lam * d2) / 2.0


@njit(cache=True, nogil=True)
def _mean_sampled(points, cx, cy, scale, dist, radians, out):  # pragma: no cover - compiled
    """For each angle: the mean of ``dist`` (nearest pixel) at ``points`` (offsets, y
    down) turned counter-clockwise on screen by it, scaled by ``scale`` and placed at
    ``(cx, cy)``; a point outside the image gets the value at the nearest border pixel
    plus its distance to it."""
    h, w = dist.shape
    n = points.shape[0]
    for a in range(radians.shape[0]):
        c, s = math.cos(radians[a]), math.sin(radians[a])
        total = 0.0
        for i in range(n):
            dx, dy = points[i, 0], points[i, 1]
            x = cx + scale * (c * dx + s * dy)
            y = cy + scale * (c * dy - s * dx)
            qx = min(max(x, 0.0), w - 1.0)
            qy = min(max(y, 0.0), h - 1.0)
            total += float(dist[int(np.rint(qy)), int(np.rint(qx))]) + math.hypot(x - qx, y - qy)
        out[a] = total / n


@dataclass(frozen=True, eq=False)
class ShapeResult:
    """One in-plane alignment of a view's outline to the query's."""

    cost: float  # normalised outline chamfer
    angle: float
    lam: float  # query pixels per view pixel
    origin_px: NDArray[np.float64]  # where the model origin lands in the query
    similarity: NDArray[np.float64]  # 2×3: view pixels → query pixels


def _similarity(query: Outline, view: Outline, lam: float, angle: float) -> NDArray[np.float64]:
    """The 2×3 map of view pixels to query pixels that :func:`_chamfer` scores: the view's
    centroid onto the query's, scaled by ``lam``, turned counter-clockwise on screen."""
    t = math.radians(angle)
    c, s = math.cos(t), math.sin(t)
    rm = lam * np.array([[c, s], [-s, c]])  # y down
    return np.hstack([rm, (query.centroid - rm @ view.centroid)[:, None]])


def align_shape(
    query: Outline, view: Outline, cand: CandidateView, config: PoseConfig,
    near: float | None = None,
) -> list[ShapeResult]:
    """The in-plane alignments of a view's outline to the query's, best first: every local
    minimum of the coarse angle search within ``config.shape_angle_slack`` of the best (at
    most ``config.shape_angles``), each refined by the fine step. With ``near``, only the
    best angle within ``config.shape_near_window`` of it."""
    lam = math.sqrt(query.area / view.area)
    norm = math.sqrt(query.area)
    if near is None:
        coarse = np.arange(0.0, 360.0, config.coarse_step)
        cost = _chamfer(query, view, lam, coarse) / norm
        minima = np.flatnonzero((cost <= np.roll(cost, 1)) & (cost <= np.roll(cost, -1)))
        minima = minima[np.argsort(cost[minima], kind="stable")]
        minima = minima[cost[minima] <= cost[minima[0]] + config.shape_angle_slack]
        minima = minima[:config.shape_angles]
    else:
        half = math.floor(config.shape_near_window / config.coarse_step) * config.coarse_step
        coarse = near + np.arange(-half, half + 1e-9, config.coarse_step)
        cost = _chamfer(query, view, lam, coarse) / norm
        minima = np.array([int(np.argmin(cost))])
    # refine every minimum in one batch of angles
    steps = np.arange(-config.coarse_step, config.coarse_step + 1e-9, config.fine_step)
    fine = (coarse[minima][:, None] + steps[None, :]).ravel()
    fine_cost = (_chamfer(query, view, lam, fine) / norm).reshape(len(minima), len(steps))
    centre = np.array([cand.image_size / 2.0 - 0.5, cand.image_size / 2.0 - 0.5, 1.0])
    out: list[ShapeResult] = []
    for i in range(len(minima)):
        j = int(np.argmin(fine_cost[i]))
        angle = normalise_angle(float(fine[i * len(steps) + j]))
        if any(angle_gap(angle, r.angle) < config.coarse_step for r in out):
            continue  # a plateau's second point, or two minima refined to one
        sim = _similarity(query, view, lam, angle)
        out.append(ShapeResult(float(fine_cost[i, j]), angle, lam, sim @ centre, sim))
    out.sort(key=lambda r: r.cost)
    return out


def shape_fit(query: QueryView, view: CandidateView, config: PoseConfig | None = None) -> float:
    """How well one view explains the query's shape: the score (``1 - cost``, in [0, 1])
    of :func:`~viewdb.pose.estimate.estimate_pose`'s shape method on this view alone, i.e. its best alignment
    of the outline and, when the view carries its shaded render, of the internal edges.
    The view's SIFT features are not used. The query's outline and edges are derived once
    per :class:`QueryView`, so fitting many views to one query costs one alignment each.

    Raises
    ------
    PoseError
        The query or the view has no usable silhouette.
    """
    config = config or PoseConfig()
    mask = np.asarray(query.mask, dtype=bool)
    if not mask.any():
        raise PoseError("the query mask is empty: no shape to fit")
    return shape_pose(query, np.asarray(query.color), mask, [view], config, None).score


def shape_pose(
    query: QueryView, color: NDArray[np.uint8], mask: NDArray[np.bool_],
    candidates: Sequence[CandidateView], config: PoseConfig, k_matrix: NDArray[np.float64] | None,
    near: float | None = None,
) -> PoseEstimate:
    """The pose by the silhouettes (:func:`~viewdb.pose.estimate.estimate_pose`'s fallback):
    the best alignment of the query's outline to a candidate's, among those that fit about
    as well, the one whose internal edges fit best; ``near`` limits the in-plane angles."""
    try:
        outline = query.derived(("outline", config.contour_samples),
                                lambda: outline_of(mask, config.contour_samples))
    except FeatureError as exc:
        raise PoseError(f"the query silhouette has no usable contour: {exc}") from exc
    hyps: list[tuple[float, int, ShapeResult]] = []
    views: dict[int, Outline] = {}
    for index, cand in enumerate(candidates):
        try:
            views[index] = candidate_outline(cand, config.contour_samples)
        except FeatureError:
            continue
        hyps.extend((res.cost, index, res)
                    for res in align_shape(outline, views[index], cand, config, near))
    if not hyps:
        raise PoseError("no candidate view has a silhouette to align the query with")
    hyps.sort(key=lambda x: x[0])  # stable: ties keep the candidates' order
    use_detail = config.detail_weight > 0 and all(
        candidates[i].color is not None or candidates[i].appearance is not None for i in views)
    detail_key = ("detail", config.edge_thresholds, config.edge_margin, config.min_detail_edges,
                  config.detail_truncation, config.detail_orientation)
    query_detail = (query.derived(detail_key, lambda: QueryDetail(color, mask, outline.area, config))
                    if use_detail else None)
    if query_detail is None or not query_detail.active:
        cost, index, res = hyps[0]
    else:
        # among the alignments whose outlines fit about as well as the best, outline +
        # weighted edge distance; the edge term is >= 0, so an alignment whose outline
        # alone is already worse than the best total cannot win
        ties = hyps[0][0] * (1.0 + config.shape_tie_ratio) + config.shape_tie_margin
        details: dict[int, ViewDetail | None] = {}
        best: tuple[float, int, ShapeResult] | None = None
        for outline_cost, index, res in hyps:
            if outline_cost > ties or (best is not None and outline_cost >= best[0]):
                break
            cand = candidates[index]
            if index not in details:
                details[index] = view_detail(cand, views[index].area, config)
            found = details[index]
            assert found is not None
            edge_cost = query_detail.cost(res.similarity, res.lam, res.angle, cand, found)
            total = outline_cost + config.detail_weight * edge_cost
            if best is None or total < best[0]:
                best = (total, index, res)
        assert best is not None
        cost, index, res = best
    cand = candidates[index]
    height, width = mask.shape
    rotation = rotation_z(res.angle) @ view_rotation(cand.azimuth, cand.elevation)
    h, v, a = rotation_to_view(rotation)
    scale = res.lam * cand.image_size / (cand.xmag * width)
    score = min(1.0, max(0.0, 1.0 - cost))
    if k_matrix is None:
        offset = query_normalised(res.origin_px, width, height)[0]
        translation = np.array([offset[0] / scale, offset[1] / scale, -CAMERA_DISTANCE])
        return PoseEstimate(h, v, a, scale, rotation, translation, "shape", 0, index, "viewdb", score)
    # weak perspective: the model origin at the depth where fx pixels span scale·W/2 per unit
    fx, fy, cx, cy = k_matrix[0, 0], k_matrix[1, 1], k_matrix[0, 2], k_matrix[1, 2]
    tz = 2.0 * fx / (scale * width)
    u, w = res.origin_px
    translation = np.array([(u - cx) * tz / fx, (w - cy) * tz / fy, tz])
    return PoseEstimate(h, v, a, scale, GL_TO_CV @ rotation, translation, "shape", 0, index,
                        "opencv", score)
