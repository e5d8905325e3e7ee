"""Each tier's key stamped in the transaction that changed its groups.

A tier file (and a ``fast`` index) beside a database is used only if its key matches the
tier's content (:func:`viewdb.storage.tier_file.tier_key`). Before this revision a fresh
open computed that key from the index's generation, the tier's group count, id sum and
maximum, and every object's id, name and content hash: a read of every object (tens of
milliseconds on a large file, on every fresh open). Every write transaction that changes
a tier now stamps its key here with the generation it wrote; a fresh open reads the stamp
of the current generation (one read) and computes the key only when there is none (a file
not written since this revision). The revision also keeps viewdbs that do not stamp (and
might change the groups without renewing the generation) from writing the file.

Revision ID: 0009
Revises: 0008
"""

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "tier_stamps",
        sa.Column("tier", sa.String, primary_key=True),
        sa.Column("generation", sa.String, nullable=False),
        sa.Column("key", sa.String, nullable=False),
    )


def downgrade() -> None:
    op.drop_table("tier_stamps")
