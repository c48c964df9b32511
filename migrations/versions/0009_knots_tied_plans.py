"""Knots: ``knots_tied`` also counts the planner's search trees, not only the collected configurations.

Merges the knot branch (0006) with the planner's knot goals (0008): the view needs ``search_nodes``.
A planner run "ties" a knot when a node of its tree ``T`` is in a state whose closure is that knot;
for those rows ``configurations`` counts tree nodes and ``first_seen`` is the run's start (the search
time of each node is ``search_nodes.created_s``).

Revision ID: 0009
Revises: 0006, 0008
"""

from __future__ import annotations

from alembic import op

revision = "0009"
down_revision = ("0006", "0008")
branch_labels = None
depends_on = None


def _collected() -> str:
    """0006's knots_tied: the collected configurations (this view adds the planner trees to it)."""
    from importlib import import_module

    return str(import_module("migrations.versions.0006_knots").KNOT_VIEWS["knots_tied"]).strip()


# Plain SQL valid on SQLite and PostgreSQL; both parts give the same column types.
PLANNER_TREES = """
    SELECT s.knot_type AS knot_type, n.run_id AS run_id, r.kind AS run_kind,
           COUNT(n.id) AS configurations, COUNT(DISTINCT s.id) AS states,
           MIN(r.started_at) AS first_seen
    FROM search_nodes n
    JOIN topological_states s ON s.id = n.state_id
    LEFT JOIN runs r ON r.id = n.run_id
    WHERE s.knot_type IS NOT NULL AND s.knot_type <> '0_1'
    GROUP BY s.knot_type, n.run_id, r.kind
"""


def upgrade() -> None:
    op.execute("DROP VIEW IF EXISTS knots_tied")
    op.execute(f"CREATE VIEW knots_tied AS {_collected()}\n  UNION ALL\n{PLANNER_TREES.rstrip()}")


def downgrade() -> None:
    op.execute("DROP VIEW IF EXISTS knots_tied")
    op.execute(f"CREATE VIEW knots_tied AS {_collected()}")
