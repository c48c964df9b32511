"""Episodes: plans executed in a world apart from the planner's model (Alembic revision 0016_episodes).

Tables (docs/DESIGN.md sections 11 and 15.5):

- ``episodes``: one row per episode, its ``runs`` row having ``kind = 'episode'`` (status, host, pid,
  timestamps): the goal, the plan it started from, the perturbation level (name and every range), the
  world's seed and the physics drawn from it, open or closed loop, the budget, how it ended
  (``outcome``) and its counters (actions, replans, planning seconds).
- ``episode_steps``: what happened, in order (``seq``): the world laid out (``reset``), each action sent
  (``curve`` with its parameters as the planner asked for them, or ``cinch``), each observation (link
  points as seen, their P-data, the plan's expected P-data, how far the points lie from the plan's,
  the fit's residual, the world's fault), each replan (``replan``: the planner's run id and seconds)
  and each pull test (``pull_test``: the knot). A step also keeps where the episode stood in its plan
  (``plan_run_id``, ``plan_step``) and the world's checkpoint, which is what ``--resume`` continues from:
  the world's, never handed to the planner.

Like the rest of the store this module knows no simulator: arrays, numbers and JSON.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import numpy.typing as npt
from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    LargeBinary,
    String,
    Text,
    UniqueConstraint,
    func,
    select,
    update,
)
from sqlalchemy.orm import Mapped, mapped_column

from twisted.rope import N_POINTS
from twisted.store.models import Base, Run, array_to_blob, blob_to_array, utcnow
from twisted.store.queries import end_run, start_run

__all__ = [
    "EPISODE_OUTCOMES",
    "STEP_KINDS",
    "EpisodeRow",
    "EpisodeStep",
    "StepRecord",
    "StoredEpisode",
    "add_step",
    "create_episode",
    "finish_episode",
    "load_episode",
    "reopen_episode",
]

EPISODE_OUTCOMES = ("running", "tied", "not_tied", "unpulled", "out_of_budget", "lost", "interrupted")
STEP_KINDS = ("reset", "curve", "cinch", "replan", "observe", "pull_test", "straighten")


class EpisodeRow(Base):
    """One episode (``runs.kind = 'episode'``)."""

    __tablename__ = "episodes"

    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), primary_key=True)
    plan_run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id"), index=True)
    goal_knot: Mapped[str] = mapped_column(String(64), index=True)
    level: Mapped[str] = mapped_column(String(200), index=True)
    level_ranges: Mapped[dict[str, Any]] = mapped_column(JSON)
    world_seed: Mapped[int] = mapped_column(BigInteger)
    physics: Mapped[dict[str, Any]] = mapped_column(JSON)
    closed_loop: Mapped[bool] = mapped_column(Boolean)
    timeout_s: Mapped[float] = mapped_column(Float)
    max_actions: Mapped[int] = mapped_column(Integer)
    outcome: Mapped[str] = mapped_column(String(16), index=True)
    actions: Mapped[int] = mapped_column(Integer, default=0)
    replans: Mapped[int] = mapped_column(Integer, default=0)
    planning_s: Mapped[float] = mapped_column(Float, default=0.0)
    elapsed_s: Mapped[float] = mapped_column(Float, default=0.0)
    final_knot: Mapped[str | None] = mapped_column(String(64))


class EpisodeStep(Base):
    """One step of an episode (see the module's docstring)."""

    __tablename__ = "episode_steps"
    __table_args__ = (UniqueConstraint("episode_id", "seq"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    episode_id: Mapped[int] = mapped_column(ForeignKey("episodes.run_id"), index=True)
    seq: Mapped[int] = mapped_column(Integer)
    kind: Mapped[str] = mapped_column(String(16))
    link: Mapped[int | None] = mapped_column(Integer)
    z_max_m: Mapped[float | None] = mapped_column(Float)
    x_m: Mapped[float | None] = mapped_column(Float)
    y_m: Mapped[float | None] = mapped_column(Float)
    points: Mapped[bytes | None] = mapped_column(LargeBinary)  # the observation, N_POINTS x 3
    observed_key: Mapped[str | None] = mapped_column(Text)
    expected_key: Mapped[str | None] = mapped_column(Text)
    drift_m: Mapped[float | None] = mapped_column(Float)
    fit_residual_m: Mapped[float | None] = mapped_column(Float)
    fault: Mapped[str | None] = mapped_column(Text)
    knot: Mapped[str | None] = mapped_column(String(64))
    replan_run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id"))
    planning_s: Mapped[float | None] = mapped_column(Float)
    plan_run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id"))
    plan_step: Mapped[int | None] = mapped_column(Integer)
    world_checkpoint: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    elapsed_s: Mapped[float] = mapped_column(Float)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


@dataclass
class StepRecord:
    """What :func:`add_step` writes (None: not applicable to this kind of step)."""

    kind: str
    elapsed_s: float
    curve: tuple[int, float, float, float] | None = None
    points: npt.NDArray[np.float64] | None = None
    observed_key: str | None = None
    expected_key: str | None = None
    drift_m: float | None = None
    fit_residual_m: float | None = None
    fault: str | None = None
    knot: str | None = None
    replan_run_id: int | None = None
    planning_s: float | None = None
    plan_run_id: int | None = None
    plan_step: int | None = None
    world_checkpoint: dict[str, Any] | None = None


# the StepRecord fields stored as they are (the curve has four columns, the points a BLOB)
CURVE_COLUMNS = ("link", "z_max_m", "x_m", "y_m")
PLAIN_COLUMNS = tuple(f.name for f in fields(StepRecord) if f.name not in ("curve", "points"))


@dataclass
class StoredEpisode:
    """An episode as stored, its steps in order (checked: a stored row is input like any other)."""

    run_id: int
    status: str
    host: str | None
    pid: int | None
    plan_run_id: int | None
    goal_knot: str
    level_ranges: dict[str, Any]
    world_seed: int
    closed_loop: bool
    timeout_s: float
    max_actions: int
    outcome: str
    steps: list[StepRecord]


def create_episode(store: Any, parameters: dict[str, Any], **columns: Any) -> int:
    """A new ``running`` episode with its ``runs`` row; the run id."""
    with store.session(write=True) as session:
        run = start_run(session, "episode", parameters, seed=columns.get("world_seed"))
        session.add(EpisodeRow(run_id=run.id, outcome="running", **columns))
        return int(run.id)


def add_step(store: Any, episode_id: int, step: StepRecord, counters: dict[str, Any]) -> None:
    """Append one step and update the episode's counters (``actions``, ``replans``, ``planning_s``,
    ``elapsed_s``) in the same transaction, so that a killed episode's row agrees with its steps."""
    with store.session(write=True) as session:
        seq = session.scalar(select(func.count(EpisodeStep.id)).where(EpisodeStep.episode_id == episode_id))
        curve = dict(zip(CURVE_COLUMNS, step.curve or (None, None, None, None), strict=True))
        plain = {name: getattr(step, name) for name in PLAIN_COLUMNS}
        points = None if step.points is None else array_to_blob(step.points)
        row = EpisodeStep(episode_id=episode_id, seq=int(seq or 0), points=points, created_at=utcnow())
        for name, value in {**curve, **plain}.items():
            setattr(row, name, value)
        session.add(row)
        session.execute(update(EpisodeRow).where(EpisodeRow.run_id == episode_id).values(**counters))
        session.execute(update(Run).where(Run.id == episode_id).values(wall_seconds=step.elapsed_s))


def finish_episode(
    store: Any, episode_id: int, outcome: str, final_knot: str | None, elapsed_s: float
) -> None:
    """Close an episode: its outcome (``interrupted`` leaves it resumable) and its run's status."""
    status = "interrupted" if outcome == "interrupted" else "finished"
    with store.session(write=True) as session:
        values = {"outcome": outcome, "final_knot": final_knot, "elapsed_s": elapsed_s}
        session.execute(update(EpisodeRow).where(EpisodeRow.run_id == episode_id).values(**values))
        end_run(session, episode_id, status, wall_seconds=elapsed_s)


def reopen_episode(store: Any, episode_id: int) -> None:
    """Make this process the writer of a stopped episode again (``--resume``)."""
    import os
    import socket

    with store.session(write=True) as session:
        session.execute(update(EpisodeRow).where(EpisodeRow.run_id == episode_id).values(outcome="running"))
        values = {"status": "running", "ended_at": None, "message": None, "host": socket.gethostname()}
        session.execute(update(Run).where(Run.id == episode_id).values(pid=os.getpid(), **values))


class EpisodeError(LookupError):
    """An episode id that names no episode here, or a stored episode that does not read back."""


def _checked_step(row: EpisodeStep) -> StepRecord:
    if row.kind not in STEP_KINDS:
        raise EpisodeError(f"episode {row.episode_id} step {row.seq}: unknown kind {row.kind!r:.40}")
    points = None
    if row.points is not None:
        if len(row.points) != N_POINTS * 3 * 8:
            raise EpisodeError(f"episode {row.episode_id} step {row.seq}: points of {len(row.points)} bytes")
        points = blob_to_array(row.points, (N_POINTS, 3))
    curve = None
    if row.kind == "curve":
        values = (row.link, row.z_max_m, row.x_m, row.y_m)
        if any(v is None for v in values):
            raise EpisodeError(f"episode {row.episode_id} step {row.seq}: a curve step without its curve")
        curve = (int(row.link or 0), float(row.z_max_m or 0), float(row.x_m or 0), float(row.y_m or 0))
    record = StepRecord(**{name: getattr(row, name) for name in PLAIN_COLUMNS}, curve=curve, points=points)
    if not isinstance(record.world_checkpoint, dict):
        record.world_checkpoint = None
    return record


def load_episode(store: Any, episode_id: int) -> StoredEpisode:
    """An episode and its steps; :class:`EpisodeError` when there is none or a row does not read back."""
    with store.session() as session:
        row = session.get(EpisodeRow, episode_id)
        run = session.get(Run, episode_id)
        if row is None or run is None:
            raise EpisodeError(f"run {episode_id} is not an episode in this database")
        if not isinstance(row.level_ranges, dict) or row.outcome not in EPISODE_OUTCOMES:
            raise EpisodeError(f"episode {episode_id}: its stored level or outcome does not read back")
        rows = session.scalars(
            select(EpisodeStep).where(EpisodeStep.episode_id == episode_id).order_by(EpisodeStep.seq)
        ).all()
        steps = [_checked_step(r) for r in rows]
        return StoredEpisode(
            run_id=episode_id,
            status=run.status,
            host=run.host,
            pid=run.pid,
            plan_run_id=row.plan_run_id,
            goal_knot=row.goal_knot,
            level_ranges=dict(row.level_ranges),
            world_seed=int(row.world_seed),
            closed_loop=bool(row.closed_loop),
            timeout_s=float(row.timeout_s),
            max_actions=int(row.max_actions),
            outcome=row.outcome,
            steps=steps,
        )
