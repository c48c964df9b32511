"""Experiments: problem_sets, problems, eval_runs, eval_results, discretisation_results.

Models in twisted/store/experiments.py.

Revision ID: 0005
Revises: 0001
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0001"
branch_labels = None
depends_on = None


def _ts(name: str, nullable: bool = False) -> sa.Column:
    return sa.Column(name, sa.DateTime(timezone=True), nullable=nullable)


def upgrade() -> None:
    op.create_table(
        "problem_sets",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("source", sa.String(length=16), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=True),
        sa.Column("parameters", sa.JSON(), nullable=False),
        _ts("created_at"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_problem_sets")),
        sa.UniqueConstraint("name", name=op.f("uq_problem_sets_name")),
    )

    op.create_table(
        "problems",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("set_id", sa.Integer(), nullable=False),
        sa.Column("idx", sa.Integer(), nullable=False),
        sa.Column("goal_key", sa.Text(), nullable=False),
        sa.Column("p_data", sa.JSON(), nullable=False),
        sa.Column("cross", sa.Integer(), nullable=False),
        sa.Column("frequency", sa.Integer(), nullable=False),
        sa.Column("tag", sa.String(length=32), nullable=False),
        sa.ForeignKeyConstraint(
            ["set_id"], ["problem_sets.id"], name=op.f("fk_problems_set_id_problem_sets")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_problems")),
        sa.UniqueConstraint("set_id", "goal_key", name="uq_problems_set_id_goal_key"),
        sa.UniqueConstraint("set_id", "idx", name="uq_problems_set_id_idx"),
    )
    with op.batch_alter_table("problems") as batch:
        batch.create_index(batch.f("ix_problems_set_id"), ["set_id"], unique=False)

    op.create_table(
        "eval_runs",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("set_id", sa.Integer(), nullable=False),
        sa.Column("planner", sa.String(length=32), nullable=False),
        sa.Column("timeout_s", sa.Float(), nullable=False),
        sa.Column("friction_scale", sa.Float(), nullable=False),
        sa.Column("seeds", sa.JSON(), nullable=False),
        sa.Column("workers", sa.Integer(), nullable=False),
        sa.Column("parallel", sa.Integer(), nullable=False),
        sa.Column("parameters", sa.JSON(), nullable=False),
        sa.Column("status", sa.String(length=16), nullable=False),
        _ts("started_at"),
        _ts("ended_at", nullable=True),
        sa.Column("host", sa.String(length=255), nullable=True),
        sa.Column("pid", sa.Integer(), nullable=True),
        sa.Column("message", sa.Text(), nullable=True),
        sa.ForeignKeyConstraint(
            ["set_id"], ["problem_sets.id"], name=op.f("fk_eval_runs_set_id_problem_sets")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_eval_runs")),
    )
    with op.batch_alter_table("eval_runs") as batch:
        batch.create_index(batch.f("ix_eval_runs_set_id"), ["set_id"], unique=False)

    op.create_table(
        "eval_results",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("eval_run_id", sa.Integer(), nullable=False),
        sa.Column("set_id", sa.Integer(), nullable=False),
        sa.Column("problem_id", sa.Integer(), nullable=False),
        sa.Column("planner", sa.String(length=32), nullable=False),
        sa.Column("goal_key", sa.Text(), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=False),
        sa.Column("timeout_s", sa.Float(), nullable=False),
        sa.Column("friction_scale", sa.Float(), nullable=False),
        sa.Column("status", sa.String(length=16), nullable=False),
        sa.Column("solved", sa.Boolean(), nullable=False),
        sa.Column("time_to_solve_s", sa.Float(), nullable=True),
        sa.Column("elapsed_s", sa.Float(), nullable=True),
        sa.Column("sim_calls", sa.Integer(), nullable=True),
        sa.Column("iterations", sa.Integer(), nullable=True),
        sa.Column("plan_run_id", sa.Integer(), nullable=True),
        sa.Column("wall_s", sa.Float(), nullable=True),
        sa.Column("host", sa.String(length=255), nullable=True),
        sa.Column("pid", sa.Integer(), nullable=True),
        sa.Column("message", sa.Text(), nullable=True),
        _ts("started_at"),
        _ts("ended_at", nullable=True),
        sa.ForeignKeyConstraint(
            ["eval_run_id"], ["eval_runs.id"], name=op.f("fk_eval_results_eval_run_id_eval_runs")
        ),
        sa.ForeignKeyConstraint(
            ["set_id"], ["problem_sets.id"], name=op.f("fk_eval_results_set_id_problem_sets")
        ),
        sa.ForeignKeyConstraint(
            ["problem_id"], ["problems.id"], name=op.f("fk_eval_results_problem_id_problems")
        ),
        sa.ForeignKeyConstraint(["plan_run_id"], ["runs.id"], name=op.f("fk_eval_results_plan_run_id_runs")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_eval_results")),
        sa.UniqueConstraint(
            "set_id", "planner", "goal_key", "seed", "timeout_s", "friction_scale", name="uq_eval_results_key"
        ),
    )
    with op.batch_alter_table("eval_results") as batch:
        batch.create_index(batch.f("ix_eval_results_eval_run_id"), ["eval_run_id"], unique=False)
        batch.create_index(batch.f("ix_eval_results_set_id"), ["set_id"], unique=False)
        batch.create_index(batch.f("ix_eval_results_problem_id"), ["problem_id"], unique=False)
        batch.create_index(batch.f("ix_eval_results_status"), ["status"], unique=False)
        batch.create_index(batch.f("ix_eval_results_plan_run_id"), ["plan_run_id"], unique=False)

    op.create_table(
        "discretisation_results",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("transition_id", sa.Integer(), nullable=False),
        sa.Column("variant", sa.String(length=16), nullable=False),
        sa.Column("friction_scale", sa.Float(), nullable=False),
        sa.Column("link", sa.Integer(), nullable=False),
        sa.Column("z_max_m", sa.Float(), nullable=False),
        sa.Column("x_m", sa.Float(), nullable=False),
        sa.Column("y_m", sa.Float(), nullable=False),
        sa.Column("recorded_key", sa.Text(), nullable=False),
        sa.Column("result_key", sa.Text(), nullable=True),
        sa.Column("ok", sa.Boolean(), nullable=False),
        sa.Column("changed", sa.Boolean(), nullable=False),
        sa.Column("reason", sa.Text(), nullable=True),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], name=op.f("fk_discretisation_results_run_id_runs")),
        sa.ForeignKeyConstraint(
            ["transition_id"],
            ["transitions.id"],
            name=op.f("fk_discretisation_results_transition_id_transitions"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_discretisation_results")),
        sa.UniqueConstraint("run_id", "transition_id", "variant", name="uq_discretisation_results_key"),
    )
    with op.batch_alter_table("discretisation_results") as batch:
        batch.create_index(batch.f("ix_discretisation_results_run_id"), ["run_id"], unique=False)
        batch.create_index(
            batch.f("ix_discretisation_results_transition_id"), ["transition_id"], unique=False
        )

    # Readable summaries for a sqlite3/psql shell (the README shows them).
    op.execute(
        """
        CREATE VIEW eval_summary AS
        SELECT ps.name AS problem_set, r.planner AS planner, r.timeout_s AS timeout_s,
               r.friction_scale AS friction_scale, COUNT(*) AS attempts,
               SUM(CASE WHEN r.solved THEN 1 ELSE 0 END) AS solved,
               AVG(CASE WHEN r.solved THEN r.time_to_solve_s END) AS mean_time_to_solve_s,
               AVG(r.sim_calls) AS mean_sim_calls
        FROM eval_results r JOIN problem_sets ps ON ps.id = r.set_id
        WHERE r.status IN ('solved', 'timeout')
        GROUP BY ps.name, r.planner, r.timeout_s, r.friction_scale
        """
    )
    op.execute(
        """
        CREATE VIEW discretisation_summary AS
        SELECT d.run_id AS run_id, d.variant AS variant, d.friction_scale AS friction_scale,
               COUNT(*) AS transitions, SUM(CASE WHEN d.changed THEN 1 ELSE 0 END) AS changed,
               SUM(CASE WHEN d.ok THEN 0 ELSE 1 END) AS rejected
        FROM discretisation_results d
        GROUP BY d.run_id, d.variant, d.friction_scale
        """
    )


def downgrade() -> None:
    op.execute("DROP VIEW IF EXISTS discretisation_summary")
    op.execute("DROP VIEW IF EXISTS eval_summary")
    op.drop_table("discretisation_results")
    op.drop_table("eval_results")
    op.drop_table("eval_runs")
    op.drop_table("problems")
    op.drop_table("problem_sets")
