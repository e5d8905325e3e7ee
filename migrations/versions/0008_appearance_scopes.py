"""Which views an object's appearance records cover.

Before this revision an ingest recorded the appearance of each object's stored views (and
of the views opposite them when that cost no renders). A view the skim plan pruned took a
recorded image twin's record when the mesh has no colour of its own and such a twin was
recorded; otherwise (a mesh with colour, whose texture need not share the shape's
symmetry, or no recorded twin) it was rendered at query time. An ingest now records every
grid direction of every object (``AppearanceConfig.every_view``), and this table marks the
objects recorded so (``scope = 'every'``). An object without a row here was recorded the
old way: ingesting its unchanged source again adds the records it lacks ("upgraded").
Read-only, a file without the table answers as before, rendering those views.

Revision ID: 0008
Revises: 0007
"""

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "appearance_scopes",
        sa.Column("object_id", sa.Integer, sa.ForeignKey("objects.id", ondelete="CASCADE"),
                  primary_key=True),
        sa.Column("scope", sa.String, nullable=False),
    )


def downgrade() -> None:
    op.drop_table("appearance_scopes")
