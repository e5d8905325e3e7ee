"""Stored appearance: each viewing direction's silhouette, internal edges and colour
signature, so the re-rankings and the pose compare stored data instead of rendering.

Files from before this revision have none; they still answer, rendering what they lack
(slower), and an ingest of their unchanged source files adds the records (only the views'
renders are redone: :mod:`viewdb.catalogue.ingest`).

Revision ID: 0005
Revises: 0004
"""

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "appearances",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("object_id", sa.Integer, sa.ForeignKey("objects.id", ondelete="CASCADE"),
                  nullable=False),
        sa.Column("azimuth", sa.Float, nullable=False),
        sa.Column("elevation", sa.Float, nullable=False),
        sa.Column("offset", sa.Integer, nullable=False),
        sa.Column("size", sa.Integer, nullable=False),
        sa.UniqueConstraint("object_id", "azimuth", "elevation", name="uq_appearances_object_view"),
    )
    op.create_table(
        "appearance_blobs",
        sa.Column("object_id", sa.Integer, sa.ForeignKey("objects.id", ondelete="CASCADE"),
                  primary_key=True),
        sa.Column("data", sa.LargeBinary, nullable=False),
    )


def downgrade() -> None:
    op.drop_table("appearance_blobs")
    op.drop_table("appearances")
