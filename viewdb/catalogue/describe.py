"""Describing an object: render its views and compute every stored feature.

This is the compute half of an ingest and touches no database: it turns a
:class:`~viewdb.catalogue.mesh.NormalisedMesh` into an :class:`ObjectDescription` (picklable, so a
worker process can hand it back to the writer).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Collection, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..camera import grid_views, sphere_views
from ..config import AppearanceConfig, BuildConfig
from ..errors import FeatureError
from .appearance import Appearance, appearance_of, carries_colour, opposite_view, turned_render, turned_view
from .features import distance_curve, fourier_point
from .mesh import NormalisedMesh
from .render import RenderedView, Renderer, get_renderer
from .sift import SiftFeatures, extract_sift, lift_points
from .skimming import plan_without_skimming, skim_plan
from .symmetry import SymmetryType, classify

__all__ = [
    "EVERY_VIEW",
    "ObjectDescription",
    "PerspectiveView",
    "ViewDescription",
    "appearance_scope",
    "appearance_views",
    "classify_object",
    "describe_appearance",
    "describe_object",
    "describe_perspective",
    "describe_view",
    "lacking_views",
    "perspective_grid",
    "recorded_views",
]

#: The appearance scope of an object whose records cover every grid direction
#: (:attr:`~viewdb.config.AppearanceConfig.every_view`; schema revision 0008's
#: ``appearance_scopes``).
EVERY_VIEW = "every"


@dataclass(frozen=True, eq=False)
class ViewDescription:
    """Everything stored for one view."""

    azimuth: float
    elevation: float
    #: Centroid distance curve, float32 (N,), mean 1.
    curve: NDArray[np.float32] = field(repr=False)
    #: First m orthonormal DFT coefficients of ``curve`` (as stored, float32), complex128.
    fourier: NDArray[np.complex128] = field(repr=False)
    sift: SiftFeatures = field(repr=False)


@dataclass(frozen=True, eq=False)
class PerspectiveView:
    """A perspective silhouette of a view direction: only its distance curve is stored."""

    azimuth: float
    elevation: float
    #: Camera distance from the model's centre, in bounding radii.
    distance: float
    #: Centroid distance curve, float32 (N,), mean 1.
    curve: NDArray[np.float32] = field(repr=False)


@dataclass(frozen=True, eq=False)
class ObjectDescription:
    """An object ready to be written: its normalised mesh and its described views."""

    name: str
    source: str
    content_hash: str
    centre: NDArray[np.float64] = field(repr=False)
    scale: float
    n_faces: int
    n_vertices: int
    glb: bytes = field(repr=False)
    views: list[ViewDescription] = field(repr=False)
    #: Grid views that gave no usable silhouette (e.g. a flat part seen edge-on).
    empty_views: list[tuple[float, float]]
    seconds: float
    #: The object's symmetry type (always classified, also without skimming).
    symmetry: SymmetryType | None = None
    #: Whether only the views the skim plan keeps were described.
    skimmed: bool = False
    #: Perspective silhouettes (:func:`describe_perspective`); empty when the build
    #: configuration has none.
    perspective: list[PerspectiveView] = field(default_factory=list, repr=False)
    #: The appearance of every direction of :func:`recorded_views`.
    appearance: list[Appearance] = field(default_factory=list, repr=False)
    #: :data:`EVERY_VIEW` when ``appearance`` covers every grid direction, else None.
    appearance_scope: str | None = None


def describe_view(view: RenderedView, config: BuildConfig) -> ViewDescription:
    """Shape and SIFT features of one rendered view.

    Raises
    ------
    FeatureError
        The silhouette is empty or degenerate.
    """
    curve = distance_curve(view.mask, config.features.curve_samples).astype(np.float32)
    fourier = fourier_point(curve.astype(np.float64), config.features.fourier_coefficients)
    keypoints, descriptors = extract_sift(view.color, view.mask, config.sift.max_keypoints)
    points, valid = lift_points(keypoints[:, :2], view.depth, view.pose, config.render.xmag)
    sift = SiftFeatures(keypoints[valid], descriptors[valid], points[valid])
    return ViewDescription(view.azimuth, view.elevation, curve, fourier, sift)


def classify_object(
    mesh: NormalisedMesh, config: BuildConfig, renderer: Renderer | None = None
) -> SymmetryType:
    """The symmetry type of ``mesh`` from silhouette-only renders (Algorithm 1 + checks).

    Only the views classification needs are rendered (the rings and a verification
    sample, depth only); a view with no silhouette gets an all-zero curve, which matches
    no real shape.
    """
    renderer = renderer or get_renderer(config.render)
    samples = config.features.curve_samples

    def curve_at(azimuth: float, elevation: float) -> NDArray[np.float64]:
        mask = renderer.render(mesh, azimuth, elevation, shaded=False).mask
        try:
            return distance_curve(mask, samples)
        except FeatureError:
            return np.zeros(samples)

    return classify(curve_at, config.gap, config.skim.sigma)


def perspective_grid(config: BuildConfig) -> list[tuple[float, float, float]]:
    """``(azimuth, elevation, distance)`` of every perspective view the configuration asks
    for: its grid's views (never finer than the server grid; :attr:`PerspectiveConfig.grid`)
    at each distance."""
    layout = sphere_views if config.perspective.grid == "sphere" else grid_views
    grid = layout(config.perspective_gap)
    return [(h, v, d) for d in config.perspective.distances for h, v in grid]


def describe_perspective(
    mesh: NormalisedMesh,
    config: BuildConfig,
    renderer: Renderer | None = None,
    on_view: Callable[[int], None] | None = None,
) -> list[PerspectiveView]:
    """The perspective silhouettes of :func:`perspective_grid`, skimmed of repeats.

    At each distance a view whose curve lies within :attr:`PerspectiveConfig.tolerance`
    of a view already kept is left out: it would be found at the same distance, give or
    take that much (an exactly axisymmetric object's views around its axis, a box's
    faces). Views with no silhouette are left out too. ``on_view(1)`` after each render.
    """
    renderer = renderer or get_renderer(config.render)
    samples = config.features.curve_samples
    tolerance = config.perspective.tolerance
    # the older files' threshold: an RMS difference of the skimming sigma
    limit = config.skim.sigma * math.sqrt(samples) if tolerance is None else tolerance
    grid = perspective_grid(config)
    kept: list[PerspectiveView] = []
    # the curves kept so far at each distance, filled row by row
    kept_curves = {d: np.empty((len(grid), samples)) for d in config.perspective.distances}
    n_kept = dict.fromkeys(config.perspective.distances, 0)
    for azimuth, elevation, distance in grid:
        mask = renderer.perspective_mask(mesh, azimuth, elevation, distance)
        if on_view is not None:
            on_view(1)
        try:
            curve = distance_curve(mask, samples)
        except FeatureError:
            continue
        same = kept_curves[distance][: n_kept[distance]]
        if len(same) and float(np.min(np.sqrt(np.sum((same - curve) ** 2, axis=1)))) < limit:
            continue
        kept_curves[distance][n_kept[distance]] = curve
        n_kept[distance] += 1
        kept.append(PerspectiveView(azimuth, elevation, distance, curve.astype(np.float32)))
    return kept


def appearance_views(
    stored: list[tuple[float, float]], config: AppearanceConfig,
    grid: Sequence[tuple[float, float]] = (),
) -> list[tuple[float, float]]:
    """The views whose appearance is recorded for an object with ``stored`` views, one per
    viewing direction (a view whose turned twin,
    :func:`~viewdb.catalogue.appearance.turned_view`, is already recorded is left out):
    each stored view, and the view opposite each
    (:func:`~viewdb.catalogue.appearance.opposite_view`, the side a mirrored match shows)
    when that adds at most ``config.opposite_cost`` of the stored views' renders; and every
    view of ``grid`` (the whole grid: :func:`recorded_views`)."""

    def directions(views: list[tuple[float, float]]) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        seen: set[tuple[float, float]] = set()
        for view in views:
            if view not in seen and turned_view(*view) not in seen:
                seen.add(view)
                out.append(view)
        return out

    both = directions([*stored, *(opposite_view(h, v) for h, v in stored)])
    if grid:
        return directions([*both, *grid])
    if len(both) <= (1.0 + config.opposite_cost) * len(stored):
        return both
    return directions(stored)


def _render_views(
    mesh: NormalisedMesh, views: list[tuple[float, float]], renderer: Renderer,
) -> Iterator[RenderedView]:
    """Renders of ``views`` (in any order): a view whose turned twin is also asked for is
    rendered once, the twin turned by 180° from it
    (:func:`~viewdb.catalogue.appearance.turned_render`)."""
    wanted = set(views)
    done: set[tuple[float, float]] = set()
    for view in views:
        if view in done:
            continue
        rendered = renderer.render(mesh, *view)
        done.add(view)
        yield rendered
        twin = turned_view(*view)
        if twin in wanted and twin not in done:
            done.add(twin)
            yield turned_render(rendered)


def recorded_views(config: BuildConfig, stored: list[tuple[float, float]]
                   ) -> tuple[list[tuple[float, float]], str | None]:
    """The views whose appearance an ingest records for an object stored with views
    ``stored`` (:func:`appearance_views`; the whole grid with
    :attr:`~viewdb.config.AppearanceConfig.every_view`), and the scope the file marks the
    object with (:data:`EVERY_VIEW`, or None)."""
    grid = grid_views(config.gap) if config.appearance.every_view else ()
    return appearance_views(stored, config.appearance, grid), appearance_scope(config)


def appearance_scope(config: BuildConfig) -> str | None:
    """The scope a file marks an object's appearance records with when ``config`` made them
    (:data:`EVERY_VIEW` with :attr:`~viewdb.config.AppearanceConfig.every_view`, else None)."""
    return EVERY_VIEW if config.appearance.every_view else None


def lacking_views(
    config: BuildConfig, stored: list[tuple[float, float]], recorded: Collection[tuple[float, float]],
) -> tuple[list[tuple[float, float]], str | None]:
    """The views of :func:`recorded_views` whose direction ``recorded`` (the views an
    object has records of) lacks (a view's turned twin's record serves it), and the scope."""
    wanted, scope = recorded_views(config, stored)
    have = set(recorded)
    return [view for view in wanted if view not in have and turned_view(*view) not in have], scope


def describe_appearance(
    mesh: NormalisedMesh, config: BuildConfig, stored: list[tuple[float, float]],
    renderer: Renderer | None = None, on_view: Callable[[int], None] | None = None,
    recorded: Collection[tuple[float, float]] = (),
) -> tuple[list[Appearance], str | None]:
    """The appearance records of an object stored with views ``stored`` (its
    :func:`recorded_views`; views without a silhouette have none) that ``recorded`` (the
    views it has records of) lacks, and its scope. ``on_view(1)`` after each."""
    todo, scope = lacking_views(config, stored, recorded)
    if not todo:
        return [], scope
    renderer = renderer or get_renderer(config.render)
    coloured = carries_colour(mesh)
    records = []
    for rendered in _render_views(mesh, todo, renderer):
        if rendered.mask.any():
            records.append(appearance_of(rendered, config.appearance, coloured))
        if on_view is not None:
            on_view(1)
    return records, scope


def describe_object(
    mesh: NormalisedMesh,
    config: BuildConfig,
    *,
    skim: bool = True,
    on_view: Callable[[int], None] | None = None,
) -> ObjectDescription:
    """Classify ``mesh``, then render and describe the views to store, and record the
    appearance of them (and of the views opposite them: :func:`appearance_views`).

    With ``skim`` only the views of the skim plan are described; otherwise the whole
    grid. ``on_view(n)`` is told of every ``n`` grid views dealt with (pruned views count
    as dealt with when the plan is made). A view whose turned twin is also rendered is
    made from the twin's render (:func:`~viewdb.catalogue.appearance.turned_render`).
    """
    start = time.perf_counter()
    renderer = get_renderer(config.render)
    symmetry = classify_object(mesh, config, renderer)
    plan = skim_plan(symmetry, config.gap) if skim else plan_without_skimming(config.gap)
    views = list(plan.kept)
    if on_view is not None and plan.views_grid > plan.views_stored:
        on_view(plan.views_grid - plan.views_stored)
    kept = set(views)
    recorded, scope = recorded_views(config, views)
    to_record = set(recorded)
    coloured = carries_colour(mesh)
    described: dict[tuple[float, float], ViewDescription] = {}
    empty: list[tuple[float, float]] = []
    appearance: dict[tuple[float, float], Appearance] = {}
    extra = [view for view in recorded if view not in kept]
    for rendered in _render_views(mesh, views + extra, renderer):
        view = (rendered.azimuth, rendered.elevation)
        if view in to_record and rendered.mask.any():
            appearance[view] = appearance_of(rendered, config.appearance, coloured)
        if view not in kept:
            continue
        try:
            described[view] = describe_view(rendered, config)
        except FeatureError:
            empty.append(view)
        if on_view is not None:
            on_view(1)
    perspective = describe_perspective(mesh, config, renderer, on_view)
    return ObjectDescription(
        name=mesh.name,
        source=mesh.source,
        content_hash=mesh.content_hash,
        centre=np.asarray(mesh.centre, dtype=np.float64),
        scale=float(mesh.scale),
        n_faces=mesh.n_faces,
        n_vertices=mesh.n_vertices,
        glb=mesh.to_glb(),
        views=[described[view] for view in views if view in described],
        empty_views=[view for view in views if view in set(empty)],
        seconds=time.perf_counter() - start,
        symmetry=symmetry,
        skimmed=skim,
        perspective=perspective,
        appearance=[appearance[view] for view in recorded if view in appearance],
        appearance_scope=scope,
    )
