"""Imported problem sets keep their parameters as made sets do: ``problem_sets.parameters`` flattened.

Before this revision ``problems import`` stored a goal-set file's whole header as an imported set's
parameters (format, name, kind, seed, command, and the drawn set's ``parameters`` one level down), so
``problems export`` wrote that header back one level deeper each round and the runner had to look for
``pull_test`` in two places. Now an imported set's parameters are the file's ``parameters`` with its
``kind`` and ``command`` (``twisted.experiments.problems.drawn_parameters``) and the count of goals;
this revision rewrites the rows stored before in that shape. The downgrade nests them again.

Revision ID: 0015
Revises: 0005
"""

from __future__ import annotations

from typing import Any

import sqlalchemy as sa
from alembic import op

revision = "0015"
down_revision = "0005"
branch_labels = None
depends_on = None

GOAL_SET_FORMAT = "twisted-goal-set/1"  # twisted.experiments.problems.GOAL_SET_FORMAT at this revision

_sets = sa.table(
    "problem_sets",
    sa.column("id", sa.Integer()),
    sa.column("name", sa.String()),
    sa.column("source", sa.String()),
    sa.column("seed", sa.BigInteger()),
    sa.column("parameters", sa.JSON()),
)


def _flat(old: dict[str, Any]) -> dict[str, Any]:
    inner = old.get("parameters")
    new = dict(inner) if isinstance(inner, dict) else {}
    for key in ("kind", "command"):
        if old.get(key) is not None:
            new.setdefault(key, old[key])
    if "goals" in old:
        new["goals"] = old["goals"]
    return new


def _nested(name: str, seed: int | None, flat: dict[str, Any]) -> dict[str, Any]:
    inner = {k: v for k, v in flat.items() if k not in ("command", "goals")}
    return {
        "format": GOAL_SET_FORMAT,
        "name": name,
        "kind": flat.get("kind"),
        "seed": seed,
        "command": flat["command"],
        "parameters": inner,
        "goals": flat.get("goals"),
    }


def _rewrite(change: Any) -> None:
    conn = op.get_bind()
    rows = conn.execute(
        sa.select(_sets.c.id, _sets.c.name, _sets.c.seed, _sets.c.parameters).where(
            _sets.c.source == "imported"
        )
    ).all()
    for row in rows:
        new = change(row.name, row.seed, dict(row.parameters or {}))
        if new is not None:
            conn.execute(sa.update(_sets).where(_sets.c.id == row.id).values(parameters=new))


def upgrade() -> None:
    _rewrite(lambda name, seed, p: _flat(p) if p.get("format") == GOAL_SET_FORMAT else None)


def downgrade() -> None:
    _rewrite(lambda name, seed, p: _nested(name, seed, p) if "command" in p and "format" not in p else None)
