"""Every tunable and tolerance of viewdb, as frozen dataclasses with documented defaults.

A database records the :class:`BuildConfig` it was built with (``settings`` table), so a
later ingest into the same file renders and describes views exactly the same way.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

__all__ = [
    "BuildConfig", "FeatureConfig", "IndexConfig", "PerspectiveConfig", "PosingConfig",
    "RecognitionConfig", "RenderConfig", "SearchConfig", "SiftConfig", "SkimConfig",
    "default_client_gap",
]


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
        if not 16 <= self.image_size <= 4096:
            raise ValueError(f"image_size must be in [16, 4096], got {self.image_size}")
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
class PerspectiveConfig:
    """Perspective silhouettes stored beside the orthographic views (schema revision 0004).

    The paper's views are orthographic; a photograph is taken through a lens from a few
    object sizes away, and its outline differs from the orthographic one (the near side
    looks larger). Each view of a ``gap`` grid is also seen through a pinhole camera on the
    view's axis at each of ``distances`` (in bounding radii from the model's centre, the
    bounding sphere just inside the frame); only its distance curve is stored, and it is
    indexed in the full tier (not the sparse one, so client files do not grow).
    ``benchmarks/perspective_views.py`` measured the gain: rank-1 on the synthetic photos
    52.5 → 60 % and 52.5 → 80 % (two seeds) with views from 3, 4 and 6 radii added.
    """

    #: Camera distances in bounding radii (each > 1); empty: no perspective views.
    distances: tuple[float, ...] = (3.0, 4.0, 6.0)
    #: Grid gap of the perspective views, degrees (divides 360).
    gap: float = 20.0

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
        if any(not d > 1.0 for d in self.distances) or len(set(self.distances)) != len(self.distances):
            raise ValueError(
                f"perspective distances must be distinct and greater than 1 (bounding radii), "
                f"got {list(self.distances)}"
            )
        if not _divides_360(self.gap):
            raise ValueError(f"perspective gap must divide 360 evenly, got {self.gap}")

    @property
    def enabled(self) -> bool:
        return bool(self.distances)


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
    return gap > 0 and abs(360.0 / gap - round(360.0 / gap)) <= 1e-9


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

    def __post_init__(self) -> None:
        if not _divides_360(self.gap):
            raise ValueError(f"gap must divide 360 evenly, got {self.gap}")
        client = self.index.client_gap
        if client is not None:
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
            perspective=PerspectiveConfig(**data.get("perspective", {})),
        )


@dataclass(frozen=True)
class RecognitionConfig:
    """Tunables of the query pipeline (:mod:`viewdb.recognition.pipeline`)."""

    #: Objects the plan finds (at least k) before the colour and shape re-rankings keep
    #: the best k.
    pool: int = 5
    #: An occluder's pixels inside the silhouette's convex hull make a completed query
    #: shape only when they are at least this share of the silhouette's area
    #: (:func:`viewdb.recognition.shapes.completed_mask`).
    hidden_min_share: float = 0.02
    #: With a gravity hint (``roll``), the in-plane turns searched: those within this many
    #: degrees of the hint's (:func:`viewdb.search.shifts.turn_window`).
    roll_tolerance: float = 15.0

    def __post_init__(self) -> None:
        if self.pool < 1:
            raise ValueError(f"pool must be at least 1, got {self.pool}")
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

    def __post_init__(self) -> None:
        if self.shift_block < 1:
            raise ValueError(f"shift_block must be at least 1, got {self.shift_block}")


@dataclass(frozen=True)
class PosingConfig:
    """How a recognised match is posed from its catalogue (:mod:`viewdb.pose.matched`)."""

    #: Most candidate poses examined per result (a sphere has every grid view as one).
    max_candidates: int = 24
    #: Besides the matched view's same-shape poses, those of the object's next nearest
    #: views (by the query curve) are candidates too: a silhouette often matches several
    #: sides of an object about equally, and SIFT can tell them apart.
    near_views: int = 4
    #: Image size of the orthographic silhouettes the perspective silhouette search aligns.
    silhouette_search_size: int = 128
    #: The off-grid shape refinement stops at this step (degrees).
    shape_refine_step: float = 2.0
    #: IoU re-ranking: results fitted again with the full silhouette search after the
    #: quick one (besides the plan's first).
    rerank_full: int = 1

    def __post_init__(self) -> None:
        if self.max_candidates < 1 or self.near_views < 0 or self.rerank_full < 0:
            raise ValueError("need max_candidates >= 1, near_views >= 0, rerank_full >= 0")
        if not (16 <= self.silhouette_search_size <= 4096 and self.shape_refine_step > 0):
            raise ValueError("need 16 <= silhouette_search_size <= 4096 and shape_refine_step > 0")
