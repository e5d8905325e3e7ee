"""An object's symmetry type from its silhouettes (Tak & Hwang, II.B and III.D, Algorithm 1).

:func:`classify` proposes symmetries from the horizontal ring of views and the vertical
ring through the base azimuth (Algorithm 1: base views, and the reflection periods of
their shape difference curves), turns each proposal, most symmetric first, into
generators and keeps a generator only when every pair of rendered views it relates
differs by at most ``sigma`` (RMS of distance curves with mean 1).  The result is a
:class:`SymmetryType`: the paper's types H1-H4 x V1-V4, the verified generators whose
view rules :mod:`viewdb.catalogue.skimming` applies, and every check made
(:attr:`SymmetryType.verification`), so pruning is never lossy by more than ``sigma`` on
what was checked.  Silhouettes come in as curves through a callback.

:data:`DEFAULT_SIGMA` (:class:`~viewdb.config.SkimConfig`) is 2.5x the worst difference
measured between truly equal views of the sample models and far below the errors of
wrong generators.  The classification step by step, the views it renders and the
measurements behind the default sigma are in ``docs/skimming.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..config import SkimConfig
from .features import mirror_curve
from .skimming import (
    Generator,
    ViewClasses,
    cached_classes,
    canonical_angle,
    canonical_generator,
    generator_matrix,
    grid_steps,
    group_elements,
    matrix_key,
)

__all__ = [
    "DEFAULT_SIGMA",
    "SymmetryType",
    "VerificationRecord",
    "classify",
    "shape_distance",
    "views_needed_for_classification",
]

#: Default tolerance of :func:`classify`: the RMS difference (curves have mean 1) below
#: which two distance curves count as the same shape (``docs/skimming.md``: the
#: measurements it is based on).
DEFAULT_SIGMA = SkimConfig().sigma


def shape_distance(a: NDArray[np.floating], b: NDArray[np.floating]) -> float:
    """RMS difference of two distance curves (Euclidean distance / sqrt(N))."""
    x, y = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return float(np.sqrt(np.mean((x - y) ** 2)))



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

    ``generators`` (canonical, see :func:`~viewdb.catalogue.skimming.canonical_generator`)
    are what pruning uses (:func:`~viewdb.catalogue.skimming.skim_plan`); the type labels
    and periods are the paper's vocabulary for them.  ``h_difference[k]`` is the shape
    difference (RMS) of view ``(k·gap, 0)`` to the base view ``(base_azimuth, 0)``;
    ``v_difference[k]`` that of ``(base_azimuth, k·gap)`` to ``(base_azimuth,
    base_elevation)`` (the vertical base as the ring's view index: the reported
    ``base_elevation`` is the smallest equivalent reflection centre).
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
        self.n = grid_steps(gap)
        self.curves: dict[int, NDArray[np.float64]] = {}
        self.calls = 0

    def get(self, ih: int, iv: int) -> NDArray[np.float64]:
        n = self.n
        i = (ih % n) * n + iv % n
        if i not in self.curves:
            j = _pair_index(i, n)
            if j is not None and j in self.curves:
                self.curves[i] = mirror_curve(self.curves[j])
            else:
                h, v = float((ih % n) * self.gap), float((iv % n) * self.gap)
                c = np.asarray(self.curve_at(h, v), dtype=np.float64)
                self.calls += 1
                self.curves[i] = c
                if j is not None and j not in self.curves:
                    self.curves[j] = mirror_curve(c)
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
    n = grid_steps(gap)
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
                view = (canonical_angle(base + off), canonical_angle(el))
                if view not in out and _on_grid(view[0], gap) and _on_grid(view[1], gap):
                    out.append(view)
    return out


def _on_grid(angle: float, gap: float) -> bool:
    q = angle / gap
    return abs(q - round(q)) < 1e-9


def _ring_views(gap: float, base: float) -> list[tuple[float, float]]:
    """The vertical ring ``(base, v)``, all ``v`` (empty if ``base`` is not on the grid)."""
    n = grid_steps(gap)
    if not _on_grid(base, gap):
        return []
    return [(canonical_angle(base), canonical_angle(k * gap)) for k in range(n)]


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
    n = grid_steps(gap)
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
        out.append((canonical_angle(h), canonical_angle(v)))
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
    rev = mirror_curve(c)
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
            w = canonical_angle(v0, P)
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
            w = canonical_angle(v0, 90.0)
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
            w = canonical_angle(v0, 180.0)
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
        self._classes = cached_classes((), float(gap))

    def _in_group(self, gen: Generator) -> bool:
        """True if ``gen`` is an element of the (finite, fully listed) accepted group."""
        elems = group_elements(self.accepted)
        if len(elems) >= 512:
            return False  # truncated: decide by the classes instead
        key = matrix_key(generator_matrix(gen))
        return any(matrix_key(e) == key for e in elems)

    @staticmethod
    def _n_labels(vc: ViewClasses) -> int:
        return int(np.unique(vc.labels).size)

    def _rendered(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        idx = np.array(sorted(self.cache.curves), dtype=np.int64)
        return idx, np.array([self.cache.curves[int(i)] for i in idx])

    def _check(self, vc: ViewClasses) -> tuple[int, float]:
        """(related rendered pairs, largest error) of ``vc`` over the rendered views."""
        idx, cur = self._rendered()
        if idx.size == 0:
            return 0, 0.0
        lab = vc.labels[idx]
        cid = np.minimum(lab[:, 0], lab[:, 1])
        selfm = lab[:, 0] == lab[:, 1]
        rev = mirror_curve(cur)
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
            trial = cached_classes((*self.accepted, g), self.gap)
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
    n = grid_steps(gap)
    cache = _CurveCache(curve_at, gap)
    for h, v in views_needed_for_classification(gap):
        cache.view(h, v)
    h_ring = [cache.get(k, 0) for k in range(n)]
    h_props, h_bis = _ring_proposals(h_ring, gap, sigma, vertical=False)
    verifier = _Verifier(cache, gap, sigma)
    h_hyp = _horizontal_type(h_props, h_bis, cache, verifier)
    b = h_hyp.base
    kb = math.floor(b / gap + 1e-9)  # the vertical ring: through b, or the view below it
    h_diff = np.sqrt(np.mean((np.array(h_ring) - h_ring[kb % n]) ** 2, axis=1))

    v_ring = [cache.get(kb, k) for k in range(n)]
    v_props, _ = _ring_proposals(v_ring, gap, sigma, vertical=True)
    v_hyp, v_base_index = _vertical_type(v_props, kb * gap, verifier)
    _try_half_turns(h_ring, v_ring, h_bis, kb, b, cache, verifier)
    v_diff = np.sqrt(np.mean((np.array(v_ring) - v_ring[v_base_index]) ** 2, axis=1))
    return SymmetryType(
        h_type=h_hyp.label,
        v_type=v_hyp.label,
        h_period=float(h_hyp.period),
        v_period=float(v_hyp.period),
        base_azimuth=canonical_angle(b),
        base_elevation=canonical_angle(v_hyp.v0),
        generators=tuple(verifier.accepted),
        h_difference=tuple(float(x) for x in h_diff),
        v_difference=tuple(float(x) for x in v_diff),
        gap=gap,
        sigma=float(sigma),
        verification=tuple(verifier.records),
        views_rendered=cache.calls,
    )


def _ensure_around(cache: _CurveCache, b: float) -> None:
    """Render the rings through ``b`` and ``b + 90`` and the verification sample around
    ``b`` (a mirror half-way between views: around the view below it)."""
    gap = cache.gap
    b = math.floor(b / gap + 1e-9) * gap
    for h, v in _ring_views(gap, b) + _ring_views(gap, b + 90.0) + _sample_views(gap, b):
        cache.view(h, v)


def _horizontal_type(
    props: list[_Proposal], bis: NDArray[np.float64], cache: _CurveCache, verifier: _Verifier
) -> _Hypothesis:
    """The first horizontal proposal whose generators all verify, else H4 (based on the
    most bisymmetric ring view, if it is bisymmetric within sigma)."""
    gap, sigma = cache.gap, verifier.sigma
    tried: set[tuple[Generator, ...]] = set()
    for hyp in _h_hypotheses(props, gap):
        key = tuple(sorted(canonical_generator(g) for g in hyp.generators))
        if key in tried:
            continue
        tried.add(key)
        _ensure_around(cache, hyp.base)
        ok, _ = verifier.try_hypothesis(hyp)
        if ok:
            return hyp
    k_best = int(np.argmin(bis))
    b = k_best * gap if bis[k_best] <= sigma else 0.0
    _ensure_around(cache, b)
    return _Hypothesis("H4", "H4", 180.0, b, [])


def _vertical_type(props: list[_Proposal], b: float, verifier: _Verifier) -> tuple[_Hypothesis, int]:
    """The first vertical proposal whose generators verify and add something to the
    horizontal group, with its base's ring index; else V4."""
    tried: set[tuple[Generator, ...]] = set()
    for hyp, prop in _v_with_props(props, verifier.gap, b):
        key = tuple(sorted(canonical_generator(g) for g in hyp.generators))
        if key in tried:
            continue
        tried.add(key)
        ok, added = verifier.try_hypothesis(hyp)
        if ok and added:
            return hyp, prop.base
        # a proposal that holds but adds nothing (all implied by the horizontal group, e.g.
        # the vertical plane of a cone) is not vertical symmetry: keep looking
    return _Hypothesis("V4", "V4", 180.0, b, [], 0.0), 0


def _try_half_turns(
    h_ring: list[NDArray[np.float64]], v_ring: list[NDArray[np.float64]], h_bis: NDArray[np.float64],
    kb: int, b: float, cache: _CurveCache, verifier: _Verifier,
) -> None:
    """Beyond the types: half turns without a mirror plane (a 2-fold vertical axis, or one
    along the horizontal axes of the vertical rings), proposed when the ring repeats
    after 180 degrees and verified like the rest; they do not change the type labels."""
    gap, sigma, n = cache.gap, verifier.sigma, cache.n
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


def _v_with_props(props: list[_Proposal], gap: float, b: float) -> list[tuple[_Hypothesis, _Proposal]]:
    out = []
    for p in props:
        for hyp in _v_hypotheses([p], gap, b):
            out.append((hyp, p))
    return out
