"""Planner: view search_plan_steps, the found low-level plan of every solved run, one row per step.

Revision ID: 0004b
Revises: 0004
"""

from __future__ import annotations

from alembic import op

revision = "0004b"
down_revision = "0004"
branch_labels = None
depends_on = None

# Step 0 is the initial configuration (no curve); step i is the i-th curve and the state after it.
# Plain SQL valid on SQLite (>= 3.25, window functions) and PostgreSQL, where CROSS is a reserved
# word: the column is always qualified.
SEARCH_PLAN_STEPS = """
    WITH RECURSIVE path(run_id, node_id, parent_id, depth) AS (
        SELECT r.run_id, n.id, n.parent_id, 0
        FROM search_runs r JOIN search_nodes n ON n.id = r.goal_node_id
      UNION ALL
        SELECT p.run_id, n.id, n.parent_id, p.depth + 1
        FROM path p JOIN search_nodes n ON n.id = p.parent_id
    )
    SELECT p.run_id AS run_id,
           MAX(p.depth) OVER (PARTITION BY p.run_id) - p.depth AS step,
           n.id AS node_id,
           n.link AS link, n.z_max_m AS z_max_m, n.x_m AS x_m, n.y_m AS y_m,
           s.key AS state, n.cross AS crossings,
           n.created_s AS created_s, n.sim_call AS sim_call
    FROM path p
    JOIN search_nodes n ON n.id = p.node_id
    JOIN topological_states s ON s.id = n.state_id
"""


def upgrade() -> None:
    op.execute(f"CREATE VIEW search_plan_steps AS {SEARCH_PLAN_STEPS}")


def downgrade() -> None:
    op.execute("DROP VIEW search_plan_steps")
