"""Compact client files: each quantised curve's proven error.

A compact client file (``export-client``) stores the sparse tier's curves once, as
8-bit codes with a per-curve offset and scale (:mod:`viewdb.storage.codecs`), and this
table holds, per index group, each view's error norms against the float32 curve it was
made from, so the client can bound its distances (:mod:`viewdb.search.quantised`).
Files without rows here (every full file, and client files written before) store exact
curves.

Revision ID: 0006
Revises: 0005
"""

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "curve_errors",
        sa.Column("group_id", sa.Integer, sa.ForeignKey("index_groups.id", ondelete="CASCADE"),
                  primary_key=True),
        sa.Column("errors", sa.LargeBinary, nullable=False),
    )


def downgrade() -> None:
    op.drop_table("curve_errors")
