"""What made a search node: ``search_nodes.action``, ``curve`` (every node before) or ``cinch``.

A cinch (docs/DESIGN.md section 8, :func:`twisted.tighten.cinch`) pulls the rope of a node tight and lets
it go: the node it makes has no curve, so its curve columns are NULL like the root's, and ``action``
tells the two apart. The root's action is ``curve`` too (it has no parent). The view
``search_plan_steps`` gains the column ``action`` after ``node_id``.

Revision ID: 0014
Revises: 0012
"""

from __future__ import annotations

from importlib import import_module

import sqlalchemy as sa
from alembic import op

revision = "0014"
down_revision = "0012"
branch_labels = None
depends_on = None


def _plan_steps(with_action: bool) -> str:
    """The view of 0004b, with the ``action`` column or as it was."""
    sql = str(import_module("migrations.versions.0004b_search_view").SEARCH_PLAN_STEPS)
    old = "n.id AS node_id,"
    assert old in sql
    return sql.replace(old, "n.id AS node_id, n.action AS action,") if with_action else sql


def upgrade() -> None:
    op.execute("DROP VIEW IF EXISTS search_plan_steps")
    op.add_column(
        "search_nodes",
        sa.Column("action", sa.String(length=16), nullable=False, server_default="curve"),
    )
    op.execute(f"CREATE VIEW search_plan_steps AS {_plan_steps(True)}")


def downgrade() -> None:
    # ALTER TABLE ... DROP COLUMN in place (SQLite >= 3.35 has it): a batch copy of search_nodes would
    # trip over the other views that read the table (knots_tied)
    op.execute("DROP VIEW IF EXISTS search_plan_steps")
    op.drop_column("search_nodes", "action")
    op.execute(f"CREATE VIEW search_plan_steps AS {_plan_steps(False)}")
