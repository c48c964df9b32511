"""Episodes: plans executed in a world apart from the planner's model (twisted/store/episodes.py), its own
branch off 0001.

``episodes`` (one row per episode, its ``runs`` row of kind ``episode``) and ``episode_steps`` (each
world reset, action sent, observation, replan and pull test, in order); docs/DESIGN.md section 15.5.

Revision ID: 0016_episodes
Revises: 0001
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0016_episodes"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "episodes",
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("plan_run_id", sa.Integer(), nullable=True),
        sa.Column("goal_knot", sa.String(length=64), nullable=False),
        sa.Column("level", sa.String(length=200), nullable=False),
        sa.Column("level_ranges", sa.JSON(), nullable=False),
        sa.Column("world_seed", sa.BigInteger(), nullable=False),
        sa.Column("physics", sa.JSON(), nullable=False),
        sa.Column("closed_loop", sa.Boolean(), nullable=False),
        sa.Column("timeout_s", sa.Float(), nullable=False),
        sa.Column("max_actions", sa.Integer(), nullable=False),
        sa.Column("outcome", sa.String(length=16), nullable=False),
        sa.Column("actions", sa.Integer(), nullable=False),
        sa.Column("replans", sa.Integer(), nullable=False),
        sa.Column("planning_s", sa.Float(), nullable=False),
        sa.Column("elapsed_s", sa.Float(), nullable=False),
        sa.Column("final_knot", sa.String(length=64), nullable=True),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], name=op.f("fk_episodes_run_id_runs")),
        sa.ForeignKeyConstraint(["plan_run_id"], ["runs.id"], name=op.f("fk_episodes_plan_run_id_runs")),
        sa.PrimaryKeyConstraint("run_id", name=op.f("pk_episodes")),
    )
    for column in ("plan_run_id", "goal_knot", "level", "outcome"):
        op.create_index(op.f(f"ix_episodes_{column}"), "episodes", [column])
    op.create_table(
        "episode_steps",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("episode_id", sa.Integer(), nullable=False),
        sa.Column("seq", sa.Integer(), nullable=False),
        sa.Column("kind", sa.String(length=16), nullable=False),
        sa.Column("link", sa.Integer(), nullable=True),
        sa.Column("z_max_m", sa.Float(), nullable=True),
        sa.Column("x_m", sa.Float(), nullable=True),
        sa.Column("y_m", sa.Float(), nullable=True),
        sa.Column("points", sa.LargeBinary(), nullable=True),
        sa.Column("observed_key", sa.Text(), nullable=True),
        sa.Column("expected_key", sa.Text(), nullable=True),
        sa.Column("drift_m", sa.Float(), nullable=True),
        sa.Column("fit_residual_m", sa.Float(), nullable=True),
        sa.Column("fault", sa.Text(), nullable=True),
        sa.Column("knot", sa.String(length=64), nullable=True),
        sa.Column("replan_run_id", sa.Integer(), nullable=True),
        sa.Column("planning_s", sa.Float(), nullable=True),
        sa.Column("plan_run_id", sa.Integer(), nullable=True),
        sa.Column("plan_step", sa.Integer(), nullable=True),
        sa.Column("world_checkpoint", sa.JSON(), nullable=True),
        sa.Column("elapsed_s", sa.Float(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["episode_id"], ["episodes.run_id"], name=op.f("fk_episode_steps_episode_id_episodes")
        ),
        sa.ForeignKeyConstraint(
            ["replan_run_id"], ["runs.id"], name=op.f("fk_episode_steps_replan_run_id_runs")
        ),
        sa.ForeignKeyConstraint(["plan_run_id"], ["runs.id"], name=op.f("fk_episode_steps_plan_run_id_runs")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_episode_steps")),
        sa.UniqueConstraint("episode_id", "seq", name=op.f("uq_episode_steps_episode_id")),
    )
    op.create_index(op.f("ix_episode_steps_episode_id"), "episode_steps", ["episode_id"])


def downgrade() -> None:
    op.drop_index(op.f("ix_episode_steps_episode_id"), table_name="episode_steps")
    op.drop_table("episode_steps")
    for column in ("plan_run_id", "goal_knot", "level", "outcome"):
        op.drop_index(op.f(f"ix_episodes_{column}"), table_name="episodes")
    op.drop_table("episodes")
