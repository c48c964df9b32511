"""Tables of the inverse model's training (Alembic revision 0003): runs, checkpoints, finished models.

* ``training_runs``: one ``twisted train`` invocation (resumed runs continue the same row): its seed,
  parameters, the data snapshot it reads (transitions with ``id <= max_transition_id``), split sizes,
  progress and final metrics.
* ``checkpoints``: everything needed to continue a run exactly (weights, optimiser, epoch, batch
  index, RNG states) as ``torch.save`` bytes; only the newest few per run are kept.
* ``models``: finished models, ``weights`` = ``torch.save`` bytes of the architecture, weights and
  metadata (what ``twisted.model.InverseModel.from_bytes`` reads), with data size and metrics.
"""

from __future__ import annotations

import datetime as dt
import math
from typing import Any

from sqlalchemy import JSON, BigInteger, DateTime, Float, ForeignKey, Integer, LargeBinary, String, delete
from sqlalchemy.orm import Mapped, mapped_column, validates

from twisted.store.models import Base, RunLifecycle, utcnow


class TrainingRun(RunLifecycle, Base):
    """One training of the inverse model (status, start, end, message: :class:`RunLifecycle`)."""

    __tablename__ = "training_runs"
    status_indexed = True

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    seed: Mapped[int] = mapped_column(BigInteger)
    parameters: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    # The data snapshot: transitions with id <= max_transition_id (so a resume reads the same data).
    max_transition_id: Mapped[int] = mapped_column(Integer)
    n_train: Mapped[int] = mapped_column(Integer, default=0)
    n_val: Mapped[int] = mapped_column(Integer, default=0)
    epochs_done: Mapped[int] = mapped_column(Integer, default=0)
    elapsed_s: Mapped[float] = mapped_column(Float, default=0.0)
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    updated_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class Checkpoint(Base):
    """A resumable snapshot of a training run, taken after ``batch_index`` batches of ``epoch``."""

    __tablename__ = "checkpoints"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    training_run_id: Mapped[int] = mapped_column(ForeignKey("training_runs.id"), index=True)
    epoch: Mapped[int] = mapped_column(Integer)
    batch_index: Mapped[int] = mapped_column(Integer)
    elapsed_s: Mapped[float] = mapped_column(Float)
    payload: Mapped[bytes] = mapped_column(LargeBinary)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class NonFiniteModelError(ValueError):
    """A model whose losses are NaN or infinite (its training diverged) is not stored; says which."""

    def __init__(self, message: str, training_run_id: int | None) -> None:
        super().__init__(message)
        self.training_run_id = training_run_id


# Losses that every finished model reports; NaN weights make them NaN, so they guard the weights too.
GUARDED_LOSSES = ("val_loss", "train_loss")


class TrainedModel(Base):
    """A finished inverse model; the planner takes the newest unless told otherwise.

    Only a model whose losses are finite numbers is stored (:class:`NonFiniteModelError` otherwise): a
    diverged training must not become the newest model that every later plan picks up.
    """

    __tablename__ = "models"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    training_run_id: Mapped[int | None] = mapped_column(ForeignKey("training_runs.id"), index=True)
    name: Mapped[str] = mapped_column(String(128))
    data_size: Mapped[int] = mapped_column(Integer)  # training transitions (before augmentation)
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    config: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)  # architecture
    size_bytes: Mapped[int] = mapped_column(Integer)
    weights: Mapped[bytes] = mapped_column(LargeBinary)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    @validates("metrics")
    def _finite_losses(self, _key: str, metrics: dict[str, Any]) -> dict[str, Any]:
        for name in GUARDED_LOSSES:
            value = (metrics or {}).get(name)
            if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise NonFiniteModelError(
                    f"training run {self.training_run_id}: the model's {name.replace('_', ' ')} is {value}, "
                    "so it was not stored (training diverged; try a smaller --lr)",
                    self.training_run_id,
                )
        return metrics


def mark_training_failed(store: Any, training_run_id: int, message: str) -> None:
    """End a training run as ``failed`` (it cannot be resumed) with ``message``; its checkpoints go
    (a diverged run's hold NaN weights, and nothing resumes a failed run)."""
    with store.session(write=True) as session:
        row = session.get(TrainingRun, training_run_id)
        if row is not None:  # the message held the command line: keep it after the reason
            row.status, row.ended_at = "failed", utcnow()
            row.message = message if not row.message else f"{message}\n{row.message}"
        session.execute(delete(Checkpoint).where(Checkpoint.training_run_id == training_run_id))
