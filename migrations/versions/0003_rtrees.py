"""The Fourier-point R-trees: groups of views per tier and the R-tree pages, in the file.

Files from before this revision get their objects indexed here, from their stored curves
(with the default client grid for their gap), so an upgraded file searches like a new one.

Revision ID: 0003
Revises: 0002
"""

import json

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "index_groups",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("tier", sa.String, nullable=False),
        sa.Column("object_id", sa.Integer, sa.ForeignKey("objects.id", ondelete="CASCADE"),
                  nullable=False),
        sa.Column("view_ids", sa.LargeBinary, nullable=False),
        sa.Column("curves", sa.LargeBinary, nullable=False),
        sa.Column("lo", sa.LargeBinary, nullable=False),
        sa.Column("hi", sa.LargeBinary, nullable=False),
        sa.Column("curve_lo", sa.LargeBinary, nullable=False),
        sa.Column("curve_hi", sa.LargeBinary, nullable=False),
    )
    op.create_index("ix_index_groups_object", "index_groups", ["object_id"])
    op.create_index("ix_index_groups_tier", "index_groups", ["tier"])
    op.create_table(
        "rtree_pages",
        sa.Column("tier", sa.Text, primary_key=True),
        sa.Column("page", sa.Integer, primary_key=True),
        sa.Column("data", sa.LargeBinary, nullable=False),
    )
    op.create_table(
        "rtree_meta",
        sa.Column("tier", sa.Text, primary_key=True),
        sa.Column("dimension", sa.Integer, nullable=False),
        sa.Column("header_page", sa.Integer, nullable=False),
    )
    from viewdb.config import BuildConfig
    from viewdb.storage.tiers import create_tiers, index_stored_objects

    bind = op.get_bind()
    create_tiers(bind)
    row = bind.exec_driver_sql("SELECT value FROM settings WHERE key = 'build'").first()
    if row is not None:
        config = BuildConfig.from_dict(json.loads(row[0])).resolved()
        bind.exec_driver_sql(
            "UPDATE settings SET value = ? WHERE key = 'build'", (json.dumps(config.to_dict()),)
        )
        index_stored_objects(bind, config)


def downgrade() -> None:
    op.drop_table("rtree_meta")
    op.drop_table("rtree_pages")
    op.drop_index("ix_index_groups_tier", "index_groups")
    op.drop_index("ix_index_groups_object", "index_groups")
    op.drop_table("index_groups")
