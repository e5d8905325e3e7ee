"""The :class:`ViewDB` facade: the one module that wires the stages together.

It takes progress callbacks and never prints; the CLI (``cli/``) is a thin shell over it.
"""

from __future__ import annotations

import json
import time
from collections import OrderedDict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from .camera import grid_views, normalise_angle
from .catalogue.describe import ObjectDescription, describe_view
from .catalogue.ingest import IngestProgress, IngestReport, PerspectiveAddition, run_ingest
from .catalogue.mesh import DEFAULT_MAX_FACES, LoadOptions, NormalisedMesh, load_mesh, mesh_from_glb
from .catalogue.render import RenderedView, get_renderer
from .catalogue.symmetry import SymmetryType, ViewClasses, plan_without_skimming, skim_plan
from .config import BuildConfig, RenderConfig
from .errors import FeatureError, NotFound, PoseError, QueryError, RenderError, StorageError, ViewDBError
from .pose.estimate import CandidateView, PoseEstimate, QueryView, shape_fit
from .recognition.colour import carries_colour, colour_signature
from .recognition.pipeline import QueryResult, pose_object, run_query
from .recognition.server_tier import ServerTier
from .search.knn import SearchStats, TierArrays, knn, objects_within
from .search.plans import (
    PLANS,
    Candidate,
    RefineRequest,
    ServerReply,
    WalkRequest,
    neighbours_to_candidates,
    refine,
    walk,
)
from .search.refine import scan_all
from .search.shifts import ShiftWindow
from .storage.export import export_client
from .storage.integrity import CheckReport, check_store
from .storage.schema import SCHEMA_REVISION
from .storage.store import ObjectRow, Store
from .storage.tiers import TIERS, TierReader

__all__ = [
    "CandidatePose",
    "DatabaseInfo",
    "QueryResult",
    "Recognition",
    "ObjectInfo",
    "SearchHit",
    "StoredView",
    "ViewDB",
    "open",
    "render_model",
]

#: How many decoded meshes a database keeps in memory for :meth:`ViewDB.render`.
MESH_CACHE_SIZE = 8
#: Views whose colour signatures stay cached.
COLOUR_CACHE_VIEWS = 4096
#: How many regenerated (pruned or off-grid) views a database keeps in memory.
VIEW_CACHE_SIZE = 256
#: How many renders (:meth:`ViewDB.render`, about 0.5 MB each) a database keeps: posing a
#: result renders its candidate views, then walks off the grid around the best, and
#: the walk's steps overlap.
RENDER_CACHE_SIZE = 64
#: How many objects' stored curves a database keeps in memory for CS2 walks.
CURVE_CACHE_OBJECTS = 64

_K = TypeVar("_K")
_V = TypeVar("_V")


def _cached(cache: OrderedDict[_K, _V], key: _K, make: Callable[[], _V], limit: int) -> _V:
    """``cache[key]``, made by ``make()`` when missing (an exception caches nothing); the
    least recently used entries go past ``limit``."""
    if key in cache:
        cache.move_to_end(key)
        return cache[key]
    value = cache[key] = make()
    while len(cache) > limit:
        cache.popitem(last=False)
    return value


@dataclass(frozen=True)
class Recognition:
    """What :meth:`ViewDB.recognise` found: the objects, best first, and what it cost."""

    plan: str
    results: list[Candidate]
    #: The client half's answer (CS1/CS2; empty for ``server``).
    client_results: list[Candidate]
    client_ms: float
    server_ms: float
    server_stats: dict[str, float]
    #: JSON bytes the client would send and receive (CS1/CS2).
    bytes_sent: int
    bytes_received: int
    #: With a remote server: the round trip's wall time beyond the server's own time.
    network_ms: float = 0.0


@dataclass(frozen=True)
class ObjectInfo:
    """One object of a database."""

    name: str
    source: str
    content_hash: str
    n_faces: int
    n_vertices: int
    #: Farthest-vertex distance in the file's units (normalised = (original − centre)/scale).
    scale: float
    centre: tuple[float, float, float]
    views_stored: int
    views_grid: int
    empty_views: int
    ingest_seconds: float
    created_at: str
    #: Whether only the skim plan's views are stored (``--no-skim`` stores the grid).
    skimmed: bool = False
    #: The symmetry type; None for objects ingested before schema revision 0002.
    symmetry: SymmetryType | None = None
    #: Perspective silhouettes stored (0 for objects ingested before revision 0004).
    perspective_views: int = 0

    def to_dict(self) -> dict[str, Any]:
        sym = self.symmetry
        return {
            "name": self.name, "source": self.source, "content_hash": self.content_hash,
            "faces": self.n_faces, "vertices": self.n_vertices, "scale": self.scale,
            "centre": list(self.centre),
            "h_type": sym.h_type if sym else None, "v_type": sym.v_type if sym else None,
            "h_period": sym.h_period if sym else None,
            "v_period": sym.v_period if sym else None,
            "base_view": [sym.base_azimuth, sym.base_elevation] if sym else None,
            "skimmed": self.skimmed, "views_stored": self.views_stored,
            "views_grid": self.views_grid, "empty_views": self.empty_views,
            "perspective_views": self.perspective_views,
            "ingest_seconds": round(self.ingest_seconds, 3), "created_at": self.created_at,
        }


@dataclass(frozen=True, eq=False)
class StoredView:
    """A view's features: read from the database, or regenerated from the stored mesh."""

    object: str
    azimuth: float
    elevation: float
    curve: NDArray[np.float32] = field(repr=False)
    fourier: NDArray[np.complex128] = field(repr=False)
    keypoints: NDArray[np.float32] = field(repr=False)
    descriptors: NDArray[np.uint8] = field(repr=False)
    points3d: NDArray[np.float32] = field(repr=False)
    #: False when read from the database; True when rendered and described on demand
    #: (a view the skim plan pruned, or one off the grid).
    regenerated: bool = False
    #: For a pruned grid view: the stored view it maps to, and whether its curve is that
    #: view's curve reversed. None for stored and off-grid views.
    stored_as: tuple[float, float] | None = None
    mirrored: bool = False


@dataclass(frozen=True)
class CandidatePose:
    """A grid view whose silhouette is the same as (or the mirror of) a matched view's."""

    azimuth: float
    elevation: float
    #: The candidate's distance curve is the matched view's curve reversed.
    mirrored: bool
    #: Whether the database stores this view (otherwise it is regenerated on demand).
    stored: bool


@dataclass(frozen=True)
class SearchHit:
    """One object found by :meth:`ViewDB.search`, with its best stored view."""

    object: str
    distance: float
    azimuth: float
    elevation: float
    #: The query matches the stored view's mirror (its reversed curve).
    mirrored: bool
    #: The view is a perspective silhouette from this many bounding radii (None: an
    #: orthographic view).
    camera_distance: float | None = None
    #: The query curve matched started at this sample (a shift search; None: as given).
    shift: int | None = None


@dataclass(frozen=True)
class DatabaseInfo:
    path: str
    file_bytes: int
    schema_revision: str
    config: BuildConfig
    objects: list[ObjectInfo]
    rows: dict[str, int]
    #: Per tier (``full``, ``sparse``): its grid gap, views, groups and R-tree bytes.
    tiers: dict[str, dict[str, float]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "path": self.path, "file_bytes": self.file_bytes,
            "schema_version": self.schema_revision, "gap": self.config.gap,
            "client_gap": self.config.client_gap, "tiers": self.tiers,
            "image_size": self.config.render.image_size,
            "curve_samples": self.config.features.curve_samples,
            "fourier_coefficients": self.config.features.fourier_coefficients,
            "sift_max_keypoints": self.config.sift.max_keypoints,
            "skim_sigma": self.config.skim.sigma,
            "perspective": {"distances": list(self.config.perspective.distances),
                            "gap": self.config.perspective_gap},
            "rows": self.rows, "objects": [o.to_dict() for o in self.objects],
        }


class ViewDB:
    """An open view database. Use :func:`viewdb.open` to get one; close it (or use ``with``)."""

    def __init__(self, store: Store, config: BuildConfig) -> None:
        self._store = store
        self.config = config
        self._meshes: OrderedDict[str, NormalisedMesh] = OrderedDict()
        self._regenerated: OrderedDict[tuple[str, float, float], StoredView] = OrderedDict()
        self._plans: dict[str, ViewClasses] = {}
        self._reader: TierReader | None = None
        self._role: str | None = None
        self._curves: OrderedDict[str, dict[tuple[float, float], NDArray[np.float32]]] = OrderedDict()
        self._colours: OrderedDict[tuple[str, float, float], NDArray[np.float32] | None] = OrderedDict()
        self._renders: OrderedDict[tuple[str, float, float], RenderedView] = OrderedDict()

    @property
    def path(self) -> Path:
        return self._store.path

    @property
    def read_only(self) -> bool:
        """Whether the file was opened with ``read_only=True`` (nothing is ever written)."""
        return self._store.read_only

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None
        self._store.close()

    def __enter__(self) -> ViewDB:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ ingest
    def ingest(
        self,
        paths: Iterable[str | Path],
        *,
        jobs: int = 1,
        skim: bool = True,
        progress: Callable[[IngestProgress], None] | None = None,
        max_faces: int | None = DEFAULT_MAX_FACES,
        allow_missing_textures: bool = False,
    ) -> IngestReport:
        """Add mesh files; an object is named after its file's stem.

        Each object is classified (symmetry type H1–H4 × V1–V4); with ``skim`` only the
        views its skim plan keeps are rendered and stored (the paper's camera view
        skimming), otherwise the whole grid; and the perspective silhouettes of the
        build configuration (:class:`~viewdb.config.PerspectiveConfig`). Unchanged files
        (same name and content hash) are skipped, except that an object stored without
        perspective views (by an older viewdb) gets them ("upgraded"); changed ones
        replace their object. Each object is written in one
        transaction. Files that fail are listed in the report's ``failed`` and the rest
        still go in: among them meshes with more than ``max_faces`` triangles (``None``:
        no cap) and meshes naming texture files that do not exist (unless
        ``allow_missing_textures``: then they go in untextured).
        """
        if self.role == "client":
            raise ViewDBError(
                "is a client database (export-client): ingest into the full database and "
                "export again", self.path,
            )
        if self.read_only:
            raise ViewDBError("is open read-only; open it without read_only to ingest", self.path)

        def write(desc: ObjectDescription) -> None:
            self._store.write_object(desc, self.config)
            self._forget(desc.name)

        def write_perspective(addition: PerspectiveAddition) -> None:
            self._store.add_perspective(addition.name, addition.views, self.config)
            self._forget(addition.name)

        try:
            options = LoadOptions(max_faces, allow_missing_textures)
        except ValueError as exc:
            raise ViewDBError(str(exc)) from exc
        return run_ingest(
            list(paths), self.config, self._store.object_hashes(), write,
            lacking_perspective=self._store.objects_lacking_perspective(),
            write_perspective=write_perspective,
            jobs=jobs, skim=skim, progress=progress, options=options,
        )

    @property
    def role(self) -> str:
        """``"full"`` (meshes, SIFT, both tiers) or ``"client"`` (from :meth:`export_client`)."""
        if self._role is None:
            self._role = self._store.role()
        return self._role

    def export_client(
        self, out: str | Path, *, client_gap: float | None = None,
        progress: Callable[[int, int], None] | None = None,
    ) -> BuildConfig:
        """Write the small client file (sparse tier only, at ``client_gap``; default this
        file's client gap) to ``out``, which must not exist. Returns its configuration."""
        return export_client(self._store, out, client_gap, progress)

    # ------------------------------------------------------------------ plans
    def client_candidates(
        self, curve: NDArray[np.floating], k: int = 5, *, band: int = 6,
        shifts: ShiftWindow | None = None,
    ) -> tuple[list[Candidate], SearchStats]:
        """The client half of CS1/CS2: the k nearest objects on this file's sparse tier
        (over ``shifts`` of the curve, as :meth:`search`)."""
        return self._knn(self._query_curve(curve, k, "sparse"), k, band, "sparse", shifts)

    def refine(self, request: RefineRequest) -> ServerReply:
        """The server half of CS1 (Algorithm 3): exact, the same answer as ``plan="server"``
        whenever the client's candidates come from this file's sparse tier (or a client
        file exported from it); candidates of objects this file lacks, or holds in another
        version (a client file exported before the object was replaced), are not used as
        bounds, so a stale client file cannot make the answer wrong."""
        self._full_tier_only()
        q = self._query_curve(request.curve, request.k, "full")
        with self._tier_reader().snapshot() as reader:
            versions = reader.object_versions()
            found, stats = refine(reader.tier("full"), replace(request, curve=q), versions)
            angles = reader.view_projections([n.view for n in found])
        return ServerReply(neighbours_to_candidates(found, angles, shifted=request.shifts is not None),
                           stats.to_dict())

    def walk(self, request: WalkRequest) -> ServerReply:
        """The server half of CS2 (Algorithm 4): the neighbour walk from the client's views.
        Candidates of objects this file lacks (a stale client file) are left out, as
        :meth:`refine` leaves them out of its bounds: the walk starts from the others."""
        self._full_tier_only()
        q = self._query_curve(request.curve, request.k, "full")
        with self._tier_reader().snapshot() as reader:
            known = reader.object_versions()
        client = [c for c in request.client if c.object in known]
        found, stats = walk(replace(request, curve=q, client=client), self._grid_curve, self.config.gap)
        return ServerReply(found, stats)

    def _full_tier_only(self) -> None:
        if self.role == "client":
            raise QueryError(
                "is a client database (no full tier): give the full database as --db, or a "
                "server", self.path,
            )

    def _grid_curve(self, name: str, azimuth: float, elevation: float) -> NDArray[np.float64] | None:
        """The curve of grid view (h, v) of ``name`` from the stored views (a pruned view is
        its stand-in's curve, reversed if mirrored); None where there is no silhouette."""
        curves = self._stored_curves(name)
        try:
            stored, mirrored = self.view_plan(name).mapping[(azimuth, elevation)]
        except KeyError:
            stored, mirrored = (azimuth, elevation), False
        curve = curves.get(stored)
        if curve is None:
            return None
        out = np.asarray(curve, np.float64)
        return np.ascontiguousarray(np.roll(out[::-1], 1)) if mirrored else out

    def _stored_curves(self, name: str) -> dict[tuple[float, float], NDArray[np.float32]]:
        """``(azimuth, elevation) -> curve`` of the object's stored views (cached)."""
        return _cached(self._curves, name, lambda: self._store.object_curves(name), CURVE_CACHE_OBJECTS)

    def recognise(
        self, curve: NDArray[np.floating], k: int = 5, *, band: int = 6, plan: str = "server",
        client: ViewDB | None = None, server: ServerTier | None = None,
        prior: Sequence[Candidate] = (), shifts: ShiftWindow | None = None,
    ) -> Recognition:
        """The k objects a distance curve shows, by ``plan`` (``server``, ``cs1``, ``cs2``).

        ``client`` is the file the client half runs on (a client file from
        :meth:`export_client`, or any full file); default this file. With ``server`` (e.g.
        :class:`viewdb.http.RemoteServer`) this file is the client: its sparse tier runs
        the client half and ``server`` the rest (for ``plan="server"``, all of it).

        ``prior`` are the best objects already found for the same photo by other curves
        (e.g. other in-plane turns; for ``server`` and ``cs1``): their distances bound
        the search as a CS1 client's do, so an object that cannot beat them (the k-th
        of them, or its own) is left out. Merging the results of several curves, each
        searched with the merged results so far as ``prior``, gives exactly the merge of
        their unbounded searches.

        ``shifts``: every plan searches the smallest distance over these circular shifts
        of the curve (:class:`~viewdb.search.shifts.ShiftWindow`; one search instead of one
        per in-plane turn); each result's ``shift`` is the start sample that matched.
        """
        if plan not in PLANS:
            raise QueryError(f"plan must be one of {', '.join(PLANS)}, got {plan!r}")
        if server is not None:
            if client is not None:
                raise QueryError("give either a client file or a server, not both")
            return self._recognise_remote(curve, k, band, plan, server, prior, shifts)
        self._full_tier_only()
        q = self._query_curve(curve, k, "full")
        start = time.perf_counter()
        if plan == "server" and prior:
            reply = self.refine(RefineRequest(q, band, k, _best_of(prior, [], k), shifts))
            return Recognition(plan, reply.results, [], 0.0, (time.perf_counter() - start) * 1e3,
                               reply.stats, 0, 0)
        if plan == "server":
            hits, stats = self.search(q, k, band=band, tier="full", shifts=shifts)
            found = [Candidate(h.object, h.distance, h.azimuth, h.elevation, h.mirrored,
                               camera_distance=h.camera_distance, shift=h.shift) for h in hits]
            return Recognition(plan, found, [], 0.0, (time.perf_counter() - start) * 1e3,
                               stats.to_dict(), 0, 0)
        side = client or self
        mine, _ = side.client_candidates(q, k, band=band, shifts=shifts)
        middle = time.perf_counter()
        if plan == "cs1":
            request: RefineRequest | WalkRequest = RefineRequest(q, band, k, _best_of(mine, prior, k),
                                                                 shifts)
            reply = self.refine(request)
        else:
            request = WalkRequest(q, band, k, side.config.client_gap, mine)
            reply = self.walk(request)
        end = time.perf_counter()
        sent = len(json.dumps(request.to_dict()))
        received = len(json.dumps(reply.to_dict()))
        return Recognition(plan, reply.results, mine, (middle - start) * 1e3, (end - middle) * 1e3,
                           reply.stats, sent, received)

    def _recognise_remote(
        self, curve: NDArray[np.floating], k: int, band: int, plan: str, server: ServerTier,
        prior: Sequence[Candidate] = (), shifts: ShiftWindow | None = None,
    ) -> Recognition:
        q = self._query_curve(curve, k, "sparse")
        start = time.perf_counter()
        mine = [] if plan == "server" else self.client_candidates(q, k, band=band, shifts=shifts)[0]
        client_ms = (time.perf_counter() - start) * 1e3
        if plan == "cs2":
            reply, exchange = server.walk(WalkRequest(q, band, k, self.config.client_gap, mine))
        else:  # cs1; and the server plan is CS1 without client candidates
            reply, exchange = server.refine(RefineRequest(q, band, k, _best_of(mine, prior, k), shifts))
        return Recognition(plan, reply.results, mine, client_ms, exchange.server_ms, reply.stats,
                           exchange.sent, exchange.received,
                           max(exchange.wall_ms - exchange.server_ms, 0.0))

    def query(
        self,
        image: str | Path | NDArray[Any],
        *,
        k: int = 5,
        plan: str = "server",
        client: ViewDB | None = None,
        server: ServerTier | None = None,
        mask: NDArray[Any] | str | Path | None = None,
        band: int = 6,
        rotations: int = 12,
        pose: bool = True,
        intrinsics: tuple[float, float, float, float] | str | Path | Sequence[Any] | None = None,
        label_map: NDArray[Any] | str | Path | None = None,
        label: int | None = None,
        rerank: bool = False,
        colour: bool = True,
        verify: bool = True,
        pose_top: int | None = None,
        shifts: ShiftWindow | None = None,
        roll: float | None = None,
    ) -> QueryResult:
        """Which k objects a photo (path or array) shows, and their poses.

        The object is segmented (alpha channel, ``mask``, or automatically from the
        background); its silhouette, also turned in the image plane by ``rotations``
        evenly spaced angles, is searched by ``plan`` (``server``, ``cs1``, ``cs2``; the
        client half runs on ``client``, default this file); the pose of each result is
        chosen among its candidate same-shape views by SIFT or by outline (see
        :mod:`viewdb.recognition.pipeline`). ``intrinsics`` (``(fx, fy, cx, cy)``, a 3×3 matrix, or a
        JSON/YAML file) give a perspective pose in that camera's OpenCV frame, in the mesh
        file's own frame and units. ``label_map`` + ``label`` pick the object out of a
        label image instead of ``mask``. ``rerank`` (with intrinsics) re-ranks the k results
        by the IoU of their perspective silhouette fit. ``colour``: a photo with colour
        re-ranks the plan's best objects by how well their colours match too
        (:mod:`viewdb.recognition.colour`); ``verify``: they are re-ranked by how well each one's
        matched view, rendered, fits the photo's outline and internal edges
        (:mod:`viewdb.recognition.verify`); ``colour=False, verify=False`` ranks by outline alone, as
        the paper does.
        ``pose_top``: pose only the best this many results (default all k; about 0.4 s
        each). ``shifts`` searches these circular shifts of the upright curve in one search
        instead of ``rotations`` turned silhouettes; ``roll`` (a gravity hint, degrees)
        only those near that in-plane turn (:func:`viewdb.recognition.pipeline.run_query`).

        With ``server`` (:class:`viewdb.http.RemoteServer`), this file is the client file:
        segmentation and the client half run here, the server half and the pose on the
        server; the answer is the one the full file gives locally.
        """
        if server is not None and client is not None:
            raise QueryError("give either a client file or a server, not both")
        return run_query(self, image, k=k, plan=plan, client=client, mask=mask, band=band,
                         rotations=rotations, pose=pose and (self.role == "full" or server is not None),
                         intrinsics=intrinsics, server=server, label_map=label_map, label=label,
                         rerank=rerank, colour=colour, verify=verify, pose_top=pose_top,
                         shifts=shifts, roll=roll)

    def estimate_pose(
        self,
        image: str | Path | NDArray[Any],
        name: str,
        intrinsics: tuple[float, float, float, float] | str | Path | Sequence[Any],
        *,
        mask: NDArray[Any] | str | Path | None = None,
        label_map: NDArray[Any] | str | Path | None = None,
        label: int | None = None,
    ) -> PoseEstimate:
        """The pose of the known object ``name`` in a calibrated photo, from its silhouette
        alone (no recognition): model-to-camera in the OpenCV frame, in the mesh file's own
        frame and units (:func:`viewdb.recognition.pipeline.pose_object`)."""
        return pose_object(self, image, name, intrinsics, mask=mask, label_map=label_map, label=label)

    def _forget(self, name: str) -> None:
        self._curves.clear()
        self._meshes.pop(name, None)
        for key in [k for k in self._colours if k[0] == name]:
            del self._colours[key]
        self._plans.pop(name, None)
        for cache in (self._regenerated, self._renders):
            for key in [k for k in cache if k[0] == name]:
                del cache[key]

    # ------------------------------------------------------------------ reading
    def _info(self, row: ObjectRow) -> ObjectInfo:
        return ObjectInfo(
            name=row.name, source=row.source, content_hash=row.content_hash,
            n_faces=row.n_faces, n_vertices=row.n_vertices, scale=row.scale,
            centre=row.centre, views_stored=row.views,
            views_grid=len(grid_views(self.config.gap)), empty_views=row.empty_views,
            ingest_seconds=row.ingest_seconds, created_at=row.created_at,
            skimmed=row.skimmed,
            symmetry=None if row.symmetry is None else SymmetryType.from_dict(row.symmetry),
            perspective_views=row.perspective_views,
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

    def search(
        self, curve: NDArray[np.floating], k: int = 5, *, band: int = 6, tier: str = "full",
        shifts: ShiftWindow | None = None,
    ) -> tuple[list[SearchHit], SearchStats]:
        """The ``k`` objects whose views in ``tier`` are nearest to a distance curve.

        Exact (Algorithm 2, best-first over lower bounds through the tier's R-tree): the
        same objects and distances as a scan of every view of the tier with DTW
        (Sakoe–Chiba band of ``band`` samples) against the curve and its mirror.
        ``tier`` is ``"full"`` (every stored view) or ``"sparse"`` (the client grid).
        ``shifts``: the distance is the smallest over these circular shifts of the curve
        (:class:`~viewdb.search.shifts.ShiftWindow`, e.g. ``ShiftWindow()`` for every
        in-plane turn), in one search; each hit's ``shift`` is the start that matched.
        """
        found, stats = self._knn(self._query_curve(curve, k, tier), k, band, tier, shifts)
        hits = [SearchHit(c.object, c.distance, c.azimuth, c.elevation, c.mirrored, c.camera_distance,
                          c.shift) for c in found]
        return hits, stats

    def _knn(
        self, q: NDArray[np.float64], k: int, band: int, tier: str, shifts: ShiftWindow | None = None,
    ) -> tuple[list[Candidate], SearchStats]:
        """Algorithm 2 on one tier, in one read snapshot, with the views' angles."""
        with self._tier_reader().snapshot() as reader:
            source = reader.tier(tier)
            if source.n_groups == 0:
                raise QueryError("the database holds no views", self.path)
            found, stats = knn(q, source, k, band, shifts=shifts)
            angles = reader.view_projections([n.view for n in found])
            versions = reader.object_versions()
        return neighbours_to_candidates(found, angles, versions, shifted=shifts is not None), stats

    def objects_within(
        self, curve: NDArray[np.floating], distance: float, *, band: int = 6, tier: str = "full"
    ) -> dict[str, float]:
        """Objects of ``tier`` that may have a view within ``distance`` of the curve (an
        R-tree range query): ``name -> lower bound of its distance``. Every object whose
        exact distance is at most ``distance`` is included (CS1's server-side candidates).
        """
        q = self._query_curve(curve, 1, tier)
        if not distance >= 0:
            raise QueryError(f"distance must be >= 0, got {distance}")
        with self._tier_reader().snapshot() as reader:
            return objects_within(q, reader.tier(tier), float(distance), band)

    def _query_curve(self, curve: NDArray[np.floating], k: int, tier: str) -> NDArray[np.float64]:
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

    def _tier_reader(self) -> TierReader:
        if self._reader is None:
            self._reader = TierReader(self.path, self._store.connect)
        return self._reader

    def search_tier(self, tier: str = "full") -> tuple[TierArrays, list[tuple[int, float, float]]]:
        """Every view of ``tier`` in memory, with ``(view id, azimuth, elevation)`` per row:
        the reference for brute force and flat scans (read in one query)."""
        if tier not in TIERS:
            raise QueryError(f"tier must be one of {', '.join(TIERS)}, got {tier!r}")
        with self._tier_reader().snapshot() as reader:
            return reader.tier_arrays(tier)

    def symmetry(self, name: str) -> SymmetryType | None:
        """The object's symmetry type (None for objects from before schema 0002)."""
        return self.object(name).symmetry

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

    def nearest_views(
        self, name: str, curve: NDArray[np.floating], n: int, *, band: int = 6
    ) -> list[tuple[float, float, float]]:
        """The ``n`` stored views of object ``name`` nearest to a query curve, as
        ``(azimuth, elevation, distance)`` (the exact distance, either orientation), best
        first: the other views a photo might show when its silhouette is ambiguous."""
        q = self._query_curve(curve, 1, "full")
        stored = self._stored_curves(name)
        if not stored:
            return []
        keys = list(stored)
        distances = scan_all(q, np.stack([np.asarray(stored[key], np.float64) for key in keys]), band)
        order = np.argsort(distances, kind="stable")[:n]
        return [(keys[i][0], keys[i][1], float(distances[i])) for i in order]

    def candidate_poses(self, name: str, azimuth: float, elevation: float) -> list[CandidatePose]:
        """Every grid view with the same or the mirrored silhouette as grid view (h, v).

        The paper's candidate pose extraction (eqs. 1–2), from the object's verified
        symmetry generators; a query matched at one view could be in any of these poses.
        """
        a, e = normalise_angle(azimuth), normalise_angle(elevation)
        stored = set(self.views(name))
        symmetry = self.symmetry(name)
        classes = skim_plan(symmetry, self.config.gap) if symmetry else self.view_plan(name)
        try:
            members = classes.members(a, e)
        except ValueError as exc:
            raise QueryError(str(exc)) from exc
        return [CandidatePose(h, v, m, (h, v) in stored) for h, v, m in members]

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
            return self._regenerate(name, a, e)
        return StoredView(name, a, e, f["curve"], f["fourier"], f["keypoints"],
                          f["descriptors"], f["points3d"])

    def _regenerate(self, name: str, azimuth: float, elevation: float) -> StoredView:
        return _cached(self._regenerated, (name, azimuth, elevation),
                       lambda: self._describe(name, azimuth, elevation), VIEW_CACHE_SIZE)

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

    def mesh(self, name: str) -> NormalisedMesh:
        """The stored normalised mesh of ``name`` (decoded once, then cached)."""
        return _cached(self._meshes, name, lambda: mesh_from_glb(self._store.mesh_glb(name), name),
                       MESH_CACHE_SIZE)

    def view_colours(
        self, views: Sequence[tuple[str, float, float]]
    ) -> list[NDArray[np.float32] | None]:
        """The colour signatures (:func:`viewdb.recognition.colour.colour_signature`) of views
        ``(object, azimuth, elevation)``, rendered from the stored meshes (:meth:`render`,
        whose cache the shape verification and the pose then use; signatures are cached
        too); None for an object whose mesh has no colour of its own
        (:func:`viewdb.recognition.colour.carries_colour`)."""
        def signature(name: str, azimuth: float, elevation: float) -> NDArray[np.float32] | None:
            if not carries_colour(self.mesh(name)):
                return None
            view = self.render(name, azimuth, elevation)
            return colour_signature(view.color, view.mask)

        return [_cached(self._colours, (name, float(azimuth), float(elevation)),
                        lambda n=name, a=azimuth, e=elevation: signature(n, a, e), COLOUR_CACHE_VIEWS)
                for name, azimuth, elevation in views]

    def view_fits(
        self, query: QueryView, views: Sequence[tuple[str, float, float]]
    ) -> list[float | None]:
        """How well each view ``(object, azimuth, elevation)``, rendered from the stored
        mesh (cached, :meth:`render`), explains the segmented query's shape
        (:func:`viewdb.pose.estimate.shape_fit`, in [0, 1]); None where the view has no silhouette."""
        empty = np.zeros((0, 3), np.float32)
        fits: list[float | None] = []
        for name, azimuth, elevation in views:
            try:
                rendered = self.render(name, azimuth, elevation)
                view = CandidateView(
                    azimuth=azimuth, elevation=elevation, mirrored=False,
                    keypoints=np.zeros((0, 5), np.float32), descriptors=np.zeros((0, 128), np.uint8),
                    points3d=empty, mask=rendered.mask, image_size=self.config.render.image_size,
                    xmag=self.config.render.xmag, color=rendered.color,
                )
                fits.append(shape_fit(query, view))
            except (PoseError, RenderError):
                fits.append(None)
        return fits

    def render(self, name: str, azimuth: float, elevation: float) -> RenderedView:
        """Render any view of a stored object from the database alone (the last
        :data:`RENDER_CACHE_SIZE` are kept; their arrays are read-only)."""
        key = (name, normalise_angle(azimuth), normalise_angle(elevation))

        def make() -> RenderedView:
            view = get_renderer(self.config.render).render(self.mesh(name), key[1], key[2])
            for array in (view.color, view.mask, view.depth, view.pose):
                array.setflags(write=False)
            return view

        return _cached(self._renders, key, make, RENDER_CACHE_SIZE)

    def check(self, progress: Callable[[int, int], None] | None = None) -> CheckReport:
        """Verify the file (see :mod:`viewdb.storage.integrity`); findings are in the report."""
        return check_store(self._store, progress)

    def info(self) -> DatabaseInfo:
        return DatabaseInfo(
            path=str(self.path), file_bytes=_file_bytes(self.path),
            schema_revision=self._store.revision() or SCHEMA_REVISION, config=self.config,
            objects=self.objects(), rows=self._store.table_counts(),
            tiers={
                tier: {"gap": self.config.gap if tier == "full" else self.config.client_gap,
                       **self._store.tier_sizes().get(tier, {"views": 0, "groups": 0, "rtree_bytes": 0})}
                for tier in TIERS
            },
        )


def _best_of(mine: Sequence[Candidate], prior: Sequence[Candidate], k: int) -> list[Candidate]:
    """The k best of two candidate lists, one per object (its smaller distance)."""
    best: dict[str, Candidate] = {}
    for c in (*mine, *prior):
        if c.object not in best or c.distance < best[c.object].distance:
            best[c.object] = c
    return sorted(best.values(), key=lambda c: (c.distance, c.object))[:k]


def _file_bytes(path: Path) -> int:
    total = 0
    for suffix in ("", "-wal"):
        p = Path(str(path) + suffix)
        if p.exists():
            total += p.stat().st_size
    return total


def open(  # noqa: A001 - mirrors sqlite3.connect / builtins.open on purpose
    path: str | Path,
    *,
    create: bool = True,
    gap: float | None = None,
    image_size: int | None = None,
    client_gap: float | None = None,
    perspective: Sequence[float] | None = None,
    config: BuildConfig | None = None,
    read_only: bool = False,
) -> ViewDB:
    """Open (or create) a view database file.

    A new file takes its build configuration from ``config`` (default
    :class:`~viewdb.config.BuildConfig`), with ``gap``, ``image_size`` and ``client_gap``
    (the sparse tier's grid; default the smallest multiple of ``gap`` of at least 30°) and
    ``perspective`` (the perspective views' camera distances in bounding radii; empty for
    none; :class:`~viewdb.config.PerspectiveConfig`) overriding it. An existing file keeps
    the configuration it was built with; asking for a different one raises
    :class:`~viewdb.errors.ViewDBError`.

    ``read_only=True`` opens an existing file without ever writing to it (no journal-mode
    switch, no migration: a file from an older viewdb must be opened once normally to be
    upgraded), e.g. for a server or a shipped client file on read-only storage.
    """
    try:  # a bad configuration is refused before any file is touched
        wanted = config or BuildConfig()
        if gap is not None:
            wanted = replace(wanted, gap=float(gap))
        if image_size is not None:
            wanted = replace(wanted, render=replace(wanted.render, image_size=image_size))
        if client_gap is not None:
            wanted = replace(wanted, index=replace(wanted.index, client_gap=float(client_gap)))
        if perspective is not None:
            wanted = replace(wanted, perspective=replace(wanted.perspective,
                                                         distances=perspective))
        wanted = wanted.resolved()
    except ValueError as exc:
        raise ViewDBError(str(exc), path) from exc
    store = Store(path, create=create, initial=(wanted, "full"), read_only=read_only)
    try:
        stored = store.build_config()
        if stored is None:  # a file whose creation by an older viewdb was cut short
            if not create or read_only:
                raise StorageError("is an unfinished database (its creation was interrupted); "
                                   "delete it and ingest again", path)
            store.set_build_config(wanted)
            stored = wanted
        else:
            if gap is not None and float(gap) != stored.gap:
                raise ViewDBError(
                    f"was built with --gap {stored.gap:g}, not {gap:g}; "
                    "use a new database file for another grid", path,
                )
            if image_size is not None and image_size != stored.render.image_size:
                raise ViewDBError(
                    f"was built with --image-size {stored.render.image_size}, not {image_size}",
                    path,
                )
            if client_gap is not None and float(client_gap) != stored.client_gap:
                raise ViewDBError(
                    f"was built with --client-gap {stored.client_gap:g}, not {client_gap:g}", path
                )
            if perspective is not None and wanted.perspective.distances != stored.perspective.distances:
                raise ViewDBError(
                    f"was built with --perspective {_distances(stored.perspective.distances)}, "
                    f"not {_distances(wanted.perspective.distances)}", path,
                )
        return ViewDB(store, stored)
    except BaseException:
        store.close()
        raise


def _distances(distances: Sequence[float]) -> str:
    return ",".join(f"{d:g}" for d in distances) or "none"


def render_model(
    path: str | Path, azimuth: float, elevation: float, *, image_size: int = 256
) -> RenderedView:
    """Render one view of a mesh file (normalised as ingest would) without a database."""
    mesh = load_mesh(path)
    return get_renderer(RenderConfig(image_size=image_size)).render(mesh, azimuth, elevation)


def describe_paths(paths: Sequence[str | Path]) -> list[Path]:
    """Expand folders into the mesh files they hold (sorted), keep files as given."""
    from .catalogue.mesh import MESH_SUFFIXES

    out: list[Path] = []
    for raw in paths:
        p = Path(raw)
        if p.is_dir():
            out.extend(sorted(q for q in p.iterdir() if q.suffix.lower() in MESH_SUFFIXES))
        else:
            out.append(p)
    return out
