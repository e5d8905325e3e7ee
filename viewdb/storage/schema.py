"""The database schema (SQLAlchemy 2.x Core), mirrored by the Alembic migrations.

``migrations/`` creates and upgrades files; this module is how code names the tables.
``tests/test_storage.py`` checks that a migrated file has exactly these tables and columns.

Tables
------
settings        key/value (JSON) of the build configuration
objects         one row per object: name, source, content hash, the normalised mesh (GLB),
                its symmetry type (H1–H4 × V1–V4, periods, verified generators as JSON)
                and whether its views were skimmed
views           one row per stored view: object, azimuth, elevation, grid gap
curves          the view's centroid distance curve (float32 blob)
fourier_points  the view's first m orthonormal DFT coefficients (complex128 blob)
sift_features   keypoints (float32 (n, 5)), descriptors (uint8 (n, 128)), 3-D points
perspective_views  perspective silhouettes (revision 0004): object, azimuth, elevation,
                camera distance in bounding radii, the distance curve (float32 blob)
appearances     a viewing direction's appearance record (revision 0005,
                :mod:`viewdb.catalogue.appearance`): object, the grid view it was
                recorded at (azimuth, elevation; its turned twin is the same turned by
                180°) and where its packed bytes lie in the object's blob
appearance_blobs  one per object: its appearance records, packed
                (:mod:`viewdb.storage.appearances`) and concatenated
index_groups    R-tree entries: a few views of one object in one tier (``full`` or
                ``sparse``), with their MBR in the indexed Fourier coordinates, the
                per-sample range of their curves and a copy of the curves (one read
                per group at search time). A view id ``i > 0`` is ``views.id``; ``-i``
                is ``perspective_views.id`` (full tier only; see
                :func:`perspective_group_id`)
rtree_pages     the libspatialindex pages of each tier's R-tree (one BLOB per page)
rtree_meta      each tier's R-tree: dimension and header page
curve_errors    per index group of a compact client file (revision 0006): each view's
                quantisation error norms, float32 (n, 2): L2 and L-infinity of the
                decoded curve minus the float32 curve it was made from, rounded up
look_samples    per coloured object (revision 0010): the looks of its training crops for
                the look model (:mod:`viewdb.catalogue.look_training`), float32 (n, d),
                and the look settings they were made with; an ingest fits the model
                again from them, making only the changed objects' anew
"""

from __future__ import annotations

from sqlalchemy import (
    Column,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Table,
    Text,
    UniqueConstraint,
)

__all__ = [
    "SCHEMA_REVISION",
    "appearance_blobs",
    "appearance_scopes",
    "appearances",
    "curve_errors",
    "curves",
    "fourier_points",
    "look_samples",
    "index_groups",
    "metadata",
    "objects",
    "perspective_group_id",
    "perspective_views",
    "rtree_meta",
    "rtree_pages",
    "settings",
    "sift_features",
    "tier_stamps",
    "views",
]

#: The Alembic revision this code reads and writes (the head of ``migrations/versions``).
SCHEMA_REVISION = "0010"

metadata = MetaData()

settings = Table(
    "settings",
    metadata,
    Column("key", String, primary_key=True),
    Column("value", Text, nullable=False),
)

objects = Table(
    "objects",
    metadata,
    Column("id", Integer, primary_key=True),
    Column("name", String, nullable=False, unique=True),
    Column("source", Text, nullable=False),
    Column("content_hash", String(64), nullable=False),
    Column("n_faces", Integer, nullable=False),
    Column("n_vertices", Integer, nullable=False),
    Column("centre", LargeBinary, nullable=False),
    Column("scale", Float, nullable=False),
    Column("mesh_glb", LargeBinary, nullable=False),
    Column("empty_views", Integer, nullable=False),
    Column("ingest_seconds", Float, nullable=False),
    Column("created_at", String, nullable=False),
    # revision 0002: camera view skimming
    Column("skimmed", Integer, nullable=False, server_default="0"),
    Column("h_type", String, nullable=True),
    Column("v_type", String, nullable=True),
    Column("h_period", Float, nullable=True),
    Column("v_period", Float, nullable=True),
    Column("symmetry", Text, nullable=True),
)
# revision 0007: what reads the columns after the mesh reads them here, not through its pages
Index("ix_objects_versions", objects.c.name, objects.c.content_hash, objects.c.skimmed, objects.c.created_at)

views = Table(
    "views",
    metadata,
    Column("id", Integer, primary_key=True),
    Column("object_id", Integer, ForeignKey("objects.id", ondelete="CASCADE"), nullable=False),
    Column("azimuth", Float, nullable=False),
    Column("elevation", Float, nullable=False),
    Column("grid_gap", Float, nullable=False),
    UniqueConstraint("object_id", "azimuth", "elevation", name="uq_views_object_angles"),
)
Index("ix_views_object", views.c.object_id)

curves = Table(
    "curves",
    metadata,
    Column("view_id", Integer, ForeignKey("views.id", ondelete="CASCADE"), primary_key=True),
    Column("samples", LargeBinary, nullable=False),
)

fourier_points = Table(
    "fourier_points",
    metadata,
    Column("view_id", Integer, ForeignKey("views.id", ondelete="CASCADE"), primary_key=True),
    Column("coefficients", LargeBinary, nullable=False),
)

sift_features = Table(
    "sift_features",
    metadata,
    Column("view_id", Integer, ForeignKey("views.id", ondelete="CASCADE"), primary_key=True),
    Column("count", Integer, nullable=False),
    Column("keypoints", LargeBinary, nullable=False),
    Column("descriptors", LargeBinary, nullable=False),
    Column("points3d", LargeBinary, nullable=False),
)

# revision 0004: perspective silhouettes
perspective_views = Table(
    "perspective_views",
    metadata,
    Column("id", Integer, primary_key=True),
    Column("object_id", Integer, ForeignKey("objects.id", ondelete="CASCADE"), nullable=False),
    Column("azimuth", Float, nullable=False),
    Column("elevation", Float, nullable=False),
    #: camera distance from the model's centre, bounding radii
    Column("distance", Float, nullable=False),
    Column("samples", LargeBinary, nullable=False),
    UniqueConstraint("object_id", "azimuth", "elevation", "distance",
                     name="uq_perspective_views_object_view"),
)
Index("ix_perspective_views_object", perspective_views.c.object_id)


# revision 0005: stored appearance (silhouette, internal edges, colour signature)
appearances = Table(
    "appearances",
    metadata,
    Column("id", Integer, primary_key=True),
    Column("object_id", Integer, ForeignKey("objects.id", ondelete="CASCADE"), nullable=False),
    Column("azimuth", Float, nullable=False),
    Column("elevation", Float, nullable=False),
    #: where the packed record (storage.appearances) lies in its object's appearance blob
    Column("offset", Integer, nullable=False),
    Column("size", Integer, nullable=False),
    UniqueConstraint("object_id", "azimuth", "elevation", name="uq_appearances_object_view"),
)

appearance_blobs = Table(
    "appearance_blobs",
    metadata,
    Column("object_id", Integer, ForeignKey("objects.id", ondelete="CASCADE"), primary_key=True),
    Column("data", LargeBinary, nullable=False),
)

# revision 0008: the objects whose appearance records cover every grid direction (every
# object an ingest writes since, with AppearanceConfig.every_view)
appearance_scopes = Table(
    "appearance_scopes",
    metadata,
    Column("object_id", Integer, ForeignKey("objects.id", ondelete="CASCADE"), primary_key=True),
    Column("scope", String, nullable=False),
)


def perspective_group_id(perspective_view_id: int) -> int:
    """How an index group names a perspective view: its id negated (orthographic views
    keep their positive ``views.id``), so one int64 array holds both kinds."""
    return -int(perspective_view_id)


# revision 0003: the Fourier-point R-trees of the sparse and full tiers
index_groups = Table(
    "index_groups",
    metadata,
    Column("id", Integer, primary_key=True),
    Column("tier", String, nullable=False),
    Column("object_id", Integer, ForeignKey("objects.id", ondelete="CASCADE"), nullable=False),
    #: int64 (n,) view ids; float32 (n, N) curves; float64 (d,) MBR corners; float32 (N,)
    #: per-sample range of the curves
    Column("view_ids", LargeBinary, nullable=False),
    Column("curves", LargeBinary, nullable=False),
    Column("lo", LargeBinary, nullable=False),
    Column("hi", LargeBinary, nullable=False),
    Column("curve_lo", LargeBinary, nullable=False),
    Column("curve_hi", LargeBinary, nullable=False),
)
Index("ix_index_groups_object", index_groups.c.object_id)
Index("ix_index_groups_tier", index_groups.c.tier)

rtree_pages = Table(
    "rtree_pages",
    metadata,
    Column("tier", Text, primary_key=True),
    Column("page", Integer, primary_key=True),
    Column("data", LargeBinary, nullable=False),
)

rtree_meta = Table(
    "rtree_meta",
    metadata,
    Column("tier", Text, primary_key=True),
    Column("dimension", Integer, nullable=False),
    Column("header_page", Integer, nullable=False),
)

# revision 0006: the proven error of each quantised curve of a compact client file
curve_errors = Table(
    "curve_errors",
    metadata,
    Column("group_id", Integer, ForeignKey("index_groups.id", ondelete="CASCADE"), primary_key=True),
    #: float32 (n, 2): per view of the group, L2 and L-infinity norm of its decoding error
    Column("errors", LargeBinary, nullable=False),
)

#: Each tier's key (:func:`~viewdb.storage.tier_file.tier_key`), stamped with the index
#: generation of the transaction that last changed the groups (revision 0009).
tier_stamps = Table(
    "tier_stamps",
    metadata,
    Column("tier", String, primary_key=True),
    Column("generation", String, nullable=False),
    Column("key", String, nullable=False),
)


# revision 0010: each coloured object's look samples (viewdb.catalogue.look_training)
look_samples = Table(
    "look_samples",
    metadata,
    Column("object_id", Integer, ForeignKey("objects.id", ondelete="CASCADE"), primary_key=True),
    #: the LookConfig.key() they were made with
    Column("config", String, nullable=False),
    Column("looks", LargeBinary, nullable=False),
)
