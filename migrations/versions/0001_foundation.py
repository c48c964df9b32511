"""Foundation: runs, topological states, configurations, transitions, collect batches, views.

Revision ID: 0001
Revises:
Create Date: 2026-11-23

Other areas branch off this revision (``down_revision = "0001"``); the store upgrades to "heads".
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0001"
down_revision: str | Sequence[str] | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# The views make the common questions one-liners in a sqlite3/psql shell. Plain SQL valid on SQLite and
# PostgreSQL (where CROSS is a reserved word: columns named cross are always qualified here).
VIEWS_0001: dict[str, str] = {
    # Per crossing count: distinct states known / reached by a configuration, and configurations.
    "states_by_cross": """
        SELECT s.cross AS cross,
               COUNT(DISTINCT s.id) AS states,
               COUNT(DISTINCT c.state_id) AS visited_states,
               COUNT(c.id) AS configurations
        FROM topological_states s LEFT JOIN configurations c ON c.state_id = s.id
        GROUP BY s.cross
    """,
    # Per state: how often it was reached (configurations) and kept transitions into / out of it.
    "state_visits": """
        SELECT s.id AS state_id, s.key AS key, s.cross AS cross,
               (SELECT COUNT(*) FROM configurations c WHERE c.state_id = s.id) AS configurations,
               (SELECT COUNT(*) FROM transitions t WHERE t.to_state_id = s.id) AS transitions_in,
               (SELECT COUNT(*) FROM transitions t WHERE t.from_state_id = s.id) AS transitions_out
        FROM topological_states s
    """,
    # Per run: kept transitions, the configurations it added, the highest crossing count reached.
    "transitions_per_run": """
        SELECT r.id AS run_id, r.kind AS kind, r.status AS status, r.started_at AS started_at,
               (SELECT COUNT(*) FROM transitions t WHERE t.run_id = r.id) AS transitions,
               (SELECT COUNT(*) FROM configurations c WHERE c.run_id = r.id) AS configurations,
               (SELECT MAX(t.to_cross) FROM transitions t WHERE t.run_id = r.id) AS max_cross
        FROM runs r
    """,
    # Per collect run: throughput. runs.wall_seconds is refreshed with every committed batch, so a killed
    # run still reports the time up to its last commit.
    "collect_throughput": """
        SELECT r.id AS run_id, r.status AS status, r.started_at AS started_at, r.ended_at AS ended_at,
               r.wall_seconds AS wall_seconds, r.tried AS tried, r.kept AS kept, r.rejected AS rejected,
               CAST(r.kept AS DOUBLE PRECISION) * 3600 / NULLIF(r.wall_seconds, 0) AS kept_per_hour,
               CAST(r.kept AS DOUBLE PRECISION) / NULLIF(r.tried, 0) AS kept_rate
        FROM runs r WHERE r.kind = 'collect'
    """,
    # Per start crossing count, over all collect batches: acceptance of random curves.
    "acceptance_by_cross": """
        SELECT t.from_cross AS from_cross, SUM(t.tried) AS tried, SUM(t.kept) AS kept,
               SUM(t.rejected) AS rejected,
               CAST(SUM(t.kept) AS DOUBLE PRECISION) / NULLIF(SUM(t.tried), 0) AS kept_rate
        FROM collect_tries t GROUP BY t.from_cross
    """,
}


def _timestamp(name: str, nullable: bool = False) -> sa.Column:
    return sa.Column(name, sa.DateTime(timezone=True), nullable=nullable)


def upgrade() -> None:
    op.create_table(
        "runs",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("kind", sa.String(length=32), nullable=False),
        sa.Column("parameters", sa.JSON(), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=True),
        sa.Column("status", sa.String(length=16), nullable=False),
        _timestamp("started_at"),
        _timestamp("ended_at", nullable=True),
        sa.Column("tried", sa.Integer(), nullable=False),
        sa.Column("kept", sa.Integer(), nullable=False),
        sa.Column("rejected", sa.Integer(), nullable=False),
        sa.Column("wall_seconds", sa.Float(), nullable=False),
        sa.Column("sim_seconds", sa.Float(), nullable=False),
        sa.Column("host", sa.String(length=255), nullable=True),
        sa.Column("pid", sa.Integer(), nullable=True),
        sa.Column("message", sa.Text(), nullable=True),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_runs")),
    )
    op.create_index(op.f("ix_runs_kind"), "runs", ["kind"])

    op.create_table(
        "topological_states",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("key", sa.Text(), nullable=False),
        sa.Column("p_data", sa.JSON(), nullable=False),
        sa.Column("cross", sa.Integer(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_topological_states")),
        sa.UniqueConstraint("key", name=op.f("uq_topological_states_key")),
    )
    op.create_index(op.f("ix_topological_states_cross"), "topological_states", ["cross"])

    op.create_table(
        "configurations",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=True),
        sa.Column("state_id", sa.Integer(), nullable=False),
        sa.Column("cross", sa.Integer(), nullable=False),
        sa.Column("q", sa.LargeBinary(), nullable=False),
        sa.Column("points", sa.LargeBinary(), nullable=False),
        _timestamp("created_at"),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], name=op.f("fk_configurations_run_id_runs")),
        sa.ForeignKeyConstraint(
            ["state_id"],
            ["topological_states.id"],
            name=op.f("fk_configurations_state_id_topological_states"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_configurations")),
    )
    op.create_index(op.f("ix_configurations_run_id"), "configurations", ["run_id"])
    op.create_index(op.f("ix_configurations_state_id"), "configurations", ["state_id"])
    op.create_index(op.f("ix_configurations_cross"), "configurations", ["cross"])

    op.create_table(
        "collect_batches",
        sa.Column("batch_id", sa.String(length=64), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("worker", sa.Integer(), nullable=False),
        sa.Column("seq", sa.Integer(), nullable=False),
        sa.Column("tried", sa.Integer(), nullable=False),
        sa.Column("kept", sa.Integer(), nullable=False),
        sa.Column("rejected", sa.Integer(), nullable=False),
        sa.Column("sim_seconds", sa.Float(), nullable=False),
        _timestamp("committed_at"),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], name=op.f("fk_collect_batches_run_id_runs")),
        sa.PrimaryKeyConstraint("batch_id", name=op.f("pk_collect_batches")),
    )
    op.create_index(op.f("ix_collect_batches_run_id"), "collect_batches", ["run_id"])

    op.create_table(
        "collect_tries",
        sa.Column("batch_id", sa.String(length=64), nullable=False),
        sa.Column("from_cross", sa.Integer(), nullable=False),
        sa.Column("tried", sa.Integer(), nullable=False),
        sa.Column("kept", sa.Integer(), nullable=False),
        sa.Column("rejected", sa.Integer(), nullable=False),
        sa.ForeignKeyConstraint(
            ["batch_id"], ["collect_batches.batch_id"], name=op.f("fk_collect_tries_batch_id_collect_batches")
        ),
        sa.PrimaryKeyConstraint("batch_id", "from_cross", name=op.f("pk_collect_tries")),
    )

    op.create_table(
        "transitions",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("batch_id", sa.String(length=64), nullable=True),
        sa.Column("from_configuration_id", sa.Integer(), nullable=False),
        sa.Column("to_configuration_id", sa.Integer(), nullable=False),
        sa.Column("link", sa.Integer(), nullable=False),
        sa.Column("z_max_m", sa.Float(), nullable=False),
        sa.Column("x_m", sa.Float(), nullable=False),
        sa.Column("y_m", sa.Float(), nullable=False),
        sa.Column("from_state_id", sa.Integer(), nullable=False),
        sa.Column("to_state_id", sa.Integer(), nullable=False),
        sa.Column("from_cross", sa.Integer(), nullable=False),
        sa.Column("to_cross", sa.Integer(), nullable=False),
        sa.Column("steps", sa.Integer(), nullable=True),
        _timestamp("created_at"),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], name=op.f("fk_transitions_run_id_runs")),
        sa.ForeignKeyConstraint(
            ["batch_id"], ["collect_batches.batch_id"], name=op.f("fk_transitions_batch_id_collect_batches")
        ),
        sa.ForeignKeyConstraint(
            ["from_configuration_id"],
            ["configurations.id"],
            name=op.f("fk_transitions_from_configuration_id_configurations"),
        ),
        sa.ForeignKeyConstraint(
            ["to_configuration_id"],
            ["configurations.id"],
            name=op.f("fk_transitions_to_configuration_id_configurations"),
        ),
        sa.ForeignKeyConstraint(
            ["from_state_id"],
            ["topological_states.id"],
            name=op.f("fk_transitions_from_state_id_topological_states"),
        ),
        sa.ForeignKeyConstraint(
            ["to_state_id"],
            ["topological_states.id"],
            name=op.f("fk_transitions_to_state_id_topological_states"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_transitions")),
    )
    op.create_index(op.f("ix_transitions_run_id"), "transitions", ["run_id"])
    op.create_index(op.f("ix_transitions_batch_id"), "transitions", ["batch_id"])
    op.create_index(op.f("ix_transitions_from_configuration_id"), "transitions", ["from_configuration_id"])
    op.create_index(op.f("ix_transitions_to_configuration_id"), "transitions", ["to_configuration_id"])
    op.create_index(
        "ix_transitions_from_state_id_to_state_id", "transitions", ["from_state_id", "to_state_id"]
    )
    op.create_index("ix_transitions_from_cross_to_cross", "transitions", ["from_cross", "to_cross"])

    for name, select in VIEWS_0001.items():
        op.execute(f"CREATE VIEW {name} AS {select.strip()}")


def downgrade() -> None:
    for name in reversed(list(VIEWS_0001)):
        op.execute(f"DROP VIEW IF EXISTS {name}")
    for table in (
        "transitions",
        "collect_tries",
        "collect_batches",
        "configurations",
        "topological_states",
        "runs",
    ):
        op.drop_table(table)
