"""Small query functions over the foundation tables (runs, states, configurations, transitions, batches).

Every function takes an open :class:`sqlalchemy.orm.Session` (from ``Store.session()``) and leaves the
commit to the caller's ``with`` block, so several calls form one transaction.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from sqlalchemy import func, select, text, update
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.orm import Session

from twisted.knots import identify
from twisted.runtime import process_alive
from twisted.store.models import (
    CollectBatch,
    CollectTry,
    Configuration,
    Run,
    TopologicalState,
    Transition,
    array_to_blob,
    utcnow,
)
from twisted.topology import PData, PDataError


def _insert(session: Session, model: type) -> Any:
    """The dialect's INSERT (both SQLite and PostgreSQL offer ON CONFLICT DO NOTHING)."""
    name = session.get_bind().dialect.name
    return (postgresql.insert if name == "postgresql" else sqlite.insert)(model)


# --- runs ---------------------------------------------------------------------------------------------


def start_run(session: Session, kind: str, parameters: Mapping[str, Any], seed: int | None = None) -> Run:
    """Insert a ``running`` run for this host/pid and return it (id assigned)."""
    run = Run(
        kind=kind,
        parameters=dict(parameters),
        seed=seed,
        status="running",
        started_at=utcnow(),
        tried=0,
        kept=0,
        rejected=0,
        wall_seconds=0.0,
        sim_seconds=0.0,
        host=socket.gethostname(),
        pid=os.getpid(),
    )
    session.add(run)
    session.flush()
    return run


def end_run(
    session: Session, run_id: int, status: str, message: str | None = None, wall_seconds: float | None = None
) -> None:
    """Set a run's final status (``finished``, ``interrupted`` or ``failed``) and end time."""
    values = Run.end_values(status, message)
    if wall_seconds is not None:
        values["wall_seconds"] = wall_seconds
    session.execute(update(Run).where(Run.id == run_id).values(**values))


STALE_RUN_MESSAGE = "process ended without closing the run (killed?)"


def mark_stale_runs(session: Session, kind: str) -> list[int]:
    """Mark ``running`` runs of ``kind`` whose process on this host is gone as ``interrupted``.

    A run killed with SIGKILL cannot mark itself; the next run of the same kind on the host does it.
    Runs of other hosts are left alone (their process cannot be checked from here).
    """
    host = socket.gethostname()
    stale = [
        run.id
        for run in session.scalars(
            select(Run).where(Run.kind == kind, Run.status == "running", Run.host == host)
        )
        if run.pid is None or not process_alive(run.pid)
    ]
    for run_id in stale:
        last = session.scalar(
            select(func.max(CollectBatch.committed_at)).where(CollectBatch.run_id == run_id)
        )
        session.execute(
            update(Run)
            .where(Run.id == run_id)
            .values(status="interrupted", ended_at=last, message=STALE_RUN_MESSAGE)
        )
    return stale


# --- states and configurations ---------------------------------------------------------------------------


def _knot_columns(p_data: PData) -> dict[str, str | None]:
    """``knot_type`` and both closures of ``p_data`` (None for P-data that cannot be drawn in the plane)."""
    try:
        k = identify(p_data)
    except PDataError:
        return {"knot_type": None, "closure_under": None, "closure_over": None}
    return {"knot_type": k.name, "closure_under": k.under.name, "closure_over": k.over.name}


def get_or_create_state(session: Session, p_data: PData) -> TopologicalState:
    """The ``topological_states`` row of ``p_data``, inserted if new (safe against concurrent writers)."""
    state = session.scalar(select(TopologicalState).where(TopologicalState.key == p_data.key))
    if state is not None:
        return state
    session.execute(
        _insert(session, TopologicalState)
        .values(key=p_data.key, p_data=p_data.to_list(), cross=p_data.cross, **_knot_columns(p_data))
        .on_conflict_do_nothing(index_elements=["key"])
    )
    return session.scalars(select(TopologicalState).where(TopologicalState.key == p_data.key)).one()


def add_configuration(
    session: Session,
    *,
    run_id: int | None,
    p_data: PData,
    q: npt.ArrayLike,
    points: npt.ArrayLike,
) -> Configuration:
    """Insert a configuration (exact state ``q`` and its N_POINTS link points) under its topological state."""
    state = get_or_create_state(session, p_data)
    config = Configuration(
        run_id=run_id,
        state_id=state.id,
        cross=p_data.cross,
        q=array_to_blob(q),
        points=array_to_blob(points),
        created_at=utcnow(),
    )
    session.add(config)
    session.flush()
    return config


def load_configuration(session: Session, configuration_id: int) -> Configuration:
    """One configuration by id (raises ``sqlalchemy.exc.NoResultFound`` if absent)."""
    return session.scalars(select(Configuration).where(Configuration.id == configuration_id)).one()


def count_configurations(session: Session, kind: str | None = "collect") -> int:
    """Number of configurations, restricted to those added by runs of ``kind`` unless ``kind`` is None."""
    query = select(func.count(Configuration.id))
    if kind is not None:
        query = query.join(Run, Run.id == Configuration.run_id).where(Run.kind == kind)
    return int(session.scalar(query) or 0)


def configuration_index(
    session: Session, *, max_cross: int | None = None, after_id: int = 0, kind: str | None = "collect"
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """``(ids, crosses)`` of configurations with ``id > after_id`` (and ``cross <= max_cross``), by id.

    With ``kind`` (default ``"collect"``) only configurations added by runs of that kind: the D_Q of the
    collection scheme. Cheap enough to call repeatedly with the last id seen to pick up new rows.
    """
    query = select(Configuration.id, Configuration.cross).where(Configuration.id > after_id)
    if max_cross is not None:
        query = query.where(Configuration.cross <= max_cross)
    if kind is not None:
        query = query.join(Run, Run.id == Configuration.run_id).where(Run.kind == kind)
    rows = session.execute(query.order_by(Configuration.id)).all()
    ids = np.fromiter((r[0] for r in rows), dtype=np.int64, count=len(rows))
    crosses = np.fromiter((r[1] for r in rows), dtype=np.int64, count=len(rows))
    return ids, crosses


def sample_configurations(
    session: Session,
    rng: np.random.Generator,
    n: int,
    *,
    cross: int | None = None,
    state_id: int | None = None,
    kind: str | None = None,
) -> list[Configuration]:
    """``n`` configurations drawn uniformly with replacement (optionally of one crossing count / state)."""
    query = select(Configuration.id)
    if cross is not None:
        query = query.where(Configuration.cross == cross)
    if state_id is not None:
        query = query.where(Configuration.state_id == state_id)
    if kind is not None:
        query = query.join(Run, Run.id == Configuration.run_id).where(Run.kind == kind)
    ids = list(session.scalars(query.order_by(Configuration.id)))
    if not ids or n <= 0:
        return []
    chosen = [ids[i] for i in rng.integers(0, len(ids), size=n)]
    by_id = {c.id: c for c in session.scalars(select(Configuration).where(Configuration.id.in_(set(chosen))))}
    return [by_id[i] for i in chosen]


# --- collect batches ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class KeptTransition:
    """A kept transition as a collector worker reports it (the new configuration is not stored yet)."""

    from_configuration_id: int
    from_state_id: int
    from_cross: int
    link: int
    z_max_m: float
    x_m: float
    y_m: float
    q: bytes  # array_to_blob of the new configuration's exact state
    points: bytes  # array_to_blob of its (N_POINTS, 3) link points
    p_data: PData
    steps: int | None = None


@dataclass(frozen=True)
class TryCount:
    """Curves tried from configurations of one crossing count; kept rose in crossings; rejected failed."""

    tried: int = 0
    kept: int = 0
    rejected: int = 0


@dataclass(frozen=True)
class BatchRecord:
    """What one collector batch commits: its id, per-start-cross try counts and kept transitions."""

    batch_id: str
    run_id: int
    worker: int
    seq: int
    tries: Mapping[int, TryCount]
    transitions: Sequence[KeptTransition] = field(default_factory=tuple)
    sim_seconds: float = 0.0

    @property
    def tried(self) -> int:
        return sum(t.tried for t in self.tries.values())

    @property
    def kept(self) -> int:
        return sum(t.kept for t in self.tries.values())

    @property
    def rejected(self) -> int:
        return sum(t.rejected for t in self.tries.values())


def batch_id(run_id: int, worker: int, seq: int) -> str:
    """The idempotency key of a collect batch."""
    return f"{run_id}-{worker}-{seq}"


def add_collect_batch(
    session: Session, batch: BatchRecord, wall_seconds: float | None = None
) -> list[tuple[int, int]] | None:
    """Store a batch atomically (within the caller's transaction); a batch id already stored is a no-op.

    Inserts the batch row, its per-cross try counts, the new configurations and their transitions, and
    adds the counters to the run (``wall_seconds``, if given, replaces the run's wall time). Returns the
    ``(configuration_id, cross)`` of the new configurations, or None when the batch was already stored.
    """
    inserted = session.execute(
        _insert(session, CollectBatch)
        .values(
            batch_id=batch.batch_id,
            run_id=batch.run_id,
            worker=batch.worker,
            seq=batch.seq,
            tried=batch.tried,
            kept=batch.kept,
            rejected=batch.rejected,
            sim_seconds=batch.sim_seconds,
            committed_at=utcnow(),
        )
        .on_conflict_do_nothing(index_elements=["batch_id"])
        .returning(CollectBatch.batch_id)
    ).first()
    if inserted is None:
        return None
    if batch.tries:
        session.execute(
            _insert(session, CollectTry),
            [
                {
                    "batch_id": batch.batch_id,
                    "from_cross": c,
                    "tried": t.tried,
                    "kept": t.kept,
                    "rejected": t.rejected,
                }
                for c, t in sorted(batch.tries.items())
            ],
        )
    new: list[tuple[int, int]] = []
    states: dict[str, int] = {}
    for kept in batch.transitions:
        state_id = states.get(kept.p_data.key)
        if state_id is None:
            state_id = states[kept.p_data.key] = get_or_create_state(session, kept.p_data).id
        config = Configuration(
            run_id=batch.run_id,
            state_id=state_id,
            cross=kept.p_data.cross,
            q=kept.q,
            points=kept.points,
            created_at=utcnow(),
        )
        session.add(config)
        session.flush()
        session.add(
            Transition(
                run_id=batch.run_id,
                batch_id=batch.batch_id,
                from_configuration_id=kept.from_configuration_id,
                to_configuration_id=config.id,
                link=kept.link,
                z_max_m=kept.z_max_m,
                x_m=kept.x_m,
                y_m=kept.y_m,
                from_state_id=kept.from_state_id,
                to_state_id=state_id,
                from_cross=kept.from_cross,
                to_cross=kept.p_data.cross,
                steps=kept.steps,
                created_at=utcnow(),
            )
        )
        new.append((config.id, config.cross))
    values: dict[str, Any] = {
        "tried": Run.tried + batch.tried,
        "kept": Run.kept + len(batch.transitions),
        "rejected": Run.rejected + batch.rejected,
        "sim_seconds": Run.sim_seconds + batch.sim_seconds,
    }
    if wall_seconds is not None:
        values["wall_seconds"] = wall_seconds
    session.execute(update(Run).where(Run.id == batch.run_id).values(**values))
    session.flush()
    return new


# --- statistics (read-only) ---------------------------------------------------------------------------


def _view(session: Session, name: str, order_by: str) -> list[dict[str, Any]]:
    rows = session.execute(text(f"SELECT * FROM {name} ORDER BY {order_by}")).mappings().all()
    return [dict(r) for r in rows]


def states_by_cross(session: Session) -> list[dict[str, Any]]:
    """Rows of the ``states_by_cross`` view (cross, states, visited_states, configurations)."""
    return _view(session, "states_by_cross", "1")


def acceptance_by_cross(session: Session) -> list[dict[str, Any]]:
    """Rows of the ``acceptance_by_cross`` view (from_cross, tried, kept, rejected, kept_rate)."""
    return _view(session, "acceptance_by_cross", "from_cross")


def collect_throughput(session: Session) -> list[dict[str, Any]]:
    """Rows of the ``collect_throughput`` view, one per collect run."""
    return _view(session, "collect_throughput", "run_id")


def transitions_per_run(session: Session) -> list[dict[str, Any]]:
    """Rows of the ``transitions_per_run`` view, one per run."""
    return _view(session, "transitions_per_run", "run_id")


def transitions_by_cross(session: Session) -> list[dict[str, Any]]:
    """Kept transitions counted per (from_cross, to_cross)."""
    query = (
        select(Transition.from_cross, Transition.to_cross, func.count(Transition.id).label("transitions"))
        .group_by(Transition.from_cross, Transition.to_cross)
        .order_by(Transition.from_cross, Transition.to_cross)
    )
    return [dict(r) for r in session.execute(query).mappings().all()]
