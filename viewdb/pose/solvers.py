"""Pose solvers over 2-D–3-D correspondences (no matching): a robust scaled-orthographic
fit (:func:`solve_orthographic`) and pinhole PnP (:func:`solve_pnp`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from .frames import intrinsics_matrix, rodrigues, skew

__all__ = ["OrthographicFit", "PnPFit", "solve_orthographic", "solve_pnp"]


# ---------------------------------------------------------------------- orthographic pose
@dataclass(frozen=True, eq=False)
class OrthographicFit:
    """A scaled-orthographic pose: ``q = scale · (R · X)_xy + offset`` in query-normalised
    coordinates (:func:`~viewdb.pose.frames.query_normalised`); the model origin projects to ``offset``."""

    rotation: NDArray[np.float64]
    scale: float
    offset: NDArray[np.float64]
    #: Indices (into the correspondences given) within the threshold of the fit.
    inliers: NDArray[np.int64]


def solve_orthographic(
    query_points: NDArray[np.floating],
    object_points: NDArray[np.floating],
    initial: OrthographicFit,
    threshold: float,
    rounds: int = 2,
) -> OrthographicFit:
    """Refine a scaled-orthographic pose over 2-D–3-D correspondences (no matching).

    ``query_points`` (n, 2) are query-normalised coordinates (half-width units, y up),
    ``object_points`` (n, 3) model-space points, ``threshold`` the inlier tolerance in the
    same units. Starting from ``initial`` (its inliers are used first), each round fits
    ``R = exp([ω]) · R₀``, scale and offset by robust least squares (soft-L1 at the
    threshold), then takes as inliers every correspondence within the threshold. Returns
    ``initial`` unchanged when fewer than 3 inliers remain.
    """
    from scipy.optimize import least_squares  # on first use: SciPy's import is slow

    q = np.asarray(query_points, dtype=np.float64).reshape(-1, 2)
    x = np.asarray(object_points, dtype=np.float64).reshape(-1, 3)
    fit = initial
    for _ in range(max(1, rounds)):
        idx = fit.inliers
        if len(idx) < 3:
            return fit
        problem = _OrthographicProblem(q[idx], x[idx], fit.rotation, threshold)
        p0 = np.array([0.0, 0.0, 0.0, math.log(fit.scale), *fit.offset])
        sol = least_squares(problem.residuals, p0, jac=problem.jacobian, loss="soft_l1",
                            f_scale=1.0, method="trf", max_nfev=100)
        rot = rodrigues(sol.x[:3]) @ fit.rotation
        scale = math.exp(sol.x[3])
        offset = sol.x[4:6].copy()
        err = np.linalg.norm(scale * (x @ rot[:2].T) + offset - q, axis=1)
        fit = OrthographicFit(rot, scale, offset, np.flatnonzero(err <= threshold))
    return fit


def _left_jacobian(w: NDArray[np.float64]) -> NDArray[np.float64]:
    """J with d(exp([w]×)·y)/dw = −[exp([w]×)·y]× · J (the left Jacobian of SO(3))."""
    theta = float(np.linalg.norm(w))
    k = skew(w)
    if theta < 1e-6:
        return np.eye(3) + k / 2.0 + k @ k / 6.0
    return (np.eye(3) + (1.0 - math.cos(theta)) / theta**2 * k
            + (theta - math.sin(theta)) / theta**3 * (k @ k))


class _OrthographicProblem:
    """Residuals ``(s·(R·X)_xy + o − q) / threshold`` with ``R = exp([ω]×)·R₀`` over
    ``p = (ω, log s, o)``, and their exact Jacobian (scipy's least_squares)."""

    def __init__(self, q: NDArray[np.float64], x: NDArray[np.float64], r0: NDArray[np.float64],
                 threshold: float) -> None:
        self.q, self.y0, self.inv = q, x @ r0.T, 1.0 / threshold

    def residuals(self, p: NDArray[np.float64]) -> NDArray[np.float64]:
        y = self.y0 @ rodrigues(p[:3]).T
        return ((math.exp(p[3]) * y[:, :2] + p[4:6] - self.q) * self.inv).ravel()

    def jacobian(self, p: NDArray[np.float64]) -> NDArray[np.float64]:
        y = self.y0 @ rodrigues(p[:3]).T
        s = math.exp(p[3])
        n = len(y)
        zero = np.zeros(n)
        # rows x and y of −[y]× per point, then · J_l(ω)
        neg_skew = np.stack([np.stack([zero, y[:, 2], -y[:, 1]], axis=1),
                             np.stack([-y[:, 2], zero, y[:, 0]], axis=1)], axis=1)  # (n, 2, 3)
        jac = np.zeros((n, 2, 6))
        jac[:, :, :3] = s * neg_skew @ _left_jacobian(p[:3])
        jac[:, :, 3] = s * y[:, :2]
        jac[:, 0, 4] = 1.0
        jac[:, 1, 5] = 1.0
        return (jac * self.inv).reshape(2 * n, 6)



# ---------------------------------------------------------------------- PnP
@dataclass(frozen=True, eq=False)
class PnPFit:
    """A pinhole pose in the OpenCV frame: ``x_cam = R · X + t``."""

    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    #: Indices (into the correspondences given) within the threshold of the refined pose.
    inliers: NDArray[np.int64]


def solve_pnp(
    image_points: NDArray[np.floating],
    object_points: NDArray[np.floating],
    intrinsics: Sequence[float],
    threshold: float,
) -> PnPFit | None:
    """Pose from 2-D–3-D correspondences (no matching): :func:`cv2.solvePnPRansac` (EPnP
    minimal sets, tolerance ``threshold`` pixels), then Levenberg–Marquardt on the
    inliers. ``image_points`` (n, 2) are pixels (x right, y down), ``object_points``
    (n, 3) model-space points, ``intrinsics`` ``(fx, fy, cx, cy)`` without distortion.
    Returns None when fewer than 6 correspondences are given or RANSAC finds no pose.
    """
    k = intrinsics_matrix(intrinsics)
    img = np.ascontiguousarray(np.asarray(image_points, dtype=np.float64).reshape(-1, 1, 2))
    obj = np.ascontiguousarray(np.asarray(object_points, dtype=np.float64).reshape(-1, 1, 3))
    if len(img) < 6 or len(img) != len(obj):
        return None
    try:
        ok, rvec, tvec, inl = cv2.solvePnPRansac(
            obj, img, k, None, iterationsCount=500, reprojectionError=float(threshold),
            confidence=0.999, flags=cv2.SOLVEPNP_EPNP,
        )
    except cv2.error:
        return None
    if not ok or inl is None or len(inl) < 4:
        return None
    idx = inl.ravel()
    try:
        rvec, tvec = cv2.solvePnPRefineLM(obj[idx], img[idx], k, None, rvec, tvec)
    except cv2.error:
        pass
    proj, _ = cv2.projectPoints(obj, rvec, tvec, k, None)
    err = np.linalg.norm(proj.reshape(-1, 2) - img.reshape(-1, 2), axis=1)
    rot, _ = cv2.Rodrigues(rvec)
    return PnPFit(np.asarray(rot, dtype=np.float64), tvec.reshape(3).astype(np.float64),
                  np.flatnonzero(err <= threshold))
