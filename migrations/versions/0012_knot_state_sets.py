"""The knot-state sets kept per database: knot_state_sets (twisted/store/knots.py), on the knots branch.

A 5-crossing knot goal enumerates and names all 130,304 states of 5 crossings; the sets are kept so
that this is paid once per database (``twisted.store.knots.cached_states_by_type``).

Revision ID: 0012
Revises: 0010
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0012"
down_revision = "0010"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "knot_state_sets",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("crossings", sa.Integer(), nullable=False),
        sa.Column("knot_type", sa.String(length=64), nullable=False),
        sa.Column("moves_version", sa.Integer(), nullable=False),
        sa.Column("n_states", sa.Integer(), nullable=False),
        sa.Column("states", sa.LargeBinary(), nullable=False),
        sa.Column("compute_s", sa.Float(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_knot_state_sets")),
        sa.UniqueConstraint(
            "crossings", "knot_type", "moves_version", name=op.f("uq_knot_state_sets_crossings")
        ),
    )


def downgrade() -> None:
    op.drop_table("knot_state_sets")
