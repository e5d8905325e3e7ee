"""Every tunable and tolerance of viewdb, as frozen dataclasses with documented defaults.

A database records the :class:`BuildConfig` it was built with (``settings`` table), so a
later ingest into the same file renders and describes views exactly the same way.
"""

from __future__ import annotations

import hashlib
import json
import math
import numbers
import os
from dataclasses import asdict, dataclass, field, replace
from typing import Any

__all__ = [
    "LIMITS", "AppearanceConfig", "BuildConfig", "ClientFileConfig", "FeatureConfig", "HttpConfig",
    "ImageConfig", "IndexConfig", "LookConfig",
    "InputLimits", "MatchedPoseConfig", "OverlayConfig", "PerspectiveConfig", "PoseConfig", "RayIngestConfig",
    "RecognitionConfig",
    "RenderConfig", "SearchConfig", "SegmentationConfig", "ShardConfig", "SiftConfig", "SilhouetteConfig",
    "SkimConfig",
    "WebConfig",
    "default_client_gap", "finite", "integer",
]


@dataclass(frozen=True)
class InputLimits:
    """The sane ranges every number from outside is checked against, by the library (a
    :class:`~viewdb.errors.ViewDBError` naming the value), the CLI (a usage error) and the
    server (a 422), so that no input can exhaust memory or reach a numeric failure."""

    #: Smallest grid gap, degrees: a grid holds (360/gap)² views per object, 129,600 at
    #: 1°; a gap of 1e-9 would ask for 1.3e23 and exhaust memory before rendering one.
    min_gap: float = 1.0
    #: Farthest perspective camera, in bounding radii (the silhouette is then within
    #: rasterisation noise of the orthographic one; at 1e300 the pinhole camera's field
    #: of view underflows to zero).
    max_perspective_distance: float = 1000.0
    #: Focal lengths fx, fy in pixels (below 1 pixel the field of view of even the
    #: smallest image is over 160°; at 1e20 the pose's depth overflows the renderer's clip
    #: planes, and at 5e-324 the projection divides by zero).
    min_focal: float = 1.0
    max_focal: float = 1e7
    #: Largest |cx|, |cy| of the principal point, pixels.
    max_principal: float = 1e7
    #: Most worker processes of an ingest (each holds a renderer, about 300 MB).
    max_jobs: int = 64
    #: Side of a rendered view, pixels.
    min_image_size: int = 16
    max_image_size: int = 4096
    #: One unit of a depth image in the meshes' units (a positive length: from a
    #: nanometre-scale unit against metres to a kilometre against micrometres, and then some).
    min_depth_scale: float = 1e-12
    max_depth_scale: float = 1e12


#: The limits in force.
LIMITS = InputLimits()

#: Meshes with more triangles than this are refused by default (rendering 1,296 views
#: of a multi-million-triangle scan takes hours in software GL and the outline gains
#: nothing at 256 px): decimate such a mesh first, or raise the cap.
DEFAULT_MAX_FACES = 2_000_000


@dataclass(frozen=True)
class HttpConfig:
    """Time and size limits of ``viewdb serve`` and of the remote client
    (:class:`viewdb.RemoteServer`), so that neither side can be held or flooded by the other."""

    #: Server: a connection must deliver a request's whole header within this many seconds
    #: of opening (or of the previous response): a client trickling a header one line at a
    #: time (slowloris) is cut off instead of holding the connection.
    header_timeout: float = 10.0
    #: Server: a request's whole body must arrive within this many seconds of its header.
    body_timeout: float = 60.0
    #: Client: seconds to open the connection.
    connect_timeout: float = 10.0
    #: Client: seconds the server may stay silent while sending a reply.
    read_timeout: float = 120.0
    #: Client: seconds for a whole exchange, however the server paces it (one header line
    #: a second is cut off here).
    total_timeout: float = 300.0
    #: Client: largest reply body in bytes (the largest real reply, 100 colour signatures,
    #: is about 0.6 MB).
    max_reply_bytes: int = 16 * 1024 * 1024
    #: Client and server: deepest nesting of arrays and objects in a JSON body (real
    #: messages nest 4 deep).
    max_json_depth: int = 32
    #: Server: most pixels of an image it decodes (the query image of /pose and /fits, the
    #: photo of /query), checked from the header before any pixel is decoded. Decoding and
    #: posing take about 16 bytes a pixel: 16 million (a 12-megapixel phone photo fits) is
    #: about 260 MB; the library's own limit for local files is ImageConfig.max_pixels.
    max_pixels: int = 16_000_000

    def __post_init__(self) -> None:
        for name in ("header_timeout", "body_timeout", "connect_timeout", "read_timeout",
                     "total_timeout"):
            finite(getattr(self, name), name, 1e-3, 86400.0)
        integer(self.max_reply_bytes, "max_reply_bytes", 1024)
        integer(self.max_json_depth, "max_json_depth", 4, 1000)
        integer(self.max_pixels, "max_pixels", 256)


def finite(value: object, what: str, low: float = -math.inf, high: float = math.inf) -> float:
    """``value`` as a float if it is a finite real number in ``[low, high]``, else a
    ValueError naming ``what`` (booleans and strings are not numbers here)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{what} must be a number, got {_shown(value)}")
    try:
        number = float(value)
    except OverflowError:  # an integer too large for a float
        number = math.inf
    if not (math.isfinite(number) and low <= number <= high):
        bounds = "" if math.isinf(low) and math.isinf(high) else f" in [{low:g}, {high:g}]"
        raise ValueError(f"{what} must be a finite number{bounds}, got {_shown(value)}")
    return number


def integer(value: object, what: str, low: int, high: int | None = None) -> int:
    """``value`` if it is an integer (not a boolean) in ``[low, high]``, else a ValueError
    naming ``what``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{what} must be an integer, got {_shown(value)}")
    number = int(value)  # exact for an Integral, and comparable both ways (Integral has no ``>``)
    if number < low or (high is not None and number > high):
        bounds = f"at least {low}" if high is None else f"in [{low}, {high}]"
        raise ValueError(f"{what} must be {bounds}, got {_shown(value)}")
    return number


def _shown(value: object) -> str:
    """``repr(value)`` cut to 40 characters (a 5,000-digit integer cannot even be printed)."""
    try:
        text = repr(value)
    except ValueError:
        return "a number too long to print"
    return text if len(text) <= 40 else text[:37] + "..."


@dataclass(frozen=True)
class RenderConfig:
    """How a view is rendered (see the camera convention in :mod:`viewdb.camera`)."""

    #: Width and height of every rendered view, in pixels.
    image_size: int = 256
    #: Half-extent of the orthographic view volume; the normalised model has radius 1.
    xmag: float = 1.0
    #: Distance of the camera from the origin along its viewing axis.
    camera_distance: float = 3.0
    #: Near and far clip planes (the unit-radius model lies between 2 and 4).
    znear: float = 0.5
    zfar: float = 5.5
    #: Share of ambient light in the shaded image; the rest is a head-light (Lambert).
    ambient: float = 0.3

    def __post_init__(self) -> None:
        integer(self.image_size, "image_size", LIMITS.min_image_size, LIMITS.max_image_size)
        if not 0.0 <= self.ambient <= 1.0:
            raise ValueError(f"ambient must be in [0, 1], got {self.ambient}")


@dataclass(frozen=True)
class FeatureConfig:
    """Shape features of a silhouette (paper section II.A)."""

    #: Samples of the centroid distance curve, equally spaced by arc length.
    curve_samples: int = 128
    #: Complex coefficients kept of the orthonormal DFT of the curve (the Fourier point).
    fourier_coefficients: int = 8

    def __post_init__(self) -> None:
        if self.curve_samples < 8:
            raise ValueError(f"curve_samples must be at least 8, got {self.curve_samples}")
        if not 1 <= self.fourier_coefficients <= self.curve_samples // 2:
            raise ValueError(
                "fourier_coefficients must be in [1, curve_samples/2], "
                f"got {self.fourier_coefficients}"
            )


@dataclass(frozen=True)
class SiftConfig:
    """SIFT features of the shaded view (paper section III.E)."""

    #: At most this many keypoints per view (the strongest are kept).
    max_keypoints: int = 128


@dataclass(frozen=True)
class SkimConfig:
    """Camera view skimming (paper section II.B; :mod:`viewdb.catalogue.symmetry`)."""

    #: RMS difference of two distance curves (mean 1) below which they are the same shape;
    #: 2.5x the worst rasterisation noise measured between truly equal views at 256 px.
    sigma: float = 0.02


@dataclass(frozen=True)
class IndexConfig:
    """The Fourier-point R-trees (paper section II.C; :mod:`viewdb.search.grouping`)."""

    #: Client grid gap of the sparse tier, a multiple of the server gap of at most 180°;
    #: None picks the smallest multiple of at least 30 degrees that divides 360 (the
    #: paper's best). A gap that does not divide 360 (the paper's 50°) gives the rings
    #: 0, g, 2g, ... < 360 (for 50°: 8 views per ring, the last step 10°), as a loop
    #: extracting views every g degrees does.
    client_gap: float | None = None
    #: At most this many views of one object under one R-tree entry (MBR).
    group_views: int = 32

    def __post_init__(self) -> None:
        if self.group_views < 1:
            raise ValueError(f"group_views must be at least 1, got {self.group_views}")


@dataclass(frozen=True)
class ClientFileConfig:
    """How ``export-client`` writes the file that ships to devices (:mod:`viewdb.storage.export`)."""

    #: Bits per curve sample (codes with a per-curve offset and scale; the client's CS1
    #: bounds grow by each curve's proven error, :mod:`viewdb.search.quantised`); 0 keeps
    #: float32 curves and the per-view curve and Fourier rows (the format before compact
    #: files, exact distances).
    curve_bits: int = 8
    #: SQLite page size of the written file (smaller pages waste less in partly filled
    #: ones; 512 to 65536, a power of two).
    page_size: int = 1024

    def __post_init__(self) -> None:
        if not 0 <= self.curve_bits <= 16:
            raise ValueError(f"curve_bits must be in [0, 16], got {self.curve_bits}")
        if self.page_size < 512 or self.page_size > 65536 or self.page_size & (self.page_size - 1):
            raise ValueError(f"page_size must be a power of two in [512, 65536], got {self.page_size}")


#: The layouts of :attr:`PerspectiveConfig.grid`.
PERSPECTIVE_GRIDS = ("sphere", "square")


@dataclass(frozen=True)
class PerspectiveConfig:
    """Perspective silhouettes stored beside the orthographic views (schema revision 0004).

    The paper's views are orthographic; a photograph is taken through a lens from a few
    object sizes away, and its outline differs from the orthographic one (the near side
    looks larger). Each view of a ``gap`` grid is also seen through a pinhole camera on the
    view's axis at each of ``distances`` (in bounding radii from the model's centre, the
    bounding sphere just inside the frame); only its distance curve is stored, and it is
    indexed in the full tier (not the sparse one, so client files do not grow).
    ``docs/results/latency.md`` compares the grids: 10° on the sphere at 2, 3, 4 and 6 radii
    (the default) against 20° at 3, 4 and 6.
    """

    #: Camera distances in bounding radii (each > 1); empty: no perspective views.
    distances: tuple[float, ...] = (2.0, 3.0, 4.0, 6.0)
    #: Grid gap of the perspective views, degrees (divides 360).
    gap: float = 10.0
    #: Which views of that grid: "sphere", one per viewing direction, spaced about ``gap``
    #: over the sphere (:func:`viewdb.camera.sphere_views`); "square", every view of the
    #: grid (:func:`viewdb.camera.grid_views`: each direction twice, crowded at the poles),
    #: what files made before the sphere layout hold.
    grid: str = "sphere"
    #: A view whose curve lies within this distance (Euclidean, the search's units: a
    #: match is typically 0.05–0.2 away) of a view already kept at the same camera
    #: distance is left out, as a repeat. ``None``: within the skimming threshold
    #: (:attr:`SkimConfig.sigma`) as an RMS difference, what files made before this
    #: setting did; it is about 0.23 in the search's units and left out views a photo
    #: needed.
    tolerance: float | None = 0.01

    def __post_init__(self) -> None:
        try:
            if isinstance(self.distances, str | bytes):  # "3,4,6" or "none" would iterate by character
                raise TypeError
            object.__setattr__(self, "distances", tuple(float(d) for d in self.distances))
        except (TypeError, ValueError):
            raise ValueError(
                f"perspective distances must be a sequence of numbers (bounding radii), e.g. "
                f"(3, 4, 6), or () for none; got {self.distances!r}"
            ) from None
        far = LIMITS.max_perspective_distance
        if (any(not 1.0 < d <= far for d in self.distances)
                or len(set(self.distances)) != len(self.distances)):
            raise ValueError(
                f"perspective distances must be distinct, greater than 1 and at most {far:g} "
                f"(bounding radii), got {', '.join(f'{d:g}' for d in self.distances)}"
            )
        if not _divides_360(self.gap) or self.gap < LIMITS.min_gap:
            raise ValueError(f"perspective gap must divide 360 evenly, got {self.gap}")
        if self.tolerance is not None and not (isinstance(self.tolerance, int | float)
                                                and 0 <= self.tolerance < math.inf):
            raise ValueError(f"perspective tolerance must be a distance of 0 or more, got {self.tolerance!r}")
        if self.grid not in PERSPECTIVE_GRIDS:
            raise ValueError(f"perspective grid must be one of {', '.join(PERSPECTIVE_GRIDS)}, "
                             f"got {self.grid!r}")

    @property
    def enabled(self) -> bool:
        return bool(self.distances)


@dataclass(frozen=True)
class AppearanceConfig:
    """What an ingest stores of each view's appearance for the re-rankings and the pose
    (schema revision 0005; :mod:`viewdb.catalogue.appearance`): its silhouette, colour
    signature and internal edges, so a query compares stored data instead of rendering.

    The edges are found as the shape pose finds them in a render
    (:mod:`viewdb.pose.edges`); a query whose :class:`PoseConfig` asks for other edges
    renders the view instead."""

    #: Canny hysteresis thresholds of the internal edges (:attr:`PoseConfig.edge_thresholds`).
    edge_thresholds: tuple[float, float] = (30.0, 90.0)
    #: Edges closer to the silhouette than this share of the image size (at least 2
    #: pixels) are the outline's and are not kept (:attr:`PoseConfig.edge_margin`).
    edge_margin: float = 0.012
    #: The views opposite the stored ones (what a mirrored match shows) are recorded too
    #: when their directions add at most this share to the renders of the stored views
    #: (:func:`viewdb.catalogue.describe.appearance_views`). An asymmetric object's add none:
    #: its stored views see each direction twice, turned by 180°, and one render serves
    #: both. A symmetric object's would add up to 90 % (measured), so it renders those on
    #: demand.
    opposite_cost: float = 0.0
    #: Record every grid direction (a view and its turned twin share one record), so that no
    #: grid view is rendered at query time: the views the skim plan pruned included, whose
    #: appearance otherwise came from a render when the mesh has colour (a texture need not
    #: share the shape's symmetry) or no recorded image twin stands in. On the 212-model
    #: 10° file, 35 % more records and a 4 % larger file than the stored views' and their
    #: opposites' (``False``, and files from before schema revision 0008, which an ingest
    #: of their unchanged sources completes).
    every_view: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "edge_thresholds", tuple(float(t) for t in self.edge_thresholds))
        lo, hi = self.edge_thresholds
        if not 0 <= lo <= hi or not 0 <= self.edge_margin < 0.5 or not self.opposite_cost >= 0:
            raise ValueError("need 0 <= low <= high edge thresholds, 0 <= edge_margin < 0.5 and "
                             "opposite_cost >= 0")


#: One unit of a query's depth image in the meshes' units, by default: millimetres
#: against meshes in metres (:mod:`viewdb.recognition.depth_image`).
DEFAULT_DEPTH_SCALE = 0.001


@dataclass(frozen=True)
class ImageConfig:
    """Limits on query images (:mod:`viewdb.recognition.image`, the HTTP query decoder)."""

    #: Default ``max_pixels`` of :func:`~viewdb.recognition.image.load_image`: larger
    #: images are refused undecoded.
    max_pixels: int = 40_000_000
    #: Smallest accepted width and height, in pixels.
    min_side: int = 16


@dataclass(frozen=True)
class SegmentationConfig:
    """Cutting the object out of a query photo (:mod:`viewdb.recognition.segmentation`)."""

    #: A kept object must cover at least this share of the image ...
    min_object_fraction: float = 0.005
    #: ... and at least this many pixels ...
    min_object_pixels: int = 64
    #: ... and at most this share (else no background was found).
    max_object_fraction: float = 0.98
    #: The colour methods work on a copy scaled to at most this many pixels on the longer side.
    work_max_side: int = 1024
    #: The colour method ``method="auto"`` uses (see ``benchmarks/segmentation.py``) ...
    default_method: str = "grabcut"
    #: ... except, when ``plain_border`` is on, on a plain background, where the border
    #: model alone is as good on average (mean IoU 0.984 against 0.985) at about a third of
    #: the time (about 7 against 20 ms). Off by default: its outline differs from GrabCut's
    #: by a few pixels, which is enough to change the matched view of a nearly symmetric
    #: object (the demo's mug) and with it the pose.
    plain_border: bool = False
    #: A background is plain when the border strip's Lab colours lie
    #: within ``plain_spread`` of their median (99th percentile), or within twice that
    #: and vary from pixel to pixel as sensor noise does (their variance at most
    #: ``plain_noise_ratio`` times half the mean squared difference of neighbouring
    #: pixels; a gradient or blobs vary smoothly, for ratios of 2 to 200).
    plain_spread: float = 5.0
    plain_noise_ratio: float = 1.3
    #: Width of the border strip that samples the background, as a share of the shorter side.
    border_strip: float = 0.02
    #: Colour clusters of the background model; clusters holding less than
    #: ``min_cluster_share`` of the border samples are dropped (object pixels on the border).
    background_clusters: int = 4
    min_cluster_share: float = 0.01
    #: At most this many border pixels (evenly spaced along the strip) fit the model.
    border_samples: int = 4000
    #: A pixel is object when its Lab distance to the background model exceeds
    #: ``max(min_threshold, threshold_factor · the border_quantile quantile of the border's
    #: own distances)``.
    min_threshold: float = 8.0
    threshold_factor: float = 2.0
    border_quantile: float = 0.99
    #: The closing that bridges cracks adds only pixels at least this share of the local
    #: object contrast away from the background.
    bridge_share: float = 0.1
    #: GrabCut starts its two colour models (a k-means of each one's samples, which costs
    #: as much as an iteration) on a copy of its crop scaled by this factor, then runs
    #: ``grabcut_iterations`` iterations at the working scale from them; 1 starts them at
    #: the working scale.
    grabcut_start_scale: float = 0.5
    #: GrabCut iterations. From the border model's mask one is enough: 4 (from a start at
    #: the working scale) give the same IoU with the true silhouettes for about twice the time
    #: (``benchmarks/segmentation.py --methods grabcut+full,grabcut``).
    grabcut_iterations: int = 1
    #: How a box prompt is cut out (:mod:`viewdb.recognition.regions`): "grabcut" (GrabCut
    #: initialised from the box) or "border" (the crop's border colours); chosen by
    #: ``benchmarks/prompts.py``.
    box_method: str = "grabcut"
    #: A box's GrabCut runs on a crop reaching this share of its longer side beyond it ...
    box_margin: float = 0.3
    #: ... and at least this many pixels ...
    box_min_margin: int = 8
    #: ... scaled to at most this many pixels on the longer side ...
    box_work_side: int = 640
    #: ... for this many iterations, ...
    box_iterations: int = 5
    #: ... with the other prompts' boxes outside this one painted over from their
    #: surroundings: another object's colours are not learnt as this one's background.
    #: Chosen with ``box_margin`` by ``benchmarks/prompts.py`` (boxes jittered by up to 4
    #: pixels: mean IoU 0.87 without, 0.91 with, at margins of 20 and 30 %).
    box_others_unknown: bool = True
    #: A box is drawn tight around its object (a detector's is): when the colour cut leaves
    #: more than this share of the box's width or height between the object and a side of
    #: the box, the colours failed (a white face on a white table), and the box is cut
    #: again on texture (grey level, local contrast and edge energy, in place of colour),
    #: which is kept if it reaches the box's sides more nearly. Every YCB-Video box's
    #: colour cut comes within 0.04 of each side; the ViSP tea box's white face leaves 0.3.
    #: 1 or more: never.
    box_texture_gap: float = 0.1
    #: In clutter the colours around a box are the neighbours' colours too, and GrabCut can
    #: give the whole box to the background. A cut that covers less than
    #: ``box_min_cover`` of the box, or still stops more than ``box_texture_gap`` short of
    #: a side, is cut again with a centred ellipse spanning ``box_core`` of the box's width
    #: and height surely object (a tight box's object holds its middle), and that cut is
    #: kept. Chosen by the cut-out's IoU with the visible masks of the 252 LM-O objects at
    #: least half visible (docs/results/real-clutter.md): mean IoU 0.33 with 136 boxes
    #: refused, 0.72 with none (ellipses of 0.3 / 0.5 / 0.7 everywhere: 0.61 / 0.69 /
    #: 0.72); the YCB-Video boxes' cuts are unchanged. 0: never.
    box_core: float = 0.7
    #: ... (see ``box_core``).
    box_min_cover: float = 0.25
    #: A box whose pixels' colour spread (the root of the trace of their CIE Lab covariance,
    #: after a blur of one pixel) is below this holds no object: it is refused as empty.
    #: An empty table top: 2.5–3.7; the LM-O, YCB-Video, ViSP and phone-box boxes: 19 or more.
    box_min_spread: float = 8.0
    #: A box narrower or lower than this many pixels is refused as degenerate.
    min_box_side: float = 4.0
    #: A point prompt starts from a square of this share of the photo's shorter side ...
    point_start: float = 0.6
    #: ... cut with this crop margin (``box_margin``'s, for a point's square) ...
    point_margin: float = 0.1
    #: ... with a disc of this share of its shorter side around the point surely object; ...
    point_seed: float = 0.02
    #: ... whose sides the object reaches move out by this share of its side ...
    point_growth: float = 0.5
    #: ... at most this many times; ...
    point_steps: int = 5
    #: ... the object is the region holding the point, or the nearest within this share of
    #: the square's shorter side.
    point_reach: float = 0.05
    #: Most objects a query for every object keeps (the largest); the default of
    #: ``max_objects``.
    max_objects: int = 8
    #: Most prompts one query takes.
    max_prompts: int = 64

    def __post_init__(self) -> None:
        if self.default_method not in ("border", "otsu", "grabcut"):
            raise ValueError(
                f"default_method must be 'border', 'otsu' or 'grabcut', got {self.default_method!r}"
            )
        if self.box_method not in ("grabcut", "border"):
            raise ValueError(f"box_method must be 'grabcut' or 'border', got {self.box_method!r}")
        if not (self.box_margin >= 0 and self.point_margin >= 0 and self.box_min_margin >= 1
                and self.box_texture_gap >= 0 and 0 <= self.box_core < 1 and 0 <= self.box_min_cover <= 1
                and self.box_min_spread >= 0
                and self.box_work_side >= 16 and self.box_iterations >= 1 and self.min_box_side >= 1):
            raise ValueError("need box_margin >= 0, point_margin >= 0, box_min_margin >= 1, "
                             "box_texture_gap >= 0, 0 <= box_core < 1, 0 <= box_min_cover <= 1, "
                             "box_min_spread >= 0, box_work_side >= 16, box_iterations >= 1 and "
                             "min_box_side >= 1")
        if not (0 < self.point_start <= 1 and self.point_growth > 0 and self.point_steps >= 1
                and self.point_reach >= 0):
            raise ValueError("need 0 < point_start <= 1, point_growth > 0, point_steps >= 1 and "
                             "point_reach >= 0")
        if self.max_objects < 1 or self.max_prompts < 1:
            raise ValueError("need max_objects >= 1 and max_prompts >= 1")
        if not (0 < self.grabcut_start_scale <= 1 and self.grabcut_iterations >= 1):
            raise ValueError("need 0 < grabcut_start_scale <= 1 and grabcut_iterations >= 1")


@dataclass(frozen=True)
class PoseConfig:
    """Tunables of :func:`viewdb.pose.estimate.estimate_pose`. Pixel tolerances are fractions of the query
    object's extent (the larger side of its mask's bounding box), floored at
    :attr:`min_threshold_px`, so they hold for any image size."""

    #: SIFT keypoints extracted from the query (views store up to 128).
    max_keypoints: int = 512
    #: Lowe's ratio test between the best and the second best match.
    ratio: float = 0.75
    #: Geometrically consistent matches needed to accept the SIFT pose.
    min_inliers: int = 8
    #: RANSAC tolerance of the 2-D similarity from a grid view to the query. Loose: an
    #: off-grid query differs from the nearest view by parallax a similarity cannot model.
    similarity_threshold: float = 0.04
    #: Reprojection tolerance of the refined 3-D pose (orthographic or PnP).
    pose_threshold: float = 0.015
    #: Floor of both tolerances, in query pixels.
    min_threshold_px: float = 2.0
    #: Refine the orthographic pose off the grid from the 2-D–3-D correspondences, scoring
    #: proposals on the matches of all candidates. False is the grid-only baseline: the
    #: similarity's pose ``R_z(α)·R_viewᵀ`` of the candidate with most RANSAC inliers.
    #: (The PnP path, with intrinsics, always refines.)
    refine: bool = True
    #: Shape fallback: in-plane angle search, coarse step then fine step (degrees).
    coarse_step: float = 5.0
    fine_step: float = 0.5
    #: Shape fallback: points sampled along each outer contour for the chamfer distance.
    contour_samples: int = 256
    #: Shape fallback: weight of the internal-edge distance added to the outline distance
    #: (both over the object's sqrt(area)) for the alignments whose outlines fit about as
    #: well as the best (:attr:`shape_tie_ratio`): Canny edges inside the query's silhouette
    #: against those of each candidate's shaded render (:attr:`viewdb.pose.views.CandidateView.color`) under
    #: the outline alignment, a symmetric oriented chamfer distance. It tells apart poses
    #: whose outlines agree (a chair from the front and from the back). 0: the outline
    #: alone. Measured on 216 off-grid renders of the sample models, segmented as queries
    #: are, among the candidate poses of the nearest grid view: a wrong pose picked 25
    #: times, against 98 by the outline alone; flat for weights 0.5-2, truncations
    #: 0.05-0.2, orientation shares 0-0.5.
    detail_weight: float = 1.0
    #: Each edge pixel's distance is truncated at this fraction of sqrt(area) ...
    detail_truncation: float = 0.1
    #: ... and mixed with this share of its difference in direction to the nearest edge
    #: pixel of the other image (0°: none, 90°: the truncated distance).
    detail_orientation: float = 0.5

    #: Matches a candidate needs to propose a pose hypothesis.
    min_hypothesis_matches: int = 4
    #: Best-supported hypotheses refined on the pooled matches, and refit rounds for each.
    refined_hypotheses: int = 3
    pooled_rounds: int = 3
    #: A query object smaller than the candidate views by at least this factor is enlarged
    #: before SIFT, by at most :attr:`max_sift_upscale`
    #: (:func:`viewdb.pose.sift_pose.sift_upscale`).
    min_sift_upscale: float = 1.5
    max_sift_upscale: float = 3.0
    #: Shape fallback: in-plane angles kept per candidate (local minima of the outline
    #: distance within :attr:`shape_angle_slack` of its best), so that when a silhouette
    #: looks alike turned (a square, a rectangle) the internal edges can choose the turn too.
    shape_angles: int = 4
    shape_angle_slack: float = 0.05
    #: Shape fallback near a known pose (``inplane_near``): the in-plane angles searched lie
    #: within this many degrees of it.
    shape_near_window: float = 15.0
    #: Shape fallback: the internal edges decide among the alignments whose outline distance
    #: is within this ratio (plus margin) of the best; an outline that fits clearly worse is
    #: not rescued by its edges (thin objects have few edges inside, and a candidate view far
    #: from the query's direction has edges in the wrong places).
    shape_tie_ratio: float = 0.1
    shape_tie_margin: float = 0.003
    #: Internal edges: Canny hysteresis thresholds (on the L2 magnitude of the 3×3 Sobel
    #: gradient of the grey image, after a 3×3 Gaussian blur). The query's are found at the
    #: level of its image pyramid nearest each view's scale. Thresholds of 15/45 and colour
    #: edges were measured no better on the sample models.
    edge_thresholds: tuple[float, float] = AppearanceConfig().edge_thresholds
    #: Edges closer to the silhouette than this fraction of the view's image size (at least
    #: 2 pixels) are the outline's, which the outline distance already scores.
    edge_margin: float = AppearanceConfig().edge_margin
    #: A query has internal detail (and the edge term is used) when its interior holds at
    #: least this many edge pixels per pixel of sqrt(area), at about the views' resolution.
    min_detail_edges: float = 0.1

    def __post_init__(self) -> None:
        if self.max_keypoints < 1:
            raise ValueError(f"max_keypoints must be at least 1, got {self.max_keypoints}")
        if not 0.0 < self.ratio <= 1.0:
            raise ValueError(f"ratio must be in (0, 1], got {self.ratio}")
        if self.min_inliers < 4:
            raise ValueError(f"min_inliers must be at least 4, got {self.min_inliers}")
        if not (self.similarity_threshold > 0 and self.pose_threshold > 0):
            raise ValueError("thresholds must be positive")
        if not 0.0 < self.fine_step <= self.coarse_step <= 90.0:
            raise ValueError("need 0 < fine_step <= coarse_step <= 90")
        if self.contour_samples < 16:
            raise ValueError(f"contour_samples must be at least 16, got {self.contour_samples}")
        if not (self.detail_weight >= 0 and self.detail_truncation > 0 and 0 <= self.detail_orientation <= 1):
            raise ValueError("need detail_weight >= 0, detail_truncation > 0, 0 <= detail_orientation <= 1")


@dataclass(frozen=True)
class SilhouetteConfig:
    """Tunables of :func:`viewdb.pose.silhouette.search_silhouette_pose`."""

    #: Viewing directions rendered for the orthographic search (about 20° apart).
    directions: int = 100
    #: Where the orthographic search's directions come from: ``"sphere"``, ``directions``
    #: evenly spread ones; ``"candidates"``, a match's candidate poses (its matched view's
    #: same-shape poses and the object's nearest views by the query curve, which the
    #: search has already ranked), aligned by their stored silhouettes in place of both
    #: the sphere's and the outline pose over the candidates
    #: (:func:`viewdb.pose.matched.pose_match` without SIFT; else the sphere's).
    start_directions: str = "sphere"
    #: Hypotheses (direction + in-plane alignment) lifted and refined coarsely ...
    coarse_starts: int = 8
    #: ... and the best of them refined finely.
    fine_starts: int = 2
    #: Window sizes (pixels) of the coarse and fine IoU refinement.
    coarse_size: int = 96
    fine_size: int = 160
    #: The coarse refinement fits the mesh decimated to about this many faces (its
    #: silhouette in a coarse window is the full mesh's to an IoU of 0.99); 0: the full mesh.
    coarse_faces: int = 4096
    #: Most IoU evaluations (renders) per refinement.
    max_evaluations: int = 400
    #: Pattern-search steps: rotation (radians), origin pixel (window pixels), log depth;
    #: the first steps, and the smallest of the coarse and of the fine refinement (the fine
    #: refinement starts from the coarse one's smallest).
    start_steps: tuple[float, float, float] = (0.12, 3.0, 0.06)
    coarse_min_steps: tuple[float, float, float] = (0.02, 0.75, 0.01)
    fine_min_steps: tuple[float, float, float] = (0.004, 0.2, 0.002)
    #: Weight of the texture score (:mod:`viewdb.pose.texture_fit`: how well a render of
    #: the mesh's own colours explains the photo's gradients inside it, in [0, 1]) beside
    #: the IoU when the refined hypotheses are ranked and the answer chosen; 0: IoU alone.
    #: Used for meshes with colour of their own, in a query that has a photo.
    texture_weight: float = 1.0
    #: The texture score's window (pixels square) around the query's silhouette.
    texture_size: int = 128
    #: Threads a fit's outline alignments and the refinements of its starts are spread
    #: over (each refinement is one compiled call without the GIL; at most the machine's
    #: CPUs): the same pose whatever the count. Default: the environment's
    #: ``VIEWDB_SEARCH_THREADS``, else 2, as for :attr:`SearchConfig.threads`.
    threads: int = field(default_factory=lambda: search_threads_from_env())

    def __post_init__(self) -> None:
        if self.threads < 1:
            raise ValueError(f"threads must be at least 1, got {self.threads}")
        if not (self.directions >= 1 and self.coarse_starts >= 1 and self.fine_starts >= 0):
            raise ValueError("need directions >= 1, coarse_starts >= 1, fine_starts >= 0")
        if not (16 <= self.coarse_size <= 1024 and 16 <= self.fine_size <= 1024):
            raise ValueError("window sizes must be in [16, 1024]")
        if self.coarse_faces < 0:
            raise ValueError("coarse_faces must be at least 0")
        if not (self.texture_weight >= 0.0 and 16 <= self.texture_size <= 1024):
            raise ValueError("need texture_weight >= 0 and texture_size in [16, 1024]")
        if self.start_directions not in ("sphere", "candidates"):
            raise ValueError(
                f"start_directions must be 'sphere' or 'candidates', got {self.start_directions!r}")


def default_client_gap(gap: float) -> float:
    """The smallest multiple of ``gap`` that is at least 30 degrees and divides 360."""
    return coarser_gap(gap, 30.0)


def coarser_gap(gap: float, at_least: float) -> float:
    """The smallest multiple of ``gap`` that is at least ``at_least`` and divides 360."""
    multiple = max(1, math.ceil(at_least / gap - 1e-9))
    while not _divides_360(multiple * gap):
        multiple += 1
    return float(multiple * gap)


def _divides_360(gap: float) -> bool:
    return math.isfinite(gap) and gap > 0 and abs(360.0 / gap - round(360.0 / gap)) <= 1e-9


@dataclass(frozen=True)
class BuildConfig:
    """Everything that decides what an ingest stores; fixed per database file."""

    #: Server grid gap in degrees: the grid has (360/gap)**2 views per object.
    gap: float = 10.0
    render: RenderConfig = field(default_factory=RenderConfig)
    features: FeatureConfig = field(default_factory=FeatureConfig)
    sift: SiftConfig = field(default_factory=SiftConfig)
    skim: SkimConfig = field(default_factory=SkimConfig)
    index: IndexConfig = field(default_factory=IndexConfig)
    perspective: PerspectiveConfig = field(default_factory=PerspectiveConfig)
    appearance: AppearanceConfig = field(default_factory=AppearanceConfig)

    def __post_init__(self) -> None:
        gap = finite(self.gap, "gap", LIMITS.min_gap, 180.0)
        if not _divides_360(gap):
            raise ValueError(f"gap must divide 360 evenly, got {gap:g}")
        client = self.index.client_gap
        if client is not None:
            client = finite(client, "client gap")
            ratio = client / self.gap
            if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-9 or client > 180:
                raise ValueError(
                    f"client gap must be a multiple of the gap ({self.gap:g}) of at most 180, "
                    f"got {client:g}"
                )

    @property
    def client_gap(self) -> float:
        """The sparse tier's grid gap (:func:`default_client_gap` unless set)."""
        client = self.index.client_gap
        return default_client_gap(self.gap) if client is None else float(client)

    @property
    def perspective_gap(self) -> float:
        """The perspective views' grid gap: the smallest multiple of the server gap that
        is at least ``perspective.gap`` and divides 360, so every perspective view's
        direction is a server-grid view (the pose stage starts from it)."""
        return coarser_gap(self.gap, self.perspective.gap)

    def resolved(self) -> BuildConfig:
        """This configuration with every default that depends on others filled in (what a
        new database file records, so later changes of defaults do not change it)."""
        return replace(self, index=replace(self.index, client_gap=self.client_gap))

    def curve_key(self) -> str:
        """A short digest of the settings that decide an object's views and their stored
        curves: the grid gap, the silhouette's rendering (all of :class:`RenderConfig` but
        the shading's ``ambient``), the curve's samples and the skimming threshold. Two
        files whose objects have the same content hash and the same key hold the same
        curves at the same angles; a client's distances bound a server's only then."""
        render = {k: v for k, v in asdict(self.render).items() if k != "ambient"}
        made = {"gap": self.gap, "render": render, "curve_samples": self.features.curve_samples,
                "skim_sigma": self.skim.sigma}
        text = json.dumps(made, sort_keys=True)
        return hashlib.blake2b(text.encode(), digest_size=8).hexdigest()

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> BuildConfig:
        return cls(
            gap=float(data["gap"]),
            render=RenderConfig(**data["render"]),
            features=FeatureConfig(**data["features"]),
            sift=SiftConfig(**data["sift"]),
            skim=SkimConfig(**data.get("skim", {})),
            index=IndexConfig(**data.get("index", {})),
            # files from before revision 0004 record none: they get the defaults, and an
            # ingest of their unchanged sources adds the perspective views they lack
            # files from before the sphere layout record no grid nor tolerance: they hold
            # the square grid, skimmed by the RMS threshold
            perspective=PerspectiveConfig(**{"grid": "square", "tolerance": None, **data["perspective"]}
                                          if "perspective" in data else {}),
            # files from before revision 0005 record none: an ingest of their unchanged
            # sources adds the appearance rows with these defaults
            appearance=AppearanceConfig(**data.get("appearance", {})),
        )


@dataclass(frozen=True)
class ShardConfig:
    """Tunables of sharded catalogues and their scatter-gather search (:mod:`viewdb.shards`)."""

    #: Shards searched in the first round of a query; the rest are searched together in
    #: the second, bounded by the k-th distance the first round found (more shards in the
    #: first round: lower latency, less pruning).
    first_round: int = 1
    #: CPUs Ray reserves for each shard's actor (a fraction lets several shards share a
    #: core; the search itself runs in the actor whatever the reservation).
    actor_cpus: float = 0.25
    #: Run ``check`` on every shard when the shards are opened, and refuse a damaged one.
    check_at_start: bool = True
    #: Seconds a round of a query may wait for its shards before the query fails.
    timeout: float = 120.0
    #: Times Ray restarts a shard's actor that died (-1: always). The restarted actor
    #: reopens and checks its file; the server readmits it once it answers as before.
    max_restarts: int = -1
    #: Seconds between two looks at every shard actor's state (to mark a dead one down at
    #: once, and readmit a restarted one).
    probe_interval: float = 0.25
    #: Seconds a restarted shard may take to answer the readmission call.
    readmit_timeout: float = 5.0
    #: The ``Retry-After`` a query needing a down shard is answered with (seconds).
    retry_after: float = 2.0

    def __post_init__(self) -> None:
        if self.max_restarts < -1:
            raise ValueError(f"max_restarts must be -1 (always) or at least 0, got {self.max_restarts}")
        for name in ("probe_interval", "readmit_timeout", "retry_after"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if self.first_round < 1:
            raise ValueError(f"first_round must be at least 1, got {self.first_round}")
        if not 0.0 <= self.actor_cpus <= 64:
            raise ValueError(f"actor_cpus must be in [0, 64], got {self.actor_cpus}")
        if not self.timeout > 0:
            raise ValueError(f"timeout must be positive, got {self.timeout}")


def search_threads_from_env(default: int = 2) -> int:
    """``VIEWDB_SEARCH_THREADS`` as a thread count (``default`` when unset)."""
    text = os.environ.get("VIEWDB_SEARCH_THREADS", "").strip()
    if not text:
        return default
    try:
        threads = int(text)
    except ValueError:
        threads = 0
    if threads < 1:
        raise ValueError(f"VIEWDB_SEARCH_THREADS must be a whole number of threads, at least 1, got {text!r}")
    return threads


#: The ways of searching a query's in-plane turns (:attr:`RecognitionConfig.turn_search`).
TURN_SEARCHES = ("stack", "separate")
#: The ways of :attr:`RecognitionConfig.cs2`.
CS2_SEARCHES = ("shortlist", "walk")
#: A photo query's plan unless told otherwise, in the library, the CLI, HTTP and the web
#: page: ``fast``, which keeps the rank-1 and rank-5 of ``server`` within half a point on
#: the 240 synthetic photos and on the real-photo benchmarks, in about half the time
#: (docs/fast-plan.md#which-plan-when). ``server`` is one flag away, and exact.
DEFAULT_PLAN = "fast"


@dataclass(frozen=True)
class RayIngestConfig:
    """Tunables of an ingest whose objects are described by Ray tasks
    (:mod:`viewdb.catalogue.distributed`)."""

    #: Times Ray runs an object's task again when its worker dies (SIGKILL, out of memory,
    #: a lost node) before the object is reported failed.
    max_retries: int = 3
    #: CPUs Ray reserves for each object's task (rendering and features use one core).
    task_cpus: float = 1.0
    #: Tasks in flight per CPU of the cluster: enough to keep every worker busy while the
    #: writer commits, few enough that described objects do not pile up in memory.
    in_flight_per_cpu: int = 2

    def __post_init__(self) -> None:
        if not 0 <= self.max_retries <= 100:
            raise ValueError(f"max_retries must be in [0, 100], got {self.max_retries}")
        if not 0 < self.task_cpus <= 64:
            raise ValueError(f"task_cpus must be in (0, 64], got {self.task_cpus}")
        if not 1 <= self.in_flight_per_cpu <= 64:
            raise ValueError(f"in_flight_per_cpu must be in [1, 64], got {self.in_flight_per_cpu}")


@dataclass(frozen=True)
class FastConfig:
    """The ``fast`` plan (:mod:`viewdb.search.fast`): a shortlist of objects from an
    approximate nearest-neighbour index over a turn-invariant embedding of every stored
    view, searched exactly. The first four settings make the index file (a file made with
    others is rebuilt), the next two say how an ingest writes it; the rest are query-time."""

    #: DFT magnitudes kept per curve (coefficients 1..m; :mod:`viewdb.search.embedding`).
    coefficients: int = 16
    #: The curve's sorted values kept beside them, at evenly spaced ranks (0: none).
    quantiles: int = 16
    #: The HNSW graph's edges per node (USearch's ``connectivity``).
    connectivity: int = 16
    #: Candidates kept while a node is inserted (USearch's ``expansion_add``): 32 built
    #: the 60-object file's index (145,164 views) in 1.8 s against 6.8 s at 64, with 98.4
    #: against 99.5 % of a query's 160 nearest views found.
    expansion_add: int = 32
    #: Threads that build the index at ingest (0: every core).
    build_threads: int = 0
    #: An ingest grows the index in place (:mod:`viewdb.search.fast_update`) while the
    #: views of objects since replaced or removed, still in its graph, are at most this
    #: share of it; past it, the index is built anew.
    dead_share: float = 0.1
    #: Candidates kept while the graph is searched (USearch's ``expansion_search``; at
    #: least the views asked for).
    expansion_search: int = 64
    #: Views asked of the index per shortlisted object and query: enough that the nearest
    #: views name ``shortlist`` distinct objects (asked again, for twice as many, otherwise).
    views_per_object: int = 8
    #: The query's curves (its in-plane turns) whose embeddings lie within this distance
    #: of each other ask the index once, by their mean: a photo's turns embed alike
    #: (0.009 apart at the median, 0.024 at most, on 80 synthetic photos) and their mean
    #: shortlists as well as each turn on its own (12 turns, at one twelfth of the asking).
    merge_radius: float = 0.03
    #: The most views the index is asked for, as a share of them: views that name fewer
    #: objects than the shortlist's make the shortlist (:func:`~viewdb.search.fast.
    #: shortlist_objects`). A catalogue too small to be asked for a shortlist's views
    #: within it is ranked exactly: every view's embedding compared, which then costs less
    #: than the graph search.
    exact_share: float = 0.02
    #: Objects shortlisted (the knob; :attr:`RecognitionConfig.fast_shortlist` is the
    #: query's default).
    shortlist: int = 20

    def __post_init__(self) -> None:
        if not 1 <= self.coefficients <= 64:
            raise ValueError(f"coefficients must be in [1, 64], got {self.coefficients}")
        if not 0 <= self.quantiles <= 128:
            raise ValueError(f"quantiles must be in [0, 128], got {self.quantiles}")
        if not 2 <= self.connectivity <= 256:
            raise ValueError(f"connectivity must be in [2, 256], got {self.connectivity}")
        if not 0.0 <= self.exact_share <= 1.0:
            raise ValueError(f"exact_share must be in [0, 1], got {self.exact_share}")
        if not 0.0 <= self.dead_share < 1.0:
            raise ValueError(f"dead_share must be in [0, 1), got {self.dead_share}")
        if not self.merge_radius >= 0:
            raise ValueError(f"merge_radius must be at least 0, got {self.merge_radius}")
        for name in ("expansion_add", "expansion_search", "views_per_object", "shortlist"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if self.build_threads < 0:
            raise ValueError(f"build_threads must be at least 0, got {self.build_threads}")

    def index_key(self) -> str:
        """What makes an index file: a file made with other settings is not used."""
        return f"dft{self.coefficients}-q{self.quantiles}-m{self.connectivity}-ef{self.expansion_add}"


@dataclass(frozen=True)
class LookConfig:
    """How an ingest fits the look model (:mod:`viewdb.catalogue.look_training`,
    :mod:`viewdb.catalogue.look`): every coloured object rendered from ``views``
    directions, each pasted ``samples`` times into synthetic clutter, its colours cast.
    All of it makes the model: a model fitted with other settings is fitted again."""

    #: Directions each object is rendered from (random over the sphere, seeded).
    views: int = 48
    #: Training crops per coloured object.
    samples: int = 200
    #: Side of each render, in pixels.
    image_size: int = 128
    #: Spread of each channel's gain (a camera's colour cast), as a share.
    colour_cast: float = 0.25
    #: Share of the crops whose render is lit again from a random direction.
    relight: float = 0.7
    #: Objects the clutter is drawn from, at most (a seeded sample of a larger catalogue),
    #: so that the renders held in memory do not grow with it.
    clutter_objects: int = 256
    #: Objects beside those whose looks are made that the clutter is drawn from when the
    #: other coloured objects' looks are stored (an ingest that adds or replaces a few):
    #: their renders, not the whole catalogue's, are what such a fit costs.
    update_clutter: int = 32
    #: Shrinkage of the within-object covariance (:func:`~viewdb.catalogue.look.fit_look_model`).
    shrinkage: float = 0.03
    seed: int = 0

    def __post_init__(self) -> None:
        integer(self.views, "views", 1, 10_000)
        integer(self.samples, "samples", 1, 100_000)
        integer(self.clutter_objects, "clutter_objects", 1, 100_000)
        integer(self.update_clutter, "update_clutter", 1, 100_000)
        integer(self.image_size, "image_size", 32, 1024)
        for name in ("colour_cast", "relight"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {getattr(self, name)}")
        if not 0.0 <= self.shrinkage <= 1.0:
            raise ValueError(f"shrinkage must be in [0, 1], got {self.shrinkage}")

    def key(self) -> str:
        """What makes a model, beside the catalogue's objects (an object's looks are made
        with it too; ``update_clutter``, how many objects their clutter is drawn from in an
        update, is left out: looks made either way serve)."""
        return (f"look3-v{self.views}-n{self.samples}-s{self.image_size}-c{self.colour_cast}"
                f"-l{self.relight}-p{self.clutter_objects}-k{self.shrinkage}-r{self.seed}")


@dataclass(frozen=True)
class RecognitionConfig:
    """Tunables of the query pipeline (:mod:`viewdb.recognition.pipeline`)."""

    #: Objects the plan finds (at least k) before the colour and shape re-rankings keep
    #: the best k.
    pool: int = 5
    #: An object cut from a prompt (a box or a point) in a cluttered photo has a less sure
    #: outline than a mask's, an alpha channel's or one on a plain background: its own
    #: mesh is often beyond the outline's best 5 while its colours and inside still tell
    #: it apart. So, when the colour channel does not rank it (a grey photo, no coloured
    #: mesh, ``colour_pool`` 0), the plan finds at least this many objects for it before
    #: the colour and shape re-rankings keep the best k. Measured with benchmarks/real_clutter.py on the
    #: 230-object file (docs/results/real-clutter.md): 50 LM-O objects at least half
    #: visible in 8 photos, right object first 3 / 5 of 50 and in the top 5 6 / 13 with
    #: pools of 5 / 20 (without the shape fit: 5 / 15 at 20, 7 / 18 at 40); the 7
    #: YCB-Video objects first 3 of 7 with 5, 4 of 7 with 40 (without the fit: 3 of 7).
    prompt_pool: int = 40
    #: An object cut from a prompt in a photo with colour is ranked by its colours first
    #: (:mod:`viewdb.search.colour_index`): the outline's best ``pool`` objects and the
    #: ``colour_pool`` objects whose stored colours lie nearest the cut-out's, each searched
    #: exactly over its own views, ranked by colour distance plus ``prompt_outline_weight``
    #: × the log of its outline distance over the best one's. On the LM-O photos the
    #: outline of a cut in clutter found the right object first for 2 % of the objects at
    #: least half visible, its colours for 38 % (docs/results/real-clutter.md). 0: no
    #: colour channel (the outline's ``prompt_pool`` re-ranked as an unprompted object's).
    colour_pool: int = 10
    #: How much the outline still counts beside the colours for a prompted object (it
    #: orders objects of equal colours, and those whose meshes have none).
    prompt_outline_weight: float = 0.05
    #: ... and for one whose surroundings are busy (the spread of the CIE Lab colours in a
    #: ring around it, :func:`viewdb.recognition.regions.surround_spread`, at least
    #: ``busy_surround``): its cut is less sure, so its outline counts less. Measured
    #: (docs/results/real-clutter.md#the-colour-channel): on the LM-O desk (ring spread
    #: 22–45 for nine boxes in ten) 0.02 puts 96 of 252 objects first against 87 with
    #: 0.05; around the tea box, the cube and the phone box (10–12) 0.05 keeps them in
    #: the best 5 where 0.02 loses two.
    busy_outline_weight: float = 0.02
    busy_surround: float = 18.0
    #: The colour distance the colour channel's ranking counts for an object whose mesh
    #: has no colour (its render says nothing of the real paint), and at least for a
    #: coloured object the channel did not name: a plausible match, no better. On the LM-O
    #: photos the right object's colour distance is under 0.34 for three objects in four;
    #: 0.35 keeps grey meshes (the YCB-Video ones) in the running, where the outline then
    #: ranks them (4 of 7 YCB-Video objects first, as without the channel).
    uncoloured_distance: float = 0.35
    #: The colour channel reads a prompted cut-out's colours from its core: the mask
    #: eroded by this share of the square root of its area (:func:`viewdb.recognition.colour.core_signature`),
    #: since a cut in clutter takes in its neighbours at its rim. On the LM-O photos
    #: (131 objects at least half visible, every other photo, colours alone) the right
    #: object came first for 29 % / 34 % / 35 % / 35 % with shares 0 / 0.05 / 0.1 / 0.2,
    #: in the best 5 for 62 % / 66 % / 69 % / 66 % (docs/results/real-clutter.md). 0: the whole cut-out.
    colour_core: float = 0.1
    #: How much a coloured object's look distance (:mod:`viewdb.catalogue.look`: the
    #: cut-out's box against a model fitted at ingest to the catalogue's renders in
    #: synthetic clutter) adds to its colour channel score, counted from the look distance
    #: at quantile ``look_reference`` of the catalogue's coloured objects (an object whose
    #: mesh has no colour counts that reference: its render says nothing of the real
    #: print). Measured in docs/results/real-clutter.md#the-look. 0: looks not used.
    look_weight: float = 0.2
    look_reference: float = 0.02
    #: With a look, the colour channel's ``colour_pool`` objects are chosen among the
    #: ``colour_candidates`` nearest by colour as those whose colour distance plus look
    #: term is least (:func:`viewdb.recognition.pipeline.named_by_look`): the part of
    #: their score known before any outline is searched. Measured with
    #: benchmarks/real_clutter.py (docs/results/real-clutter.md#the-look): LM-O objects at
    #: least half visible, in the top 5 191 of 252 against 172 named by colour alone,
    #: first 124 against 125, at the same time per object. At most 100 (a request's k).
    colour_candidates: int = 40
    #: An occluder's pixels inside the silhouette's convex hull make a completed query
    #: shape only when they are at least this share of the silhouette's area
    #: (:func:`viewdb.recognition.shapes.completed_mask`).
    hidden_min_share: float = 0.02
    #: With a gravity hint (``roll``), the in-plane turns searched: those within this many
    #: degrees of the hint's (:func:`viewdb.search.shifts.turn_window`).
    roll_tolerance: float = 10.0
    #: How the in-plane turns (``rotations``) are searched by the ``server`` and ``cs1``
    #: plans: "stack" (one search whose distance is the smallest over the turned curves,
    #: :func:`viewdb.search.knn.knn_stack`) or "separate" (one search per turn, each
    #: bounded by the turns before it). Both give the same answer; ``cs2`` walks per turn.
    turn_search: str = "stack"
    #: How the ``cs2`` plan's server half searches: "shortlist" (exactly, over the
    #: objects of the client's shortlist alone) or "walk" (the paper's neighbour walk,
    #: Algorithm 4, from the client's best k views): :mod:`viewdb.search.plans`.
    cs2: str = "shortlist"
    #: "shortlist": the client's nearest objects on its sparse tier the server searches
    #: (at most 100; at least k). The sparse tier holds coarse orthographic views, so a
    #: photo's object ranks lower there than on the full tier
    #: (docs/results/synthetic-photos.md#cs2).
    cs2_shortlist: int = 100
    #: The ``fast`` plan's shortlist: objects its approximate index finds, searched exactly
    #: (at least k; :mod:`viewdb.search.fast`, docs/fast-plan.md).
    fast_shortlist: int = FastConfig().shortlist

    def __post_init__(self) -> None:
        integer(self.fast_shortlist, "fast_shortlist", 1, 100_000)
        integer(self.cs2_shortlist, "cs2_shortlist", 1, 100)
        integer(self.colour_candidates, "colour_candidates", 1, 100)
        if self.cs2 not in CS2_SEARCHES:
            raise ValueError(f"cs2 must be one of {', '.join(CS2_SEARCHES)}, got {self.cs2!r}")
        if self.turn_search not in TURN_SEARCHES:
            raise ValueError(f"turn_search must be one of {', '.join(TURN_SEARCHES)}, "
                             f"got {self.turn_search!r}")
        if self.pool < 1 or self.prompt_pool < 1:
            raise ValueError(f"pool and prompt_pool must be at least 1, got {self.pool}, {self.prompt_pool}")
        if self.colour_pool < 0:
            raise ValueError(f"colour_pool must be at least 0, got {self.colour_pool}")
        for name in ("prompt_outline_weight", "busy_outline_weight", "busy_surround", "look_weight"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be at least 0, got {getattr(self, name)}")
        if not 0.0 <= self.look_reference <= 1.0:
            raise ValueError(f"look_reference must be in [0, 1], got {self.look_reference}")
        if not 0.0 <= self.colour_core <= 0.5:
            raise ValueError(f"colour_core must be in [0, 0.5], got {self.colour_core}")
        if not 0.0 <= self.uncoloured_distance <= 1.0:
            raise ValueError(f"uncoloured_distance must be in [0, 1], got {self.uncoloured_distance}")
        if self.prompt_outline_weight < 0:
            raise ValueError(f"prompt_outline_weight must be at least 0, got {self.prompt_outline_weight}")
        if not 0.0 <= self.hidden_min_share <= 1.0:
            raise ValueError(f"hidden_min_share must be in [0, 1], got {self.hidden_min_share}")
        if not 0.0 <= self.roll_tolerance <= 180.0:
            raise ValueError(f"roll_tolerance must be in [0, 180], got {self.roll_tolerance}")


@dataclass(frozen=True)
class SearchConfig:
    """The search over a stack of query curves (:func:`viewdb.search.knn.knn_stack`, the
    circular shifts of a curve). Query-time settings, not stored in a file."""

    #: Consecutive curves (shifts) bounded together by one wedge before they are tried one
    #: by one (``benchmarks/shift_search.py`` measured the choice).
    shift_block: int = 8
    #: The same for a stack of in-plane turns (:meth:`viewdb.search.plans.RefineRequest.of_stack`):
    #: turns 30 degrees apart make wide wedges, so each is bounded on its own
    #: (``benchmarks/shift_search.py``'s ``stack12``).
    stack_block: int = 1
    #: Threads one search is split over (:func:`viewdb.search.knn.knn_stack`; at most the
    #: machine's CPUs): the same answer, found about 1.6 times sooner on 2 idle cores
    #: (``benchmarks/parallel_search.py``). 1 keeps every search on the calling thread
    #: (a server busy with other queries gains nothing from more). Default: the
    #: environment's ``VIEWDB_SEARCH_THREADS``, else 2.
    threads: int = field(default_factory=lambda: search_threads_from_env())
    #: Sources with fewer groups are searched on one thread: starting threads costs more
    #: than they save on a small catalogue.
    parallel_min_groups: int = 512
    #: A browse of a stored tier whose boxes meet more than this share of its groups
    #: (estimated on a sample) compares every group's MBR with them instead of asking the
    #: R-tree: the same groups (:meth:`viewdb.storage.tiers.StoredTier.groups_meeting`;
    #: a photo's browses meet 70–98 % of the 212-model file's groups, and the R-tree took
    #: 19 ms a browse). 0: always compare; 1: always ask the R-tree.
    scan_share: float = 0.25
    #: CS2's walk ends by comparing the object's perspective views within this many
    #: perspective grid gaps of arc of where it ended (:func:`viewdb.search.plans.walk`);
    #: 0: those of that direction alone; negative: none.
    walk_perspective: float = 1.0
    #: The colour channel (:mod:`viewdb.search.colour_index`) compares the stored views on
    #: a grid this many degrees apart (rounded to a multiple of the file's grid): 30° holds
    #: 72 views an object, read in well under a second for 230 objects.
    colour_grid: float = 30.0

    def __post_init__(self) -> None:
        if self.threads < 1:
            raise ValueError(f"threads must be at least 1, got {self.threads}")
        if self.shift_block < 1:
            raise ValueError(f"shift_block must be at least 1, got {self.shift_block}")
        if self.stack_block < 1:
            raise ValueError(f"stack_block must be at least 1, got {self.stack_block}")
        if not 0.0 <= self.scan_share <= 1.0:
            raise ValueError(f"scan_share must be in [0, 1], got {self.scan_share}")
        if not self.colour_grid > 0:
            raise ValueError(f"colour_grid must be positive, got {self.colour_grid}")


@dataclass(frozen=True)
class MatchedPoseConfig:
    """How a recognised match is posed from its catalogue (:mod:`viewdb.pose.matched`)."""

    #: Most candidate poses examined per result (a sphere has every grid view as one).
    max_candidates: int = 24
    #: Besides the matched view's same-shape poses, those of the object's next nearest
    #: views (by the query curve) are candidates too: a silhouette often matches several
    #: sides of an object about equally, and SIFT can tell them apart.
    near_views: int = 4
    #: How a shape pose leaves the grid (:func:`viewdb.pose.matched.refine_shape`):
    #: "interpolate" (between the fits of the grid neighbours, from their stored
    #: appearance: no render), "walk" (rendering off-grid views in halving steps) or
    #: "none" (the best grid view's direction).
    shape_refine: str = "interpolate"
    #: "interpolate": moves to a better-fitting grid neighbour before interpolating, at most.
    shape_climb: int = 3
    #: "walk": the off-grid walk stops at this step (degrees).
    shape_refine_step: float = 2.0
    #: IoU re-ranking: the best results by their quick fits, fitted again with the full
    #: silhouette search and ranked among themselves by it. Two: the quick fits of
    #: look-alikes differ by less than a quick fit's own error (0.001–0.01 against 0.01–0.03
    #: of IoU), so the best two are compared on the better fit (docs/results/real-photos.md).
    rerank_full: int = 2
    #: Whether, when the stored candidates give no SIFT pose, the SIFT features of the
    #: candidates the file does not store (pruned by skimming: e.g. the side opposite a
    #: stored view) are made from renders of the mesh ("always", 3-30 ms a view) or not
    #: ("never": the outlines decide). Measured on 92 synthetic photos (docs/appearance.md):
    #: the renders gave a SIFT pose once, and that pose was further off than the outline's.
    regenerate: str = "never"

    def __post_init__(self) -> None:
        if self.max_candidates < 1 or self.near_views < 0 or self.rerank_full < 0 or self.shape_climb < 0:
            raise ValueError("need max_candidates >= 1, near_views >= 0, rerank_full >= 0, shape_climb >= 0")
        if self.regenerate not in ("always", "never"):
            raise ValueError(f"regenerate must be 'always' or 'never', got {self.regenerate!r}")
        if self.shape_refine not in ("interpolate", "walk", "none"):
            raise ValueError(
                f"shape_refine must be 'interpolate', 'walk' or 'none', got {self.shape_refine!r}")
        if not self.shape_refine_step > 0:
            raise ValueError("need shape_refine_step > 0")


@dataclass(frozen=True)
class OverlayConfig:
    """How a posed mesh is drawn over a photo (:mod:`viewdb.recognition.overlay`). Widths
    and the label's size are per 1000 pixels of the drawn image's longer side, so an
    overlay looks the same at any resolution (never thinner than one pixel)."""

    #: Longest side of the drawn image in pixels (the photo is shrunk to it first);
    #: None: the photo's own size.
    max_side: int | None = None
    #: A photo whose longer side is shorter than this is enlarged to it first (so that
    #: lines and labels stay legible over a small photo); None: never enlarged.
    min_side: int | None = None
    #: Width of the outline (the posed mesh's silhouette, its holes included).
    outline_width: float = 3.0
    #: Width of the internal edges (creases and parts in front of others).
    edge_width: float = 1.5
    #: Faces whose normals differ by more than this (degrees) meet at a drawn crease.
    crease_degrees: float = 35.0
    #: Neighbouring visible surfaces further apart in depth than this share of the
    #: model's bounding radius meet at a drawn edge (a part in front of another).
    occlusion_depth: float = 0.1
    #: Opacity of the shaded mesh drawn under the lines (0: lines only).
    fill_opacity: float = 0.3
    #: Length of the drawn model axes (x red, y green, z blue) in bounding radii; 0: none.
    axis_length: float = 0.6
    #: Height of the label's letters.
    label_size: float = 22.0
    #: Whether each result is labelled with its rank, name and score.
    labels: bool = True
    #: One colour (RGB) per result, best first; repeated when there are more results.
    colours: tuple[tuple[int, int, int], ...] = (
        (0, 230, 118), (41, 121, 255), (255, 145, 0), (213, 0, 249), (255, 23, 68), (0, 229, 255),
    )

    def __post_init__(self) -> None:
        if self.max_side is not None and self.max_side < 16:
            raise ValueError(f"max_side must be at least 16 pixels, got {self.max_side}")
        if self.min_side is not None and not 16 <= self.min_side <= (self.max_side or self.min_side):
            raise ValueError(f"min_side must be at least 16 pixels and at most max_side, got {self.min_side}")
        for name in ("outline_width", "edge_width", "axis_length", "label_size", "occlusion_depth"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be at least 0, got {getattr(self, name)}")
        if not 0.0 <= self.fill_opacity <= 1.0:
            raise ValueError(f"fill_opacity must be in [0, 1], got {self.fill_opacity}")
        if not 0.0 <= self.crease_degrees <= 180.0:
            raise ValueError(f"crease_degrees must be in [0, 180], got {self.crease_degrees}")
        if not self.colours or any(len(c) != 3 or not all(0 <= v <= 255 for v in c) for c in self.colours):
            raise ValueError("colours must be RGB triples of 0-255")


@dataclass(frozen=True)
class WebConfig:
    """The web page of ``viewdb serve`` and the endpoints behind it (:mod:`viewdb.http.web`)."""

    #: The photo and each result's overlay come back at most this many pixels on the
    #: longer side (a phone's photo is shrunk; the query itself runs at full size)...
    display_side: int = 1024
    #: ... and at least this many (a small photo is enlarged, so the overlay is legible).
    display_min_side: int = 512
    #: JPEG quality of the photo sent back to draw the overlays on.
    photo_quality: int = 85
    #: Most results one query through the page may ask for.
    max_k: int = 10
    #: View PNGs (thumbnails, the turntable) kept rendered per worker.
    view_cache: int = 512
    #: The view ``(azimuth, elevation)`` that pictures each object in the catalogue.
    picture_view: tuple[float, float] = (30.0, 20.0)

    def __post_init__(self) -> None:
        if not 64 <= self.display_min_side <= self.display_side:
            raise ValueError("display_side and display_min_side must be at least 64, in that order, "
                             f"got {self.display_side} and {self.display_min_side}")
        if not 1 <= self.photo_quality <= 100:
            raise ValueError(f"photo_quality must be in [1, 100], got {self.photo_quality}")
        if self.max_k < 1 or self.view_cache < 1:
            raise ValueError("max_k and view_cache must be at least 1")
