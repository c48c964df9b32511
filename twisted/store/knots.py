"""Knot questions over the foundation tables (``topological_states.knot_type``, revision 0006).

The same answers are in the views ``knot_visits`` and ``knots_tied`` for a sqlite3/psql shell;
:func:`knots_tied` reads its view (it spans two areas' tables: configurations and planner trees).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterable
from dataclasses import dataclass

from sqlalchemy import DateTime, Integer, String, column, func, select, table
from sqlalchemy.orm import Session

from twisted.store.models import Configuration, TopologicalState

__all__ = [
    "KNOT_VIEW_NAMES",
    "KnotTied",
    "KnotVisits",
    "configurations_per_state",
    "knot_visits",
    "knots_tied",
]

KNOT_VIEW_NAMES = ("knots_tied", "knot_visits")


@dataclass(frozen=True, slots=True)
class KnotVisits:
    """One knot type: distinct states known, states reached by a configuration, configurations."""

    knot_type: str | None
    states: int
    visited_states: int
    configurations: int


@dataclass(frozen=True, slots=True)
class KnotTied:
    """One knot type in one run: configurations and distinct states that tie it, first reached when."""

    knot_type: str
    run_id: int | None
    run_kind: str | None
    configurations: int
    states: int
    first_seen: dt.datetime | None


def knot_visits(session: Session) -> list[KnotVisits]:
    """Per knot type (the view ``knot_visits``), most configurations first."""
    s, c = TopologicalState, Configuration
    rows = session.execute(
        select(
            s.knot_type,
            func.count(func.distinct(s.id)),
            func.count(func.distinct(c.state_id)),
            func.count(c.id),
        )
        .select_from(s)
        .outerjoin(c, c.state_id == s.id)
        .group_by(s.knot_type)
    ).all()
    out = [KnotVisits(k, int(a), int(b), int(n)) for k, a, b, n in rows]
    return sorted(out, key=lambda v: (-v.configurations, v.knot_type or ""))


# The view of migration 0009: collected configurations and planner tree nodes, per knot type and run.
_KNOTS_TIED = table(
    "knots_tied",
    column("knot_type", String),
    column("run_id", Integer),
    column("run_kind", String),
    column("configurations", Integer),
    column("states", Integer),
    column("first_seen", DateTime(timezone=True)),
)


def knots_tied(session: Session) -> list[KnotTied]:
    """Per knot type other than the unknot, per run (collect: configurations; plan: nodes of ``T``)."""
    v = _KNOTS_TIED.c
    rows = session.execute(
        select(v.knot_type, v.run_id, v.run_kind, v.configurations, v.states, v.first_seen).order_by(
            v.knot_type, v.run_id, v.run_kind
        )
    ).all()
    return [KnotTied(str(k), r, kind, int(n), int(m), first) for k, r, kind, n, m, first in rows]


def configurations_per_state(session: Session, keys: Iterable[str]) -> dict[str, int]:
    """How many configurations reached each state (by P-data key); 0 for states never reached."""
    wanted = list(dict.fromkeys(keys))
    out = dict.fromkeys(wanted, 0)
    for start in range(0, len(wanted), 500):  # bounded IN lists
        chunk = wanted[start : start + 500]
        rows = session.execute(
            select(TopologicalState.key, func.count(Configuration.id))
            .join(Configuration, Configuration.state_id == TopologicalState.id)
            .where(TopologicalState.key.in_(chunk))
            .group_by(TopologicalState.key)
        ).all()
        out.update({key: int(n) for key, n in rows})
    return out
