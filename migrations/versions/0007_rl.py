"""SAC+HER baseline: rl_runs, rl_checkpoints, rl_success (twisted/store/rl.py).

Revision ID: 0007
Revises: 0001
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0001"
branch_labels = None
depends_on = None


def _ts(name: str, nullable: bool = False) -> sa.Column:
    return sa.Column(name, sa.DateTime(timezone=True), nullable=nullable)


def upgrade() -> None:
    op.create_table(
        "rl_runs",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("status", sa.String(length=16), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=False),
        sa.Column("parameters", sa.JSON(), nullable=False),
        sa.Column("total_steps", sa.Integer(), nullable=False),
        sa.Column("steps_done", sa.Integer(), nullable=False),
        sa.Column("episodes", sa.Integer(), nullable=False),
        sa.Column("elapsed_s", sa.Float(), nullable=False),
        sa.Column("metrics", sa.JSON(), nullable=False),
        _ts("started_at"),
        _ts("updated_at"),
        _ts("ended_at", nullable=True),
        sa.Column("message", sa.Text(), nullable=True),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_rl_runs")),
    )
    with op.batch_alter_table("rl_runs") as batch:
        batch.create_index(batch.f("ix_rl_runs_status"), ["status"], unique=False)

    op.create_table(
        "rl_checkpoints",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("rl_run_id", sa.Integer(), nullable=False),
        sa.Column("steps", sa.Integer(), nullable=False),
        sa.Column("episodes", sa.Integer(), nullable=False),
        sa.Column("elapsed_s", sa.Float(), nullable=False),
        sa.Column("final", sa.Boolean(), nullable=False),
        sa.Column("policy", sa.LargeBinary(), nullable=False),
        sa.Column("replay_buffer", sa.LargeBinary(), nullable=True),
        sa.Column("size_bytes", sa.Integer(), nullable=False),
        _ts("created_at"),
        sa.ForeignKeyConstraint(
            ["rl_run_id"], ["rl_runs.id"], name=op.f("fk_rl_checkpoints_rl_run_id_rl_runs")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_rl_checkpoints")),
    )
    with op.batch_alter_table("rl_checkpoints") as batch:
        batch.create_index(batch.f("ix_rl_checkpoints_rl_run_id"), ["rl_run_id"], unique=False)

    op.create_table(
        "rl_success",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("rl_run_id", sa.Integer(), nullable=False),
        sa.Column("steps", sa.Integer(), nullable=False),
        sa.Column("goal_cross", sa.Integer(), nullable=False),
        sa.Column("episodes", sa.Integer(), nullable=False),
        sa.Column("successes", sa.Integer(), nullable=False),
        _ts("created_at"),
        sa.ForeignKeyConstraint(["rl_run_id"], ["rl_runs.id"], name=op.f("fk_rl_success_rl_run_id_rl_runs")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_rl_success")),
    )
    with op.batch_alter_table("rl_success") as batch:
        batch.create_index(batch.f("ix_rl_success_rl_run_id"), ["rl_run_id"], unique=False)


def downgrade() -> None:
    op.drop_table("rl_success")
    op.drop_table("rl_checkpoints")
    op.drop_table("rl_runs")
