"""Camera-view skimming by symmetry (Tak & Hwang, II.B and III.D, eqs. 1-2, Algorithm 1).

Views of a symmetric object repeat: several grid views have the same silhouette, or its
left-right mirror (the reversed distance curve, :func:`reverse_curve`).  This module
works out *which* views repeat, as exact rules from the camera convention, classifies an
object into the paper's types H1-H4 x V1-V4 from its silhouettes, and turns the result
into a skim plan (which views to store, and how every grid view maps to a stored one).
It is pure numpy; silhouettes come in as curves through a callback.

The rule
--------
Grid view ``(h, v)`` has the camera rotation ``C(h, v) = R_y(h)·R_x(-v)``
(:mod:`viewdb.camera`).  Its silhouette is the orthographic projection of the object on
the camera's x-y plane.  If ``g`` in O(3) maps the object onto itself and ``M`` is one of
``diag(1,1,1)``, ``diag(1,1,-1)``, ``diag(-1,1,1)``, ``diag(-1,1,-1)`` with
``det g · det M = +1``, the rotation ``C' = g·C·M`` projects the object onto the same
silhouette as ``C`` (x-entry of ``M`` +1) or onto its left-right mirror (x-entry -1):
``C'^T·(g p) = M·C^T·p``.  The z-entry of ``M`` does not matter for an orthographic
silhouette.  The rule is used only where ``C'`` is itself a grid pose: no roll (its first
column is horizontal), ``C' = R_y(h')·R_x(-v')`` with ``h'``, ``v'`` on the grid
(:func:`grid_pose_of`).  :func:`related_views` applies every element of the group of the
given generators (:func:`group_elements`: the whole group when finite, else its 512
shortest products) to every grid view and joins the results by union-find with a parity
bit (same / mirrored); relations compose through the union-find.

Special cases (contract): ``g = I``, ``M = diag(-1,1,-1)`` gives ``(h, v) ~ mirror
(h + 180, -v)`` for every object (the paper's mirror-image pairing).  ``(h + 180,
180 - v)`` is the same direction turned 180 degrees in the image; that is *not* the same
curve (the curve starts at the top), and in-plane turns are never used.

Notation: ``a == b`` same curve, ``a =~ b`` reversed (mirrored) curve; angles mod 360;
``b`` base azimuth, ``v0`` base elevation, ``P`` period, ``d`` any multiple of the gap
(or of gap/2 where the result lands on the grid).

Types and their generators (:func:`canonical_generator` names)
--------------------------------------------------------------
=====  ===============================================  ==========================================
type   asserted symmetry / generators                   derived rules (besides the pairing)
=====  ===============================================  ==========================================
H1     every rotation about +Y (sphere, upright         ``(h, v) == (h', v)`` for all ``h'``; every
       cylinder, bottle); ``rot_y(gap)`` and            view is self-mirror, ``(h, v) =~ (h, v)``;
       ``mirror_azimuth(b)`` (implied: a set            with the pairing ``(h, v) == (h', -v)``.
       invariant under all turns about Y is also        HR_period = 0.
       symmetric in every vertical plane through Y).
H2     exactly one vertical mirror plane, at azimuth    ``(b + d, v) =~ (b - d, v)``;
       ``b`` (car: b = 0, plane x = 0):                 ``(b + d, v) == (b + 180 - d, -v)``.
       ``mirror_azimuth(b)`` = R_y(b)·diag(-1,1,1)·     HR_period = 90: with the pairing the ring
       R_y(-b).                                         pattern also reflects about b + 90.
H3     two or more vertical mirror planes (dice,        the H2 rules about ``b + kP`` for every k,
       square table): ``mirror_azimuth(b)``,            hence ``(h, v) == (h + 2P, v)``.
       ``mirror_azimuth(b + P)`` (when 90/P is odd      HR_period = P < 90 (45 for a square).
       also tried: planes every 2P, e.g. a triangle).
H4     no vertical mirror plane: no generator.          pairing only; HR_period = 180.
V1     every rotation about the horizontal axis         ``(b, v) == (b, v')`` for all ``v'`` (on
       ``a_b = R_y(b)·e_x`` (sphere):                   grid only on that ring, elsewhere through
       ``rot_horizontal(gap, b)``, ``mirror_azimuth     products); VR_period = 0.
       (b + 90)``.
V2     one mirror plane through the horizontal axis,    ``mirror_y``: ``(h, v) == (h, 180 - v)`` for
       in practice y = 0 (top-bottom symmetric):        every h.  A plane with v0 = 0 is the
       ``mirror_y``; in general                         vertical plane ``mirror_azimuth(b + 90)``:
       ``mirror_elevation(v0, b)``; a pattern of        ``(b + 90 + d, v) =~ (b + 90 - d, v)``.
       period 90 asserts the planes at v0 and v0+90.    VR_period = 90.
V3     more frequent (dice: front = top):               ``(b, v) == (b, v + 2P)``,
       ``mirror_elevation(v0, b)`` and                  ``(b, v0 + d) == (b, v0 - d)``, and (grid-
       ``rot_horizontal(2P, b)``.                       preserving everywhere) the half turn
                                                        ``(h, v) == (2b - h, v + 180)``.  VR = P.
V4     none beyond the horizontal type.                 VR_period = 180.
=====  ===============================================  ==========================================

A combination ``Hx/Vy`` asserts the union of both generator sets (closed through the grid
by :func:`related_views`).  Classes per grid (``views_stored`` at gap 10 / 30 for b = 0,
H3 and V3 with P = 45, V2 = ``mirror_y``; ``V2'`` = the period-90 form with
``mirror_azimuth(90)`` too; the full grid is 1296 / 144 views):

=====  =========  =========  =========  =========  =========
       V1 (*)     V2         V2'        V3         V4
=====  =========  =========  =========  =========  =========
H1     1 / 1      10 / 4     10 / 4     1 / 1      19 / 7
H2     91 / 13    181 / 25   100 / 16   95 / 14    343 / 43
H3     77 / 1     50 / 8     50 / 8     45 / 6     95 / 14
H4     172 / 22   342 / 42   181 / 25   176 / 23   648 / 72
=====  =========  =========  =========  =========  =========

(*) V1 with anything but H1 generates an infinite group (e.g. H2/V1: a cylinder lying
along x); :func:`group_elements` lists its 512 shortest products, so these counts are
upper bounds that depend on that cut (every relation found is still exact).

Derived rules of the combinations, beyond the union of the two rows above:

* H1/V1: one class (only a sphere has both).  H1/V3 also collapses to one class: a
  set invariant under all turns about Y and a quarter turn about X is a sphere.
* H1/V2 (upright cylinder, torus): ``(h, v) == (h', +-v) == (h', 180 +- v)``: one class
  per folded elevation ``|asin(sin v)|``.  H1/V4 (cone, bottle): one per elevation
  ``v`` up to ``v <-> -v``.
* H2/V2 with ``mirror_y`` (the mug: planes z = 0 and y = 0): also ``(b + d, v) =~
  (b - d, 180 - v)`` and, from the half turn about the viewing axis of azimuth b (the
  line in both planes), ``(b + d, v) == (b + 180 - d, v + 180)``; the period-90 form
  (box: three planes) adds ``(b + 90 + d, v) =~ (b + 90 - d, v)``.
* H2/V3, H3/V2, H3/V3 (dice: 48 symmetries): the rules of both rows, plus their grid
  products, e.g. for the dice quarter turns about all three axes wherever they land on
  the grid.
* H4/Vy: the V rules alone (an H4 object with ``mirror_y`` keeps ``(h, v) == (h, 180 - v)``).

The paper's eqs. 1-2 list, for a base view ``(k, l)``, the azimuths ``HR·(i-1) + k`` /
``HR·i - k`` and elevations ``VR·(j-1) + l`` / ``VR·j - l``; :func:`candidate_poses`
returns the exact class instead (every grid view with the same or mirrored silhouette,
with the mirror flag), which contains those poses and the ``v -> -v`` companions the
paper leaves implicit.

Classification (:func:`classify`)
---------------------------------
Algorithm 1 proposes, the curves verify.

(a) On the horizontal ring ``(h, 0)`` every bisymmetric view
(``shape_distance(c, reverse_curve(c)) <= sigma``) is a base view; no base view means
H4.  For each base the shape difference curve ``d_k`` (RMS distance of view k's curve to
the base's) is tested for reflection symmetry about every multiple of ``P`` from the base
(``max |d_k - d_k'| <= sigma``), ``P`` running over the multiples of gap/2 that divide
180 (the paper's divide 90; 60 or 36 only arise where the pairing is off the grid, e.g.
gap 40, or on the vertical ring); a flat curve (``max d <= sigma``) proposes H1,
``P < 90`` H3, ``P = 90`` (or a lone reflection about the base) H2.  A mirror half-way
between two grid views has no base view; those centres are tested on the curves directly
(``(c + d) =~ (c - d)``).  On the vertical ring ``(b, v)`` the same is done, but every
view may be a base (a mirror through the horizontal axis relates ``(b, w + d)`` and
``(b, w - d)`` unmirrored, so its centre view need not be bisymmetric), and a reflection
about the base alone proposes a single mirror (V2).

(b) Proposals, most symmetric first, become generators; each generator is verified on
every view rendered so far (the horizontal ring, the vertical rings through ``b`` and
``b + 90``, a sample of 16-32 off-ring views around ``b``, and, for free, all their
mirror-image pairs): after adding it, every rendered view must be within sigma of the
first rendered view of its class (both parities for self-mirror classes).  A generator
already in the accepted group, or adding nothing on the grid, is *redundant* (skipped; a
vertical proposal whose mirrors are all redundant, like the cone's vertical plane,
leaves V4); one that relates no two rendered views is *unverifiable* and fails.  A
proposal stands only if all its generators pass, otherwise the next one is tried
(H1 -> H3 -> H2 -> H4, V1/V3 -> V2 -> V4).  Finally half turns without a mirror
(``rot_y(180)``, ``rot_horizontal(180, b)`` and ``(180, b + 90)``) are proposed when a
ring repeats after 180 degrees and verified the same way; they add pruning but do not
change the labels (the types are defined by the mirrors and turns above).  So pruning
is never lossy by more than sigma on what was checked, and every check is recorded in
:attr:`SymmetryType.verification`.

Views: :func:`views_needed_for_classification` lists what is rendered when the base
azimuth is a multiple of 90 (every sample model); other bases make :func:`classify`
ask its callback for the rings and sample around them as well.

Noise and the default sigma
---------------------------
Curves have mean 1; distances are RMS.  Measured on silhouette renders of all 15 sample
models (every grid view, true symmetry groups from the geometry):

* truly equal views (exact symmetries, incl. the pairing): max 0.0078 at 256 px (one car
  view: a rasteriser tie), otherwise <= 0.0031 (icosphere and 48-gon faceting at gap 10);
  at 128 px max 0.0057 (icosphere).  Meshes with exact symmetries give 0 to 1e-15.
* genuinely different views: at gap 30 the 1st percentile of the nearest other class is
  0.007-0.12 per model, but a few coincidences are nearly equal without any symmetry
  (box_long front vs 30 degrees: 0.003; torus near the top at gap 10: 0.005).  Views
  whose silhouettes coincide by 2-D accident (top views of the chair) are 0; such
  coincidences are not symmetries and are never used.
* a wrong generator breaks many pairs: the rejected proposals on the samples had errors
  0.24-0.69.

``DEFAULT_SIGMA = 0.02`` is 2.5x the worst equal-view noise and far below the errors of
wrong generators.  With it every sample model gets the same type at 128 and 256 px and
at gaps 10 and 30, and rendering *every* grid view, the worst pruned view differs from
its kept view by 0.0078 (256 px) / 0.0057 (128 px).  The no-loss tests check every
pruned view against its kept view within sigma.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..camera import camera_direction, rotation_x, rotation_y

__all__ = [
    "DEFAULT_SIGMA",
    "SkimPlan",
    "SymmetryType",
    "VerificationRecord",
    "ViewClasses",
    "candidate_poses",
    "canonical_generator",
    "classify",
    "generator_matrix",
    "grid_pose_of",
    "group_elements",
    "plan_without_skimming",
    "pose_rotation",
    "related_views",
    "reverse_curve",
    "shape_distance",
    "skim_plan",
    "views_needed_for_classification",
]

#: Default tolerance of :func:`classify`: the RMS difference (curves have mean 1) below
#: which two distance curves count as the same shape.  See the module docstring for the
#: measurements it is based on.
DEFAULT_SIGMA = 0.02

#: Entry-wise tolerance when deciding that a rotation is a grid pose.
POSE_TOLERANCE = 1e-6

Generator = tuple[Any, ...]

_MIRROR_X = np.diag([-1.0, 1.0, 1.0])


# ---------------------------------------------------------------------------------------
# Geometry: grid poses and symmetry generators
# ---------------------------------------------------------------------------------------


def pose_rotation(h: float, v: float) -> NDArray[np.float64]:
    """Camera rotation ``C(h, v) = R_y(h) · R_x(−v)`` of view ``(h, v)`` (see :mod:`viewdb.camera`)."""
    return rotation_y(h) @ rotation_x(-v)


def _n_steps(gap: float) -> int:
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
    n = _n_steps(gap)
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
    n = _n_steps(gap)
    return (float(idx // n * gap), float(idx % n * gap))


def _norm(a: float, period: float = 360.0) -> float:
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
        return ("rot_y", _norm(gen[1]))
    if kind == "mirror_azimuth":
        return ("mirror_azimuth", _norm(gen[1], 180.0))
    if kind == "mirror_y":
        return ("mirror_y", 0.0)
    if kind == "rot_horizontal":
        a, b = float(gen[1]), float(gen[2])
        if _norm(b) >= 180.0:
            a, b = -a, b - 180.0
        return ("rot_horizontal", _norm(a), _norm(b, 180.0))
    if kind == "mirror_elevation":
        w, b = float(gen[1]), float(gen[2])
        if _norm(b) >= 180.0:
            w, b = 180.0 - w, b - 180.0
        w = _norm(w, 180.0)
        if w == 90.0:
            return ("mirror_y", 0.0)
        if w == 0.0:
            return ("mirror_azimuth", _norm(b + 90.0, 180.0))
        return ("mirror_elevation", w, _norm(b, 180.0))
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


def _matrix_key(m: NDArray[np.float64]) -> bytes:
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
    seen = {_matrix_key(np.eye(3)): np.eye(3)}
    frontier = [np.eye(3)]
    for _ in range(max_word):
        new = []
        for x in frontier:
            for s in symbols:
                y = s @ x
                k = _matrix_key(y)
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
    :class:`SymmetryType`) or :func:`plan_without_skimming` (every view its own class).
    This is also the *skim plan* of an ingest: store :attr:`kept`, and for every grid view
    :attr:`mapping` gives ``((h_kept, v_kept), mirrored)``: its distance curve is the kept
    view's curve, reversed (:func:`reverse_curve`) when ``mirrored``.

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
    #: Component label of node ``(view, parity)``, shape (n_views, 2).
    _labels: NDArray[np.int64] = field(repr=False)
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
        n = _n_steps(self.gap)
        ih, iv = h / self.gap, v / self.gap
        if abs(ih - round(ih)) > 1e-6 or abs(iv - round(iv)) > 1e-6:
            raise ValueError(f"({h}, {v}) is not a view of the {self.gap}-degree grid")
        return (round(ih) % n) * n + round(iv) % n

    def class_id(self, h: float, v: float) -> int:
        i = self.index(h, v)
        return int(min(self._labels[i, 0], self._labels[i, 1]))

    def is_self_mirror(self, h: float, v: float) -> bool:
        """True when the class relates its views to themselves mirrored."""
        i = self.index(h, v)
        return bool(self._labels[i, 0] == self._labels[i, 1])

    def relation(self, a: tuple[float, float], b: tuple[float, float]) -> str | None:
        """``"same"``, ``"mirror"``, ``"both"`` (self-mirror class) or ``None`` (unrelated)."""
        i, j = self.index(*a), self.index(*b)
        la, lb = self._labels[i], self._labels[j]
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
        li = self._labels[i]
        cls = min(li)
        both = li[0] == li[1]
        lab0 = self._labels[:, 0]
        sel = np.flatnonzero(np.minimum(self._labels[:, 0], self._labels[:, 1]) == cls)
        return [(*self.views[j], bool(not both and lab0[j] != li[0])) for j in sel]

    def classes(self) -> list[list[tuple[float, float]]]:
        """All classes, each a list of views in grid order; classes ordered by first view."""
        cid = np.minimum(self._labels[:, 0], self._labels[:, 1])
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
    n = _n_steps(gap)
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
        gap=float(gap), generators=generators, views=views, _labels=lab, kept=kept, mapping=mapping
    )


def _relation_edges(
    matrices: Sequence[NDArray[np.float64]], gap: float, chunk: int = 32
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Edges (view, related view, mirrored) of every ``g·C·M`` that lands on the grid.

    For each ``g`` exactly one ``M`` per parity has ``det g · det M = +1``:
    ``diag(1, 1, det g)`` (same image) and ``diag(-1, 1, -det g)`` (mirrored).
    """
    n = _n_steps(gap)
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
def _cached_classes(generators: tuple[Generator, ...], gap: float) -> ViewClasses:
    return related_views(generators, gap)


def skim_plan(symmetry: SymmetryType, gap: float | None = None) -> ViewClasses:
    """The skim plan (view classes) of a classified object on the grid of ``gap``
    (default: the gap it was classified at)."""
    return _cached_classes(tuple(symmetry.generators), float(symmetry.gap if gap is None else gap))


def candidate_poses(
    sym_or_classes: SymmetryType | ViewClasses, h: float, v: float
) -> list[tuple[float, float, bool]]:
    """Every grid view whose silhouette is the same as, or the mirror of, that of ``(h, v)``.

    Returns ``(h', v', mirrored)`` in grid order, ``(h, v)`` itself included; ``mirrored``
    means the curve of ``(h', v')`` is the reverse of that of ``(h, v)``.  This generalises
    the paper's eqs. 1–2 (which list azimuths ``HR·(i−1) + k`` / ``HR·i − k`` and
    elevations likewise) to the exact relations of the object's symmetry group.
    """
    classes = skim_plan(sym_or_classes) if isinstance(sym_or_classes, SymmetryType) else sym_or_classes
    return classes.members(h, v)


# ---------------------------------------------------------------------------------------
# Curves
# ---------------------------------------------------------------------------------------


def reverse_curve(curve: NDArray[np.floating]) -> NDArray[np.float64]:
    """``c'[i] = c[−i mod N]``: the curve of the left–right mirrored silhouette
    (the same as :func:`viewdb.catalogue.features.mirror_curve`, kept here so this
    module needs numpy only)."""
    x = np.asarray(curve, dtype=np.float64)
    return np.roll(x[::-1], 1)


def shape_distance(a: NDArray[np.floating], b: NDArray[np.floating]) -> float:
    """RMS difference of two distance curves (Euclidean distance / sqrt(N))."""
    x, y = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return float(np.sqrt(np.mean((x - y) ** 2)))


# ---------------------------------------------------------------------------------------
# Classification (Algorithm 1 proposes, curves verify)
# ---------------------------------------------------------------------------------------

CurveFn = Callable[[float, float], NDArray[np.floating]]


@dataclass(frozen=True)
class VerificationRecord:
    """What :func:`classify` checked for one proposed generator.

    ``status`` is ``"accepted"`` (every rendered pair it relates is within σ),
    ``"rejected"`` (some pair is not), ``"redundant"`` (it adds no relation on the grid to
    the generators already accepted) or ``"unverifiable"`` (it relates no two rendered
    views, so it is not used).  ``new_pairs`` counts the pairs of rendered views (a view
    with itself for a new self-mirror) it newly relates, ``max_error`` is the largest
    distance found over all related rendered views (0 when nothing was compared).
    """

    hypothesis: str
    generator: Generator
    status: str
    new_pairs: int
    max_error: float

    def to_list(self) -> list[Any]:
        return [self.hypothesis, list(self.generator), self.status, self.new_pairs, self.max_error]

    @classmethod
    def from_list(cls, data: Sequence[Any]) -> VerificationRecord:
        return cls(str(data[0]), tuple(data[1]), str(data[2]), int(data[3]), float(data[4]))


@dataclass(frozen=True)
class SymmetryType:
    """An object's symmetry type (paper II.B) with the verified generators behind it.

    ``generators`` (canonical, see :func:`canonical_generator`) are what pruning uses
    (:func:`skim_plan`); the type labels and periods are the paper's vocabulary for them.
    ``h_difference[k]`` is the shape difference (RMS) of view ``(k·gap, 0)`` to the base view
    ``(base_azimuth, 0)``; ``v_difference[k]`` that of ``(base_azimuth, k·gap)`` to
    ``(base_azimuth, base_elevation)`` (the vertical base as the ring's view index: the
    reported ``base_elevation`` is the smallest equivalent reflection centre).
    """

    h_type: str
    v_type: str
    h_period: float
    v_period: float
    base_azimuth: float
    base_elevation: float
    generators: tuple[Generator, ...]
    h_difference: tuple[float, ...] = ()
    v_difference: tuple[float, ...] = ()
    gap: float = 10.0
    sigma: float = DEFAULT_SIGMA
    verification: tuple[VerificationRecord, ...] = ()
    #: Number of curves :func:`classify` asked its callback for.
    views_rendered: int = 0

    @property
    def type_name(self) -> str:
        return f"{self.h_type}/{self.v_type}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable form (lists, floats, strings)."""
        return {
            "h_type": self.h_type,
            "v_type": self.v_type,
            "h_period": self.h_period,
            "v_period": self.v_period,
            "base_azimuth": self.base_azimuth,
            "base_elevation": self.base_elevation,
            "generators": [list(g) for g in self.generators],
            "h_difference": list(self.h_difference),
            "v_difference": list(self.v_difference),
            "gap": self.gap,
            "sigma": self.sigma,
            "verification": [r.to_list() for r in self.verification],
            "views_rendered": self.views_rendered,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SymmetryType:
        return cls(
            h_type=str(data["h_type"]),
            v_type=str(data["v_type"]),
            h_period=float(data["h_period"]),
            v_period=float(data["v_period"]),
            base_azimuth=float(data["base_azimuth"]),
            base_elevation=float(data["base_elevation"]),
            generators=tuple(canonical_generator(tuple(g)) for g in data["generators"]),
            h_difference=tuple(float(x) for x in data.get("h_difference", ())),
            v_difference=tuple(float(x) for x in data.get("v_difference", ())),
            gap=float(data.get("gap", 10.0)),
            sigma=float(data.get("sigma", DEFAULT_SIGMA)),
            verification=tuple(VerificationRecord.from_list(r) for r in data.get("verification", ())),
            views_rendered=int(data.get("views_rendered", 0)),
        )


def _pair_index(i: int, n: int) -> int | None:
    """Grid index of the mirror-image pair ``(h + 180, −v)`` of index ``i``, if on the grid."""
    if n % 2:
        return None
    ih, iv = divmod(i, n)
    return ((ih + n // 2) % n) * n + (-iv) % n


class _CurveCache:
    """Curves by grid index; a view whose mirror-image pair is known is not rendered."""

    def __init__(self, curve_at: CurveFn, gap: float) -> None:
        self.curve_at = curve_at
        self.gap = float(gap)
        self.n = _n_steps(gap)
        self.curves: dict[int, NDArray[np.float64]] = {}
        self.calls = 0

    def get(self, ih: int, iv: int) -> NDArray[np.float64]:
        n = self.n
        i = (ih % n) * n + iv % n
        if i not in self.curves:
            j = _pair_index(i, n)
            if j is not None and j in self.curves:
                self.curves[i] = reverse_curve(self.curves[j])
            else:
                h, v = float((ih % n) * self.gap), float((iv % n) * self.gap)
                c = np.asarray(self.curve_at(h, v), dtype=np.float64)
                self.calls += 1
                self.curves[i] = c
                if j is not None and j not in self.curves:
                    self.curves[j] = reverse_curve(c)
        return self.curves[i]

    def view(self, h: float, v: float) -> NDArray[np.float64]:
        if not (_on_grid(h, self.gap) and _on_grid(v, self.gap)):
            raise ValueError(f"({h}, {v}) is not a view of the {self.gap}-degree grid")
        return self.get(round(h / self.gap), round(v / self.gap))


def _sample_views(gap: float, base: float) -> list[tuple[float, float]]:
    """Deterministic off-ring verification sample around azimuth ``base``.

    One or two seeds ``(h0, v0)`` with ``0 < h0, v0 < 90``, each expanded to azimuths
    ``base ± h0``, ``base + 180 ± h0`` (and ``base + 90 ± h0``, ``base + 270 ± h0`` when
    ``gap`` divides 90) and elevations ``v0``, ``180 − v0``, so that vertical mirrors at and
    between the axes, 90-degree turns and ``mirror_y`` all relate sample views to each other
    (their mirror-image pairs, at ``−v0`` and ``180 + v0``, come for free).
    """
    n = _n_steps(gap)
    inner = [k * gap for k in range(1, n) if k * gap < 90.0 - 1e-9]
    if not inner:
        return []
    m = len(inner) - 1
    h0, v0 = inner[round(m / 3)], inner[round(2 * m / 3)]
    seeds = [(h0, v0)] if h0 == v0 else [(h0, v0), (v0, h0)]
    quarter = abs(90.0 / gap - round(90.0 / gap)) < 1e-9
    out: list[tuple[float, float]] = []
    for hs, vs in seeds:
        offsets = [hs, -hs, 180 + hs, 180 - hs] + ([90 + hs, 90 - hs, 270 + hs, 270 - hs] if quarter else [])
        for off in offsets:
            for el in (vs, 180.0 - vs):
                view = (_norm(base + off), _norm(el))
                if view not in out and _on_grid(view[0], gap) and _on_grid(view[1], gap):
                    out.append(view)
    return out


def _on_grid(angle: float, gap: float) -> bool:
    q = angle / gap
    return abs(q - round(q)) < 1e-9


def _ring_views(gap: float, base: float) -> list[tuple[float, float]]:
    """The vertical ring ``(base, v)``, all ``v`` (empty if ``base`` is not on the grid)."""
    n = _n_steps(gap)
    if not _on_grid(base, gap):
        return []
    return [(_norm(base), _norm(k * gap)) for k in range(n)]


def views_needed_for_classification(
    gap: float = 10.0, base_azimuth: float = 0.0
) -> list[tuple[float, float]]:
    """The views :func:`classify` renders (base azimuth a multiple of 90 from ``base_azimuth``).

    The horizontal ring, the vertical rings through ``base_azimuth`` and
    ``base_azimuth + 90`` and the verification sample (:func:`_sample_views`), leaving
    out views whose mirror-image pair ``(h + 180, −v)`` is already listed (its curve is
    the reverse).  With a base azimuth that is not a multiple of 90 from ``base_azimuth``,
    :func:`classify` also asks for the rings and sample around that base.  120 views at
    gap 10 (of 1296), 60 at gap 30 (of 144).
    """
    n = _n_steps(gap)
    seen: set[int] = set()
    out: list[tuple[float, float]] = []
    wanted = [(k * gap, 0.0) for k in range(n)]
    wanted += _ring_views(gap, base_azimuth) + _ring_views(gap, base_azimuth + 90.0)
    wanted += _sample_views(gap, base_azimuth)
    for h, v in wanted:
        i = (round(h / gap) % n) * n + round(v / gap) % n
        if i in seen:
            continue
        seen.add(i)
        j = _pair_index(i, n)
        if j is not None:
            seen.add(j)
        out.append((_norm(h), _norm(v)))
    return out


def _allowed_periods(gap: float) -> list[int]:
    """Periods as ``m`` (P = m·gap/2 <= 90): multiples of gap/2 that divide 180, ascending.

    The paper's periods divide 90 (with the pairing a horizontal pattern always reflects
    about b + 90 too); 60 or 36 occur when the pairing is off the grid (e.g. gap 40) or on
    the vertical ring (a 3-fold axis lying horizontally).
    """
    out = []
    m = 1
    while m * gap / 2.0 <= 90.0 + 1e-9:
        q = 360.0 / (m * gap)
        if abs(q - round(q)) < 1e-9:
            out.append(m)
        m += 1
    return out


def _reflection_error(d: NDArray[np.float64], k0: int, m: int, n_centres: int) -> float:
    """Largest ``|d[k] − d[k']|`` over reflections of the ring about ``k0 + j·m/2`` (index units)."""
    n = len(d)
    k = np.arange(n)
    err = 0.0
    for j in range(n_centres):
        kr = (2 * k0 + j * m - k) % n
        err = max(err, float(np.max(np.abs(d - d[kr]))))
    return err


@dataclass(frozen=True)
class _Proposal:
    label: str
    period: float
    base: int  # ring index of the base view (the one below a half-grid centre)
    rank: tuple[Any, ...]
    centre2: int | None = None  # reflection centre in units of gap/2 (default 2·base)

    @property
    def centre(self) -> int:
        return 2 * self.base if self.centre2 is None else self.centre2


def _ring_proposals(
    curves: Sequence[NDArray[np.float64]], gap: float, sigma: float, *, vertical: bool
) -> tuple[list[_Proposal], NDArray[np.float64]]:
    """Algorithm 1 on one ring: base views, shape difference curves, reflection periods.

    Returns every (base, period) whose difference pattern is reflection-symmetric about
    every multiple of the period from the base within ``sigma`` (all periods, ascending,
    for every admissible base), best first, and the bisymmetry of each ring view.
    On the horizontal ring a base must be bisymmetric (a vertical mirror plane through
    the viewing direction makes it so); on the vertical ring any view may be a base,
    because a mirror through the horizontal axis relates ``(b, w + δ)`` and ``(b, w − δ)``
    without mirroring the image, so the view at ``w`` need not be bisymmetric.  A
    reflection about the base alone (period 180) is proposed last; on the horizontal ring
    it only matters when 90 is not a multiple of gap/2 (e.g. gap 40), where the pairing's
    apparent axis at b + 90 is off the grid.
    """
    n = len(curves)
    c = np.array(curves, dtype=np.float64)
    rev = np.array([reverse_curve(x) for x in c])
    bis = np.sqrt(np.mean((c - rev) ** 2, axis=1))
    bases = list(range(n)) if vertical else [k for k in range(n) if bis[k] <= sigma]
    out: list[_Proposal] = []
    periods = _allowed_periods(gap)
    for k0 in bases:
        d = np.sqrt(np.mean((c - c[k0]) ** 2, axis=1))
        angle = k0 * gap
        if vertical:
            fold = min(angle % 180.0, 180.0 - angle % 180.0)
            pref: tuple[Any, ...] = (round(fold, 6), angle)
        else:
            pref = (round(angle % 180.0, 6), angle)
        if float(d.max()) <= sigma:
            out.append(_Proposal("flat", 0.0, k0, (0, 0.0, *pref)))
        for m in periods:
            p = m * gap / 2.0
            if _reflection_error(d, k0, m, round(180.0 / p)) <= sigma:
                out.append(_Proposal("period", p, k0, (1, p, *pref)))
        if _reflection_error(d, k0, 0, 1) <= sigma:
            out.append(_Proposal("single", 180.0, k0, (2, 180.0, *pref)))
    # Mirror centres half-way between grid views have no base view; a reflection there is
    # tested on the curves directly: (c + d) mirrored of (c - d) on the horizontal ring,
    # (c + d) the same as (c - d) on the vertical one.
    k = np.arange(n)
    for c2 in range(1, n, 2):  # centres in [0, 180): c and c + 180 are the same reflection
        other = c[(c2 - k) % n] if vertical else rev[(c2 - k) % n]
        if float(np.sqrt(np.mean((c - other) ** 2, axis=1)).max()) <= sigma:
            angle = c2 * gap / 2.0
            fold = min(angle % 180.0, 180.0 - angle % 180.0) if vertical else angle % 180.0
            out.append(_Proposal("single", 180.0, c2 // 2, (2, 180.0, round(fold, 6), angle), c2))
    out.sort(key=lambda p: p.rank)
    return out, bis


@dataclass
class _Hypothesis:
    name: str
    label: str
    period: float
    base: float
    generators: list[Generator]
    v0: float = 0.0


def _h_hypotheses(props: list[_Proposal], gap: float) -> list[_Hypothesis]:
    out: list[_Hypothesis] = []
    for p in props:
        b = p.centre * gap / 2.0
        if p.label == "flat":
            out.append(_Hypothesis(f"H1@{b:g}", "H1", 0.0, b, [("rot_y", gap), ("mirror_azimuth", b)]))
        elif p.period >= 90.0:
            out.append(_Hypothesis(f"H2@{b:g}", "H2", 90.0, b, [("mirror_azimuth", b)]))
        else:
            P = p.period
            out.append(
                _Hypothesis(f"H3/{P:g}@{b:g}", "H3", P, b, [("mirror_azimuth", b), ("mirror_azimuth", b + P)])
            )
            k = 90.0 / P
            if abs(k - round(k)) < 1e-9 and round(k) % 2 == 1 and k > 1:
                # an odd number of mirror planes: with the pairing they show a pattern of period P
                out.append(
                    _Hypothesis(
                        f"H3/{P:g}(odd)@{b:g}",
                        "H3",
                        P,
                        b,
                        [("mirror_azimuth", b), ("mirror_azimuth", b + 2 * P)],
                    )
                )
    return out


def _v_hypotheses(props: list[_Proposal], gap: float, b: float) -> list[_Hypothesis]:
    out: list[_Hypothesis] = []
    for p in props:
        v0 = p.centre * gap / 2.0
        if p.label == "flat":
            out.append(
                _Hypothesis(
                    f"V1@{b:g}", "V1", 0.0, b, [("rot_horizontal", gap, b), ("mirror_elevation", 0.0, b)], 0.0
                )
            )
        elif p.period < 90.0:
            P = p.period
            w = _norm(v0, P)
            out.append(
                _Hypothesis(
                    f"V3/{P:g}@{b:g},{w:g}",
                    "V3",
                    P,
                    b,
                    [("mirror_elevation", w, b), ("rot_horizontal", 2 * P, b)],
                    w,
                )
            )
        elif p.period == 90.0:
            w = _norm(v0, 90.0)
            out.append(
                _Hypothesis(
                    f"V2/90@{b:g},{w:g}",
                    "V2",
                    90.0,
                    b,
                    [("mirror_elevation", w, b), ("mirror_elevation", w + 90, b)],
                    w,
                )
            )
            for ww in (w, w + 90.0):
                out.append(_Hypothesis(f"V2@{b:g},{ww:g}", "V2", 90.0, b, [("mirror_elevation", ww, b)], ww))
        else:
            w = _norm(v0, 180.0)
            out.append(_Hypothesis(f"V2@{b:g},{w:g}", "V2", 90.0, b, [("mirror_elevation", w, b)], w))
    return out


class _Verifier:
    """Accepts generators whose relations hold (within σ) on every rendered view."""

    def __init__(self, cache: _CurveCache, gap: float, sigma: float) -> None:
        self.cache = cache
        self.gap = float(gap)
        self.sigma = sigma
        self.accepted: list[Generator] = []
        self.records: list[VerificationRecord] = []
        self._classes = _cached_classes((), float(gap))

    def _in_group(self, gen: Generator) -> bool:
        """True if ``gen`` is an element of the (finite, fully listed) accepted group."""
        elems = group_elements(self.accepted)
        if len(elems) >= 512:
            return False  # truncated: decide by the classes instead
        key = _matrix_key(generator_matrix(gen))
        return any(_matrix_key(e) == key for e in elems)

    @staticmethod
    def _n_labels(vc: ViewClasses) -> int:
        return int(np.unique(vc._labels).size)

    def _rendered(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        idx = np.array(sorted(self.cache.curves), dtype=np.int64)
        return idx, np.array([self.cache.curves[int(i)] for i in idx])

    def _check(self, vc: ViewClasses) -> tuple[int, float]:
        """(related rendered pairs, largest error) of ``vc`` over the rendered views."""
        idx, cur = self._rendered()
        if idx.size == 0:
            return 0, 0.0
        lab = vc._labels[idx]
        cid = np.minimum(lab[:, 0], lab[:, 1])
        selfm = lab[:, 0] == lab[:, 1]
        rev = np.roll(cur[:, ::-1], 1, axis=1)
        first: dict[int, int] = {}
        ref = np.empty(idx.size, dtype=np.int64)
        for r, c in enumerate(cid):
            ref[r] = first.setdefault(int(c), r)
        same_side = lab[:, 0] == lab[ref, 0]
        target = cur[ref]

        def dist(x: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.sqrt(np.mean((x - target) ** 2, axis=1))

        err = np.where(
            selfm, np.maximum(dist(cur), dist(rev)), dist(np.where(same_side[:, None], cur, rev))
        )
        _, counts = np.unique(cid, return_counts=True)
        pairs = int(np.sum(counts * (counts - 1) // 2) + np.count_nonzero(selfm))
        return pairs, float(err.max())

    def try_hypothesis(self, hyp: _Hypothesis) -> tuple[bool, list[Generator]]:
        """Add the hypothesis's generators if all verify.

        Returns ``(ok, generators that changed the classes)``; on failure nothing is kept.
        """
        saved_acc, saved_cls = list(self.accepted), self._classes
        added: list[Generator] = []
        base_pairs, _ = self._check(self._classes)
        for gen in hyp.generators:
            g = canonical_generator(gen)
            if self._in_group(g):
                self.records.append(VerificationRecord(hyp.name, g, "redundant", 0, 0.0))
                continue
            trial = _cached_classes((*self.accepted, g), self.gap)
            if self._n_labels(trial) == self._n_labels(self._classes):
                self.records.append(VerificationRecord(hyp.name, g, "redundant", 0, 0.0))
                continue
            pairs, err = self._check(trial)
            new = pairs - base_pairs
            if new <= 0:
                status = "unverifiable"
            elif err <= self.sigma:
                status = "accepted"
            else:
                status = "rejected"
            self.records.append(VerificationRecord(hyp.name, g, status, new, err))
            if status != "accepted":
                self.accepted, self._classes = saved_acc, saved_cls
                return False, []
            self.accepted.append(g)
            self._classes = trial
            base_pairs = pairs
            added.append(g)
        return True, added


def classify(
    curve_at: CurveFn,
    gap: float = 10.0,
    sigma: float = DEFAULT_SIGMA,
) -> SymmetryType:
    """Classify an object's symmetry from its silhouettes (Algorithm 1, then verification).

    Parameters
    ----------
    curve_at : callable
        ``curve_at(h, v)`` returns the distance curve (mean 1, length N) of the
        silhouette of grid view ``(h, v)``; it is called at most once per view (and not
        for a view whose mirror-image pair was already asked for) — mostly for
        :func:`views_needed_for_classification`, but any grid view may be asked for.
    gap : float
        The server grid gap in degrees.
    sigma : float
        Largest RMS curve difference still counted as the same shape.

    Steps: (a) on the horizontal ring find base views (bisymmetric) and for each the
    shape difference curve and the reflection periods of its pattern (Algorithm 1; no
    base ⇒ H4); (b) turn each proposal, most symmetric first, into generators and verify
    every generator on all rendered views (the rings through the base azimuth and the
    azimuth 90° from it, and an off-ring sample): a generator is kept only if every pair
    of rendered views it relates differs by at most ``sigma``; the first proposal whose
    generators all verify gives the horizontal type (down to H4 = no generator); (c) the
    same on the vertical ring through the base azimuth gives the vertical type, where a
    mirror proposal that the horizontal group already implies (e.g. the vertical plane
    of a cone) does not count as vertical symmetry.
    """
    gap = float(gap)
    n = _n_steps(gap)
    cache = _CurveCache(curve_at, gap)
    for h, v in views_needed_for_classification(gap):
        cache.view(h, v)
    h_ring = [cache.get(k, 0) for k in range(n)]
    h_props, h_bis = _ring_proposals(h_ring, gap, sigma, vertical=False)
    verifier = _Verifier(cache, gap, sigma)

    def ensure(b: float) -> None:
        b = math.floor(b / gap + 1e-9) * gap  # a mirror half-way between views: the view below
        for h, v in _ring_views(gap, b) + _ring_views(gap, b + 90.0) + _sample_views(gap, b):
            cache.view(h, v)

    h_hyp: _Hypothesis | None = None
    tried: set[tuple[Generator, ...]] = set()
    for hyp in _h_hypotheses(h_props, gap):
        key = tuple(sorted(canonical_generator(g) for g in hyp.generators))
        if key in tried:
            continue
        tried.add(key)
        ensure(hyp.base)
        ok, _ = verifier.try_hypothesis(hyp)
        if ok:
            h_hyp = hyp
            break
    if h_hyp is None:
        k_best = int(np.argmin(h_bis))
        b = k_best * gap if h_bis[k_best] <= sigma else 0.0
        h_hyp = _Hypothesis("H4", "H4", 180.0, b, [])
        ensure(b)
    b = h_hyp.base
    kb = math.floor(b / gap + 1e-9)  # the vertical ring: through b, or the view below it
    h_diff = np.sqrt(np.mean((np.array(h_ring) - h_ring[kb % n]) ** 2, axis=1))

    v_ring = [cache.get(kb, k) for k in range(n)]
    v_props, _ = _ring_proposals(v_ring, gap, sigma, vertical=True)
    v_hyp = _Hypothesis("V4", "V4", 180.0, kb * gap, [], 0.0)
    v_base_index = 0
    tried = set()
    for hyp, prop in _v_with_props(v_props, gap, kb * gap):
        key = tuple(sorted(canonical_generator(g) for g in hyp.generators))
        if key in tried:
            continue
        tried.add(key)
        ok, added = verifier.try_hypothesis(hyp)
        if ok and added:
            v_hyp, v_base_index = hyp, prop.base
            break
        # a proposal that holds but adds nothing (all implied by the horizontal group, e.g.
        # the vertical plane of a cone) is not vertical symmetry: keep looking
    # Beyond the types: half turns without a mirror plane (a 2-fold vertical axis, or one
    # along the horizontal axes of the vertical rings), proposed when the ring repeats
    # after 180 degrees and verified like the rest; they do not change the type labels.
    if n % 2 == 0:
        half = n // 2
        extras: list[tuple[list[NDArray[np.float64]], Generator]] = [(h_ring, ("rot_y", 180.0))]
        extras.append((v_ring, ("rot_horizontal", 180.0, kb * gap)))
        if _on_grid(kb * gap + 90.0, gap):
            k90 = round((kb * gap + 90.0) / gap)
            extras.append(([cache.get(k90, k) for k in range(n)], ("rot_horizontal", 180.0, k90 * gap)))
        for ring, gen in extras:
            arr = np.array(ring)
            if float(np.sqrt(np.mean((arr - np.roll(arr, -half, axis=0)) ** 2, axis=1)).max()) <= sigma:
                verifier.try_hypothesis(_Hypothesis("2-fold", "", 0.0, b, [gen]))
    elif float(h_bis.max()) <= sigma:  # odd grid: the vertical half turn gives (h, v) =~ (h, -v)
        verifier.try_hypothesis(_Hypothesis("2-fold", "", 0.0, b, [("rot_y", 180.0)]))
    v_diff = np.sqrt(np.mean((np.array(v_ring) - v_ring[v_base_index]) ** 2, axis=1))
    return SymmetryType(
        h_type=h_hyp.label,
        v_type=v_hyp.label,
        h_period=float(h_hyp.period),
        v_period=float(v_hyp.period),
        base_azimuth=_norm(b),
        base_elevation=_norm(v_hyp.v0),
        generators=tuple(verifier.accepted),
        h_difference=tuple(float(x) for x in h_diff),
        v_difference=tuple(float(x) for x in v_diff),
        gap=gap,
        sigma=float(sigma),
        verification=tuple(verifier.records),
        views_rendered=cache.calls,
    )


def _v_with_props(props: list[_Proposal], gap: float, b: float) -> list[tuple[_Hypothesis, _Proposal]]:
    out = []
    for p in props:
        for hyp in _v_hypotheses([p], gap, b):
            out.append((hyp, p))
    return out
