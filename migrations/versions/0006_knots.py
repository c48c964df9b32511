"""Knots: ``topological_states.knot_type`` (filled for existing rows) and the views knots_tied, knot_visits.

``knot_type`` is :func:`twisted.knots.identify` of the state's P-data: the rope closed by an arc under
everything, named from the catalogue ("0_1", "3_1+", "3_1-", "4_1", "5_1+", ...; "unknown" outside it).
New rows get it where they are inserted (``twisted.store.queries.get_or_create_state``).

Revision ID: 0006
Revises: 0001
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0001"
branch_labels = None
depends_on = None

# Plain SQL valid on SQLite and PostgreSQL. The unknot is left out of knots_tied: "which knots have we
# tied" means every closure that is not the unknot ("unknown" included).
KNOT_VIEWS: dict[str, str] = {
    # Per knot type and run: configurations reached that tie it, distinct states, when first reached.
    "knots_tied": """
        SELECT s.knot_type AS knot_type, c.run_id AS run_id, r.kind AS run_kind,
               COUNT(c.id) AS configurations, COUNT(DISTINCT s.id) AS states,
               MIN(c.created_at) AS first_seen
        FROM configurations c
        JOIN topological_states s ON s.id = c.state_id
        LEFT JOIN runs r ON r.id = c.run_id
        WHERE s.knot_type IS NOT NULL AND s.knot_type <> '0_1'
        GROUP BY s.knot_type, c.run_id, r.kind
    """,
    # Per knot type (the unknot included): states known, states reached, configurations.
    "knot_visits": """
        SELECT s.knot_type AS knot_type,
               COUNT(DISTINCT s.id) AS states,
               COUNT(DISTINCT c.state_id) AS visited_states,
               COUNT(c.id) AS configurations
        FROM topological_states s LEFT JOIN configurations c ON c.state_id = s.id
        GROUP BY s.knot_type
    """,
}


def _fill_knot_types() -> None:
    # Imported here so that loading the migration scripts does not import the knot code.
    from twisted.knots import identify
    from twisted.topology import PDataError, parse_p_data

    conn = op.get_bind()
    table = sa.table(
        "topological_states",
        sa.column("id", sa.Integer),
        sa.column("p_data", sa.JSON),
        sa.column("knot_type", sa.String),
    )
    rows = conn.execute(sa.select(table.c.id, table.c.p_data)).all()
    updates = []
    for state_id, p_data in rows:
        try:
            name: str | None = identify(parse_p_data(p_data)).name
        except PDataError:
            name = None  # not drawable in the plane: no knot to name
        updates.append({"state_id": state_id, "knot_type": name})
    if updates:
        conn.execute(
            table.update()
            .where(table.c.id == sa.bindparam("state_id"))
            .values(knot_type=sa.bindparam("knot_type")),
            updates,
        )


def upgrade() -> None:
    # A plain ADD COLUMN (no batch table copy): SQLite supports it, and copying topological_states would
    # trip over the views and foreign keys that refer to it.
    op.add_column("topological_states", sa.Column("knot_type", sa.String(length=16), nullable=True))
    op.create_index(
        op.f("ix_topological_states_knot_type"), "topological_states", ["knot_type"], unique=False
    )
    _fill_knot_types()
    for name, select in KNOT_VIEWS.items():
        op.execute(f"CREATE VIEW {name} AS {select.strip()}")


def downgrade() -> None:
    for name in reversed(list(KNOT_VIEWS)):
        op.execute(f"DROP VIEW IF EXISTS {name}")
    op.drop_index(op.f("ix_topological_states_knot_type"), table_name="topological_states")
    op.drop_column("topological_states", "knot_type")
