"""The rope's crossing limit: ``rope_profile.max_crossings`` (twisted/store/rope_profile.py).

A rope profile now names the most crossings its states may have (``TWISTED_ROPE=31c7``, docs/DESIGN.md
section 2.6): the inverse model's input has room for that many, so data and models of one limit do not
mix with another's, as with another rope. Every store before this revision was made with the limit 6.

Revision ID: 0017
Revises: 0013
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0017"
down_revision = "0013"
branch_labels = None
depends_on = None

LEGACY_MAX_CROSSINGS = 6  # twisted.rope.MAX_CROSSINGS before ropes named their own


def upgrade() -> None:
    op.add_column(
        "rope_profile",
        sa.Column("max_crossings", sa.Integer(), nullable=False, server_default=str(LEGACY_MAX_CROSSINGS)),
    )


def downgrade() -> None:
    op.drop_column("rope_profile", "max_crossings")
