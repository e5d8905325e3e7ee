"""Which grid views of a symmetric object repeat, and the skim plan (Tak & Hwang, II.B and
III.D, eqs. 1-2).

Views of a symmetric object repeat: several grid views have the same silhouette, or its
left-right mirror (the reversed distance curve,
:func:`~viewdb.catalogue.features.mirror_curve`).  This module works out *which* views
repeat, as exact rules from the camera convention.  Grid view ``(h, v)`` has the camera
rotation ``C(h, v) = R_y(h)·R_x(-v)`` (:mod:`viewdb.camera`); if ``g`` in O(3) maps the
object onto itself and ``M`` is one of ``diag(±1, 1, ±1)`` with ``det g · det M = +1``,
the camera ``C' = g·C·M`` sees the silhouette of ``C`` (mirrored when ``M``'s x-entry is
-1).  :func:`related_views` applies every element of the group of the given generators
(:func:`group_elements`) to every grid view and, where ``C'`` is itself a grid pose
(:func:`grid_pose_of`), joins the two views by union-find with a parity bit (same /
mirrored).  ``(h, v) ~ mirror (h + 180, -v)`` holds for every object (the paper's
mirror-image pairing); in-plane turns are never used.  The classes (:class:`ViewClasses`)
are also an ingest's skim plan (:func:`skim_plan`): which views to store, and how every
grid view maps to a stored one.  It is pure numpy.

The derivation (the rule, the generators of each type H1-H4 x V1-V4, the classes per
grid, the rules of the combinations and how they contain the paper's eqs. 1-2) is in
``docs/skimming.md``; :mod:`viewdb.catalogue.symmetry` classifies an object into a type.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from ..camera import camera_direction, rotation_x, rotation_y

__all__ = [
    "Generator",
    "SkimPlan",
    "Symmetric",
    "ViewClasses",
    "cached_classes",
    "candidate_poses",
    "canonical_angle",
    "canonical_generator",
    "image_twins",
    "generator_matrix",
    "grid_pose_of",
    "grid_steps",
    "group_elements",
    "matrix_key",
    "plan_without_skimming",
    "pose_rotation",
    "related_views",
    "skim_plan",
]

#: Entry-wise tolerance when deciding that a rotation is a grid pose.
POSE_TOLERANCE = 1e-6

#: A symmetry generator by name and parameters (:func:`canonical_generator`).
Generator = tuple[Any, ...]

_MIRROR_X = np.diag([-1.0, 1.0, 1.0])


class Symmetric(Protocol):
    """What a skim plan is made from: verified generators and the gap they were found at
    (a :class:`~viewdb.catalogue.symmetry.SymmetryType`)."""

    @property
    def generators(self) -> tuple[Generator, ...]: ...

    @property
    def gap(self) -> float: ...


# ---------------------------------------------------------------------------------------
# Geometry: grid poses and symmetry generators
# ---------------------------------------------------------------------------------------


def pose_rotation(h: float, v: float) -> NDArray[np.float64]:
    """Camera rotation ``C(h, v) = R_y(h) · R_x(−v)`` of view ``(h, v)`` (see :mod:`viewdb.camera`)."""
    return rotation_y(h) @ rotation_x(-v)


def grid_steps(gap: float) -> int:
    """Grid views per ring, ``360 / gap``; ``ValueError`` unless ``gap`` divides 360."""
    steps = 360.0 / float(gap)
    n = round(steps)
    if gap <= 0 or abs(steps - n) > 1e-9:
        raise ValueError(f"gap must divide 360 evenly, got {gap}")
    return int(n)


def _poses_batch(h_deg: NDArray[np.float64], v_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """``R_y(h) · R_x(−v)`` for arrays of angles, shape (k, 3, 3)."""
    h, v = np.radians(h_deg), np.radians(v_deg)
    ch, sh, cv, sv = np.cos(h), np.sin(h), np.cos(v), np.sin(v)
    out = np.empty(h.shape + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2] = ch, -sh * sv, sh * cv
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2] = 0.0, cv, sv
    out[..., 2, 0], out[..., 2, 1], out[..., 2, 2] = -sh, -ch * sv, ch * cv
    return out


def _grid_indices(rots: NDArray[np.float64], gap: float, tol: float = POSE_TOLERANCE) -> NDArray[np.int64]:
    """Grid index ``i_h · n + i_v`` of each rotation in ``rots`` (k, 3, 3), or −1 if it is not a grid pose."""
    n = grid_steps(gap)
    r = np.asarray(rots, dtype=np.float64)
    out = np.full(len(r), -1, dtype=np.int64)
    cand = np.flatnonzero(np.abs(r[:, 1, 0]) <= tol)  # no roll: the image's x axis is horizontal
    if cand.size == 0:
        return out
    rc = r[cand]
    h = np.degrees(np.arctan2(-rc[:, 2, 0], rc[:, 0, 0]))
    v = np.degrees(np.arctan2(rc[:, 1, 2], rc[:, 1, 1]))
    ih = np.rint(h / gap)
    iv = np.rint(v / gap)
    recon = _poses_batch(ih * gap, iv * gap)
    ok = np.max(np.abs(recon - rc), axis=(1, 2)) <= tol
    idx = (ih.astype(np.int64) % n) * n + (iv.astype(np.int64) % n)
    out[cand[ok]] = idx[ok]
    return out


def grid_pose_of(
    rotation: NDArray[np.floating], gap: float, tol: float = POSE_TOLERANCE
) -> tuple[float, float] | None:
    """The grid view ``(h, v)`` whose camera rotation is ``rotation``, or ``None``.

    A rotation is a grid pose when it has no roll (its first column, the image's right
    axis, is horizontal), decomposes as ``R_y(h) · R_x(−v)`` and both angles are multiples
    of ``gap`` (all within ``tol``).  Angles are returned in [0, 360) as ``i · gap``, the
    same numbers :func:`viewdb.camera.grid_views` uses.  A reflection (det −1) is never a
    grid pose.
    """
    r = np.asarray(rotation, dtype=np.float64).reshape(1, 3, 3)
    idx = int(_grid_indices(r, gap, tol)[0])
    if idx < 0:
        return None
    n = grid_steps(gap)
    return (float(idx // n * gap), float(idx % n * gap))


def canonical_angle(a: float, period: float = 360.0) -> float:
    """``a`` mod ``period``, rounded to 9 decimals, in [0, period) (no ``-0.0``)."""
    x = round(float(a) % period, 9)
    return 0.0 if x in (0.0, period) else x + 0.0


def canonical_generator(gen: Generator) -> Generator:
    """A generator in its canonical, serialisable form (floats rounded, angles normalised).

    Named generators (angles in degrees; ``a_b = R_y(b)·e_x`` is the horizontal axis at
    right angles to the viewing direction of azimuth ``b``):

    ``("rot_y", a)``
        rotation by ``a`` about +Y; relates ``(h, v)`` and ``(h + a, v)``.
    ``("mirror_azimuth", c)``
        reflection in the vertical plane containing +Y and the viewing direction of
        azimuth ``c`` (``c`` mod 180): ``R_y(c)·diag(−1,1,1)·R_y(−c)``; ``c = 0`` is the
        plane x = 0.  Relates ``(c + δ, v)`` and the mirror of ``(c − δ, v)``.
    ``("mirror_y", 0.0)``
        reflection in the horizontal plane y = 0; relates ``(h, v)`` and ``(h, 180 − v)``.
    ``("rot_horizontal", a, b)``
        rotation ``R_y(b)·R_x(−a)·R_y(−b)`` about ``a_b``; relates ``(b, v)`` and
        ``(b, v + a)`` (on other azimuths only where it lands on the grid).
    ``("mirror_elevation", w, b)``
        reflection in the plane through ``a_b`` whose normal is the viewing direction of
        ``(b, w)``; relates ``(b, w + δ)`` and ``(b, w − δ)``.  ``w = 90`` is
        ``mirror_y``, ``w = 0`` is ``mirror_azimuth(b + 90)``; those forms are preferred.
    ``("matrix", m00, m01, …, m22)``
        any orthogonal 3×3 matrix, row-major.
    """
    kind = str(gen[0])
    if kind == "rot_y":
        return ("rot_y", canonical_angle(gen[1]))
    if kind == "mirror_azimuth":
        return ("mirror_azimuth", canonical_angle(gen[1], 180.0))
    if kind == "mirror_y":
        return ("mirror_y", 0.0)
    if kind == "rot_horizontal":
        a, b = float(gen[1]), float(gen[2])
        if canonical_angle(b) >= 180.0:
            a, b = -a, b - 180.0
        return ("rot_horizontal", canonical_angle(a), canonical_angle(b, 180.0))
    if kind == "mirror_elevation":
        w, b = float(gen[1]), float(gen[2])
        if canonical_angle(b) >= 180.0:
            w, b = 180.0 - w, b - 180.0
        w = canonical_angle(w, 180.0)
        if w == 90.0:
            return ("mirror_y", 0.0)
        if w == 0.0:
            return ("mirror_azimuth", canonical_angle(b + 90.0, 180.0))
        return ("mirror_elevation", w, canonical_angle(b, 180.0))
    if kind == "matrix":
        vals = [round(float(x), 12) + 0.0 for x in gen[1:]]
        if len(vals) != 9:
            raise ValueError(f"a matrix generator needs 9 entries, got {len(vals)}")
        return ("matrix", *vals)
    raise ValueError(f"unknown symmetry generator {gen!r}")


def generator_matrix(gen: Generator | NDArray[np.floating]) -> NDArray[np.float64]:
    """The 3×3 orthogonal matrix of a named generator (or a matrix, returned as float64)."""
    if isinstance(gen, np.ndarray):
        m = np.asarray(gen, dtype=np.float64)
        if m.shape != (3, 3) or not np.allclose(m @ m.T, np.eye(3), atol=1e-9):
            raise ValueError("a symmetry matrix must be orthogonal 3x3")
        return m
    g = canonical_generator(gen)
    kind = g[0]
    if kind == "rot_y":
        return rotation_y(g[1])
    if kind == "mirror_azimuth":
        return rotation_y(g[1]) @ _MIRROR_X @ rotation_y(-g[1])
    if kind == "mirror_y":
        return np.diag([1.0, -1.0, 1.0])
    if kind == "rot_horizontal":
        return rotation_y(g[2]) @ rotation_x(-g[1]) @ rotation_y(-g[2])
    if kind == "mirror_elevation":
        n = camera_direction(g[2], g[1])
        return np.eye(3) - 2.0 * np.outer(n, n)
    return generator_matrix(np.array(g[1:], dtype=np.float64).reshape(3, 3))


def matrix_key(m: NDArray[np.float64]) -> bytes:
    """A hashable key of a 3×3 matrix, equal for matrices equal to 7 decimals."""
    return (np.round(m, 7) + 0.0).tobytes()


def group_elements(
    generators: Iterable[Generator | NDArray[np.floating]], max_word: int = 64, max_elements: int = 512
) -> list[NDArray[np.float64]]:
    """Distinct products of the generators and their inverses, identity first.

    Breadth-first over words of length at most ``max_word``, stopping when the group
    closes (every finite group of up to ``max_elements`` elements is listed in full) or
    holds ``max_elements`` (an infinite group such as a sphere's: the shortest words
    first).  Truncation never adds a wrong relation, it can only miss one; and
    :func:`related_views` composes relations through the grid by union–find, so only
    products whose intermediate camera leaves the grid need to be listed at all.
    """
    symbols: list[NDArray[np.float64]] = []
    for gen in generators:
        m = generator_matrix(gen)
        symbols += [m, m.T]
    seen = {matrix_key(np.eye(3)): np.eye(3)}
    frontier = [np.eye(3)]
    for _ in range(max_word):
        new = []
        for x in frontier:
            for s in symbols:
                y = s @ x
                k = matrix_key(y)
                if k not in seen:
                    seen[k] = y
                    new.append(y)
                    if len(seen) >= max_elements:
                        return list(seen.values())
        if not new:
            break
        frontier = new
    return list(seen.values())


# ---------------------------------------------------------------------------------------
# View classes: union–find with parity over the grid
# ---------------------------------------------------------------------------------------


def _components(n_nodes: int, a: NDArray[np.int64], b: NDArray[np.int64]) -> NDArray[np.int64]:
    """Connected-component labels (smallest node of each component) by hooking and jumping."""
    lab = np.arange(n_nodes, dtype=np.int64)
    if a.size == 0:
        return lab
    while True:
        la, lb = lab[a], lab[b]
        if np.array_equal(la, lb):
            return lab
        np.minimum.at(lab, np.maximum(la, lb), np.minimum(la, lb))
        while True:
            nxt = lab[lab]
            if np.array_equal(nxt, lab):
                break
            lab = nxt


def _elevation_key(h: float, v: float) -> tuple[float, bool, bool, float, float]:
    """Sort key of the kept representative: nearest the horizontal ring, upright, above, then h, v."""
    w = v % 360.0
    if w <= 90.0:
        e, upside_down, below = w, False, False
    elif w < 270.0:
        e, upside_down, below = abs(180.0 - w), True, w > 180.0
    else:
        e, upside_down, below = 360.0 - w, False, True
    return (round(e, 9), upside_down, below, h, v)


@dataclass(frozen=True, eq=False)
class ViewClasses:
    """Grid views grouped into classes of equal (or mirrored) silhouettes.

    Built by :func:`related_views` (from symmetry generators), :func:`skim_plan` (from a
    :class:`~viewdb.catalogue.symmetry.SymmetryType`) or :func:`plan_without_skimming`
    (every view its own class).
    This is also the *skim plan* of an ingest: store :attr:`kept`, and for every grid view
    :attr:`mapping` gives ``((h_kept, v_kept), mirrored)``: its distance curve is the kept
    view's curve, reversed (:func:`~viewdb.catalogue.features.mirror_curve`) when ``mirrored``.

    Each class keeps one view: the one nearest the horizontal ring (smallest folded
    elevation ``|asin(sin v)|``), preferring upright (``cos v ≥ 0``) to upside-down and
    above (``sin v ≥ 0``) to below, then the smallest azimuth — e.g. ``(0, 0)`` for a
    sphere.  A class that relates some view to itself mirrored (a self-mirror silhouette,
    whose curve equals its reverse) maps all its views with ``mirrored=False``.
    """

    gap: float
    generators: tuple[Generator, ...]
    #: Grid views in :func:`viewdb.camera.grid_views` order (azimuth-major).
    views: tuple[tuple[float, float], ...] = field(repr=False)
    #: Component label of node ``(view, parity)``, shape (n_views, 2): a view's class is
    #: ``min(labels[i])``; ``labels[i, 0] == labels[i, 1]`` for a self-mirror class.
    labels: NDArray[np.int64] = field(repr=False)
    #: Kept views, sorted.
    kept: tuple[tuple[float, float], ...] = field(repr=False)
    mapping: dict[tuple[float, float], tuple[tuple[float, float], bool]] = field(repr=False)

    @property
    def views_stored(self) -> int:
        return len(self.kept)

    @property
    def views_grid(self) -> int:
        return len(self.views)

    def index(self, h: float, v: float) -> int:
        """Grid index of view ``(h, v)``; ``ValueError`` if it is not a grid view."""
        n = grid_steps(self.gap)
        ih, iv = h / self.gap, v / self.gap
        if abs(ih - round(ih)) > 1e-6 or abs(iv - round(iv)) > 1e-6:
            raise ValueError(f"({h}, {v}) is not a view of the {self.gap}-degree grid")
        return (round(ih) % n) * n + round(iv) % n

    def class_id(self, h: float, v: float) -> int:
        i = self.index(h, v)
        return int(min(self.labels[i, 0], self.labels[i, 1]))

    def is_self_mirror(self, h: float, v: float) -> bool:
        """True when the class relates its views to themselves mirrored."""
        i = self.index(h, v)
        return bool(self.labels[i, 0] == self.labels[i, 1])

    def relation(self, a: tuple[float, float], b: tuple[float, float]) -> str | None:
        """``"same"``, ``"mirror"``, ``"both"`` (self-mirror class) or ``None`` (unrelated)."""
        i, j = self.index(*a), self.index(*b)
        la, lb = self.labels[i], self.labels[j]
        if min(la) != min(lb):
            return None
        if la[0] == la[1]:
            return "both"
        return "same" if la[0] == lb[0] else "mirror"

    def members(self, h: float, v: float) -> list[tuple[float, float, bool]]:
        """Every grid view of the class of ``(h, v)`` as ``(h', v', mirrored)``, grid order.

        ``mirrored`` is relative to ``(h, v)``: the curve of ``(h', v')`` is the reverse of
        the curve of ``(h, v)``.  Self-mirror classes report ``False`` (both hold).
        """
        i = self.index(h, v)
        li = self.labels[i]
        cls = min(li)
        both = li[0] == li[1]
        lab0 = self.labels[:, 0]
        sel = np.flatnonzero(np.minimum(self.labels[:, 0], self.labels[:, 1]) == cls)
        return [(*self.views[j], bool(not both and lab0[j] != li[0])) for j in sel]

    def classes(self) -> list[list[tuple[float, float]]]:
        """All classes, each a list of views in grid order; classes ordered by first view."""
        cid = np.minimum(self.labels[:, 0], self.labels[:, 1])
        out: dict[int, list[tuple[float, float]]] = {}
        for j, c in enumerate(cid):
            out.setdefault(int(c), []).append(self.views[j])
        return list(out.values())


#: The skim plan of an ingest is a :class:`ViewClasses`.
SkimPlan = ViewClasses


def _build_classes(
    gap: float,
    generators: tuple[Generator, ...],
    a: NDArray[np.int64],
    b: NDArray[np.int64],
    par: NDArray[np.int64],
) -> ViewClasses:
    n = grid_steps(gap)
    nv = n * n
    views = tuple((float(i * gap), float(j * gap)) for i in range(n) for j in range(n))
    # doubled graph: node 2·view + parity; an edge (a, b, p) joins (a, q) and (b, q ^ p)
    ea = np.concatenate([2 * a, 2 * a + 1])
    eb = np.concatenate([2 * b + par, 2 * b + (1 - par)])
    lab = _components(2 * nv, ea, eb).reshape(nv, 2)
    cid = np.minimum(lab[:, 0], lab[:, 1])
    best: dict[int, int] = {}
    for j in range(nv):
        c = int(cid[j])
        if c not in best or _elevation_key(*views[j]) < _elevation_key(*views[best[c]]):
            best[c] = j
    mapping: dict[tuple[float, float], tuple[tuple[float, float], bool]] = {}
    for j in range(nv):
        k = best[int(cid[j])]
        mirrored = bool(lab[j, 0] != lab[j, 1] and lab[j, 0] != lab[k, 0])
        mapping[views[j]] = (views[k], mirrored)
    kept = tuple(sorted(views[k] for k in best.values()))
    return ViewClasses(
        gap=float(gap), generators=generators, views=views, labels=lab, kept=kept, mapping=mapping
    )


def _relation_edges(
    matrices: Sequence[NDArray[np.float64]], gap: float, chunk: int = 32
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Edges (view, related view, mirrored) of every ``g·C·M`` that lands on the grid.

    For each ``g`` exactly one ``M`` per parity has ``det g · det M = +1``:
    ``diag(1, 1, det g)`` (same image) and ``diag(-1, 1, -det g)`` (mirrored).
    """
    n = grid_steps(gap)
    nv = n * n
    ih, iv = np.divmod(np.arange(nv), n)
    cams = _poses_batch(ih * float(gap), iv * float(gap))
    keys = []
    mats = np.asarray(matrices, dtype=np.float64).reshape(-1, 3, 3)
    for start in range(0, len(mats), chunk):
        g = mats[start : start + chunk]
        det = np.sign(np.linalg.det(g))
        gc = np.matmul(g[:, None], cams[None])
        for parity in (0, 1):
            r = gc.copy()
            r[..., :, 0] *= -1.0 if parity else 1.0
            r[..., :, 2] *= (-det if parity else det)[:, None, None]
            tgt = _grid_indices(r.reshape(-1, 3, 3), gap).reshape(len(g), nv)
            e, a = np.nonzero(tgt >= 0)
            keys.append((a * nv + tgt[e, a]) * 2 + parity)
    if not keys:
        z = np.zeros(0, dtype=np.int64)
        return z, z, z
    key = np.unique(np.concatenate(keys).astype(np.int64))
    return key // 2 // nv, key // 2 % nv, key % 2


def related_views(
    generators: Iterable[Generator | NDArray[np.floating]],
    gap: float,
    *,
    max_word: int = 64,
    max_elements: int = 512,
) -> ViewClasses:
    """Classes of grid views that must have the same (or mirrored) silhouette.

    For every grid view ``C`` and every element ``g`` of the group generated by
    ``generators`` (products up to ``max_word``, see :func:`group_elements`), and each
    ``M`` of ``diag(±1, 1, ±1)`` with ``det g · det M = +1``, the camera ``g·C·M`` sees
    the silhouette of ``C`` (mirrored when ``M``'s x-entry is −1); when it is a grid pose
    (:func:`grid_pose_of`) the two views are joined.  ``g = I`` with ``M = diag(−1,1,−1)``
    is the mirror-image pairing ``(h, v) ~ mirror (h + 180, −v)``, present for every object.
    """
    gens = tuple(
        canonical_generator(("matrix", *np.asarray(g, dtype=np.float64).ravel()))
        if isinstance(g, np.ndarray)
        else canonical_generator(g)
        for g in generators
    )
    mats = group_elements(gens, max_word=max_word, max_elements=max_elements)
    a, b, p = _relation_edges(mats, gap)
    return _build_classes(gap, gens, a, b, p)


def plan_without_skimming(gap: float) -> ViewClasses:
    """Every grid view kept, each mapped to itself (``--no-skim``; not even mirror pairing)."""
    z = np.zeros(0, dtype=np.int64)
    return _build_classes(gap, (), z, z, z)


@lru_cache(maxsize=64)
def cached_classes(generators: tuple[Generator, ...], gap: float) -> ViewClasses:
    """:func:`related_views` of canonical generators, cached (the last 64)."""
    return related_views(generators, gap)


def skim_plan(symmetry: Symmetric, gap: float | None = None) -> ViewClasses:
    """The skim plan (view classes) of a classified object on the grid of ``gap``
    (default: the gap it was classified at)."""
    return cached_classes(tuple(symmetry.generators), float(symmetry.gap if gap is None else gap))


@lru_cache(maxsize=64)
def _elements(generators: tuple[Generator, ...]) -> NDArray[np.float64]:
    """:func:`group_elements` of canonical generators as one array (k, 3, 3), cached."""
    return np.asarray(group_elements(generators), dtype=np.float64).reshape(-1, 3, 3)


#: The camera turned by 180° about its viewing axis: the turned twin's camera is ``C · _TURN``.
_TURN = np.diag([-1.0, -1.0, 1.0])


def image_twins(symmetry: Symmetric, gap: float, h: float, v: float) -> list[tuple[float, float, bool, bool]]:
    """The grid views whose *render* is that of ``(h, v)`` mirrored left to right and/or
    turned by 180°, by the object's symmetry: ``(h', v', mirrored, turned)``, without
    ``(h, v)`` itself.

    Unlike the silhouette relations of :func:`related_views` (whose ``M`` may look from
    the other side, ``M``'s z-entry −1), these keep the viewing side: a rotation ``g``
    gives the camera ``g·C`` (the same image), a reflection ``g·C·diag(−1, 1, 1)`` (the
    image mirrored), and either times ``diag(−1, −1, 1)`` the image turned by 180°. The
    shaded render of a mesh that has the symmetry, and no colour that breaks it, is then
    the same up to rasterisation ties (the head-light moves with the camera).

    Only the elements that keep the vertical axis are used (turns about it, mirrors
    through vertical planes): a symmetry is verified on silhouettes, which do not see
    what one that swaps top and bottom would change inside the outline (a mug's
    opening, seen from above, is not its base seen from below)."""
    mats = _elements(tuple(canonical_generator(g) for g in symmetry.generators))
    mats = mats[np.abs(mats[:, 1, 1] - 1.0) < 1e-9]  # g·e_y = e_y: the vertical axis kept
    det = np.sign(np.linalg.det(mats))
    cams = mats @ pose_rotation(h, v)
    cams[det < 0] = cams[det < 0] @ _MIRROR_X
    n = grid_steps(gap)
    own = _grid_indices(pose_rotation(h, v)[None], gap)[0]
    out: dict[int, tuple[float, float, bool, bool]] = {}
    for turned in (False, True):
        found = _grid_indices(cams @ _TURN if turned else cams, gap)
        for j in np.flatnonzero(found >= 0):
            index = int(found[j])
            if index != own and index not in out:
                ih, iv = divmod(index, n)
                out[index] = (float(ih * gap), float(iv * gap), bool(det[j] < 0), turned)
    return list(out.values())


def candidate_poses(
    sym_or_classes: Symmetric | ViewClasses, h: float, v: float
) -> list[tuple[float, float, bool]]:
    """Every grid view whose silhouette is the same as, or the mirror of, that of ``(h, v)``.

    Returns ``(h', v', mirrored)`` in grid order, ``(h, v)`` itself included; ``mirrored``
    means the curve of ``(h', v')`` is the reverse of that of ``(h, v)``.  This generalises
    the paper's eqs. 1–2 (which list azimuths ``HR·(i−1) + k`` / ``HR·i − k`` and
    elevations likewise) to the exact relations of the object's symmetry group.
    """
    classes = sym_or_classes if isinstance(sym_or_classes, ViewClasses) else skim_plan(sym_or_classes)
    return classes.members(h, v)
