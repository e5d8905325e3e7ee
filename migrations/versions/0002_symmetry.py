"""Camera view skimming: each object's symmetry type and whether its views were skimmed.

Objects written before this revision keep every grid view (``skimmed = 0``) and have no
symmetry type until they are re-ingested.

Revision ID: 0002
Revises: 0001
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("objects") as batch:
        batch.add_column(sa.Column("skimmed", sa.Integer, nullable=False, server_default="0"))
        batch.add_column(sa.Column("h_type", sa.String, nullable=True))
        batch.add_column(sa.Column("v_type", sa.String, nullable=True))
        batch.add_column(sa.Column("h_period", sa.Float, nullable=True))
        batch.add_column(sa.Column("v_period", sa.Float, nullable=True))
        batch.add_column(sa.Column("symmetry", sa.Text, nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("objects") as batch:
        for column in ("symmetry", "v_period", "h_period", "v_type", "h_type", "skimmed"):
            batch.drop_column(column)
