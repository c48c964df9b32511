"""Experiment tables (Alembic revision 0005): problem sets, evaluation results, discretisation results.

- ``problem_sets``: a named set of goals (``easy``, ``medium``, ``hard``, ``unseen-3``, ``4``, or an
  imported file), how it was made (seed, parameters).
- ``problems``: the goals of a set, in order, with the goal's visit frequency in our data at the
  time the set was made and a tag saying where it came from.
- ``eval_runs``: one row per ``twisted eval`` invocation (its options, host, pid, status).
- ``eval_results``: one row per (set, planner, goal, seed, timeout_s, friction_scale), the unique key
  that lets an interrupted evaluation resume without rerunning finished goals. A row is written
  ``running`` when its goal starts (with the planner's run id once known) and completed with
  ``solved`` / ``timeout`` (finished), or ``interrupted`` / ``failed`` (to be run again).
- ``discretisation_results``: one row per (experiment run, transition, variant) of the
  discretisation experiment (paper section 5.1): the curve re-simulated, the state the store
  recorded, the state obtained, and whether it changed.

This module knows no simulator or planner; it stores numbers and hands back plain records.
"""

from __future__ import annotations

import datetime as dt
import os
import socket
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    String,
    Text,
    UniqueConstraint,
    delete,
    func,
    select,
    update,
)
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Mapped, Session, mapped_column

from twisted.goals import KNOT_PREFIX
from twisted.runtime import process_alive
from twisted.store.models import Base, RunLifecycle, utcnow
from twisted.topology import PData, parse_p_data

__all__ = [
    "DiscretisationResult",
    "EvalResult",
    "EvalRun",
    "FINISHED_STATUSES",
    "Problem",
    "ProblemRecord",
    "ProblemSet",
    "ProblemSetRecord",
    "ResultKey",
    "claim_result",
    "delete_problem_set",
    "free_result",
    "result_rows",
    "update_result",
    "list_problem_sets",
    "load_problem_set",
    "save_problem_set",
]

# An eval_results row in one of these is done; any other status (running, interrupted, failed) is rerun.
FINISHED_STATUSES = ("solved", "timeout")
RESULT_STATUSES = ("running", "solved", "timeout", "interrupted", "failed")


class ProblemSet(Base):
    """A named set of goal states."""

    __tablename__ = "problem_sets"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    source: Mapped[str] = mapped_column(String(16))  # "made" (from our data) or "imported"
    seed: Mapped[int | None] = mapped_column(BigInteger)
    parameters: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class Problem(Base):
    """One goal of a set: its P-data, crossing count, visit frequency in our data and origin tag."""

    __tablename__ = "problems"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    set_id: Mapped[int] = mapped_column(ForeignKey("problem_sets.id"), index=True)
    idx: Mapped[int] = mapped_column(Integer)  # order within the set, 0-based
    goal_key: Mapped[str] = mapped_column(Text)
    p_data: Mapped[list[Any]] = mapped_column(JSON)
    cross: Mapped[int] = mapped_column(Integer)
    frequency: Mapped[int] = mapped_column(Integer)  # transitions reaching the state when the set was made
    tag: Mapped[str] = mapped_column(String(32))

    __table_args__ = (
        UniqueConstraint("set_id", "goal_key", name="uq_problems_set_id_goal_key"),
        UniqueConstraint("set_id", "idx", name="uq_problems_set_id_idx"),
    )


class EvalRun(RunLifecycle, Base):
    """One ``twisted eval`` invocation over a set (status, start, end, message: :class:`RunLifecycle`)."""

    __tablename__ = "eval_runs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    set_id: Mapped[int] = mapped_column(ForeignKey("problem_sets.id"), index=True)
    planner: Mapped[str] = mapped_column(String(32))
    timeout_s: Mapped[float] = mapped_column(Float)
    friction_scale: Mapped[float] = mapped_column(Float)
    seeds: Mapped[list[Any]] = mapped_column(JSON)
    workers: Mapped[int] = mapped_column(Integer)  # simulator processes per planner
    parallel: Mapped[int] = mapped_column(Integer)  # planners run at once
    parameters: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    host: Mapped[str | None] = mapped_column(String(255))
    pid: Mapped[int | None] = mapped_column(Integer)


class EvalResult(Base):
    """One planner run on one goal; unique per (set, planner, goal, seed, timeout, friction)."""

    __tablename__ = "eval_results"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    eval_run_id: Mapped[int] = mapped_column(ForeignKey("eval_runs.id"), index=True)
    set_id: Mapped[int] = mapped_column(ForeignKey("problem_sets.id"), index=True)
    problem_id: Mapped[int] = mapped_column(ForeignKey("problems.id"), index=True)
    planner: Mapped[str] = mapped_column(String(32))
    goal_key: Mapped[str] = mapped_column(Text)
    seed: Mapped[int] = mapped_column(BigInteger)
    timeout_s: Mapped[float] = mapped_column(Float)
    friction_scale: Mapped[float] = mapped_column(Float)
    status: Mapped[str] = mapped_column(String(16), index=True)
    solved: Mapped[bool] = mapped_column(Boolean, default=False)
    time_to_solve_s: Mapped[float | None] = mapped_column(Float)  # search time when the goal entered T
    elapsed_s: Mapped[float | None] = mapped_column(Float)  # search time spent in all
    sim_calls: Mapped[int | None] = mapped_column(Integer)
    iterations: Mapped[int | None] = mapped_column(Integer)
    plan_run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id"), index=True)
    wall_s: Mapped[float | None] = mapped_column(Float)  # wall time of the worker, start-up included
    host: Mapped[str | None] = mapped_column(String(255))
    pid: Mapped[int | None] = mapped_column(Integer)
    message: Mapped[str | None] = mapped_column(Text)
    started_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    ended_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True))

    __table_args__ = (
        UniqueConstraint(
            "set_id", "planner", "goal_key", "seed", "timeout_s", "friction_scale", name="uq_eval_results_key"
        ),
    )


class DiscretisationResult(Base):
    """One transition re-simulated in one variant (``control``, ``rounded`` or ``friction``)."""

    __tablename__ = "discretisation_results"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), index=True)  # runs.kind = 'discretise'
    transition_id: Mapped[int] = mapped_column(ForeignKey("transitions.id"), index=True)
    variant: Mapped[str] = mapped_column(String(16))
    friction_scale: Mapped[float] = mapped_column(Float)
    link: Mapped[int] = mapped_column(Integer)
    z_max_m: Mapped[float] = mapped_column(Float)
    x_m: Mapped[float] = mapped_column(Float)
    y_m: Mapped[float] = mapped_column(Float)
    recorded_key: Mapped[str] = mapped_column(Text)  # the state the stored transition reached
    result_key: Mapped[str | None] = mapped_column(Text)  # the state reached now; NULL when rejected
    ok: Mapped[bool] = mapped_column(Boolean)
    changed: Mapped[bool] = mapped_column(Boolean)  # result differs from recorded (a rejection counts)
    reason: Mapped[str | None] = mapped_column(Text)

    __table_args__ = (
        UniqueConstraint("run_id", "transition_id", "variant", name="uq_discretisation_results_key"),
    )


# --- problem sets --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ProblemRecord:
    """A goal of a set as plain data.

    ``p_data`` is the goal state, or for a knot goal its first state; ``spec`` is then the knot goal
    (``knot:<name>@<crossings>``, see :mod:`twisted.goals`) and ``frequency`` counts all its states.
    """

    id: int | None
    idx: int
    p_data: PData
    frequency: int
    tag: str
    spec: str | None = None

    @property
    def goal_key(self) -> str:
        """What ``problems.goal_key`` and ``eval_results.goal_key`` hold: the goal spec or the P-data key."""
        return self.spec if self.spec is not None else self.p_data.key


@dataclass(frozen=True)
class ProblemSetRecord:
    """A problem set with its goals, in order."""

    id: int
    name: str
    source: str
    seed: int | None
    parameters: dict[str, Any]
    created_at: dt.datetime
    problems: list[ProblemRecord]


def save_problem_set(
    session: Session,
    name: str,
    problems: Sequence[ProblemRecord],
    *,
    source: str,
    seed: int | None = None,
    parameters: dict[str, Any] | None = None,
) -> int:
    """Insert a set and its problems (in the given order); returns the set id. The name must be new."""
    row = ProblemSet(
        name=name, source=source, seed=seed, parameters=dict(parameters or {}), created_at=utcnow()
    )
    session.add(row)
    session.flush()
    for i, p in enumerate(problems):
        session.add(
            Problem(
                set_id=row.id,
                idx=i,
                goal_key=p.goal_key,
                p_data=p.p_data.to_list(),
                cross=p.p_data.cross,
                frequency=int(p.frequency),
                tag=p.tag,
            )
        )
    session.flush()
    return row.id


def _record(row: ProblemSet, problems: Sequence[Problem]) -> ProblemSetRecord:
    return ProblemSetRecord(
        id=row.id,
        name=row.name,
        source=row.source,
        seed=row.seed,
        parameters=dict(row.parameters or {}),
        created_at=row.created_at,
        problems=[
            ProblemRecord(
                p.id,
                p.idx,
                parse_p_data(p.p_data),
                p.frequency,
                p.tag,
                spec=p.goal_key if p.goal_key.startswith(KNOT_PREFIX) else None,
            )
            for p in problems
        ],
    )


def load_problem_set(session: Session, name: str) -> ProblemSetRecord | None:
    """The set called ``name`` with its problems, or None."""
    row = session.scalar(select(ProblemSet).where(ProblemSet.name == name))
    if row is None:
        return None
    problems = session.scalars(select(Problem).where(Problem.set_id == row.id).order_by(Problem.idx)).all()
    return _record(row, problems)


def list_problem_sets(session: Session) -> list[dict[str, Any]]:
    """Every set with its size, crossing counts, frequency range and number of stored eval results."""
    out = []
    for row in session.scalars(select(ProblemSet).order_by(ProblemSet.id)):
        stats = session.execute(
            select(
                func.count(Problem.id),
                func.min(Problem.cross),
                func.max(Problem.cross),
                func.min(Problem.frequency),
                func.max(Problem.frequency),
            ).where(Problem.set_id == row.id)
        ).one()
        results = session.scalar(select(func.count(EvalResult.id)).where(EvalResult.set_id == row.id))
        out.append(
            {
                "id": row.id,
                "name": row.name,
                "source": row.source,
                "seed": row.seed,
                "problems": stats[0],
                "cross": (stats[1], stats[2]),
                "frequency": (stats[3], stats[4]),
                "results": results or 0,
                "created_at": row.created_at,
            }
        )
    return out


def count_results(session: Session, set_id: int) -> int:
    """Stored evaluation results of a set."""
    return session.scalar(select(func.count(EvalResult.id)).where(EvalResult.set_id == set_id)) or 0


def delete_problem_set(session: Session, set_id: int) -> None:
    """Delete a set and its problems (the caller checks that no eval results refer to it)."""
    session.execute(delete(Problem).where(Problem.set_id == set_id))
    session.execute(delete(ProblemSet).where(ProblemSet.id == set_id))


# --- eval runs and results ------------------------------------------------------------------------------


def start_eval_run(
    session: Session,
    *,
    set_id: int,
    planner: str,
    timeout_s: float,
    friction_scale: float,
    seeds: Sequence[int],
    workers: int,
    parallel: int,
    parameters: dict[str, Any] | None = None,
) -> int:
    """Insert a ``running`` eval run for this host/pid; returns its id."""
    row = EvalRun(
        set_id=set_id,
        planner=planner,
        timeout_s=float(timeout_s),
        friction_scale=float(friction_scale),
        seeds=[int(s) for s in seeds],
        workers=workers,
        parallel=parallel,
        parameters=dict(parameters or {}),
        status="running",
        started_at=utcnow(),
        host=socket.gethostname(),
        pid=os.getpid(),
    )
    session.add(row)
    session.flush()
    return row.id


def end_eval_run(session: Session, eval_run_id: int, status: str, message: str | None = None) -> None:
    """Close an eval run (``finished``, ``interrupted`` or ``failed``)."""
    values = EvalRun.end_values(status, message)
    session.execute(update(EvalRun).where(EvalRun.id == eval_run_id).values(values))


def pid_alive(host: str | None, pid: int | None) -> bool:
    """Whether a process of this host still runs (other hosts: assumed alive, cannot be checked)."""
    if host != socket.gethostname():
        return host is not None
    return pid is not None and process_alive(pid)


@dataclass(frozen=True)
class ResultKey:
    """The unique key of an ``eval_results`` row: set, planner label, goal, seed, timeout, friction."""

    set_id: int
    planner: str  # the label the results are stored under
    goal_key: str
    seed: int
    timeout_s: float
    friction_scale: float

    def where(self) -> Any:
        """The SQL condition selecting the row."""
        return (
            (EvalResult.set_id == self.set_id)
            & (EvalResult.planner == self.planner)
            & (EvalResult.goal_key == self.goal_key)
            & (EvalResult.seed == self.seed)
            & (EvalResult.timeout_s == self.timeout_s)
            & (EvalResult.friction_scale == self.friction_scale)
        )


def claim_result(
    store: Any, key: ResultKey, eval_run_id: int, problem_id: int
) -> tuple[int, int | None] | None:
    """Mark the row of ``key`` ``running`` for this process (inserting it when new); (row id, planner run
    to resume) or None when it is finished or a live process holds it (or inserted it meanwhile)."""
    me = (socket.gethostname(), os.getpid())
    try:
        with store.session(write=True) as session:
            row = session.scalar(select(EvalResult).where(key.where()))
            if row is not None:
                if row.status in FINISHED_STATUSES:
                    return None
                if row.status == "running" and (row.host, row.pid) != me and pid_alive(row.host, row.pid):
                    return None
                resume = row.plan_run_id
                row.status, row.eval_run_id, row.host, row.pid = "running", eval_run_id, *me
                row.started_at, row.ended_at, row.message = utcnow(), None, None
                return row.id, resume
            row = EvalResult(
                eval_run_id=eval_run_id,
                set_id=key.set_id,
                problem_id=problem_id,
                planner=key.planner,
                goal_key=key.goal_key,
                seed=key.seed,
                timeout_s=key.timeout_s,
                friction_scale=key.friction_scale,
                status="running",
                solved=False,
                host=me[0],
                pid=me[1],
                started_at=utcnow(),
            )
            session.add(row)
            session.flush()
            return row.id, None
    except IntegrityError:  # another process inserted the same key first
        return None


def update_result(store: Any, row_id: int, **values: Any) -> None:
    """Update the result row ``row_id`` (in its own transaction)."""
    with store.session(write=True) as session:
        session.execute(update(EvalResult).where(EvalResult.id == row_id).values(**values))


def free_result(store: Any, key: ResultKey, message: str) -> None:
    """Mark the row of ``key`` ``interrupted`` when it is still ``running`` (its runner died holding it)."""
    with store.session(write=True) as session:
        session.execute(
            update(EvalResult)
            .where(key.where() & (EvalResult.status == "running"))
            .values(status="interrupted", message=message)
        )


def result_rows(
    session: Session, set_id: int, planner: str, timeout_s: float, friction_scale: float
) -> list[EvalResult]:
    """The result rows of one evaluation's key (set, label, timeout, friction), every goal and seed."""
    return list(
        session.scalars(
            select(EvalResult).where(
                (EvalResult.set_id == set_id)
                & (EvalResult.planner == planner)
                & (EvalResult.timeout_s == timeout_s)
                & (EvalResult.friction_scale == friction_scale)
            )
        )
    )
