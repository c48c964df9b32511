"""Tables of the SAC+HER baseline (Alembic revision 0007): runs, checkpoints (= policies), success log.

* ``rl_runs``: one ``twisted rl train`` run (a resumed run continues the same row): seed, goal
  source and hyper-parameters, steps asked and done, status.
* ``rl_checkpoints``: Stable-Baselines3 ``SAC.save`` bytes (``policy``) after ``steps`` environment
  steps, with the replay buffer (zlib-compressed pickle) on the newest checkpoint of a run only, so a
  run resumes with its experience while old checkpoints stay small. A checkpoint id is what
  ``twisted plan --planner sac --model ID`` loads; ``final`` marks the one a run finished with.
* ``rl_success``: per run, interval and goal crossing count, the training episodes that ended and
  how many reached their goal (the success rate during training, as the paper reports it).
"""

from __future__ import annotations

import datetime as dt
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
    LargeBinary,
    select,
    update,
)
from sqlalchemy.orm import Mapped, Session, mapped_column

from twisted.store.boundary import stored_count, stored_seconds
from twisted.store.models import Base, RunLifecycle, utcnow

__all__ = [
    "RlCheckpoint",
    "RlCheckpointInfo",
    "RlRun",
    "RlSuccess",
    "add_checkpoint",
    "add_success",
    "checkpoint_counters",
    "list_checkpoints",
    "success_table",
]

class RlRun(RunLifecycle, Base):
    """One SAC+HER training run (status, start, end, message: :class:`RunLifecycle`)."""

    __tablename__ = "rl_runs"
    status_indexed = True

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    seed: Mapped[int] = mapped_column(BigInteger)
    parameters: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)  # goal source, SAC/HER settings
    total_steps: Mapped[int] = mapped_column(Integer)  # environment steps asked for
    steps_done: Mapped[int] = mapped_column(Integer, default=0)
    episodes: Mapped[int] = mapped_column(Integer, default=0)
    elapsed_s: Mapped[float] = mapped_column(Float, default=0.0)
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    updated_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class RlCheckpoint(Base):
    """A stored policy: SB3 ``SAC.save`` bytes, plus the replay buffer on a run's newest checkpoint."""

    __tablename__ = "rl_checkpoints"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    rl_run_id: Mapped[int] = mapped_column(ForeignKey("rl_runs.id"), index=True)
    steps: Mapped[int] = mapped_column(Integer)
    episodes: Mapped[int] = mapped_column(Integer)
    elapsed_s: Mapped[float] = mapped_column(Float)
    final: Mapped[bool] = mapped_column(Boolean, default=False)
    policy: Mapped[bytes] = mapped_column(LargeBinary)
    replay_buffer: Mapped[bytes | None] = mapped_column(LargeBinary)
    size_bytes: Mapped[int] = mapped_column(Integer)  # policy + replay buffer
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class RlSuccess(Base):
    """Training episodes that ended in the interval up to ``steps``, for goals of ``goal_cross`` crossings."""

    __tablename__ = "rl_success"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    rl_run_id: Mapped[int] = mapped_column(ForeignKey("rl_runs.id"), index=True)
    steps: Mapped[int] = mapped_column(Integer)  # environment steps at the end of the interval
    goal_cross: Mapped[int] = mapped_column(Integer)
    episodes: Mapped[int] = mapped_column(Integer)
    successes: Mapped[int] = mapped_column(Integer)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


@dataclass(frozen=True)
class RlCheckpointInfo:
    """A row of ``rl_checkpoints`` without its blobs."""

    id: int
    rl_run_id: int
    steps: int
    episodes: int
    final: bool
    size_bytes: int
    has_replay_buffer: bool
    created_at: dt.datetime


def add_checkpoint(
    session: Session,
    run: RlRun,
    *,
    policy: bytes,
    replay_buffer: bytes | None,
    final: bool = False,
) -> int:
    """Store a checkpoint of ``run`` at its current counters; older replay buffers of the run are dropped."""
    if replay_buffer is not None:
        session.execute(
            update(RlCheckpoint).where(RlCheckpoint.rl_run_id == run.id).values(replay_buffer=None)
        )
    row = RlCheckpoint(
        rl_run_id=run.id,
        steps=run.steps_done,
        episodes=run.episodes,
        elapsed_s=run.elapsed_s,
        final=final,
        policy=policy,
        replay_buffer=replay_buffer,
        size_bytes=len(policy) + len(replay_buffer or b""),
        created_at=utcnow(),
    )
    session.add(row)
    session.flush()
    return row.id


def checkpoint_counters(row: RlCheckpoint) -> tuple[int, int, float]:
    """A checkpoint's ``(steps, episodes, elapsed_s)`` as stored, checked at the boundary (counts in
    [0, 2**31), seconds finite and not negative): StoredValueError naming the field otherwise."""
    table = "rl_checkpoints"
    return (
        stored_count(row.steps, table, row.id, "steps"),
        stored_count(row.episodes, table, row.id, "episodes"),
        stored_seconds(row.elapsed_s, table, row.id, "elapsed_s"),
    )


def add_success(session: Session, run_id: int, steps: int, counts: dict[int, tuple[int, int]]) -> None:
    """Log ``{goal_cross: (episodes, successes)}`` for the interval ending at ``steps``."""
    for cross, (episodes, successes) in sorted(counts.items()):
        session.add(
            RlSuccess(
                rl_run_id=run_id,
                steps=steps,
                goal_cross=cross,
                episodes=episodes,
                successes=successes,
                created_at=utcnow(),
            )
        )


def list_checkpoints(session: Session, run_id: int | None = None) -> list[RlCheckpointInfo]:
    """Checkpoints (of one run, or all), newest first, without their blobs."""
    cols = (
        RlCheckpoint.id,
        RlCheckpoint.rl_run_id,
        RlCheckpoint.steps,
        RlCheckpoint.episodes,
        RlCheckpoint.final,
        RlCheckpoint.size_bytes,
        RlCheckpoint.replay_buffer.is_not(None),
        RlCheckpoint.created_at,
    )
    query = select(*cols).order_by(RlCheckpoint.id.desc())
    if run_id is not None:
        query = query.where(RlCheckpoint.rl_run_id == run_id)
    return [RlCheckpointInfo(*row) for row in session.execute(query).all()]


def success_table(session: Session, run_id: int) -> list[tuple[int, int, int, int]]:
    """``(steps, goal_cross, episodes, successes)`` rows of a run, in order."""
    rows = session.execute(
        select(RlSuccess.steps, RlSuccess.goal_cross, RlSuccess.episodes, RlSuccess.successes)
        .where(RlSuccess.rl_run_id == run_id)
        .order_by(RlSuccess.steps, RlSuccess.goal_cross)
    ).all()
    return [tuple(r) for r in rows]  # type: ignore[misc]
