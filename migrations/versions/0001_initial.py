"""Initial schema: settings, objects, views, curves, Fourier points, SIFT features.

Revision ID: 0001
Revises:
"""

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "settings",
        sa.Column("key", sa.String, primary_key=True),
        sa.Column("value", sa.Text, nullable=False),
    )
    op.create_table(
        "objects",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("name", sa.String, nullable=False, unique=True),
        sa.Column("source", sa.Text, nullable=False),
        sa.Column("content_hash", sa.String(64), nullable=False),
        sa.Column("n_faces", sa.Integer, nullable=False),
        sa.Column("n_vertices", sa.Integer, nullable=False),
        sa.Column("centre", sa.LargeBinary, nullable=False),
        sa.Column("scale", sa.Float, nullable=False),
        sa.Column("mesh_glb", sa.LargeBinary, nullable=False),
        sa.Column("empty_views", sa.Integer, nullable=False),
        sa.Column("ingest_seconds", sa.Float, nullable=False),
        sa.Column("created_at", sa.String, nullable=False),
    )
    op.create_table(
        "views",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column(
            "object_id",
            sa.Integer,
            sa.ForeignKey("objects.id", ondelete="CASCADE"),
            nullable=False,
        ),
        sa.Column("azimuth", sa.Float, nullable=False),
        sa.Column("elevation", sa.Float, nullable=False),
        sa.Column("grid_gap", sa.Float, nullable=False),
        sa.UniqueConstraint("object_id", "azimuth", "elevation", name="uq_views_object_angles"),
    )
    op.create_index("ix_views_object", "views", ["object_id"])
    for table, column in (("curves", "samples"), ("fourier_points", "coefficients")):
        op.create_table(
            table,
            sa.Column(
                "view_id",
                sa.Integer,
                sa.ForeignKey("views.id", ondelete="CASCADE"),
                primary_key=True,
            ),
            sa.Column(column, sa.LargeBinary, nullable=False),
        )
    op.create_table(
        "sift_features",
        sa.Column(
            "view_id", sa.Integer, sa.ForeignKey("views.id", ondelete="CASCADE"), primary_key=True
        ),
        sa.Column("count", sa.Integer, nullable=False),
        sa.Column("keypoints", sa.LargeBinary, nullable=False),
        sa.Column("descriptors", sa.LargeBinary, nullable=False),
        sa.Column("points3d", sa.LargeBinary, nullable=False),
    )


def downgrade() -> None:
    for table in ("sift_features", "fourier_points", "curves", "views", "objects", "settings"):
        op.drop_table(table)
