"""Each coloured object's look samples, kept for the next fit of the look model.

An ingest that changes any object fits the look model again
(:mod:`viewdb.catalogue.look_training`). Before this revision that meant rendering every
object of the catalogue and pasting every coloured one 200 times into synthetic clutter
again: minutes on a catalogue of a few hundred objects, for one object added. The looks
of each coloured object's training crops are now stored here with the look settings they
were made with; the next fit makes only the looks of the objects that lack them (added
or replaced: a replaced object's row goes with it) and fits the model from all of them.
Only an ingest reads the table.

Revision ID: 0010
Revises: 0009
"""

import sqlalchemy as sa
from alembic import op

revision = "0010"
down_revision = "0009"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "look_samples",
        sa.Column("object_id", sa.Integer, sa.ForeignKey("objects.id", ondelete="CASCADE"),
                  primary_key=True),
        sa.Column("config", sa.String, nullable=False),
        sa.Column("looks", sa.LargeBinary, nullable=False),
    )


def downgrade() -> None:
    op.drop_table("look_samples")
