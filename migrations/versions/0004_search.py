"""Planner search tree: search_runs, search_nodes, search_checkpoints (twisted/store/search_tree.py).

Revision ID: 0004
Revises: 0001
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "search_runs",
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("goal_state_id", sa.Integer(), nullable=False),
        sa.Column("goal_cross", sa.Integer(), nullable=False),
        sa.Column("planner", sa.String(length=32), nullable=False),
        sa.Column("heuristic", sa.String(length=16), nullable=False),
        sa.Column("start_configuration_id", sa.Integer(), nullable=True),
        sa.Column("outcome", sa.String(length=16), nullable=False),
        sa.Column("goal_node_id", sa.Integer(), nullable=True),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], name=op.f("fk_search_runs_run_id_runs")),
        sa.ForeignKeyConstraint(
            ["goal_state_id"],
            ["topological_states.id"],
            name=op.f("fk_search_runs_goal_state_id_topological_states"),
        ),
        sa.ForeignKeyConstraint(
            ["start_configuration_id"],
            ["configurations.id"],
            name=op.f("fk_search_runs_start_configuration_id_configurations"),
        ),
        sa.PrimaryKeyConstraint("run_id", name=op.f("pk_search_runs")),
    )
    with op.batch_alter_table("search_runs") as batch:
        batch.create_index(batch.f("ix_search_runs_goal_state_id"), ["goal_state_id"], unique=False)
        batch.create_index(batch.f("ix_search_runs_outcome"), ["outcome"], unique=False)

    op.create_table(
        "search_nodes",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("seq", sa.Integer(), nullable=False),
        sa.Column("parent_id", sa.Integer(), nullable=True),
        sa.Column("state_id", sa.Integer(), nullable=False),
        sa.Column("cross", sa.Integer(), nullable=False),
        sa.Column("q", sa.LargeBinary(), nullable=False),
        sa.Column("points", sa.LargeBinary(), nullable=False),
        sa.Column("link", sa.Integer(), nullable=True),
        sa.Column("z_max_m", sa.Float(), nullable=True),
        sa.Column("x_m", sa.Float(), nullable=True),
        sa.Column("y_m", sa.Float(), nullable=True),
        sa.Column("iteration", sa.Integer(), nullable=False),
        sa.Column("sim_call", sa.Integer(), nullable=False),
        sa.Column("created_s", sa.Float(), nullable=False),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], name=op.f("fk_search_nodes_run_id_runs")),
        sa.ForeignKeyConstraint(
            ["parent_id"], ["search_nodes.id"], name=op.f("fk_search_nodes_parent_id_search_nodes")
        ),
        sa.ForeignKeyConstraint(
            ["state_id"], ["topological_states.id"], name=op.f("fk_search_nodes_state_id_topological_states")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_search_nodes")),
        sa.UniqueConstraint("run_id", "seq", name=op.f("uq_search_nodes_run_id_seq")),
    )
    with op.batch_alter_table("search_nodes") as batch:
        batch.create_index(batch.f("ix_search_nodes_run_id"), ["run_id"], unique=False)
        batch.create_index(batch.f("ix_search_nodes_parent_id"), ["parent_id"], unique=False)
        batch.create_index(batch.f("ix_search_nodes_state_id"), ["state_id"], unique=False)

    op.create_table(
        "search_checkpoints",
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("iteration", sa.Integer(), nullable=False),
        sa.Column("elapsed_s", sa.Float(), nullable=False),
        sa.Column("sim_calls", sa.Integer(), nullable=False),
        sa.Column("nodes", sa.Integer(), nullable=False),
        sa.Column("rng_state", sa.Text(), nullable=False),
        sa.Column("stats", sa.JSON(), nullable=False),
        sa.Column("updated_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], name=op.f("fk_search_checkpoints_run_id_runs")),
        sa.PrimaryKeyConstraint("run_id", name=op.f("pk_search_checkpoints")),
    )


def downgrade() -> None:
    op.drop_table("search_checkpoints")
    op.drop_table("search_nodes")
    op.drop_table("search_runs")
