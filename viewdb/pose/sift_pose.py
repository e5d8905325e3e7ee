"""The SIFT pose: query keypoints matched to each candidate view's, each candidate's
matches proposing a pose (a RANSAC 2-D similarity refined to a scaled-orthographic pose,
or PnP with intrinsics), every proposal scored on the matches of all candidates and the
best refit on the matches it explains (:func:`viewdb.pose.estimate.estimate_pose`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from ..config import PoseConfig
from .frames import CAMERA_DISTANCE, query_normalised, query_pixels, rotation_z, view_plane, view_rotation
from .solvers import OrthographicFit, solve_orthographic, solve_pnp
from .views import CandidateView

__all__ = ["Hypothesis", "SiftQuery", "sift_pose", "sift_upscale"]


def _threshold(config: PoseConfig, fraction: float, extent: float) -> float:
    return max(config.min_threshold_px, fraction * extent)


def _match(
    query_desc: NDArray[np.float32], view_desc: NDArray[np.uint8], ratio: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Lowe-ratio matches ``(query indices, view indices)``; a view keypoint is kept once
    (its best query match), so one feature cannot vote many times."""
    if len(query_desc) == 0 or len(view_desc) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    pairs = matcher.knnMatch(query_desc, np.ascontiguousarray(view_desc, dtype=np.float32), k=2)
    best: dict[int, tuple[float, int]] = {}
    for p in pairs:
        if len(p) == 2 and p[0].distance < ratio * p[1].distance:
            m = p[0]
            if m.trainIdx not in best or m.distance < best[m.trainIdx][0]:
                best[m.trainIdx] = (m.distance, m.queryIdx)
    if not best:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    view_idx = np.fromiter(best.keys(), np.int64)
    query_idx = np.fromiter((best[int(i)][1] for i in view_idx), np.int64)
    return query_idx, view_idx


@dataclass(frozen=True, eq=False)
class Hypothesis:
    """A pose proposed by one candidate's matches (rotation and translation in the result's
    frame: viewdb for orthographic, opencv for PnP)."""

    candidate: int
    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    scale: float
    #: The candidate's own matches that the pose explains, and their share (tie-break).
    own_inliers: int
    own_ratio: float


class SiftQuery:
    """The query's keypoints and what projecting model points into it takes."""

    def __init__(
        self, keypoints: NDArray[np.float32], width: int, height: int,
        k_matrix: NDArray[np.float64] | None,
    ) -> None:
        self.px = keypoints[:, :2].astype(np.float64)
        self.width, self.height = width, height
        self.norm = query_normalised(self.px, width, height)
        self.k = k_matrix

    def project(self, hyp: Hypothesis, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Query pixels of model points under ``hyp`` (inf behind a pinhole camera)."""
        r, t = hyp.rotation, hyp.translation
        if self.k is None:
            return query_pixels(hyp.scale * (points @ r[:2].T + t[:2]), self.width, self.height)
        cam = points @ r.T + t
        z = np.where(cam[:, 2] > 1e-9, cam[:, 2], np.nan)
        out = np.stack([self.k[0, 0] * cam[:, 0] / z + self.k[0, 2],
                        self.k[1, 1] * cam[:, 1] / z + self.k[1, 2]], axis=1)
        return np.where(np.isfinite(out), out, np.inf)


def _hypothesis(
    index: int, cand: CandidateView, query: SiftQuery, qi: NDArray[np.int64], vi: NDArray[np.int64],
    sim_thr: float, pose_thr: float, config: PoseConfig,
) -> Hypothesis | None:
    """The pose one candidate's matches give (None if they give none)."""
    points = cand.points3d[vi].astype(np.float64)
    if query.k is not None:
        fit = solve_pnp(query.px[qi], points, (query.k[0, 0], query.k[1, 1], query.k[0, 2],
                                               query.k[1, 2]), pose_thr)
        if fit is None or not fit.translation[2] > 0 or len(fit.inliers) < 4:
            return None
        scale = 2.0 * query.k[0, 0] / (query.width * float(fit.translation[2]))
        return Hypothesis(index, fit.rotation, fit.translation, scale, len(fit.inliers),
                           len(fit.inliers) / len(qi))
    px = query.width / 2.0  # query pixels per normalised unit
    src = view_plane(cand.keypoints[vi, :2], cand.image_size, cand.xmag)
    dst = query.norm[qi]
    m, mask = cv2.estimateAffinePartial2D(
        src.astype(np.float32), dst.astype(np.float32), method=cv2.RANSAC,
        ransacReprojThreshold=sim_thr / px, maxIters=2000, confidence=0.995,
    )
    if m is None or mask is None or int(mask.sum()) < 3:
        return None
    a, b = float(m[0, 0]), float(m[1, 0])
    scale = math.hypot(a, b)
    if not scale > 0:
        return None
    alpha = math.degrees(math.atan2(b, a))
    r0 = rotation_z(alpha) @ view_rotation(cand.azimuth, cand.elevation)
    ortho = OrthographicFit(r0, scale, m[:, 2].astype(np.float64), np.flatnonzero(mask.ravel()))
    if config.refine:
        ortho = solve_orthographic(dst, points, ortho, pose_thr / px)
    t = np.array([ortho.offset[0] / ortho.scale, ortho.offset[1] / ortho.scale, -CAMERA_DISTANCE])
    return Hypothesis(index, ortho.rotation, t, ortho.scale, len(ortho.inliers), len(ortho.inliers) / len(qi))


def _support(
    hyp: Hypothesis, query: SiftQuery, pool_q: NDArray[np.int64], pool_x: NDArray[np.float64],
    threshold: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The query keypoints ``hyp`` explains (some match of theirs, in any candidate, lands
    within ``threshold`` pixels) and, for each, the pooled match that lands nearest."""
    err = np.linalg.norm(query.project(hyp, pool_x) - query.px[pool_q], axis=1)
    ok = np.flatnonzero(err <= threshold)
    if len(ok) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = ok[np.lexsort((err[ok], pool_q[ok]))]
    first = np.ones(len(order), bool)
    first[1:] = pool_q[order][1:] != pool_q[order][:-1]
    chosen = order[first]
    return pool_q[chosen], chosen


def _refine_pooled(
    hyp: Hypothesis, query: SiftQuery, q_idx: NDArray[np.int64], points: NDArray[np.float64],
    threshold: float,
) -> Hypothesis:
    """Refit ``hyp`` on the pooled correspondences it explains."""
    if query.k is not None:
        if len(q_idx) < 4:
            return hyp
        rvec, _ = cv2.Rodrigues(hyp.rotation)
        try:
            rvec, tvec = cv2.solvePnPRefineLM(
                np.ascontiguousarray(points.reshape(-1, 1, 3)),
                np.ascontiguousarray(query.px[q_idx].reshape(-1, 1, 2)), query.k, None,
                rvec, hyp.translation.reshape(3, 1).copy(),
            )
        except cv2.error:
            return hyp
        t = tvec.reshape(3).astype(np.float64)
        if not t[2] > 0:
            return hyp
        rot, _ = cv2.Rodrigues(rvec)
        scale = 2.0 * query.k[0, 0] / (query.width * float(t[2]))
        return Hypothesis(hyp.candidate, np.asarray(rot, dtype=np.float64), t, scale, hyp.own_inliers,
                          hyp.own_ratio)
    px = query.width / 2.0
    start = OrthographicFit(hyp.rotation, hyp.scale, hyp.scale * hyp.translation[:2],
                            np.arange(len(q_idx)))
    fit = solve_orthographic(query.norm[q_idx], points, start, threshold / px, rounds=1)
    t = np.array([fit.offset[0] / fit.scale, fit.offset[1] / fit.scale, -CAMERA_DISTANCE])
    return Hypothesis(hyp.candidate, fit.rotation, t, fit.scale, hyp.own_inliers, hyp.own_ratio)


def sift_pose(
    query: SiftQuery, descriptors: NDArray[np.uint8], candidates: Sequence[CandidateView],
    extent: float, config: PoseConfig,
) -> tuple[Hypothesis, int, float] | None:
    """The best SIFT pose, its support (query keypoints explained) and its inlier ratio."""
    sim_thr = _threshold(config, config.similarity_threshold, extent)
    pose_thr = _threshold(config, config.pose_threshold, extent)
    pooled = config.refine or query.k is not None
    q_desc = descriptors.astype(np.float32)
    hyps: list[Hypothesis] = []
    pool_q: list[NDArray[np.int64]] = []
    pool_x: list[NDArray[np.float64]] = []
    for index, cand in enumerate(candidates):
        qi, vi = _match(q_desc, cand.descriptors, config.ratio)
        if len(qi) == 0:
            continue
        pool_q.append(qi)
        pool_x.append(cand.points3d[vi].astype(np.float64))
        if len(qi) >= config.min_hypothesis_matches:
            hyp = _hypothesis(index, cand, query, qi, vi, sim_thr, pose_thr, config)
            if hyp is not None:
                hyps.append(hyp)
    if not hyps:
        return None
    if not pooled:  # the grid-view similarity alone: rank by the candidate's own inliers
        best = max(hyps, key=lambda h: (h.own_inliers, h.own_ratio))
        return best, best.own_inliers, best.own_ratio
    all_q, all_x = np.concatenate(pool_q), np.concatenate(pool_x)
    matched = len(np.unique(all_q))

    def rank(h: Hypothesis) -> tuple[int, float]:
        return len(_support(h, query, all_q, all_x, pose_thr)[0]), h.own_ratio

    hyps.sort(key=rank, reverse=True)
    best, best_rank = hyps[0], rank(hyps[0])
    for hyp in hyps[:config.refined_hypotheses]:
        current = rank(hyp)
        for _ in range(config.pooled_rounds):
            q_idx, chosen = _support(hyp, query, all_q, all_x, pose_thr)
            refined = _refine_pooled(hyp, query, q_idx, all_x[chosen], pose_thr)
            refined_rank = rank(refined)
            if refined_rank[0] < current[0]:
                break
            improved = refined_rank[0] > current[0]
            hyp, current = refined, refined_rank
            if not improved:
                break
        if current > best_rank:
            best, best_rank = hyp, current
    return best, best_rank[0], best_rank[0] / matched


def sift_upscale(extent: float, candidates: Sequence[CandidateView], config: PoseConfig) -> float:
    """How much to enlarge the query before SIFT so that its object is about as large as
    in the candidate views (a photo's object often spans a fraction of the views' size,
    and SIFT then finds few keypoints that match); only when it is at least
    ``config.min_sift_upscale`` times smaller, by at most ``config.max_sift_upscale``."""
    sizes = []
    for c in candidates:
        rows, cols = np.flatnonzero(c.mask.any(axis=1)), np.flatnonzero(c.mask.any(axis=0))
        if len(rows):
            sizes.append(max(rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1))
    if not sizes or extent <= 0:
        return 1.0
    ratio = float(np.median(sizes)) / extent
    # about the views' size already: as it is (interpolation only adds edge keypoints)
    return 1.0 if ratio < config.min_sift_upscale else min(ratio, config.max_sift_upscale)
