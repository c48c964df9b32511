"""Real knots: both closures of every state, ``knot_type`` only when they agree; pull-test results.

``topological_states.closure_under`` / ``closure_over`` name the knot of the rope closed under / over
the table (:class:`twisted.knots.RopeKnot`); ``knot_type`` becomes the knot the rope really ties: the
common name when both closures are the same knot, ``"knotoid"`` when they differ (an end lies inside a
loop; pulling the ends decides). Existing rows are recomputed here. The views keep their columns:
``knot_visits`` now has a ``knotoid`` row, and ``knots_tied`` leaves the unknot and knotoids out.

``tightenings`` stores each pull test (``twisted replay --tighten``, ``twisted plan --tighten``): the
configuration pulled, the state and knot before and after, whether the tightened rope ties the goal's
knot, and how long the simulation took.

Revision ID: 0010
Revises: 0009
"""

from __future__ import annotations

from importlib import import_module

import sqlalchemy as sa
from alembic import op

revision = "0010"
down_revision = "0009"
branch_labels = None
depends_on = None

NOT_TIED = ("0_1", "knotoid")


def _views() -> tuple[str, str]:
    """knots_tied (both parts of 0009) and knot_visits (0006), leaving out knotoids as well."""
    knots_0006 = import_module("migrations.versions.0006_knots").KNOT_VIEWS
    trees = import_module("migrations.versions.0009_knots_tied_plans").PLANNER_TREES
    old = "s.knot_type <> '0_1'"
    new = "s.knot_type NOT IN ('0_1', 'knotoid')"
    collected = str(knots_0006["knots_tied"]).strip().replace(old, new)
    planner = str(trees).strip().replace(old, new)
    assert new in collected and new in planner
    return f"{collected}\n  UNION ALL\n{planner}", str(knots_0006["knot_visits"]).strip()


def _fill() -> None:
    from twisted.knots import identify
    from twisted.topology import PDataError, parse_p_data

    conn = op.get_bind()
    table = sa.table(
        "topological_states",
        sa.column("id", sa.Integer),
        sa.column("p_data", sa.JSON),
        sa.column("knot_type", sa.String),
        sa.column("closure_under", sa.String),
        sa.column("closure_over", sa.String),
    )
    updates = []
    for state_id, p_data in conn.execute(sa.select(table.c.id, table.c.p_data)).all():
        try:
            k = identify(parse_p_data(p_data))
            values = {"knot_type": k.name, "closure_under": k.under.name, "closure_over": k.over.name}
        except PDataError:
            values = {"knot_type": None, "closure_under": None, "closure_over": None}
        updates.append({"state_id": state_id, **values})
    if updates:
        conn.execute(
            table.update()
            .where(table.c.id == sa.bindparam("state_id"))
            .values(
                knot_type=sa.bindparam("knot_type"),
                closure_under=sa.bindparam("closure_under"),
                closure_over=sa.bindparam("closure_over"),
            ),
            updates,
        )


def upgrade() -> None:
    op.execute("DROP VIEW IF EXISTS knots_tied")
    op.execute("DROP VIEW IF EXISTS knot_visits")
    op.add_column("topological_states", sa.Column("closure_under", sa.String(length=16), nullable=True))
    op.add_column("topological_states", sa.Column("closure_over", sa.String(length=16), nullable=True))
    _fill()
    knots_tied, knot_visits = _views()
    op.execute(f"CREATE VIEW knots_tied AS {knots_tied}")
    op.execute(f"CREATE VIEW knot_visits AS {knot_visits}")
    op.create_table(
        "tightenings",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("run_id", sa.Integer(), sa.ForeignKey("runs.id"), nullable=True, index=True),
        sa.Column("configuration_id", sa.Integer(), sa.ForeignKey("configurations.id"), nullable=True),
        sa.Column("node_seq", sa.Integer(), nullable=True),
        sa.Column("state_id", sa.Integer(), sa.ForeignKey("topological_states.id"), nullable=False),
        sa.Column("tightened_state_id", sa.Integer(), sa.ForeignKey("topological_states.id"), nullable=True),
        sa.Column("knot_before", sa.String(length=64), nullable=True),
        sa.Column("knot_after", sa.String(length=64), nullable=True),
        sa.Column("goal_knot", sa.String(length=64), nullable=True),
        sa.Column("ties_goal", sa.Boolean(), nullable=True),
        sa.Column("ok", sa.Boolean(), nullable=False),
        sa.Column("reason", sa.Text(), nullable=True),
        sa.Column("end_distance_m", sa.Float(), nullable=True),
        sa.Column("sim_seconds", sa.Float(), nullable=False),
        sa.Column("wall_seconds", sa.Float(), nullable=False),
        sa.Column("points", sa.LargeBinary(), nullable=True),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    )


def downgrade() -> None:
    op.drop_table("tightenings")
    op.execute("DROP VIEW IF EXISTS knots_tied")
    op.execute("DROP VIEW IF EXISTS knot_visits")
    # 0006's meaning: the knot of the closure under the table
    op.execute("UPDATE topological_states SET knot_type = closure_under")
    op.drop_column("topological_states", "closure_over")
    op.drop_column("topological_states", "closure_under")
    knots_0006 = import_module("migrations.versions.0006_knots").KNOT_VIEWS
    m0009 = import_module("migrations.versions.0009_knots_tied_plans")
    op.execute(f"CREATE VIEW knot_visits AS {str(knots_0006['knot_visits']).strip()}")
    op.execute(f"CREATE VIEW knots_tied AS {m0009._collected()}\n  UNION ALL\n{m0009.PLANNER_TREES.rstrip()}")
