"""The read side of a viewdb file: its objects, any view of them (stored, or rendered from
the stored mesh and described on demand), any view's appearance (stored, or rendered and
recorded on demand), renders, meshes, curves, and its tiers for the k-NN search (read
snapshots, which the callers hand to :func:`viewdb.search.route.nearest_candidates`).

:class:`StoredCatalogue` implements :class:`viewdb.catalogue.reading.CatalogueReader`. It
keeps bounded caches of what is dear to make (decoded meshes, renders, regenerated views,
an object's curves); :meth:`StoredCatalogue.forget` drops an object's entries when it is
written again.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import replace
from functools import cached_property
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from ..camera import camera_direction, grid_views, normalise_angle
from ..catalogue.appearance import BINS, Appearance, appearance_of, carries_colour, turned_view
from ..catalogue.describe import describe_view
from ..catalogue.features import mirror_curve
from ..catalogue.look import LookModel
from ..catalogue.look_training import look_key
from ..catalogue.mesh import NormalisedMesh, mesh_from_glb
from ..catalogue.reading import CandidatePose, ObjectInfo, StoredView
from ..catalogue.render import RenderedView, get_renderer
from ..catalogue.skimming import ViewClasses, image_twins, plan_without_skimming, skim_plan
from ..catalogue.symmetry import SymmetryType
from ..config import BuildConfig, SearchConfig
from ..errors import FeatureError, NotFound, QueryError
from ..search.colour_index import ColourIndex
from ..search.knn import TierArrays, objects_within
from ..search.refine import scan_all
from .appearances import decode_record, decode_signature
from .store import ObjectRow, Store
from .tiers import TIERS, TierReader

__all__ = ["StoredCatalogue"]

#: How many decoded meshes a catalogue keeps in memory: at least the k results a query
#: re-ranks by silhouette fit (each fitted quickly, the best two again), and as many as the
#: pinhole renderer keeps triangles for (:data:`~viewdb.catalogue.pinhole.TRIANGLE_CACHE_MESHES`,
#: by the mesh's identity: a mesh decoded again is decimated again).
MESH_CACHE_SIZE = 32
#: How many regenerated (pruned or off-grid) views a catalogue keeps in memory.
VIEW_CACHE_SIZE = 256
#: How many renders (about 0.5 MB each) a catalogue keeps: posing a result renders its
#: candidate views, then walks off the grid around the best, and the walk's steps overlap.
RENDER_CACHE_SIZE = 64
#: How many objects' stored curves a catalogue keeps in memory for CS2 walks.
CURVE_CACHE_OBJECTS = 64
#: How many views' appearance records (read and decoded, or made from a render) a
#: catalogue keeps in memory, about 70 kB each.
APPEARANCE_CACHE_VIEWS = 1024

_K = TypeVar("_K")
_V = TypeVar("_V")


def cached(cache: OrderedDict[_K, _V], key: _K, make: Callable[[], _V], limit: int) -> _V:
    """``cache[key]``, made by ``make()`` when missing (an exception caches nothing); the
    least recently used entries go past ``limit``."""
    if key in cache:
        cache.move_to_end(key)
        return cache[key]
    value = cache[key] = make()
    while len(cache) > limit:
        cache.popitem(last=False)
    return value


class StoredCatalogue:
    """The read side of an open :class:`~viewdb.storage.store.Store` built with ``config``."""

    def __init__(self, store: Store, config: BuildConfig, *, stored_appearance: bool = True) -> None:
        """``stored_appearance=False`` ignores the file's appearance records and makes every
        view's from a render, as for a file without them (to measure what they save)."""
        self._store = store
        self.config = config
        self.stored_appearance = stored_appearance
        #: Whether a view without a record takes an image twin's (:meth:`_symmetric_appearance`);
        #: False renders it instead (to measure what that saves).
        self.image_twins = True
        self._meshes: OrderedDict[str, NormalisedMesh] = OrderedDict()
        self._regenerated: OrderedDict[tuple[str, float, float], StoredView] = OrderedDict()
        self._renders: OrderedDict[tuple[str, float, float], RenderedView] = OrderedDict()
        self._curves: OrderedDict[str, dict[tuple[float, float], NDArray[np.float32]]] = OrderedDict()
        self._plans: dict[str, ViewClasses] = {}
        self._derived: dict[str, OrderedDict[tuple[Any, ...], Any]] = {}
        self._reader: TierReader | None = None
        self._role: str | None = None
        self._colour_index: ColourIndex | None = None
        #: The look model read and its catalogue key (``False``: not read yet; None: none valid).
        self._look: tuple[str, LookModel] | None | bool = False
        self._look_key: str | None = None

    @property
    def path(self) -> Path:
        return self._store.path

    @property
    def role(self) -> str:
        """``"full"`` (meshes, SIFT, both tiers) or ``"client"`` (an exported client file)."""
        if self._role is None:
            self._role = self._store.role()
        return self._role

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None

    def forget(self, name: str) -> None:
        """Drop what is cached of object ``name`` (it was written again)."""
        if self._reader is not None:
            self._reader.written()
        self._curves.clear()
        self._colour_index = None
        self._look = False
        self._look_key = None
        self._meshes.pop(name, None)
        self._plans.pop(name, None)
        caches: list[OrderedDict[Any, Any]] = [self._regenerated, self._renders, *self._derived.values()]
        for cache in caches:  # each keyed by a tuple starting with the object's name
            for key in [k for k in cache if k[0] == name]:
                del cache[key]

    def colour_index(self) -> ColourIndex:
        """The colour channel's index (:mod:`viewdb.search.colour_index`): the stored colour
        signatures of every coloured object's views on a grid of
        :attr:`~viewdb.config.SearchConfig.colour_grid` degrees (a multiple of the file's
        grid), read once; an object without colour, or without stored appearance records
        (a file from before revision 0005), is not in it."""
        if self._colour_index is None:
            gap = self.config.gap
            step = gap * max(1, round(SearchConfig().colour_grid / gap))
            names, views, signatures = [], [], []
            if self.stored_appearance:
                for name, azimuth, elevation, data in self._store.grid_appearance_records(step):
                    signature = decode_signature(data)
                    if signature is not None:
                        names.append(name)
                        views.append((azimuth, elevation))
                        signatures.append(signature)
            rows = np.asarray(signatures, np.float64).reshape(len(names), BINS * BINS)
            self._colour_index = ColourIndex(names, np.asarray(views, np.float64).reshape(-1, 2), rows)
        return self._colour_index

    def look_key(self) -> str:
        """What a look model of this file's objects is fitted for
        (:func:`~viewdb.catalogue.look_training.look_key`; computed once)."""
        if self._look_key is None:
            self._look_key = look_key(self._store.object_hashes())
        return self._look_key

    def forget_look(self) -> None:
        """Read the look model afresh next time (it was written again)."""
        self._look = False
        self._look_key = None

    def look_model(self) -> LookModel | None:
        """The look model (:mod:`viewdb.catalogue.look`) stored by the last ingest, or None
        when there is none or it was fitted for other objects (never trusted stale)."""
        found = self.shard_look()
        return found[1] if found is not None and found[0] == self.look_key() else None

    def shard_look(self) -> tuple[str, LookModel] | None:
        """The stored look model and the key of the catalogue it serves, when this file's
        objects are still those it was stored with (read once). A shard's model serves
        every shard: the sharded tier checks that all of them serve the same catalogue."""
        if self._look is False:
            stored = self._store.look_model()
            found = None
            if stored is not None and stored.own == self.look_key():
                try:
                    found = (stored.key, LookModel.from_bytes(stored.model))
                except ValueError:
                    found = None
            self._look = found
        return self._look if isinstance(self._look, tuple) else None

    def derived(self, kind: str, key: tuple[Any, ...], make: Callable[[], _V], limit: int) -> _V:
        """A bounded cache of what later stages derive from this file's data (e.g. colour
        signatures of renders), by ``kind``; ``key`` starts with the object's name, so
        :meth:`forget` drops it with the object."""
        return cached(self._derived.setdefault(kind, OrderedDict()), key, make, limit)

    # ------------------------------------------------------------------ objects
    def _info(self, row: ObjectRow) -> ObjectInfo:
        return ObjectInfo(
            name=row.name, source=row.source, content_hash=row.content_hash,
            n_faces=row.n_faces, n_vertices=row.n_vertices, scale=row.scale,
            centre=row.centre, views_stored=row.views,
            views_grid=len(grid_views(self.config.gap)), empty_views=row.empty_views,
            ingest_seconds=row.ingest_seconds, created_at=row.created_at,
            skimmed=row.skimmed,
            symmetry=None if row.symmetry is None else SymmetryType.from_dict(row.symmetry),
            perspective_views=row.perspective_views, appearances=row.appearances,
        )

    def objects(self) -> list[ObjectInfo]:
        """Every object, by name."""
        return [self._info(r) for r in self._store.objects()]

    def object(self, name: str) -> ObjectInfo:
        rows = self._store.objects(name)
        if not rows:
            raise NotFound(f"no object named {name!r}", self.path)
        return self._info(rows[0])

    def views(self, name: str) -> list[tuple[float, float]]:
        """``(azimuth, elevation)`` of every stored view of object ``name``."""
        return [(v.azimuth, v.elevation) for v in self._store.views(name)]

    def view_plan(self, name: str) -> ViewClasses:
        """How the object's grid views map to its stored ones (identity if not skimmed)."""
        plan = self._plans.get(name)
        if plan is None:
            info = self.object(name)
            if info.skimmed and info.symmetry is not None:
                plan = skim_plan(info.symmetry, self.config.gap)
            else:
                plan = plan_without_skimming(self.config.gap)
            self._plans[name] = plan
        return plan

    def candidate_poses(self, name: str, azimuth: float, elevation: float) -> list[CandidatePose]:
        """Every grid view with the same or the mirrored silhouette as grid view (h, v).

        The paper's candidate pose extraction (eqs. 1–2), from the object's verified
        symmetry generators; a query matched at one view could be in any of these poses.
        """
        a, e = normalise_angle(azimuth), normalise_angle(elevation)
        stored, classes = self.derived("candidate_classes", (name,), lambda: self._candidate_classes(name),
                                       CURVE_CACHE_OBJECTS)
        try:
            members = classes.members(a, e)
        except ValueError as exc:
            raise QueryError(str(exc)) from exc
        return [CandidatePose(h, v, m, (h, v) in stored) for h, v, m in members]

    def _candidate_classes(self, name: str) -> tuple[frozenset[tuple[float, float]], ViewClasses]:
        """The object's stored views, and the view classes its candidate poses come from."""
        symmetry = self.object(name).symmetry
        classes = skim_plan(symmetry, self.config.gap) if symmetry else self.view_plan(name)
        return frozenset(self.views(name)), classes

    # ------------------------------------------------------------------ views
    def view(self, name: str, azimuth: float, elevation: float) -> StoredView:
        """The features of any view of a stored object.

        A stored view is read from the database; any other (pruned by skimming, or off
        the grid) is rendered from the stored mesh and described, and kept in a bounded
        cache. Either way the result has the same fields.
        """
        a, e = normalise_angle(azimuth), normalise_angle(elevation)
        try:
            f = self._store.view_features(name, a, e)
        except NotFound:
            return cached(self._regenerated, (name, a, e), lambda: self._describe(name, a, e),
                          VIEW_CACHE_SIZE)
        return StoredView(name, a, e, f["curve"], f["fourier"], f["keypoints"],
                          f["descriptors"], f["points3d"])

    def _describe(self, name: str, azimuth: float, elevation: float) -> StoredView:
        stored_as, mirrored = None, False
        try:
            stored_as, mirrored = self.view_plan(name).mapping[(azimuth, elevation)]
        except KeyError:
            pass  # off the grid
        try:
            desc = describe_view(self.render(name, azimuth, elevation), self.config)
        except FeatureError as exc:
            raise NotFound(
                f"object {name!r} has no silhouette at azimuth {azimuth:g}, "
                f"elevation {elevation:g}", self.path,
            ) from exc
        return StoredView(
            name, azimuth, elevation, desc.curve, desc.fourier, desc.sift.keypoints,
            desc.sift.descriptors, desc.sift.points3d, regenerated=True,
            stored_as=stored_as, mirrored=mirrored,
        )

    def appearance(self, name: str, azimuth: float, elevation: float) -> Appearance:
        """The appearance of any view of a stored object: its stored record, or its turned
        twin's turned (:meth:`~viewdb.catalogue.appearance.Appearance.turned`), or a
        recorded view's that the symmetry of a mesh without colour makes the same image
        mirrored or turned (:meth:`_symmetric_appearance`), or, for a view without any
        (pruned by skimming and not opposite a stored view, of a coloured mesh, off the
        grid, or a file from before revision 0005), one made from its render. Cached
        either way."""
        a, e = normalise_angle(azimuth), normalise_angle(elevation)

        def make() -> Appearance:
            if self.stored_appearance:
                twin = turned_view(a, e)
                records = self._store.appearance_records(name, [(a, e), twin])
                size = self.config.render.image_size
                if (a, e) in records:
                    return decode_record(records[(a, e)], a, e, size)
                if twin in records:
                    return decode_record(records[twin], *twin, size).turned()
                derived = self._symmetric_appearance(name, a, e)
                if derived is not None:
                    return derived
            coloured = self.derived("carries_colour", (name,), lambda: carries_colour(self.mesh(name)),
                                    APPEARANCE_CACHE_VIEWS)
            return appearance_of(self.render(name, a, e), self.config.appearance, coloured)

        return self.derived("appearance", (name, a, e), make, APPEARANCE_CACHE_VIEWS)

    def _symmetric_appearance(self, name: str, azimuth: float, elevation: float) -> Appearance | None:
        """The appearance of a view without a record of its own from a recorded view whose
        render is this one's mirrored or turned by the object's symmetry
        (:func:`~viewdb.catalogue.skimming.image_twins`), for a mesh without colour of its
        own (a texture need not share the symmetry of the shape); else None."""
        symmetry = self.object(name).symmetry if self.image_twins else None
        if symmetry is None or not symmetry.generators:
            return None
        twins = image_twins(symmetry, self.config.gap, azimuth, elevation)
        records = self._store.appearance_records(name, [(h, v) for h, v, _, _ in twins])
        for h, v, mirrored, turned in twins:
            if (h, v) in records:
                record = decode_record(records[(h, v)], h, v, self.config.render.image_size)
                if record.signature is not None:
                    return None  # a coloured mesh: its records all have a signature
                if turned:
                    record = replace(record.turned(), azimuth=azimuth, elevation=elevation)
                return (record.mirrored(azimuth, elevation) if mirrored
                        else replace(record, azimuth=azimuth, elevation=elevation))
        return None

    def mesh(self, name: str) -> NormalisedMesh:
        """The stored normalised mesh of ``name`` (decoded once, then cached)."""
        return cached(self._meshes, name, lambda: mesh_from_glb(self._store.mesh_glb(name), name),
                      MESH_CACHE_SIZE)

    def render(self, name: str, azimuth: float, elevation: float) -> RenderedView:
        """Render any view of a stored object from the database alone (the last
        :data:`RENDER_CACHE_SIZE` are kept; their arrays are read-only)."""
        key = (name, normalise_angle(azimuth), normalise_angle(elevation))

        def make() -> RenderedView:
            view = get_renderer(self.config.render).render(self.mesh(name), key[1], key[2])
            for array in (view.color, view.mask, view.depth, view.pose):
                array.setflags(write=False)
            return view

        return cached(self._renders, key, make, RENDER_CACHE_SIZE)

    # ------------------------------------------------------------------ curves
    def stored_curves(self, name: str) -> dict[tuple[float, float], NDArray[np.float32]]:
        """``(azimuth, elevation) -> curve`` of the object's stored views (cached), in the
        order of their directions."""
        def read() -> dict[tuple[float, float], NDArray[np.float32]]:
            found = self._tier_curves(name)
            return self._store.object_curves(name) if found is None else found

        return cached(self._curves, name, read, CURVE_CACHE_OBJECTS)

    def _tier_curves(self, name: str) -> dict[tuple[float, float], NDArray[np.float32]] | None:
        """:meth:`stored_curves` from the full tier's mapped arrays, when a search has
        mapped them (the same float32 curves; only the views' directions are read from the
        file, through the views' index, not the curves' pages), else None."""
        tier = None if self._reader is None else self._reader.loaded("full")
        found = None if tier is None or tier.quantised else tier.orthographic_views(name)
        if found is None or not len(found[0]):
            return None
        ids, curves = found
        angles = self._store.view_angles(ids.tolist())
        if len(angles) != len(ids):  # written again since that search: read it from the file
            return None
        order = sorted(range(len(ids)), key=lambda i: angles[int(ids[i])])
        return {angles[int(ids[i])]: curves[i] for i in order}

    def perspective_near(
        self, name: str, azimuth: float, elevation: float, radius: float
    ) -> list[tuple[float, float, float, NDArray[np.float64]]]:
        """``(azimuth, elevation, camera distance, curve)`` of the object's perspective views
        whose direction is within ``radius`` degrees of arc of ``(azimuth, elevation)``
        (read from the file by their directions, and cached)."""
        def read() -> list[tuple[float, float, float, NDArray[np.float64]]]:
            grid, directions = self._perspective_directions
            near = directions @ camera_direction(azimuth, elevation) >= math.cos(math.radians(radius)) - 1e-9
            rows = self._store.perspective_curves_at(name, [grid[i] for i in np.flatnonzero(near)])
            return [(a, e, d, np.asarray(c, np.float64)) for a, e, d, c in rows]

        return self.derived("perspective_near", (name, azimuth, elevation, radius), read,
                            CURVE_CACHE_OBJECTS * 8)

    @cached_property
    def _perspective_directions(self) -> tuple[list[tuple[float, float]], NDArray[np.float64]]:
        """The perspective grid's views (every one a perspective view may sit at) and their
        unit viewing directions."""
        grid = grid_views(self.config.perspective_gap)
        return grid, np.array([camera_direction(h, v) for h, v in grid])

    def grid_curve(self, name: str, azimuth: float, elevation: float) -> NDArray[np.float64] | None:
        """The curve of grid view (h, v) of ``name`` from the stored views (a pruned view is
        its stand-in's curve, reversed if mirrored); None where there is no silhouette."""
        curves = self.stored_curves(name)
        try:
            stored, mirrored = self.view_plan(name).mapping[(azimuth, elevation)]
        except KeyError:
            stored, mirrored = (azimuth, elevation), False
        curve = curves.get(stored)
        if curve is None:
            return None
        out = np.asarray(curve, np.float64)
        return np.ascontiguousarray(mirror_curve(out)) if mirrored else out

    def query_curve(self, curve: NDArray[np.floating], k: int = 1, tier: str = "full") -> NDArray[np.float64]:
        """``curve`` as a search query of this file (``QueryError`` if it is not one)."""
        if k < 1:
            raise QueryError(f"k must be at least 1, got {k}")
        if tier not in TIERS:
            raise QueryError(f"tier must be one of {', '.join(TIERS)}, got {tier!r}")
        q = np.asarray(curve, dtype=np.float64)
        if q.shape != (self.config.features.curve_samples,) or not np.all(np.isfinite(q)):
            raise QueryError(
                f"query curve must be {self.config.features.curve_samples} finite samples"
            )
        return q

    def nearest_views(
        self, name: str, curve: NDArray[np.floating], n: int, *, band: int = 6
    ) -> list[tuple[float, float, float]]:
        """The ``n`` stored views of object ``name`` nearest to a query curve, as
        ``(azimuth, elevation, distance)`` (the exact distance, either orientation), best
        first: the other views a photo might show when its silhouette is ambiguous."""
        q = self.query_curve(curve)
        keys, curves = self.derived("stacked_curves", (name,), lambda: self._stacked_curves(name),
                                    CURVE_CACHE_OBJECTS)
        if not keys:
            return []
        distances = scan_all(q, curves, band)
        order = np.argsort(distances, kind="stable")[:n]
        return [(keys[i][0], keys[i][1], float(distances[i])) for i in order]

    def _stacked_curves(self, name: str) -> tuple[list[tuple[float, float]], NDArray[np.float64]]:
        """The object's stored views and their curves as one array, in that order."""
        stored = self.stored_curves(name)
        keys = list(stored)
        if not keys:
            return [], np.zeros((0, self.config.features.curve_samples))
        return keys, np.stack([np.asarray(stored[key], np.float64) for key in keys])

    # ------------------------------------------------------------------ tiers
    def tier_reader(self) -> TierReader:
        """The read connection the searches use (opened on first use)."""
        if self._reader is None:
            self._reader = TierReader(self.path, self._store.connect,
                                       write_files=not self._store.read_only)
        return self._reader

    def objects_within(
        self, curve: NDArray[np.floating], distance: float, band: int = 6, tier: str = "full"
    ) -> dict[str, float]:
        """Objects of ``tier`` that may have a view within ``distance`` of the curve (an
        R-tree range query): ``name -> lower bound of its distance``."""
        q = self.query_curve(curve, 1, tier)
        if not distance >= 0:
            raise QueryError(f"distance must be >= 0, got {distance}")
        with self.tier_reader().snapshot() as reader:
            return objects_within(q, reader.tier(tier), float(distance), band)

    def tier_arrays(self, tier: str = "full") -> tuple[TierArrays, list[tuple[int, float, float]]]:
        """Every view of ``tier`` in memory, with ``(view id, azimuth, elevation)`` per row."""
        if tier not in TIERS:
            raise QueryError(f"tier must be one of {', '.join(TIERS)}, got {tier!r}")
        with self.tier_reader().snapshot() as reader:
            return reader.tier_arrays(tier)

