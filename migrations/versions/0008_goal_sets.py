"""Planner: knot goals. ``search_runs.goal_knot`` names the knot a run plans to (NULL: one P-data state).

A knot goal is the set of states of ``goal_cross`` crossings that tie the knot; they are listed in the
run's ``runs.parameters['goal_states']``, and ``goal_state_id`` is the first of them by key.

Revision ID: 0008
Revises: 0004b
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0004b"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("search_runs") as batch:
        batch.add_column(sa.Column("goal_knot", sa.String(length=64), nullable=True))
        batch.create_index(batch.f("ix_search_runs_goal_knot"), ["goal_knot"], unique=False)


def downgrade() -> None:
    with op.batch_alter_table("search_runs") as batch:
        batch.drop_index(batch.f("ix_search_runs_goal_knot"))
        batch.drop_column("goal_knot")
