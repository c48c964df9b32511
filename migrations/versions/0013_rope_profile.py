"""The rope of the database's data: rope_profile (twisted/store/rope_profile.py), its own branch off 0001.

One row: the links and their spacing of the rope every configuration, plan and model in the database
was made on (``TWISTED_ROPE``, docs/DESIGN.md section 2). ``open_store`` records the process's rope
in a database that has none yet and refuses a process running another. A database that already
holds configurations was made before ropes could differ: on the paper's 21 links, 0.04 m apart.

Revision ID: 0013
Revises: 0001
"""

from __future__ import annotations

import datetime as dt

import sqlalchemy as sa
from alembic import op

revision = "0013"
down_revision = "0001"
branch_labels = None
depends_on = None

# Every store before this revision was made on this rope (twisted.rope.DEFAULT_ROPE at the time).
LEGACY_N_LINKS = 21
LEGACY_LINK_SPACING_M = 0.04


def upgrade() -> None:
    rope = op.create_table(
        "rope_profile",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("n_links", sa.Integer(), nullable=False),
        sa.Column("link_spacing_m", sa.Float(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_rope_profile")),
    )
    has_data = op.get_bind().execute(sa.text("SELECT 1 FROM configurations LIMIT 1")).first() is not None
    if has_data:
        op.bulk_insert(
            rope,
            [
                {
                    "id": 1,
                    "n_links": LEGACY_N_LINKS,
                    "link_spacing_m": LEGACY_LINK_SPACING_M,
                    "created_at": dt.datetime.now(dt.UTC),
                }
            ],
        )


def downgrade() -> None:
    op.drop_table("rope_profile")
