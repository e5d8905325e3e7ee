"""Pose of a recognised object in a query image: SIFT against candidate views, or its shape.

After Tak & Hwang, section III.E: a query matched to a view of an object could be in any of
that view's candidate poses (:meth:`viewdb.ViewDB.candidate_poses`); SIFT matches between
the query and each candidate's view pick the pose, and the stored 3-D point of every view
keypoint turns the matches into 2-D–3-D correspondences that refine it off the grid.
Texture-less objects give too few keypoints; their pose comes from aligning silhouettes,
and among candidates whose silhouettes agree, from the edges inside them.

Frames and units (public contract): :mod:`viewdb.pose.frames`. The work is split by job:
:mod:`~viewdb.pose.frames` (rotations and image coordinates), :mod:`~viewdb.pose.solvers`
(orthographic and PnP fits), :mod:`~viewdb.pose.sift_pose`, :mod:`~viewdb.pose.shape_pose`
(with :mod:`~viewdb.pose.edges`); this module chooses between them.

How (see :func:`estimate_pose`): SIFT matches to every candidate view propose poses (a 2-D
similarity refined to a scaled-orthographic pose, or PnP); each proposal is scored by the
query keypoints it explains among the matches of *all* candidates (one object, one model
space); the best is refit and accepted with ``PoseConfig.min_inliers``. Otherwise the
query silhouette is aligned to each candidate's (chamfer distance) at its grid direction,
and alignments that fit about equally well are ranked by that distance plus the distance
between the internal edges (creases, shading, texture) of the query and of the candidate's
shaded render.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..catalogue.sift import extract_sift
from ..config import PoseConfig
from ..errors import PoseError
from ..typed import Intrinsics
from .frames import GL_TO_CV, intrinsics_matrix, rotation_to_view
from .shape_pose import shape_pose
from .sift_pose import SiftQuery, sift_pose, sift_upscale
from .views import CandidateView, PoseEstimate, QueryView

__all__ = ["CandidateView", "PoseConfig", "PoseEstimate", "QueryView", "estimate_pose", "sift_estimate"]


def estimate_pose(
    query: QueryView,
    candidates: Sequence[CandidateView],
    config: PoseConfig | None = None,
    intrinsics: Intrinsics | None = None,
    *,
    inplane_near: float | None = None,
) -> PoseEstimate:
    """The pose of the object in ``query``, choosing among ``candidates``.

    ``candidates`` are candidate poses of **one** object (e.g. from
    :meth:`viewdb.ViewDB.candidate_poses`): their 3-D points share one model space. To
    choose between objects, estimate once per object.

    SIFT first. The query's keypoints are matched to each candidate view's (Lowe ratio).
    Each candidate's matches propose a pose: without ``intrinsics`` a RANSAC 2-D
    similarity from the view to the query (in-plane angle, scale, shift) starts a robust
    scaled-orthographic fit over the matched 3-D points, which moves the pose off the
    grid; with ``intrinsics`` PnP RANSAC. Every proposal is scored on the matches of *all*
    candidates: its support is the number of query keypoints with a match landing within
    ``pose_threshold`` of where the pose projects that match's 3-D point (candidates of one
    object share model space, so correct matches from neighbouring views vote for the same
    pose while confusions between look-alike parts rarely agree). The best-supported
    proposals are refit on the matches they explain, and the best (ties: the larger share
    of its own candidate's matches) is accepted with at least ``config.min_inliers``.

    Otherwise the silhouettes decide: the query's outer contour is aligned to each
    candidate's by centroid, area and in-plane angle (symmetric chamfer distance; every
    angle that fits nearly as well as the best is kept, up to ``config.shape_angles``). When
    every candidate carries its shaded render (:attr:`CandidateView.color`) and the query
    has edges inside its silhouette, the alignments whose outlines fit about as well as
    the best (``config.shape_tie_ratio``) are also scored by the distance between those
    internal edges and the render's under the alignment (an oriented chamfer distance,
    weighted by ``config.detail_weight``): silhouettes that agree (a chair from the front
    and from the back, the faces of a cube) are told apart by their creases, shading and
    texture. The best alignment gives the pose at that candidate's grid direction.
    ``inplane_near`` (degrees, for refining a known pose over nearby views): the outline is
    aligned only at in-plane angles within ``config.shape_near_window`` of it, plus the fine
    search's one coarse step (the angle of
    ``R_z`` in ``rotation = R_z(angle) · view_rotation(h, v)`` of each candidate).

    Raises
    ------
    PoseError
        No candidates, an empty or malformed query, or no candidate with a silhouette.
    """
    config = config or PoseConfig()
    if len(candidates) == 0:
        raise PoseError("no candidate views to estimate a pose from")
    color, mask = _checked(query)
    k_matrix = None if intrinsics is None else intrinsics_matrix(intrinsics)
    found = sift_estimate(query, candidates, config, intrinsics)
    if found is not None:
        return found
    return shape_pose(query, color, mask, candidates, config, k_matrix, inplane_near)


def _checked(query: QueryView) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
    """The query's colour and mask, or ``PoseError`` if they are not a segmented image."""
    color = np.asarray(query.color)
    mask = np.asarray(query.mask, dtype=bool)
    if mask.ndim != 2 or color.shape[:2] != mask.shape:
        raise PoseError(f"query colour {color.shape} and mask {mask.shape} do not match")
    if color.dtype != np.uint8 or not (color.ndim == 2 or (color.ndim == 3 and color.shape[2] == 3)):
        raise PoseError(f"query colour must be uint8 RGB (H, W, 3) or grey (H, W), got "
                        f"{color.dtype} {color.shape}")
    if not mask.any():
        raise PoseError("the query mask is empty: no object to estimate a pose for")
    return color, mask


def sift_estimate(
    query: QueryView, candidates: Sequence[CandidateView], config: PoseConfig,
    intrinsics: Intrinsics | None = None,
) -> PoseEstimate | None:
    """:func:`estimate_pose`'s SIFT pose, or None when it is not accepted (fewer than
    ``config.min_inliers``, or no candidate with features)."""
    if not any(len(c.descriptors) for c in candidates):
        return None  # nothing to match (e.g. refining)
    color, mask = _checked(query)
    k_matrix = None if intrinsics is None else intrinsics_matrix(intrinsics)
    height, width = mask.shape
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    extent = float(max(rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1))
    upscale = sift_upscale(extent, candidates, config)
    keypoints, descriptors = query.derived(
        ("sift", config.max_keypoints, upscale),
        lambda: extract_sift(color, mask, config.max_keypoints, upscale))
    found = sift_pose(SiftQuery(keypoints, width, height, k_matrix), descriptors, candidates,
                      extent, config)
    if found is None or found[1] < config.min_inliers:
        return None
    hyp, support, ratio = found
    if k_matrix is None:
        h, v, a = rotation_to_view(hyp.rotation)
        frame = "viewdb"
    else:
        h, v, a = rotation_to_view(GL_TO_CV @ hyp.rotation)
        frame = "opencv"
    return PoseEstimate(h, v, a, hyp.scale, hyp.rotation, hyp.translation, "sift", support,
                        hyp.candidate, frame, ratio)
