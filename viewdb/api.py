"""The :class:`ViewDB` facade: one open file, and the library's verbs on it.

It delegates: reading to :class:`~viewdb.storage.stored_catalogue.StoredCatalogue`, ingest to
:mod:`viewdb.catalogue.ingest`, queries to :mod:`viewdb.recognition.pipeline` over a
client and a server tier, export and checks to :mod:`viewdb.storage`. It takes progress
callbacks and never prints; the CLI (``cli/``) is a thin shell over it.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from .catalogue.describe import ObjectDescription
from .catalogue.ingest import IngestProgress, IngestReport, IngestTarget, Upgrade, checked_options, run_ingest
from .catalogue.look_training import look_key, refresh_looks
from .catalogue.mesh import DEFAULT_MAX_FACES, NormalisedMesh, load_mesh
from .catalogue.reading import CandidatePose, ObjectInfo, StoredView
from .catalogue.render import RenderedView, get_renderer
from .catalogue.skimming import ViewClasses
from .catalogue.symmetry import SymmetryType
from .config import (
    DEFAULT_DEPTH_SCALE,
    DEFAULT_PLAN,
    BuildConfig,
    ClientFileConfig,
    LookConfig,
    OverlayConfig,
    RayIngestConfig,
    RecognitionConfig,
    RenderConfig,
    finite,
)
from .errors import QueryError, StorageError, ViewDBError
from .pose.estimate import PoseEstimate
from .pose.intrinsics import Intrinsics, parse_intrinsics
from .pose.matched import pose_known
from .recognition.client_tier import ClientTier, nearest_objects
from .recognition.depth_image import load_depth
from .recognition.image import LoadedImage, load_image
from .recognition.local_tier import LocalServerTier
from .recognition.options import QueryOptions
from .recognition.overlay import draw_result
from .recognition.pipeline import run_query, segment_photo
from .recognition.regions import Box, Point, Prompts
from .recognition.results import QueryResult, SearchHit
from .recognition.retrieval import Recognition, recognise_curve
from .recognition.server_tier import ServerTier
from .search.knn import SearchStats, TierArrays
from .search.plans import Candidate
from .search.shifts import ShiftWindow
from .storage.export import export_client
from .storage.integrity import CheckReport, check_store, missing_schema
from .storage.schema import SCHEMA_REVISION
from .storage.store import Store, StoredLook
from .storage.stored_catalogue import StoredCatalogue
from .storage.tiers import TIERS

__all__ = ["DatabaseInfo", "ViewDB", "describe_paths", "fit_shared_looks", "open", "render_model",
           "share_looks"]


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
    #: The valid look model's objects and whether it serves a sharded catalogue
    #: (``{"objects": n, "shared": bool}``), or None.
    look: dict[str, Any] | None = None

    @property
    def bytes_per_view(self) -> float:
        """File bytes per stored view (0 for a file without views)."""
        return self.file_bytes / self.rows["views"] if self.rows.get("views") else 0.0

    @property
    def bytes_per_object(self) -> float:
        return self.file_bytes / len(self.objects) if self.objects else 0.0

    @property
    def curve_storage(self) -> str:
        """``"quantised"`` (a compact client file, :mod:`viewdb.search.quantised`) or ``"float32"``."""
        return "quantised" if self.rows.get("curve_errors") else "float32"

    def to_dict(self) -> dict[str, Any]:
        return {
            "path": self.path, "file_bytes": self.file_bytes,
            "bytes_per_view": round(self.bytes_per_view, 1),
            "bytes_per_object": round(self.bytes_per_object, 1), "curves": self.curve_storage,
            "schema_version": self.schema_revision, "gap": self.config.gap,
            "client_gap": self.config.client_gap, "tiers": self.tiers,
            "image_size": self.config.render.image_size,
            "curve_samples": self.config.features.curve_samples,
            "fourier_coefficients": self.config.features.fourier_coefficients,
            "sift_max_keypoints": self.config.sift.max_keypoints,
            "skim_sigma": self.config.skim.sigma,
            "perspective": {"distances": list(self.config.perspective.distances),
                            "gap": self.config.perspective_gap},
            "rows": self.rows, "look_model": self.look, "objects": [o.to_dict() for o in self.objects],
        }


class ViewDB:
    """An open view database. Use :func:`viewdb.open` to get one; close it (or use ``with``)."""

    def __init__(self, store: Store, config: BuildConfig) -> None:
        self._store = store
        self.config = config
        self._catalogue = StoredCatalogue(store, config)

    @property
    def path(self) -> Path:
        return self._store.path

    @property
    def read_only(self) -> bool:
        """Whether the file was opened with ``read_only=True`` (nothing is ever written)."""
        return self._store.read_only

    @property
    def role(self) -> str:
        """``"full"`` (meshes, SIFT, both tiers) or ``"client"`` (from :meth:`export_client`)."""
        return self._catalogue.role

    def close(self) -> None:
        self._catalogue.close()
        self._store.close()

    def __enter__(self) -> ViewDB:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ writing
    def ingest(
        self,
        paths: Iterable[str | Path],
        *,
        jobs: int = 1,
        skim: bool = True,
        progress: Callable[[IngestProgress], None] | None = None,
        max_faces: int | None = DEFAULT_MAX_FACES,
        allow_missing_textures: bool = False,
        ray: str | None = None,
        ray_config: RayIngestConfig | None = None,
        look_progress: Callable[[int, int], None] | None = None,
    ) -> IngestReport:
        """Add mesh files; an object is named after its file's stem.

        Each object is classified (symmetry type H1–H4 × V1–V4); with ``skim`` only the
        views its skim plan keeps are rendered and stored (the paper's camera view
        skimming), otherwise the whole grid; and the perspective silhouettes of the
        build configuration (:class:`~viewdb.config.PerspectiveConfig`); and the
        appearance of the stored views and of the views opposite them
        (:mod:`viewdb.catalogue.appearance`). Unchanged files (same name and content hash)
        are skipped, except that an object stored without perspective views or without
        appearance records (by an older viewdb) gets them ("upgraded"); changed ones
        replace their object. Each object is written in one
        transaction. Files that fail are listed in the report's ``failed`` and the rest
        still go in: among them meshes with more than ``max_faces`` triangles (``None``:
        no cap) and meshes naming texture files that do not exist (unless
        ``allow_missing_textures``: then they go in untextured).

        ``ray`` (``"auto"``: the Ray cluster on this machine, or a new local one;
        ``"HOST:PORT"``: a head node) describes the objects as Ray tasks across the
        cluster instead of in ``jobs`` local processes; this process still writes each one
        (:mod:`viewdb.catalogue.distributed`). Ray is the optional extra ``viewdb[ray]``.

        When it ends it writes the tier files and fits the look model again if any object
        changed (:meth:`fit_look_model`; ``look_progress(done, total)`` follows it).
        """
        options = checked_options(jobs, max_faces, allow_missing_textures)
        report = run_ingest(list(paths), self.config, self.ingest_target(), jobs=jobs, skim=skim,
                            progress=progress, options=options, ray=ray, ray_config=ray_config)
        self.write_tier_files()
        self.fit_look_model(look_progress)
        return report

    def fit_look_model(self, progress: Callable[[int, int], None] | None = None) -> bool:
        """Fit the look model (:mod:`viewdb.catalogue.look_training`: every coloured
        object's renders in synthetic clutter) and store it in the file, unless the stored
        one was fitted for these objects and reads. With fewer than two coloured objects
        there is none (any stored one is removed). Returns whether it fitted one. Needs GL."""
        return fit_shared_looks([self], progress)

    def ingest_target(self) -> IngestTarget:
        """What an ingest into this file needs to know (the objects stored, what older
        ones lack) and how it writes an object (one transaction each); for an ingest that
        spreads objects over several files (:mod:`viewdb.shards.writing`)."""
        if self.role == "client":
            raise ViewDBError(
                "is a client database (export-client): ingest into the full database and "
                "export again", self.path,
            )
        if self.read_only:
            raise ViewDBError("is open read-only; open it without read_only to ingest", self.path)

        def write(desc: ObjectDescription) -> None:
            self._store.write_object(desc, self.config)
            self._catalogue.forget(desc.name)

        def write_upgrade(upgrade: Upgrade) -> None:
            if upgrade.perspective is not None:
                self._store.add_perspective(upgrade.name, upgrade.perspective, self.config)
            if upgrade.appearance is not None:
                self._store.add_appearance(upgrade.name, upgrade.appearance, upgrade.appearance_scope)
            self._catalogue.forget(upgrade.name)

        return IngestTarget(
            self._store.object_hashes(), write, self._store.objects_lacking_perspective(),
            {name: (self._catalogue.views(name), recorded)
             for name, recorded in self._store.objects_lacking_appearance(
                 self.config.appearance.every_view).items()},
            write_upgrade,
        )

    def write_tier_files(self) -> None:
        """Write the tiers' search arrays next to the file, ready to map for the next fresh
        process (:mod:`viewdb.storage.tier_file`), and the ``fast`` plan's index
        (:mod:`viewdb.storage.ann_file`); an ingest does it when it ends. A file
        written before index generations gets one first, which makes checking its tier
        files quick."""
        if not self.read_only:
            self._store.mark_generation()
        with self._catalogue.tier_reader().snapshot() as reader:
            reader.write_tier_files()

    def export_client(
        self, out: str | Path, *, client_gap: float | None = None,
        progress: Callable[[int, int], None] | None = None, file: ClientFileConfig | None = None,
    ) -> BuildConfig:
        """Write the small client file (sparse tier only, at ``client_gap``; default this
        file's client gap) to ``out``, which must not exist. Returns its configuration.
        ``file``: how it is written (default compact: quantised curves)."""
        return export_client(self._store, out, client_gap, progress, file)

    # ------------------------------------------------------------------ queries
    def query(
        self,
        image: str | Path | NDArray[Any] | LoadedImage,
        *,
        k: int = 5,
        plan: str = DEFAULT_PLAN,
        client: ViewDB | None = None,
        server: ServerTier | None = None,
        mask: NDArray[Any] | str | Path | None = None,
        band: int = 6,
        rotations: int = 8,
        pose: bool = True,
        intrinsics: Intrinsics | str | Path | Sequence[Any] | None = None,
        label_map: NDArray[Any] | str | Path | None = None,
        label: int | None = None,
        depth: NDArray[Any] | str | Path | None = None,
        depth_scale: float = DEFAULT_DEPTH_SCALE,
        rerank: bool = False,
        colour: bool = True,
        verify: bool = True,
        pose_top: int | None = 1,
        shifts: ShiftWindow | None = None,
        roll: float | None = None,
        options: QueryOptions | None = None,
        boxes: Sequence[str | Sequence[float] | Box] | None = None,
        points: Sequence[str | Sequence[float] | Point] | None = None,
        every: bool = False,
        max_objects: int | None = None,
        fast_shortlist: int | None = None,
    ) -> QueryResult:
        """Which k objects a photo (path or array) shows, and their poses
        (:mod:`viewdb.recognition.pipeline`).

        The object is segmented (alpha channel, ``mask``, ``label_map`` + ``label``, or
        automatically from the background); its silhouette, also turned in the image plane
        by ``rotations`` evenly spaced angles, is searched by ``plan`` (``fast``, the
        default: exactly the ``fast_shortlist`` objects its approximate index finds, default
        :attr:`~viewdb.config.RecognitionConfig.fast_shortlist`; ``server``, exact;
        ``cs1``, ``cs2``: the client half runs on ``client``, default this file); a photo with colour
        re-ranks the plan's best objects by colour (``colour``), and all by how well each
        matched view fits the photo's shape (``verify``; ``colour=False, verify=False``
        ranks by outline alone, as the paper does); the best ``pose_top`` (default the top one; None: all k)
        are posed by SIFT or by outline. ``intrinsics`` (``(fx, fy, cx, cy)``, a 3×3 matrix,
        or a JSON/YAML file) give a perspective pose in that camera's OpenCV frame, in the
        mesh file's own frame and units; with them ``rerank`` re-ranks the k results by the
        IoU of their perspective silhouette fit. ``depth`` (with ``intrinsics``): the photo's
        depth image, aligned pixel for pixel, a file or an array, one unit of it
        ``depth_scale`` of the meshes' units (default 0.001: millimetres against meshes in
        metres); it sets each perspective pose's distance
        (:mod:`viewdb.pose.depth_distance`). ``shifts`` searches these circular shifts of
        the upright curve in one search instead of ``rotations`` turned silhouettes
        (:class:`~viewdb.search.shifts.ShiftWindow`); ``roll`` (a gravity hint, degrees) only
        those near that in-plane turn. ``options`` gives all of these as one
        :class:`~viewdb.recognition.options.QueryOptions` instead; a keyword it holds that
        is given as well, with another value, is refused (:class:`~viewdb.errors.QueryError`).

        A photo of several objects: ``boxes`` (``(x1, y1, x2, y2)`` or ``"x1,y1,x2,y2"``,
        pixels) and ``points`` (``(x, y)`` or ``"x,y"``) each ask for one object, cut out
        from the prompt; ``every=True`` asks for every object that stands out from the
        background (or, with ``label_map`` and no ``label``, every label), the largest
        ``max_objects`` (default 8). Each is recognised and posed as a single-object query
        is; the answer's ``objects`` hold them, in the prompts' order (boxes, then points;
        every object: largest first), and its ``results`` is empty
        (:mod:`viewdb.recognition.regions`).

        With ``server`` (:class:`viewdb.http.RemoteServer`), this file is the client file:
        segmentation and the client half run here, the server half and the pose on the
        server; the answer is the one the full file gives locally.
        """
        keywords = {"k": k, "plan": plan, "band": band, "rotations": rotations, "pose": pose,
                    "pose_top": pose_top, "intrinsics": intrinsics, "rerank": rerank, "colour": colour,
                    "verify": verify, "shifts": shifts, "roll": roll, "fast_shortlist": fast_shortlist}
        options = _query_options(options, keywords)
        prompts = Prompts.of(boxes, points, every, max_objects)
        server_tier, client_tier = self._tiers(options.plan, client, server)
        if depth is not None:
            image = self._with_depth(image, depth, depth_scale, options.camera, remote=server is not None)
        result = run_query(image, options, server_tier, client_tier, self.config.features.curve_samples,
                           mask=mask, label_map=label_map, label=label, prompts=prompts)
        if server is not None or self.role != "full":
            return result
        return replace(result, drawer=partial(self._draw, intrinsics=options.camera))

    def _with_depth(self, image: str | Path | NDArray[Any] | LoadedImage, depth: NDArray[Any] | str | Path,
                    scale: float, camera: Intrinsics | None, *, remote: bool = False) -> LoadedImage:
        """The photo loaded with its depth image (:meth:`query`'s ``depth``); ``remote``:
        the pose is asked of a server."""
        if camera is None:
            raise QueryError("`depth` needs the camera's `intrinsics`: it sets a perspective pose's distance")
        if remote or self.role != "full":
            raise QueryError("`depth` is used where the meshes are: query the full file (over HTTP, its "
                             "server's POST /query), not a client file")
        loaded = image if isinstance(image, LoadedImage) else load_image(image)
        return replace(loaded, depth=load_depth(depth, (loaded.height, loaded.width), scale))

    def _draw(self, result: QueryResult, top: int, config: OverlayConfig | None, *,
              intrinsics: Intrinsics | None) -> NDArray[np.uint8]:
        """A result of a query on this file drawn over its photo (:meth:`QueryResult.overlay`)."""
        assert result.photo is not None
        return draw_result(result.photo, result, self._catalogue.mesh, self.placement, intrinsics, top,
                           config)

    def placement(self, name: str) -> tuple[NDArray[np.float64], float]:
        """``(centre, scale)`` of the object ``name``: its mesh file's units are
        ``centre + scale · normalised`` (a pose in mesh units drawn from the normalised mesh)."""
        info = self._catalogue.object(name)
        return np.asarray(info.centre, dtype=np.float64), float(info.scale)

    def recognise(
        self, curve: NDArray[np.floating], k: int = 5, *, band: int = 6, plan: str = "server",
        client: ViewDB | None = None, server: ServerTier | None = None,
        prior: Sequence[Candidate] = (), shifts: ShiftWindow | None = None,
        cs2: str = RecognitionConfig().cs2, shortlist: int = RecognitionConfig().cs2_shortlist,
        fast_shortlist: int = RecognitionConfig().fast_shortlist,
    ) -> Recognition:
        """The k objects a distance curve shows, by ``plan`` (``server``, ``cs1``, ``cs2``,
        ``fast``; :mod:`viewdb.recognition.retrieval`; ``cs2`` searches the client's
        ``shortlist`` or walks, as :attr:`~viewdb.config.RecognitionConfig.cs2`; ``fast``
        the ``fast_shortlist`` objects its approximate index finds, exactly).

        ``client`` is the file the client half runs on (a client file from
        :meth:`export_client`, or any full file); default this file. With ``server`` (e.g.
        :class:`viewdb.http.RemoteServer`) this file is the client: its sparse tier runs
        the client half and ``server`` the rest (for ``plan="server"``, all of it).

        ``prior`` are the best objects already found for the same photo by other curves:
        their distances bound the search as a CS1 client's do, so an object that cannot
        beat them is left out; merging the results of several curves, each searched with
        the merged results so far as ``prior``, gives exactly the merge of their unbounded
        searches. ``shifts``: the distance is the smallest over these circular shifts of the
        curve, in one search (each result's ``shift`` is the start that matched).
        """
        q = self._catalogue.query_curve(curve, k, "full" if server is None else "sparse")
        return recognise_curve(q, k, band, plan, *self._tiers(plan, client, server), prior, shifts,
                               cs2=cs2, shortlist=shortlist, fast_shortlist=fast_shortlist)

    def _tiers(
        self, plan: str, client: ViewDB | None, server: ServerTier | None
    ) -> tuple[ServerTier, ClientTier]:
        """The server tier (``server``, or this file) and the client tier (this file with a
        server, else ``client`` or this file) a query runs on."""
        if server is not None:
            if client is not None:
                raise QueryError("give either a client file or a server, not both")
            return server, ClientTier(self._catalogue)
        side = self if client is None else client
        return (LocalServerTier(self._catalogue, count_bytes=plan not in ("server", "fast")),
                ClientTier(side._catalogue))

    def server_tier(self) -> LocalServerTier:
        """This full file as a server tier (what ``viewdb serve`` answers from): the server
        half of CS1/CS2, the re-rankings' colours and fits, and the poses."""
        return LocalServerTier(self._catalogue, count_bytes=False)

    def client_candidates(
        self, curve: NDArray[np.floating], k: int = 5, *, band: int = 6,
        shifts: ShiftWindow | None = None,
    ) -> tuple[list[Candidate], SearchStats]:
        """The client half of CS1/CS2: the k nearest objects on this file's sparse tier
        (over ``shifts`` of the curve, as :meth:`search`)."""
        return nearest_objects(self._catalogue, curve, k, band, "sparse", shifts)

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
        found, stats = nearest_objects(self._catalogue, curve, k, band, tier, shifts)
        hits = [SearchHit(c.object, c.distance, c.azimuth, c.elevation, c.mirrored, c.camera_distance,
                          c.shift) for c in found]
        return hits, stats

    def objects_within(
        self, curve: NDArray[np.floating], distance: float, *, band: int = 6, tier: str = "full"
    ) -> dict[str, float]:
        """Objects of ``tier`` that may have a view within ``distance`` of the curve (an
        R-tree range query): ``name -> lower bound of its distance``. Every object whose
        exact distance is at most ``distance`` is included (CS1's server-side candidates).
        """
        return self._catalogue.objects_within(curve, distance, band, tier)

    def search_tier(self, tier: str = "full") -> tuple[TierArrays, list[tuple[int, float, float]]]:
        """Every view of ``tier`` in memory, with ``(view id, azimuth, elevation)`` per row:
        the reference for brute force and flat scans (read in one query)."""
        return self._catalogue.tier_arrays(tier)

    def estimate_pose(
        self,
        image: str | Path | NDArray[Any] | LoadedImage,
        name: str,
        intrinsics: Intrinsics | str | Path | Sequence[Any],
        *,
        mask: NDArray[Any] | str | Path | None = None,
        label_map: NDArray[Any] | str | Path | None = None,
        label: int | None = None,
        depth: NDArray[Any] | str | Path | None = None,
        depth_scale: float = DEFAULT_DEPTH_SCALE,
    ) -> PoseEstimate:
        """The pose of the known object ``name`` in a calibrated photo, from its silhouette
        alone (no recognition): model-to-camera in the OpenCV frame, in the mesh file's own
        frame and units (:func:`viewdb.pose.matched.pose_known`); its distance from
        ``depth``, as in :meth:`query`."""
        if (label_map is None) != (label is None):
            raise QueryError("a label map and a label go together: give both or neither")
        if label_map is not None and mask is not None:
            raise QueryError("give either a mask or a label map, not both")
        camera = parse_intrinsics(intrinsics)
        self.object(name)  # NotFound for an unknown name
        if depth is not None:
            image = self._with_depth(image, depth, depth_scale, camera)
        _, _, query = segment_photo(image, mask=mask, label_map=label_map, label=label)
        return pose_known(self._catalogue, query, name, camera)

    # ------------------------------------------------------------------ reading
    def objects(self) -> list[ObjectInfo]:
        """Every object, by name."""
        return self._catalogue.objects()

    def object(self, name: str) -> ObjectInfo:
        """The object ``name`` (:class:`~viewdb.errors.NotFound` if there is none)."""
        return self._catalogue.object(name)

    def views(self, name: str) -> list[tuple[float, float]]:
        """``(azimuth, elevation)`` of every stored view of object ``name``."""
        return self._catalogue.views(name)

    def symmetry(self, name: str) -> SymmetryType | None:
        """The object's symmetry type (None for objects from before schema 0002)."""
        return self.object(name).symmetry

    def view_plan(self, name: str) -> ViewClasses:
        """How the object's grid views map to its stored ones (identity if not skimmed)."""
        return self._catalogue.view_plan(name)

    def nearest_views(
        self, name: str, curve: NDArray[np.floating], n: int, *, band: int = 6
    ) -> list[tuple[float, float, float]]:
        """The ``n`` stored views of object ``name`` nearest to a query curve, as
        ``(azimuth, elevation, distance)``, best first."""
        return self._catalogue.nearest_views(name, curve, n, band=band)

    def candidate_poses(self, name: str, azimuth: float, elevation: float) -> list[CandidatePose]:
        """Every grid view with the same or the mirrored silhouette as grid view (h, v)
        (the paper's candidate pose extraction, eqs. 1–2)."""
        return self._catalogue.candidate_poses(name, azimuth, elevation)

    def view(self, name: str, azimuth: float, elevation: float) -> StoredView:
        """The features of any view of a stored object: read from the database, or (pruned
        by skimming, or off the grid) rendered from the stored mesh and described."""
        return self._catalogue.view(name, azimuth, elevation)

    def mesh(self, name: str) -> NormalisedMesh:
        """The stored normalised mesh of ``name`` (decoded once, then cached)."""
        return self._catalogue.mesh(name)

    def render(self, name: str, azimuth: float, elevation: float) -> RenderedView:
        """Render any view of a stored object from the database alone (recent renders are
        cached; their arrays are read-only)."""
        azimuth, elevation = _view_angles(azimuth, elevation, self.path)
        return self._catalogue.render(name, azimuth, elevation)

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
            look=self._look_info(),
        )

    def _look_info(self) -> dict[str, Any] | None:
        found = self._catalogue.shard_look()
        if found is None:
            return None
        return {"objects": len(found[1].objects), "shared": found[0] != self._catalogue.look_key()}


#: The defaults of :meth:`ViewDB.query`'s keywords (those ``QueryOptions`` holds among them).
_QUERY_DEFAULTS = {name: p.default for name, p in inspect.signature(ViewDB.query).parameters.items()}


def _same(a: object, b: object) -> bool:
    """``a == b`` as one truth value (arrays, which compare element-wise, are never the same)."""
    try:
        return bool(a == b)
    except (TypeError, ValueError):
        return False


def fit_shared_looks(dbs: Sequence[ViewDB], progress: Callable[[int, int], None] | None = None) -> bool:
    """Fit one look model over the objects of every file of ``dbs`` (one file, or the
    shards of one catalogue) and store it in each, unless each already holds the model of
    these objects; writable full files only. Each coloured object's looks are stored in
    its file and made again only when it changed
    (:func:`~viewdb.catalogue.look_training.refresh_looks`). Returns whether it fitted one."""
    if any(db.read_only or db.role != "full" for db in dbs):
        return False
    hashes: dict[str, str] = {}
    owner: dict[str, StoredCatalogue] = {}
    coloured: set[str] = set()
    for db in dbs:
        held = db._store.object_hashes()
        hashes.update(held)
        owner.update(dict.fromkeys(held, db._catalogue))
        coloured |= set(db._catalogue.colour_index().objects)
    key = look_key(hashes)
    held_looks = [db._catalogue.shard_look() for db in dbs]
    if all(found is not None and found[0] == key for found in held_looks):
        return False
    look_settings = LookConfig().key()
    stored: dict[str, NDArray[np.float32]] = {}
    for db in dbs:
        stored.update(db._store.look_samples(look_settings))
    model, made = refresh_looks(lambda name: owner[name].mesh(name), list(hashes), coloured, stored,
                                progress=progress)
    for db in dbs:
        own = {n: v for n, v in made.items() if owner[n] is db._catalogue}
        db._store.set_look_samples(own, look_settings)
    _store_looks(dbs, key, None if model is None else model.to_bytes())
    return model is not None


def share_looks(source: ViewDB, parts: Sequence[ViewDB]) -> bool:
    """Store the look model of ``source`` in each of ``parts`` (its shards, which together
    hold its objects), when the model is valid for ``source``. Returns whether it did."""
    found = source._catalogue.shard_look()
    if found is None or found[0] != source._catalogue.look_key():
        return False
    _store_looks(parts, found[0], found[1].to_bytes())
    return True


def _store_looks(dbs: Sequence[ViewDB], key: str, model: bytes | None) -> None:
    """Store ``model`` (None: remove it) in each of ``dbs`` as the look model of the
    catalogue ``key``, stamped with each file's own objects."""
    for db in dbs:
        db._store.set_look_model(None if model is None else StoredLook(key, db._catalogue.look_key(), model))
        db._catalogue.forget_look()


def _query_options(options: QueryOptions | None, keywords: dict[str, Any]) -> QueryOptions:
    """``options``, or the :class:`QueryOptions` of :meth:`ViewDB.query`'s ``keywords``.

    With ``options``, a keyword moved from its default to a value other than the option's
    is refused: one of the two would be silently ignored."""
    if options is None:
        shortlist = keywords.pop("fast_shortlist")
        recognition = RecognitionConfig() if shortlist is None else RecognitionConfig(
            fast_shortlist=shortlist)
        return QueryOptions(**keywords, recognition=recognition)
    held = {name: getattr(options, name) for name in keywords if name != "fast_shortlist"}
    held["fast_shortlist"] = options.recognition.fast_shortlist
    conflicts = [f"{name}={value!r} (options.{name}={held[name]!r})" for name, value in keywords.items()
                 if not _same(value, _QUERY_DEFAULTS[name]) and not _same(value, held[name])]
    if conflicts:
        raise QueryError("query: " + ", ".join(conflicts) + " conflict with options; "
                         "give them in options (dataclasses.replace(options, ...)) or leave options out")
    return options


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
    perspective_gap: float | None = None,
    config: BuildConfig | None = None,
    read_only: bool = False,
) -> ViewDB:
    """Open (or create) a view database file.

    A new file takes its build configuration from ``config`` (default
    :class:`~viewdb.config.BuildConfig`), with ``gap``, ``image_size`` and ``client_gap``
    (the sparse tier's grid; default the smallest multiple of ``gap`` of at least 30°) and
    ``perspective`` (the perspective views' camera distances in bounding radii; empty for
    none) and ``perspective_gap`` (their grid's gap in degrees, rounded up to a multiple
    of ``gap``; :class:`~viewdb.config.PerspectiveConfig`) overriding it. An existing file keeps
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
            # any sequence: PerspectiveConfig checks it and makes it a tuple of floats
            distances = cast(tuple[float, ...], perspective)
            wanted = replace(wanted, perspective=replace(wanted.perspective, distances=distances))
        if perspective_gap is not None:
            wanted = replace(wanted, perspective=replace(wanted.perspective, gap=float(perspective_gap)))
        wanted = wanted.resolved()
    except ValueError as exc:
        raise ViewDBError(str(exc), path) from exc
    store = Store(path, create=create, initial=(wanted, "full"), read_only=read_only)
    try:
        damage = missing_schema(store)
        if damage:
            raise StorageError(f"is damaged: it lacks {', '.join(damage[:4])}"
                               + (f" and {len(damage) - 4} more" if len(damage) > 4 else "")
                               + "; restore it from a copy, or ingest its meshes into a new file", path)
        try:
            stored = store.build_config()
        except (ValueError, KeyError, TypeError) as exc:  # written by hand, or by a viewdb
            # that accepted settings now known to be unusable (a perspective distance of 1e308)
            raise StorageError(f"has unusable build settings ({exc}); rebuild it", path) from exc
        if stored is None:  # a file whose creation by an older viewdb was cut short
            if not create or read_only:
                raise StorageError("is an unfinished database (its creation was interrupted); "
                                   "delete it and ingest again", path)
            store.set_build_config(wanted)
            stored = wanted
        else:
            _refuse_other_settings(stored, wanted, path, gap=gap, image_size=image_size,
                                   client_gap=client_gap, perspective=perspective,
                                   perspective_gap=perspective_gap)
        return ViewDB(store, stored)
    except BaseException:
        store.close()
        raise


def _refuse_other_settings(
    stored: BuildConfig, wanted: BuildConfig, path: str | Path, *, gap: float | None,
    image_size: int | None, client_gap: float | None, perspective: Sequence[float] | None,
    perspective_gap: float | None,
) -> None:
    """:class:`~viewdb.errors.ViewDBError` when a setting asked for is not the one an
    existing file was built with."""
    if gap is not None and float(gap) != stored.gap:
        raise ViewDBError(
            f"was built with `gap` {stored.gap:g}, not {gap:g}; "
            "use a new database file for another grid", path,
        )
    if image_size is not None and image_size != stored.render.image_size:
        raise ViewDBError(
            f"was built with `image_size` {stored.render.image_size}, not {image_size}",
            path,
        )
    if client_gap is not None and float(client_gap) != stored.client_gap:
        raise ViewDBError(
            f"was built with `client_gap` {stored.client_gap:g}, not {client_gap:g}", path
        )
    if perspective is not None and wanted.perspective.distances != stored.perspective.distances:
        raise ViewDBError(
            f"was built with `perspective` {_distances(stored.perspective.distances)}, "
            f"not {_distances(wanted.perspective.distances)}", path,
        )
    if perspective_gap is not None:  # as the file's own grid would round it
        asked = replace(stored, perspective=replace(stored.perspective, gap=wanted.perspective.gap))
        if asked.perspective_gap != stored.perspective_gap:
            raise ViewDBError(
                f"was built with `perspective_gap` {stored.perspective_gap:g}, "
                f"not {asked.perspective_gap:g}", path,
            )


def _distances(distances: Sequence[float]) -> str:
    return ",".join(f"{d:g}" for d in distances) or "none"


def render_model(
    path: str | Path, azimuth: float, elevation: float, *, image_size: int = 256
) -> RenderedView:
    """Render one view of a mesh file (normalised as ingest would) without a database."""
    azimuth, elevation = _view_angles(azimuth, elevation, path)
    try:
        config = RenderConfig(image_size=image_size)
    except ValueError as exc:
        raise ViewDBError(str(exc), path) from exc
    mesh = load_mesh(path)
    return get_renderer(config).render(mesh, azimuth, elevation)


def _view_angles(azimuth: float, elevation: float, path: str | Path) -> tuple[float, float]:
    """The angles of a view as floats, refused (naming ``path``) unless finite."""
    try:
        return finite(azimuth, "azimuth"), finite(elevation, "elevation")
    except ValueError as exc:
        raise ViewDBError(str(exc), path) from exc


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
