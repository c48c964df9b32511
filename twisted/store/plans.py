"""The plan cache (Alembic revision 0002): BFS plans kept in the database, keyed by (start, goal).

- ``plan_queries``: one row per (start P-data key, goal P-data key) answered: the plan limit it was
  computed with, how many plans it found, whether that is all of them (``complete``: fewer than the
  limit exist, so an empty answer means "unreachable"), the version of the moves that produced it
  and the BFS time.
- ``plans``: the plans of a query, ``plan_index`` 0, 1, ... shortest first, each with its state
  sequence (P-data lists) and moves (dicts of :meth:`twisted.moves.Move.to_dict`) as JSON.

``cached_plans(store, start, goal, limit)`` answers from these tables when it can and otherwise runs
the BFS (:func:`twisted.moves.plans`) and stores the answer, so plans are shared by every run and
command using the same database. Example, from a sqlite3 shell::

    SELECT q.start_key, q.goal_key, q.n_plans, p.length, p.moves
    FROM plan_queries q JOIN plans p ON p.query_id = q.id WHERE p.plan_index = 0;
"""

from __future__ import annotations

import datetime as dt
import time
from typing import Any, get_args

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    Text,
    UniqueConstraint,
    delete,
    select,
)
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Mapped, Session, mapped_column

from twisted.goals import Goal
from twisted.moves import (
    MOVES_VERSION,
    REMOVALS_VERSION,
    Move,
    MoveKind,
    Plan,
    plans_both_ways,
    plans_to_any,
)
from twisted.store.boundary import StoredValueError, shown
from twisted.store.db import Store
from twisted.store.models import Base, utcnow
from twisted.topology import PData, PDataError, parse_p_data

__all__ = [
    "BOTH_WAYS_SUFFIX",
    "PlanQuery",
    "PlanRow",
    "cached_plans",
    "check_cached_plans",
    "get_plans",
    "put_plans",
]


class PlanQuery(Base):
    """One answered (start, goal) plan question."""

    __tablename__ = "plan_queries"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    start_key: Mapped[str] = mapped_column(Text)
    goal_key: Mapped[str] = mapped_column(Text, index=True)
    start_cross: Mapped[int] = mapped_column(Integer)
    goal_cross: Mapped[int] = mapped_column(Integer)
    plan_limit: Mapped[int] = mapped_column(Integer)
    n_plans: Mapped[int] = mapped_column(Integer)
    complete: Mapped[bool] = mapped_column(Boolean)  # n_plans < plan_limit: these are all the plans
    moves_version: Mapped[int] = mapped_column(Integer)
    compute_s: Mapped[float] = mapped_column(Float)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    __table_args__ = (UniqueConstraint("start_key", "goal_key", name="uq_plan_queries_key"),)


class PlanRow(Base):
    """One cached plan: the ``plan_index``-th shortest plan from start to goal."""

    __tablename__ = "plans"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    query_id: Mapped[int] = mapped_column(ForeignKey("plan_queries.id", ondelete="CASCADE"), index=True)
    start_key: Mapped[str] = mapped_column(Text)
    goal_key: Mapped[str] = mapped_column(Text)
    plan_index: Mapped[int] = mapped_column(Integer)
    length: Mapped[int] = mapped_column(Integer)
    states: Mapped[list[Any]] = mapped_column(JSON)
    moves: Mapped[list[Any]] = mapped_column(JSON)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    __table_args__ = (UniqueConstraint("start_key", "goal_key", "plan_index", name="uq_plans_key"),)

    def to_plan(self) -> Plan:
        """The plan, its states and moves checked (a :class:`StoredValueError` names the field)."""
        states, moves = self.states, self.moves
        bad = [moves] if not isinstance(moves, list) else [m for m in moves if not _is_move(m)][:1]
        if bad:
            raise StoredValueError("plans", self.id, "moves", f"must be a list of moves, got {shown(bad[0])}")
        if not isinstance(states, list) or not states:
            problem = f"must be a list of P-data, the plan's start first, got {shown(states)}"
            raise StoredValueError("plans", self.id, "states", problem)
        try:
            parsed = [parse_p_data(s) for s in states]
        except (PDataError, TypeError, ValueError) as exc:
            raise StoredValueError("plans", self.id, "states", str(exc)[:200]) from None
        return Plan(parsed, [Move.from_dict(m) for m in moves])


_MOVE_FIELDS: dict[str, tuple[Any, ...]] = {
    "kind": get_args(MoveKind),
    "side": ("L", "R"),
    "other_side": ("L", "R"),
    "sign": ("+", "-"),
    "over": ("O", "U"),
    "remove": (True, False),
}


def _is_move(value: Any) -> bool:
    """``value`` is a dict of :meth:`Move.to_dict`: a kind, segments that are counts, known words."""
    if not isinstance(value, dict) or "kind" not in value or "segment" not in value:
        return False
    for name, item in value.items():
        if name in ("segment", "other_segment"):
            if isinstance(item, bool) or not isinstance(item, int) or not 0 <= item < 2**31:
                return False
        elif name not in _MOVE_FIELDS or not any(item is w or item == w for w in _MOVE_FIELDS[name]):
            return False
    return True


def check_cached_plans(store: Store, run_id: int, goal: PData | Goal, both_ways: bool) -> None:
    """Read every cached plan toward ``goal`` from a state of run ``run_id``'s tree, as a search of the
    run will (:meth:`PlanRow.to_plan`): a damaged one is refused before the run is resumed, not in the
    middle of its search (the plans cached for states the search has not met yet are read when it meets
    them)."""
    tables = Base.metadata.tables
    nodes, states = tables["search_nodes"], tables["topological_states"]
    starts = (
        select(states.c.key).join(nodes, nodes.c.state_id == states.c.id).where(nodes.c.run_id == run_id)
    )
    with store.session() as session:
        queries = select(PlanQuery).where(
            PlanQuery.goal_key == _goal_key(goal, both_ways), PlanQuery.start_key.in_(starts)
        )
        for query in session.scalars(queries):
            for row in session.scalars(select(PlanRow).where(PlanRow.query_id == query.id)):
                row.to_plan()


BOTH_WAYS_SUFFIX = f"|both-ways@{REMOVALS_VERSION}"


def _goal_key(goal: PData | Goal, both_ways: bool = False) -> str:
    """The goal's key; an answer with removing moves (:func:`twisted.moves.plans_both_ways`) is kept
    under the key with :data:`BOTH_WAYS_SUFFIX`, which names the removing moves' version, so the
    adding-only answers stored before keep their keys and stay valid."""
    key = goal.key if isinstance(goal, PData) else goal.cache_key
    return key + BOTH_WAYS_SUFFIX if both_ways else key


def get_plans(
    session: Session, start: PData, goal: PData | Goal, limit: int, both_ways: bool = False
) -> list[Plan] | None:
    """The cached answer to ``plans(start, goal, limit)``, or None when the cache cannot give it.

    A query stored with a limit of at least ``limit``, or one stored complete, answers any limit:
    the BFS order is deterministic, so the first ``limit`` plans of a larger answer are the answer.
    """
    query = session.scalars(
        select(PlanQuery).where(
            PlanQuery.start_key == start.key, PlanQuery.goal_key == _goal_key(goal, both_ways)
        )
    ).one_or_none()
    if query is None or query.moves_version != MOVES_VERSION:
        return None
    if not query.complete and query.plan_limit < limit:
        return None
    rows = session.scalars(
        select(PlanRow)
        .where(PlanRow.query_id == query.id, PlanRow.plan_index < limit)
        .order_by(PlanRow.plan_index)
    ).all()
    return [row.to_plan() for row in rows]


def put_plans(
    session: Session,
    start: PData,
    goal: PData | Goal,
    limit: int,
    found: list[Plan],
    compute_s: float = 0.0,
    both_ways: bool = False,
) -> None:
    """Store the answer ``found = plans(start, goal, limit)``, replacing any older one (flushes)."""
    goal_key = _goal_key(goal, both_ways)
    old = session.scalars(
        select(PlanQuery).where(PlanQuery.start_key == start.key, PlanQuery.goal_key == goal_key)
    ).one_or_none()
    if old is not None:
        session.execute(delete(PlanRow).where(PlanRow.query_id == old.id))
        session.delete(old)
        session.flush()
    query = PlanQuery(
        start_key=start.key,
        goal_key=goal_key,
        start_cross=start.cross,
        goal_cross=goal.cross,
        plan_limit=limit,
        n_plans=len(found),
        complete=len(found) < limit,
        moves_version=MOVES_VERSION,
        compute_s=compute_s,
    )
    session.add(query)
    session.flush()
    session.add_all(
        PlanRow(
            query_id=query.id,
            start_key=start.key,
            goal_key=goal_key,
            plan_index=i,
            length=plan.length,
            states=[s.to_list() for s in plan.states],
            moves=[m.to_dict() for m in plan.moves],
        )
        for i, plan in enumerate(found)
    )
    session.flush()


def _compute(start: PData, goal: PData | Goal, limit: int, both_ways: bool) -> tuple[list[Plan], float]:
    t0 = time.perf_counter()
    members = [goal] if isinstance(goal, PData) else list(goal.states)
    if both_ways:
        found = plans_both_ways(start, members, limit)
    else:
        found = plans_to_any(start, members, limit)
    return found, time.perf_counter() - t0


def cached_plans(
    store_or_session: Store | Session, start: PData, goal: PData | Goal, limit: int, both_ways: bool = False
) -> list[Plan]:
    """``plans(start, goal, limit)`` through the database cache (shortest first; ``[]`` = unreachable).

    ``goal`` may be a set of states (:class:`twisted.goals.Goal`, e.g. a knot): then the plans lead to
    any member (:func:`twisted.moves.plans_to_any`), cached under :attr:`Goal.cache_key`. With
    ``both_ways`` the plans may also remove crossings (:func:`twisted.moves.plans_both_ways`: the
    shortest only), cached under the goal's key with :data:`BOTH_WAYS_SUFFIX`.

    With a :class:`Store` the answer is read in one short transaction and, on a miss, computed outside
    any transaction and written in another (if a concurrent process stored it first, its rows are
    kept). With a :class:`Session` everything happens in that session and the caller commits.
    """
    if limit < 1:
        raise ValueError(f"limit must be >= 1, got {limit}")
    if isinstance(store_or_session, Session):
        session = store_or_session
        cached = get_plans(session, start, goal, limit, both_ways)
        if cached is not None:
            return cached
        found, compute_s = _compute(start, goal, limit, both_ways)
        put_plans(session, start, goal, limit, found, compute_s, both_ways)
        return found

    store = store_or_session
    with store.session() as session:
        cached = get_plans(session, start, goal, limit, both_ways)
    if cached is not None:
        return cached
    found, compute_s = _compute(start, goal, limit, both_ways)
    try:
        with store.session(write=True) as session:
            if get_plans(session, start, goal, limit, both_ways) is None:
                put_plans(session, start, goal, limit, found, compute_s, both_ways)
    except IntegrityError:
        # PostgreSQL: another process inserted the same (start, goal) between our check and insert;
        # its answer is the same BFS result, so ours is simply not stored.
        pass
    return found
