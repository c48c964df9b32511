"""The planner's search tree ``T`` in the store (Alembic revision 0004).

Tables:

- ``search_runs``: one row per planner run (its ``runs`` row has ``kind = 'plan'``): the goal, the
  planner and heuristic, how it ended (``outcome``) and the node where the goal was reached.
- ``search_nodes``: the vertices of ``T`` in creation order (``seq``; 0 is the root): the exact
  configuration ``q`` and link points, the topological state, the curve from the parent (NULL for
  the root), the iteration and simulator call that created it and the search time at that moment.
- ``search_checkpoints``: the consistent cut of a run at an iteration boundary (iteration, elapsed
  search time, simulator calls, the numpy RNG state, the selection statistics), written in the
  same transaction as the nodes created up to that boundary.

A run is written by one process at a time, its *lease holder*: ``runs.host`` / ``runs.pid`` while
``runs.status = 'running'``. :func:`take_lease` makes the calling process the holder atomically (under
the write lock, or a row lock on PostgreSQL), refusing while the holder is alive; a holder that is gone
(SIGKILL) is taken over. Every write of :class:`SearchRun` checks that this process still holds it.

The found low-level plan is the path from the root to ``search_runs.goal_node_id`` (a recursive
query over ``parent_id``; see :func:`solution_path` and the README). The high-level plans live in
the plan cache (``twisted/store/plans.py``). This module knows no simulator: it stores arrays and
numbers, and hands back plain records.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import socket
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
from sqlalchemy import (
    JSON,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    LargeBinary,
    String,
    Text,
    UniqueConstraint,
    delete,
    func,
    select,
    update,
)
from sqlalchemy.orm import Mapped, Session, mapped_column

from twisted.goals import Goal, PlanInputError, state_goal
from twisted.rope import N_LINKS, N_POINTS
from twisted.runtime import process_alive
from twisted.store.boundary import (
    StoredValueError,
    check_checkpoint,
    check_configuration,
    get_row,
    shown,
    stored_count,
    stored_curve,
    stored_floats,
    stored_object,
    stored_seconds,
)
from twisted.store.models import Base, Run, TopologicalState, array_to_blob, utcnow
from twisted.store.queries import get_or_create_state
from twisted.topology import PData, parse_p_data

__all__ = [
    "LEASE_STALE_S",
    "OUTCOMES",
    "DamagedRunError",
    "NoPlanError",
    "RunBusyError",
    "SearchCheckpoint",
    "SearchNode",
    "SearchRun",
    "SearchRunInfo",
    "SearchRunRow",
    "StoredCheckpoint",
    "StoredNode",
    "find_resumable_run",
    "load_run",
    "mark_failed",
    "solution_path",
    "solved_run",
    "take_lease",
]

# running: in progress (or killed without a chance to say so); the others are set when it stops.
OUTCOMES = ("running", "solved", "timeout", "interrupted", "stopped")

# A lease held from another host (whose process cannot be checked from here) is taken over only when its
# run has written nothing for this long (a search writes a checkpoint every few seconds).
LEASE_STALE_S = 600.0


class RunBusyError(RuntimeError):
    """Another live process writes the run (or took it over from this one); the message names it."""


def _other_holder(
    status: str, host: str | None, pid: int | None, last_write: dt.datetime | None = None
) -> str | None:
    """Who else holds a run's lease ("process 123 on host h"), or None when nobody alive does.

    ``last_write`` (when known) lets a lease from another host expire after :data:`LEASE_STALE_S`.
    """
    if status != "running" or pid is None:
        return None
    here = socket.gethostname()
    if host == here:
        if pid == os.getpid() or not process_alive(pid):
            return None
        return f"process {pid}"
    if last_write is None:
        return None
    if last_write.tzinfo is None:  # SQLite hands back naive UTC
        last_write = last_write.replace(tzinfo=dt.UTC)
    if (utcnow() - last_write).total_seconds() >= LEASE_STALE_S:
        return None
    return f"process {pid} on host {host}"


class SearchRunRow(Base):
    """A planner run: goal, planner, heuristic and how it ended (the ``runs`` row has the timestamps)."""

    __tablename__ = "search_runs"

    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), primary_key=True)
    goal_state_id: Mapped[int] = mapped_column(ForeignKey("topological_states.id"), index=True)
    goal_cross: Mapped[int] = mapped_column(Integer)
    # A knot goal (revision 0008): the knot's name; any state of ``goal_cross`` crossings that ties it is
    # the goal (the members are in ``runs.parameters['goal_states']``). NULL: the goal is goal_state_id.
    goal_knot: Mapped[str | None] = mapped_column(String(64), index=True)
    planner: Mapped[str] = mapped_column(String(32))
    heuristic: Mapped[str] = mapped_column(String(16))
    start_configuration_id: Mapped[int | None] = mapped_column(ForeignKey("configurations.id"))
    outcome: Mapped[str] = mapped_column(String(16), default="running", index=True)
    # No foreign key: search_nodes already refers to this table, and a cycle needs deferred constraints.
    goal_node_id: Mapped[int | None] = mapped_column(Integer)


class SearchNode(Base):
    """A vertex of ``T``: configuration q (exact simulator state), state, and the curve from its parent."""

    __tablename__ = "search_nodes"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), index=True)
    seq: Mapped[int] = mapped_column(Integer)  # creation order within the run, root = 0
    parent_id: Mapped[int | None] = mapped_column(ForeignKey("search_nodes.id"), index=True)
    state_id: Mapped[int] = mapped_column(ForeignKey("topological_states.id"), index=True)
    cross: Mapped[int] = mapped_column(Integer)
    q: Mapped[bytes] = mapped_column(LargeBinary)
    points: Mapped[bytes] = mapped_column(LargeBinary)
    link: Mapped[int | None] = mapped_column(Integer)
    z_max_m: Mapped[float | None] = mapped_column(Float)
    x_m: Mapped[float | None] = mapped_column(Float)
    y_m: Mapped[float | None] = mapped_column(Float)
    # what made it from its parent: "curve" (the columns above), or "cinch" (the rope pulled tight and
    # let go, twisted.tighten.cinch: no curve, the columns above NULL); the root's is "curve"
    action: Mapped[str] = mapped_column(String(16), default="curve", server_default="curve")
    iteration: Mapped[int] = mapped_column(Integer)
    sim_call: Mapped[int] = mapped_column(Integer)  # 1-based number of the simulation that produced it
    created_s: Mapped[float] = mapped_column(Float)  # search time (s) when it was created

    # (run_id, seq) is unique: resuming can never write a node twice.
    __table_args__ = (UniqueConstraint("run_id", "seq", name="uq_search_nodes_run_id_seq"),)


class SearchCheckpoint(Base):
    """The latest consistent cut of a run; the nodes up to ``iteration`` are in ``search_nodes``."""

    __tablename__ = "search_checkpoints"

    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), primary_key=True)
    iteration: Mapped[int] = mapped_column(Integer)
    elapsed_s: Mapped[float] = mapped_column(Float)
    sim_calls: Mapped[int] = mapped_column(Integer)
    nodes: Mapped[int] = mapped_column(Integer)
    # JSON text written by us: PCG64's 128-bit integers must survive every backend exactly.
    rng_state: Mapped[str] = mapped_column(Text)
    stats: Mapped[dict[str, Any]] = mapped_column(JSON)
    updated_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


# --- what the planner hands in ------------------------------------------------------------------------


class NodeLike(Protocol):
    """What :meth:`SearchRun.save` reads from a planner node."""

    index: int
    parent: int | None
    q: np.ndarray
    points: np.ndarray
    p_data: PData
    curve: Any | None  # has link, z_max_m, x_m, y_m; or an ``action`` other than "curve" (a cinch)
    iteration: int
    sim_call: int
    created_s: float
    db_id: int | None


class CheckpointLike(Protocol):
    iteration: int
    elapsed_s: float
    sim_calls: int
    rng_state: dict[str, Any]
    stats: dict[str, Any]


@dataclass
class StoredNode:
    """A ``search_nodes`` row as plain values (``parent_seq`` instead of the row id)."""

    id: int
    seq: int
    parent_seq: int | None
    p_data: PData
    q: npt.NDArray[np.float64]
    points: npt.NDArray[np.float64]
    curve: tuple[int, float, float, float] | None  # (link, z_max_m, x_m, y_m)
    iteration: int
    sim_call: int
    created_s: float
    action: str = "curve"  # or "cinch": made by pulling the parent's rope tight (no curve)


@dataclass
class StoredCheckpoint:
    iteration: int
    elapsed_s: float
    sim_calls: int
    nodes: int
    rng_state: dict[str, Any]
    stats: dict[str, Any]


@dataclass
class SearchRunInfo:
    """A planner run as stored: its parameters, outcome, checkpoint and (optionally) its tree."""

    run_id: int
    goal: Goal
    parameters: dict[str, Any]
    outcome: str
    status: str
    start_configuration_id: int | None
    goal_node_id: int | None
    checkpoint: StoredCheckpoint | None
    nodes: list[StoredNode]
    host: str | None = None
    pid: int | None = None
    last_write: dt.datetime | None = None  # the checkpoint's updated_at

    @property
    def live(self) -> bool:
        """Still searched by another live process (a killed one left ``running`` behind is not).

        A run of another host counts as live until it has written nothing for :data:`LEASE_STALE_S`.
        """
        return self.holder is not None

    @property
    def holder(self) -> str | None:
        """The other live process that holds the run's lease, in words; None when there is none."""
        return _other_holder(self.status, self.host, self.pid, self.last_write)


# --- writing a run ---------------------------------------------------------------------------------------


class SearchRun:
    """Writes one planner run: nodes and checkpoints in one transaction each, then the outcome."""

    def __init__(self, store: Any, run_id: int, node_ids: dict[int, int] | None = None) -> None:
        self.store = store
        self.run_id = run_id
        self._node_ids: dict[int, int] = dict(node_ids or {})  # seq -> search_nodes.id
        self._state_ids: dict[str, int] = {}

    @classmethod
    def create(
        cls,
        store: Any,
        goal: Goal,
        parameters: dict[str, Any],
        root: NodeLike,
        checkpoint: CheckpointLike,
        start_configuration_id: int | None = None,
    ) -> SearchRun:
        """Insert the ``runs`` / ``search_runs`` rows, the root node and the first checkpoint."""
        with store.session(write=True) as session:
            run = Run(
                kind="plan",
                parameters={
                    **parameters,
                    "goal": goal.representative.to_list(),
                    "goal_spec": goal.spec,
                    "goal_states": [p.to_list() for p in goal.states],
                    "start_configuration_id": start_configuration_id,
                },
                seed=parameters.get("seed"),
                status="running",
                host=socket.gethostname(),
                pid=os.getpid(),
            )
            session.add(run)
            session.flush()
            session.add(
                SearchRunRow(
                    run_id=run.id,
                    goal_state_id=get_or_create_state(session, goal.representative).id,
                    goal_cross=goal.cross,
                    goal_knot=goal.knot,
                    planner=parameters.get("planner", "twisted"),
                    heuristic=parameters.get("heuristic", "crs"),
                    start_configuration_id=start_configuration_id,
                    outcome="running",
                )
            )
            recorder = cls(store, run.id)
            recorder._write(session, [root], checkpoint)
        return recorder

    def record_tightening(self, node: NodeLike, result: Any, goal: Goal, ties_goal: bool) -> None:
        """Store the pull test of ``node`` (``plan --tighten``) with this run."""
        from twisted.store.knots import record_tightening

        with self.store.session(write=True) as session:
            record_tightening(
                session,
                result,
                node.p_data,
                run_id=self.run_id,
                node_seq=node.index,
                goal_knot=goal.knot_label,
                ties_goal=ties_goal,
            )

    def _state_id(self, session: Session, p_data: PData) -> int:
        key = p_data.key
        if key not in self._state_ids:
            self._state_ids[key] = get_or_create_state(session, p_data).id
        return self._state_ids[key]

    def _write(self, session: Session, nodes: Sequence[NodeLike], checkpoint: CheckpointLike) -> None:
        pending: list[tuple[NodeLike, SearchNode]] = []

        def flush() -> None:
            session.flush()  # one multi-row INSERT ... RETURNING, in order
            for node, row in pending:
                self._node_ids[node.index] = row.id
                node.db_id = row.id
            pending.clear()

        for node in nodes:
            if node.parent is not None and node.parent not in self._node_ids:
                flush()  # its parent is in this batch: its id must be known first
            action = getattr(node.curve, "action", "curve")
            curve = node.curve if action == "curve" else None
            row = SearchNode(
                run_id=self.run_id,
                seq=node.index,
                parent_id=None if node.parent is None else self._node_ids[node.parent],
                state_id=self._state_id(session, node.p_data),
                cross=node.p_data.cross,
                q=array_to_blob(node.q),
                points=array_to_blob(node.points),
                link=None if curve is None else int(curve.link),
                z_max_m=None if curve is None else float(curve.z_max_m),
                x_m=None if curve is None else float(curve.x_m),
                y_m=None if curve is None else float(curve.y_m),
                action=action,
                iteration=node.iteration,
                sim_call=node.sim_call,
                created_s=float(node.created_s),
            )
            session.add(row)
            pending.append((node, row))
        flush()
        values = {
            "iteration": checkpoint.iteration,
            "elapsed_s": float(checkpoint.elapsed_s),
            "sim_calls": checkpoint.sim_calls,
            "nodes": len(self._node_ids),
            "rng_state": json.dumps(checkpoint.rng_state),
            "stats": checkpoint.stats,
            "updated_at": utcnow(),
        }
        existing = session.get(SearchCheckpoint, self.run_id)
        if existing is None:
            session.add(SearchCheckpoint(run_id=self.run_id, **values))
        else:
            for name, value in values.items():
                setattr(existing, name, value)
        # the generic counters of runs: simulator calls tried, nodes kept, search time
        self._update_held_run(
            session,
            tried=checkpoint.sim_calls,
            kept=len(self._node_ids),
            wall_seconds=float(checkpoint.elapsed_s),
        )

    def _update_held_run(self, session: Session, **values: Any) -> None:
        """Update the ``runs`` row if this process still holds the lease, else RunBusyError (rolled back)."""
        done: Any = session.execute(
            update(Run)
            .where(Run.id == self.run_id, Run.host == socket.gethostname(), Run.pid == os.getpid())
            .values(**values)
        )
        if done.rowcount != 1:
            message = f"run {self.run_id} is no longer held by this process (another one took it over)"
            raise RunBusyError(message)

    def save(self, nodes: Sequence[NodeLike], checkpoint: CheckpointLike) -> None:
        """Write ``nodes`` (setting their ``db_id``) and ``checkpoint`` in one transaction."""
        with self.store.session(write=True) as session:
            self._write(session, nodes, checkpoint)

    def resumed(self) -> None:
        """Take the run over for this process after a resume (:func:`take_lease`)."""
        take_lease(self.store, self.run_id)

    def finish(self, outcome: str, goal_node: NodeLike | None, checkpoint: CheckpointLike) -> None:
        """Record how the run ended: solved / timeout / interrupted / stopped."""
        if outcome not in OUTCOMES:
            raise ValueError(f"unknown outcome {outcome!r}")
        goal_id = None
        if goal_node is not None:
            goal_id = goal_node.db_id if goal_node.db_id is not None else self._node_ids.get(goal_node.index)
        with self.store.session(write=True) as session:
            session.execute(
                update(SearchRunRow)
                .where(SearchRunRow.run_id == self.run_id)
                .values(outcome=outcome, goal_node_id=goal_id)
            )
            self._update_held_run(
                session,
                status="interrupted" if outcome == "interrupted" else "finished",
                ended_at=utcnow(),
                message=outcome,
                wall_seconds=float(checkpoint.elapsed_s),
            )


# --- reading runs ------------------------------------------------------------------------------------------


class DamagedRunError(PlanInputError, LookupError):
    """A stored planner run whose checkpoint or nodes do not read back (not JSON, arrays of odd size);
    the commands refuse it as bad input (exit 2)."""


def _checkpoint(row: SearchCheckpoint | None) -> StoredCheckpoint | None:
    """A checkpoint as stored, checked at the boundary (StoredValueError naming the field)."""
    if row is None:
        return None
    iteration, elapsed_s, sim_calls, nodes, rng_state, stats = check_checkpoint(
        row.run_id, row.iteration, row.elapsed_s, row.sim_calls, row.nodes, row.rng_state, row.stats
    )
    return StoredCheckpoint(iteration, elapsed_s, sim_calls, nodes, rng_state, stats)


def _nodes(session: Session, run_id: int, where: Any | None = None) -> list[StoredNode]:
    query = (
        select(SearchNode, TopologicalState.key)
        .join(TopologicalState, TopologicalState.id == SearchNode.state_id)
        .where(SearchNode.run_id == run_id)
        .order_by(SearchNode.seq)
    )
    if where is not None:
        query = query.where(where)
    seq_of: dict[int, int] = {}
    out = []
    table = "search_nodes"
    for row, key in session.execute(query):
        seq = stored_count(row.seq, table, row.id, "seq")
        seq_of[row.id] = seq
        curve = None
        if row.link is not None:  # the curve columns are NULL together (root) or set together
            curve = stored_curve(row.link, row.z_max_m, row.x_m, row.y_m, N_LINKS, table, row.id)
        # a rope configuration: finite, the profile's points (whether the simulator takes q is the
        # planner's check, twisted.planner.both_ways.accepted_configuration)
        q = stored_floats(row.q, table, row.id, "q")
        points = stored_floats(row.points, table, row.id, "points", width=3)
        check_configuration(q, points, N_POINTS, table, row.id)
        if row.action not in ("curve", "cinch"):
            problem = f"must be 'curve' or 'cinch', got {shown(row.action)}"
            raise StoredValueError(table, row.id, "action", problem)
        out.append(
            StoredNode(
                id=row.id,
                seq=seq,
                parent_seq=None if row.parent_id is None else seq_of.get(row.parent_id),
                p_data=_state(key, row.state_id),
                q=q,
                points=points,
                curve=curve,
                iteration=stored_count(row.iteration, table, row.id, "iteration"),
                sim_call=stored_count(row.sim_call, table, row.id, "sim_call"),
                created_s=stored_seconds(row.created_s, table, row.id, "created_s"),
                action=row.action,
            )
        )
    return out


def load_run(store: Any, run_id: int, with_nodes: bool = True) -> SearchRunInfo | None:
    """A planner run, or None when ``run_id`` is not one. ``with_nodes`` loads the whole tree."""
    with store.session() as session:
        row = session.get(SearchRunRow, run_id)
        run = get_row(session, Run, run_id)  # the boundary: JSON bounded, a bad column named
        if row is None or run is None:
            return None
        goal_key = session.scalar(
            select(TopologicalState.key).where(TopologicalState.id == row.goal_state_id)
        )
        checkpoint_row = get_row(session, SearchCheckpoint, run_id)
        checkpoint = _checkpoint(checkpoint_row)
        try:  # float64 arrays: data only, never code (docs/security.md); damage is refused
            nodes = _nodes(session, run_id) if with_nodes else []
        except StoredValueError:
            raise
        except (ValueError, TypeError, UnicodeDecodeError) as exc:
            raise DamagedRunError(
                f"planner run {run_id} is damaged in the database ({type(exc).__name__}: "
                f"{str(exc)[:200]}): it cannot be resumed or replayed"
            ) from None
        parameters = stored_object(run.parameters, "runs", run_id, "parameters")
        if row.goal_knot is not None:
            members = _goal_states(parameters.get("goal_states"), run_id)
            members.sort(key=lambda p: p.key)
            goal = Goal(tuple(members), knot=row.goal_knot, crossings=row.goal_cross)
        else:
            goal = state_goal(_state(goal_key or "[]", row.goal_state_id))
        return SearchRunInfo(
            run_id=run_id,
            goal=goal,
            parameters=parameters,
            outcome=row.outcome,
            status=run.status,
            start_configuration_id=row.start_configuration_id,
            goal_node_id=row.goal_node_id,
            checkpoint=checkpoint,
            nodes=nodes,
            host=run.host,
            pid=run.pid,
            last_write=checkpoint_row.updated_at if checkpoint_row is not None else None,
        )


def _state(key: Any, state_id: int) -> PData:
    """A node's state (``topological_states.key``) read back."""
    try:
        return parse_p_data(key)
    except (ValueError, TypeError) as exc:
        raise StoredValueError("topological_states", state_id, "key", str(exc)[:200]) from None


def _goal_states(value: Any, run_id: int) -> list[PData]:
    """The members of a knot goal as stored (``runs.parameters.goal_states``): a list of P-data."""
    field = "parameters.goal_states"
    if not isinstance(value, list) or not value:
        problem = f"must be a non-empty list of P-data, got {shown(value)}"
        raise StoredValueError("runs", run_id, field, problem)
    try:
        return [parse_p_data(p) for p in value]
    except ValueError as exc:
        raise StoredValueError("runs", run_id, field, str(exc)[:200]) from None


def mark_failed(store: Any, run_id: int | None, message: str) -> None:
    """End planner run ``run_id`` as ``failed`` with ``message`` (what killed it), unless it has already
    ended: a run that dies of an exception is not left ``running`` (a resume would take it up again)."""
    if run_id is None:
        return
    with store.session(write=True) as session:
        session.execute(
            update(Run)
            .where(Run.id == run_id, Run.status == "running")
            .values(**Run.end_values("failed", message[:2000]))
        )


def take_lease(store: Any, run_id: int) -> None:
    """Make this process the one writer of planner run ``run_id`` (status ``running``, its host and pid).

    Atomic: SQLite's write lock (PostgreSQL: a row lock) is held from the check to the update, so of two
    processes resuming one run at once exactly one gets it. Raises :class:`RunBusyError` while another
    live process holds it, and LookupError when the run is not a resumable planner run.
    """
    with store.session(write=True) as session:
        run = session.get(Run, run_id, with_for_update=True)
        row = session.get(SearchRunRow, run_id)
        if run is None or row is None:
            raise LookupError(f"run {run_id} is not a planner run in this database")
        if row.outcome == "solved":
            raise LookupError(f"run {run_id} already solved its goal (see `twisted replay {run_id}`)")
        checkpoint = session.get(SearchCheckpoint, run_id)
        holder = _other_holder(
            run.status, run.host, run.pid, checkpoint.updated_at if checkpoint is not None else None
        )
        if holder is not None:
            raise RunBusyError(
                f"run {run_id} is being searched by {holder}: stop it first (Ctrl-C checkpoints it), "
                "or wait for it to end"
            )
        run.status, run.ended_at, run.host, run.pid = "running", None, socket.gethostname(), os.getpid()
        row.outcome = "running"


def discard_after_checkpoint(store: Any, run_id: int) -> int:
    """Delete nodes newer than the run's checkpoint (none, when every write went through :class:`SearchRun`).

    Returns how many were deleted.
    """
    with store.session(write=True) as session:
        checkpoint = session.get(SearchCheckpoint, run_id)
        if checkpoint is None:
            return 0
        doomed = select(SearchNode.id).where(
            SearchNode.run_id == run_id, SearchNode.iteration > checkpoint.iteration
        )
        count = session.scalar(select(func.count()).select_from(doomed.subquery())) or 0
        if count:
            session.execute(delete(SearchNode).where(SearchNode.id.in_(doomed)))
        return int(count)


def find_resumable_run(store: Any, goal: Goal | None = None) -> int | None:
    """The newest planner run that did not solve its goal and is not live (for ``goal`` when given)."""
    with store.session() as session:
        query = select(SearchRunRow.run_id).where(SearchRunRow.outcome != "solved")
        if goal is not None and goal.knot is not None:
            query = query.where(SearchRunRow.goal_knot == goal.knot, SearchRunRow.goal_cross == goal.cross)
        elif goal is not None:
            query = query.join(TopologicalState, TopologicalState.id == SearchRunRow.goal_state_id).where(
                TopologicalState.key == goal.representative.key, SearchRunRow.goal_knot.is_(None)
            )
        candidates = list(session.scalars(query.order_by(SearchRunRow.run_id.desc())))
    for run_id in candidates:
        info = load_run(store, run_id, with_nodes=False)
        if info is not None and not info.live:
            return run_id
    return None


class NoPlanError(LookupError):
    """A run id that names no planner run here, or a run that found no plan; the message says which."""


def solved_run(store: Any, run_id: int) -> tuple[SearchRunInfo, list[StoredNode]]:
    """A planner run and the nodes of its plan, root to goal (what replay and render take).

    Raises :class:`NoPlanError` when ``run_id`` is no planner run in this database or found no plan.
    """
    info = load_run(store, run_id, with_nodes=False)
    if info is None:
        raise NoPlanError(f"run {run_id} is not a planner run in this database")
    path = solution_path(store, run_id)
    if not path:
        raise NoPlanError(f"run {run_id} found no plan (outcome: {info.outcome})")
    return info, path


def solution_path(store: Any, run_id: int) -> list[StoredNode]:
    """The nodes from the root to the goal node of a solved run (empty when it has none)."""
    with store.session() as session:
        row = session.get(SearchRunRow, run_id)
        if row is None or row.goal_node_id is None:
            return []
        # walk parent links in SQL (the README shows the same query as a recursive CTE)
        path = (
            select(SearchNode.id, SearchNode.parent_id)
            .where(SearchNode.id == row.goal_node_id)
            .cte("path", recursive=True)
        )
        path = path.union_all(
            select(SearchNode.id, SearchNode.parent_id).join(path, SearchNode.id == path.c.parent_id)
        )
        ids = set(session.scalars(select(path.c.id)))
        nodes = _nodes(session, run_id, SearchNode.id.in_(ids))
        # parent_seq above only resolves parents seen earlier in this partial load, which holds here:
        # the path is loaded in seq order and every parent precedes its child
        return nodes
