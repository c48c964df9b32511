"""Plan cache: plan_queries and plans (models in twisted/store/plans.py).

Revision ID: 0002
Revises: 0001
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "plan_queries",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("start_key", sa.Text(), nullable=False),
        sa.Column("goal_key", sa.Text(), nullable=False),
        sa.Column("start_cross", sa.Integer(), nullable=False),
        sa.Column("goal_cross", sa.Integer(), nullable=False),
        sa.Column("plan_limit", sa.Integer(), nullable=False),
        sa.Column("n_plans", sa.Integer(), nullable=False),
        sa.Column("complete", sa.Boolean(), nullable=False),
        sa.Column("moves_version", sa.Integer(), nullable=False),
        sa.Column("compute_s", sa.Float(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_plan_queries")),
        sa.UniqueConstraint("start_key", "goal_key", name="uq_plan_queries_key"),
    )
    with op.batch_alter_table("plan_queries") as batch:
        batch.create_index(batch.f("ix_plan_queries_goal_key"), ["goal_key"], unique=False)

    op.create_table(
        "plans",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("query_id", sa.Integer(), nullable=False),
        sa.Column("start_key", sa.Text(), nullable=False),
        sa.Column("goal_key", sa.Text(), nullable=False),
        sa.Column("plan_index", sa.Integer(), nullable=False),
        sa.Column("length", sa.Integer(), nullable=False),
        sa.Column("states", sa.JSON(), nullable=False),
        sa.Column("moves", sa.JSON(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["query_id"], ["plan_queries.id"], name=op.f("fk_plans_query_id_plan_queries"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_plans")),
        sa.UniqueConstraint("start_key", "goal_key", "plan_index", name="uq_plans_key"),
    )
    with op.batch_alter_table("plans") as batch:
        batch.create_index(batch.f("ix_plans_query_id"), ["query_id"], unique=False)


def downgrade() -> None:
    op.drop_table("plans")
    op.drop_table("plan_queries")
