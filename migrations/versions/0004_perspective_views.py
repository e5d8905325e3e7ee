"""Perspective silhouettes: each object's distance curves seen through a pinhole camera.

Files from before this revision have none; their objects still search as before (the
orthographic views), and an ingest of their unchanged source files adds the perspective
views (only those are rendered: :mod:`viewdb.catalogue.ingest`).

Revision ID: 0004
Revises: 0003
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "perspective_views",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("object_id", sa.Integer, sa.ForeignKey("objects.id", ondelete="CASCADE"),
                  nullable=False),
        sa.Column("azimuth", sa.Float, nullable=False),
        sa.Column("elevation", sa.Float, nullable=False),
        sa.Column("distance", sa.Float, nullable=False),
        sa.Column("samples", sa.LargeBinary, nullable=False),
        sa.UniqueConstraint("object_id", "azimuth", "elevation", "distance",
                            name="uq_perspective_views_object_view"),
    )
    op.create_index("ix_perspective_views_object", "perspective_views", ["object_id"])


def downgrade() -> None:
    op.drop_index("ix_perspective_views_object", "perspective_views")
    op.drop_table("perspective_views")
