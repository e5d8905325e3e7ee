"""An index that holds each object's name, content hash, skimming and time of writing.

An object's row holds its mesh (``mesh_glb``, tens of kB to MB, in overflow pages), and the
columns after it (``created_at``, ``skimmed``) are reached only by walking those pages. The
objects' versions (what a CS1 server checks a client's candidates against) and the key of a
tier file of a file without an index generation read those columns for every object: every
stored mesh, 64 MB for the 212-model file, seconds from a cold disk. This covering index
answers them without the table's rows.

Revision ID: 0007
Revises: 0006
"""

from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_index("ix_objects_versions", "objects", ["name", "content_hash", "skimmed", "created_at"])


def downgrade() -> None:
    op.drop_index("ix_objects_versions", table_name="objects")
