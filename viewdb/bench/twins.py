"""Twins: two objects of a catalogue with near-identical meshes.

No silhouette tells twins apart, so a photo of one recognised as the other is not a
recognition error but an ambiguity of the catalogue (and colour tells them apart only when
their paint differs). Two meshes are compared by their shapes alone, whatever their files'
frames (one may be Y-up and the other Z-up, mirrored, or scaled):

1. each mesh is sampled at :attr:`~viewdb.bench.config.TwinConfig.samples` random surface
   points, centred on their mean, scaled to a root-mean-square radius of 1 and turned to
   their principal axes (:func:`shape_cloud`);
2. the two clouds are aligned by each of the 48 signed permutations of those axes (the
   principal axes are defined up to sign and, for equal extents, order; reflections
   included, since a mirrored object shows mirrored silhouettes, which the search matches
   too); the best few alignments are refined by ICP (rigid, reflection kept);
3. the *twin distance* is the smallest symmetric chamfer distance over the alignments: the
   mean distance from each of a few of one cloud's points (``probes``) to the other's dense
   cloud, a stand-in for its surface, averaged both ways, in units of the RMS radius
   (:func:`twin_distance`).

Objects are twins when their twin distance is at most
:attr:`~viewdb.bench.config.TwinConfig.threshold` (a few per cent of the radius: the
sampling's own noise between two samplings of one mesh is about 0.02).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ..catalogue.mesh import NormalisedMesh
from .config import TwinConfig

__all__ = ["Twins", "rigid_alignment", "shape_cloud", "twin_distance"]

#: The 48 signed permutations of three axes (rotations and reflections of a box's frame).
AXIS_FRAMES = np.array([np.diag(signs) @ np.eye(3)[list(order)]
                        for signs in itertools.product((1.0, -1.0), repeat=3)
                        for order in itertools.permutations(range(3))])
#: The 24 of them that are rotations (a box's frame turned, not mirrored).
AXIS_TURNS = AXIS_FRAMES[np.linalg.det(AXIS_FRAMES) > 0]


def shape_cloud(mesh: NormalisedMesh, samples: int, seed: int = 0) -> NDArray[np.float64]:
    """``samples`` random points of the mesh's surface (area-weighted, seeded, in random
    order), centred, scaled to RMS radius 1 and expressed in their principal axes."""
    return normalised_cloud(_surface(mesh, samples, seed))


def _surface(mesh: NormalisedMesh, samples: int, seed: int) -> NDArray[np.float64]:
    """``samples`` random points of the mesh's surface (area-weighted, seeded), in its
    normalised frame."""
    import trimesh  # noqa: PLC0415 - heavy; only the twin test needs it here

    points, _ = trimesh.sample.sample_surface(mesh.geometry, samples, seed=seed)
    return np.asarray(points, np.float64)


def normalised_cloud(points: NDArray[np.floating]) -> NDArray[np.float64]:
    """Points centred on their mean, scaled to RMS radius 1, in their principal axes."""
    p = np.asarray(points, np.float64)
    p = p - p.mean(axis=0)
    rms = float(np.sqrt((p * p).sum(axis=1).mean()))
    if rms <= 0.0:
        raise ValueError("a shape cloud needs points that are not all equal")
    p /= rms
    _, axes = np.linalg.eigh(p.T @ p)
    return np.ascontiguousarray(p @ axes)


class _Cloud:
    """A shape cloud, a few of its points to measure from, and a tree to measure to."""

    def __init__(self, points: NDArray[np.float64], probes: int) -> None:
        self.points = points
        self.probes = points[:probes]
        self.tree = cKDTree(points)


def _chamfer(a: _Cloud, b: _Cloud, rotation: NDArray[np.float64], shift: NDArray[np.float64]) -> float:
    """The symmetric chamfer distance with ``a`` moved by ``x @ rotation + shift`` (rotation
    orthogonal): ``a``'s probes to ``b``'s points and ``b``'s probes moved back to ``a``'s."""
    there = b.tree.query(a.probes @ rotation + shift)[0].mean()
    back = a.tree.query((b.probes - shift) @ rotation.T)[0].mean()
    return float((there + back) / 2.0)


def _icp(
    a: _Cloud, b: _Cloud, rotation: NDArray[np.float64], iterations: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """ICP from ``rotation``: the rigid motion ``(rotation, shift)`` moving ``a``'s probes
    onto ``b`` (each step a proper rotation, so the start's handedness is kept)."""
    shift = np.zeros(3)
    for _ in range(iterations):
        moved = a.probes @ rotation + shift
        target = b.points[b.tree.query(moved)[1]]
        mm, mt = moved.mean(axis=0), target.mean(axis=0)
        u, _, vt = np.linalg.svd((moved - mm).T @ (target - mt))
        d = 1.0 if np.linalg.det(u @ vt) >= 0 else -1.0
        step = u @ np.diag([1.0, 1.0, d]) @ vt
        new_rotation, new_shift = rotation @ step, (shift - mm) @ step + mt
        converged = np.abs(new_rotation - rotation).max() < 1e-7 and np.abs(new_shift - shift).max() < 1e-7
        rotation, shift = new_rotation, new_shift
        if converged:
            break
    return rotation, shift


def twin_distance(
    a: NDArray[np.float64], b: NDArray[np.float64], config: TwinConfig | None = None
) -> float:
    """The symmetric chamfer distance of two shape clouds (:func:`shape_cloud`) in their best
    alignment (module doc), measured from the first ``config.probes`` points of each to all
    the points of the other: about 0 for one mesh sampled twice."""
    config = config or TwinConfig()
    return _best_alignment(_Cloud(a, config.probes), _Cloud(b, config.probes), AXIS_FRAMES, config)[0]


def rigid_alignment(
    a: NormalisedMesh, b: NormalisedMesh, config: TwinConfig | None = None
) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """``(distance, rotation, shift)``: the rigid motion ``x @ rotation + shift`` (a turn,
    never a mirror) that takes mesh ``a``'s surface onto ``b``'s, both in their normalised
    frames (e.g. two copies of one scan from sources with other axes and units), and the
    symmetric chamfer distance it leaves, in normalised units: :func:`twin_distance`'s
    search over the 24 turns of the axes, on the surfaces as they are (not rescaled or
    turned to their principal axes)."""
    config = config or TwinConfig()
    ca, cb = (_Cloud(_surface(mesh, config.samples, config.seed), config.probes) for mesh in (a, b))
    return _best_alignment(ca, cb, AXIS_TURNS, config)


def _best_alignment(
    a: _Cloud, b: _Cloud, frames: NDArray[np.float64], config: TwinConfig
) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """``(chamfer, rotation, shift)`` of the best alignment of ``a`` onto ``b``: each of
    ``frames`` scored unmoved, the best ``config.icp_starts`` refined by ICP."""
    zero = np.zeros(3)
    coarse = sorted((_chamfer(a, b, frame, zero), i) for i, frame in enumerate(frames))
    best = (coarse[0][0], frames[coarse[0][1]], zero)
    for _, i in coarse[:config.icp_starts]:
        rotation, shift = _icp(a, b, frames[i], config.icp_iterations)
        distance = _chamfer(a, b, rotation, shift)
        if distance < best[0]:
            best = (distance, rotation, shift)
    return best


class Twins:
    """The twin test over a catalogue's meshes, each mesh sampled once and each pair
    compared once. ``mesh``: an object's normalised mesh by name (e.g. ``ViewDB.mesh``)."""

    def __init__(self, mesh: Callable[[str], NormalisedMesh], config: TwinConfig | None = None) -> None:
        self._mesh = mesh
        self.config = config or TwinConfig()
        self._clouds: dict[str, NDArray[np.float64]] = {}
        self._distances: dict[tuple[str, str], float] = {}

    def cloud(self, name: str) -> NDArray[np.float64]:
        if name not in self._clouds:
            self._clouds[name] = shape_cloud(self._mesh(name), self.config.samples, self.config.seed)
        return self._clouds[name]

    def distance(self, a: str, b: str) -> float:
        """The twin distance of objects ``a`` and ``b`` (0 for an object and itself)."""
        if a == b:
            return 0.0
        key = (a, b) if a < b else (b, a)
        if key not in self._distances:
            self._distances[key] = twin_distance(self.cloud(key[0]), self.cloud(key[1]), self.config)
        return self._distances[key]

    def are_twins(self, a: str, b: str) -> bool:
        return self.distance(a, b) <= self.config.threshold
