"""Knot questions over the foundation tables (``topological_states.knot_type``, revisions 0006 and 0010).

``knot_type`` is the knot a state really ties (both closures agree) or ``"knotoid"``; the closures are
``closure_under`` / ``closure_over``. ``tightenings`` (0010) holds the pull tests
(:mod:`twisted.tighten`) run by ``twisted replay --tighten`` and ``twisted plan --tighten``.

The same answers are in the views ``knot_visits`` and ``knots_tied`` for a sqlite3/psql shell;
:func:`knots_tied` reads its view (it spans two areas' tables: configurations and planner trees).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from sqlalchemy import (
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    LargeBinary,
    String,
    Text,
    UniqueConstraint,
    column,
    func,
    select,
    table,
)
from sqlalchemy.orm import Mapped, Session, mapped_column

from twisted.store.models import Base, Configuration, TopologicalState, array_to_blob, blob_to_array, utcnow
from twisted.store.queries import get_or_create_state

__all__ = [
    "KNOT_VIEW_NAMES",
    "KnotStateSet",
    "cached_states_by_type",
    "keep_states_by_type",
    "kept_crossings",
    "load_states_by_type",
    "prime_goal_spec",
    "prime_knot_goal",
    "Tightening",
    "TighteningRecord",
    "record_tightening",
    "tightenings",
    "KnotTied",
    "KnotVisits",
    "configurations_per_state",
    "nodes_per_state",
    "knot_table",
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
    return _count_per_state(session, keys, Configuration, Configuration.id, Configuration.state_id)


# search_nodes read by name (twisted.store.search imports this module): the planner trees' vertices
_SEARCH_NODES = table(
    "search_nodes", column("id", Integer), column("state_id", Integer), column("seq", Integer)
)


def nodes_per_state(session: Session, keys: Iterable[str]) -> dict[str, int]:
    """How many planner tree nodes reached each state (by P-data key), each run's root left out (it is the
    run's start: the straight rope or a configuration counted already); 0 for states never reached."""
    n = _SEARCH_NODES.c
    return _count_per_state(session, keys, _SEARCH_NODES, n.id, n.state_id, n.seq > 0)


def _count_per_state(
    session: Session, keys: Iterable[str], rows_of: Any, counted: Any, state_id: Any, *where: Any
) -> dict[str, int]:
    wanted = list(dict.fromkeys(keys))
    out = dict.fromkeys(wanted, 0)
    for start in range(0, len(wanted), 500):  # bounded IN lists
        chunk = wanted[start : start + 500]
        rows = session.execute(
            select(TopologicalState.key, func.count(counted))
            .join_from(TopologicalState, rows_of, state_id == TopologicalState.id)
            .where(TopologicalState.key.in_(chunk), *where)
            .group_by(TopologicalState.key)
        ).all()
        out.update({key: int(c) for key, c in rows})
    return out


def knot_table(store: Any | None, crossings: int | None, max_crossings: int) -> list[dict[str, Any]]:
    """``twisted knots list``: for each knot of the table (:data:`twisted.knots.CATALOGUE`) its names,
    invariants and the P-data states that really tie it at ``crossings`` (None: its crossing number; above
    it they are enumerated up to ``max_crossings``, else ``listed`` is False), each with its visits in
    ``store``: the configurations collected in it and the planner tree nodes reached in it (None: no store).
    The states are sorted most visited first; the entries in table order."""
    from twisted.knots import CATALOGUE, crossing_number, knotinfo_name, shown_name, states_tying

    found: dict[str, list[Any] | None] = {}  # None: not enumerated at that count (see max_crossings)
    counts: dict[str, int] = {}
    for knot_type in CATALOGUE:
        counts[knot_type] = count = crossings if crossings is not None else crossing_number(knot_type)
        try:
            found[knot_type] = states_tying(knot_type, count, max_crossings=max_crossings)
        except ValueError:
            found[knot_type] = None
    keys = [p.key for states in found.values() for p in states or ()]
    configurations: dict[str, int] | None = None
    nodes: dict[str, int] = {}
    if store is not None:
        with store.session() as session:
            configurations, nodes = configurations_per_state(session, keys), nodes_per_state(session, keys)

    def state(p: Any) -> dict[str, Any]:
        if configurations is None:
            return {"p_data": p.to_list(), "configurations": None, "nodes": None, "visits": None}
        c, n = configurations[p.key], nodes[p.key]
        return {"p_data": p.to_list(), "configurations": c, "nodes": n, "visits": c + n}

    def total(states: list[dict[str, Any]], what: str) -> int | None:
        return None if configurations is None else sum(s[what] for s in states)

    entries: list[dict[str, Any]] = []
    for knot_type, k in CATALOGUE.items():
        ordered = sorted(found[knot_type] or (), key=lambda p: (-(state(p)["visits"] or 0), p.key))
        states = [state(p) for p in ordered]
        entries.append(
            {
                "name": shown_name(knot_type),
                "knot_type": knot_type,
                "knotinfo": knotinfo_name(knot_type),
                "alexander": k.alexander_text(),
                "determinant": k.determinant,
                "jones": k.jones_text(),
                "crossing_number": crossing_number(knot_type),
                "crossings": counts[knot_type],
                "listed": found[knot_type] is not None,
                "states": states,
                "visited_states": None if configurations is None else sum(s["visits"] > 0 for s in states),
                "configurations": total(states, "configurations"),
                "nodes": total(states, "nodes"),
                "visits": total(states, "visits"),
            }
        )
    return entries


# --- pull tests (revision 0010) ------------------------------------------------------------------------


class Tightening(Base):
    """One pull test: a configuration (stored, or a node of run ``run_id``'s tree), before and after."""

    __tablename__ = "tightenings"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id"), index=True)
    configuration_id: Mapped[int | None] = mapped_column(ForeignKey("configurations.id"))
    node_seq: Mapped[int | None] = mapped_column(Integer)  # search_nodes.seq of the node pulled
    state_id: Mapped[int] = mapped_column(ForeignKey("topological_states.id"))
    tightened_state_id: Mapped[int | None] = mapped_column(ForeignKey("topological_states.id"))
    knot_before: Mapped[str | None] = mapped_column(String(64))  # RopeKnot.describe() of the state
    knot_after: Mapped[str | None] = mapped_column(String(64))  # ... of the tightened rope
    goal_knot: Mapped[str | None] = mapped_column(String(64))  # what it had to tie (a name), if any
    ties_goal: Mapped[bool | None] = mapped_column(Boolean)
    ok: Mapped[bool] = mapped_column(Boolean)  # False: the simulation was rejected (reason)
    reason: Mapped[str | None] = mapped_column(Text)
    end_distance_m: Mapped[float | None] = mapped_column(Float)
    sim_seconds: Mapped[float] = mapped_column(Float)
    wall_seconds: Mapped[float] = mapped_column(Float)
    points: Mapped[bytes | None] = mapped_column(LargeBinary)  # the tightened rope's N_POINTS link points
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


@dataclass(frozen=True, slots=True)
class TighteningRecord:
    """A stored pull test, read back."""

    id: int
    run_id: int | None
    node_seq: int | None
    knot_before: str | None
    knot_after: str | None
    goal_knot: str | None
    ties_goal: bool | None
    ok: bool
    reason: str | None
    end_distance_m: float | None
    sim_seconds: float
    wall_seconds: float
    points: npt.NDArray[np.float64] | None


def record_tightening(
    session: Session,
    result: Any,
    state: Any,
    *,
    run_id: int | None = None,
    configuration_id: int | None = None,
    node_seq: int | None = None,
    goal_knot: str | None = None,
    ties_goal: bool | None = None,
) -> int:
    """Store a :class:`twisted.tighten.Tightened` of the rope in P-data ``state``; returns its id."""
    from twisted.knots import identify

    row = Tightening(
        run_id=run_id,
        configuration_id=configuration_id,
        node_seq=node_seq,
        state_id=get_or_create_state(session, state).id,
        tightened_state_id=None if result.p_data is None else get_or_create_state(session, result.p_data).id,
        knot_before=identify(state).describe(),
        knot_after=None if result.knot is None else result.knot.describe(),
        goal_knot=goal_knot,
        ties_goal=ties_goal,
        ok=bool(result.ok),
        reason=result.reason,
        end_distance_m=result.end_distance_m,
        sim_seconds=float(result.sim_seconds),
        wall_seconds=float(result.wall_seconds),
        points=None if result.points is None else array_to_blob(result.points),
    )
    session.add(row)
    session.flush()
    return int(row.id)


def tightenings(session: Session, run_id: int) -> list[TighteningRecord]:
    """The pull tests stored with run ``run_id``, oldest first."""
    rows = session.scalars(select(Tightening).where(Tightening.run_id == run_id).order_by(Tightening.id))
    return [
        TighteningRecord(
            r.id,
            r.run_id,
            r.node_seq,
            r.knot_before,
            r.knot_after,
            r.goal_knot,
            r.ties_goal,
            r.ok,
            r.reason,
            r.end_distance_m,
            r.sim_seconds,
            r.wall_seconds,
            None if r.points is None else blob_to_array(r.points, (-1, 3)),
        )
        for r in rows
    ]


# --- the knot-state sets (revision 0012) ----------------------------------------------------------------


class KnotStateSet(Base):
    """Every state of one crossing count that ties one knot type (or is a knotoid, or ties none named):
    the sets :func:`twisted.knots.states_by_type` computes by enumerating, kept so that a 5-crossing
    knot goal's set-up (130,304 states enumerated and named) is paid once per database."""

    __tablename__ = "knot_state_sets"
    __table_args__ = (UniqueConstraint("crossings", "knot_type", "moves_version"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    crossings: Mapped[int] = mapped_column(Integer)
    knot_type: Mapped[str] = mapped_column(String(64))
    moves_version: Mapped[int] = mapped_column(Integer)  # twisted.moves.MOVES_VERSION it was made with
    n_states: Mapped[int] = mapped_column(Integer)
    states: Mapped[bytes] = mapped_column(LargeBinary)  # zlib of the JSON list of P-data lists, by key
    compute_s: Mapped[float] = mapped_column(Float)  # enumerating and naming every state of the count
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


def _pack(states: Iterable[Any]) -> bytes:
    import json
    import zlib

    return zlib.compress(json.dumps([p.to_list() for p in states], separators=(",", ":")).encode(), 6)


def _unpack(blob: bytes) -> tuple[Any, ...]:
    import json
    import zlib

    from twisted.topology import parse_p_data

    return tuple(parse_p_data(p) for p in json.loads(zlib.decompress(blob)))


def load_states_by_type(store: Any, crossings: int) -> dict[str, tuple[Any, ...]] | None:
    """The sets of :func:`twisted.knots.states_by_type` a process before kept in the store (same move
    set), handed to :mod:`twisted.knots` for this process; None when none are kept."""
    from twisted.knots import prime_states_by_type
    from twisted.moves import MOVES_VERSION

    with store.session() as session:
        rows = session.execute(
            select(KnotStateSet.knot_type, KnotStateSet.states).where(
                KnotStateSet.crossings == crossings, KnotStateSet.moves_version == MOVES_VERSION
            )
        ).all()
    if not rows:
        return None
    by_type = {knot_type: _unpack(blob) for knot_type, blob in rows}
    prime_states_by_type(crossings, by_type)
    return by_type


def keep_states_by_type(store: Any, crossings: int) -> dict[str, tuple[Any, ...]]:
    """:func:`twisted.knots.states_by_type` (computed in this process unless primed) kept in the store
    unless it already holds them (another process may have stored them meanwhile)."""
    import time

    from twisted.knots import states_by_type
    from twisted.moves import MOVES_VERSION

    t0 = time.perf_counter()
    by_type = states_by_type(crossings)
    compute_s = time.perf_counter() - t0
    with store.session(write=True) as session:
        exists = session.scalar(
            select(func.count(KnotStateSet.id)).where(
                KnotStateSet.crossings == crossings, KnotStateSet.moves_version == MOVES_VERSION
            )
        )
        if not exists:
            for knot_type, states in sorted(by_type.items()):
                session.add(
                    KnotStateSet(
                        crossings=crossings,
                        knot_type=knot_type,
                        moves_version=MOVES_VERSION,
                        n_states=len(states),
                        states=_pack(states),
                        compute_s=compute_s,
                    )
                )
    return by_type


def cached_states_by_type(store: Any, crossings: int) -> dict[str, tuple[Any, ...]]:
    """:func:`twisted.knots.states_by_type` through the store: read when a process before computed it
    (same move set), else computed and stored; either way handed to :mod:`twisted.knots` for this process."""
    by_type = load_states_by_type(store, crossings)
    return by_type if by_type is not None else keep_states_by_type(store, crossings)


# Crossing counts whose enumeration is worth keeping (below 5 it takes seconds)
CACHED_CROSSINGS = (5,)


def kept_crossings(knot: str | None, crossings: int | None = None) -> int | None:
    """The crossing count whose state sets a goal of ``knot`` enumerates and the store keeps (None: a
    name that is no knot, which the goal's own check reports, a count not worth keeping, or the knot's
    crossing number, where its states are made from its diagram without enumerating)."""
    from twisted.knots import KnotNameError, least_crossings

    if knot is None:
        return None
    try:
        least = least_crossings(knot)
    except KnotNameError:
        return None
    count = crossings if crossings is not None else least
    return count if count in CACHED_CROSSINGS and count != least else None


def prime_knot_goal(store: Any, knot: str | None, crossings: int | None = None) -> None:
    """Before a knot goal is built: read (or make and keep) the sets it enumerates. Does nothing for a
    name that is no knot (the goal's own check reports it) or a count that is not enumerated."""
    count = kept_crossings(knot, crossings)
    if count is not None:
        cached_states_by_type(store, count)


def prime_goal_spec(store: Any, spec: str) -> None:
    """:func:`prime_knot_goal` for a stored goal spec (``knot:<name>@<crossings>``; other specs: nothing)."""
    from twisted.goals import KNOT_PREFIX

    if not spec.startswith(KNOT_PREFIX):
        return
    name, _, count = spec[len(KNOT_PREFIX) :].partition("@")
    prime_knot_goal(store, name, int(count) if count.isdigit() else None)
