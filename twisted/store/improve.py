"""Expert iteration's generations (Alembic revision 0011): one row per generation of ``twisted improve``.

``improve_generations``: a lineage (``--name``) is a chain of generations; generation 0 is the model
the loop starts from (scored only), generation ``g >= 1`` plans toward training goals with its
parent's model, fine-tunes the parent on the planner trees (and collected transitions, if any) and is
scored on the tuning set. The row holds the models (parent and new), the training run, what the
generation planned (``training_goals``: per goal its key, run, outcome and calls), the data counts and
the tuning-set scores (``tune_results``: per goal and seed); ``status`` says which phase a resumed loop
continues with.
"""

from __future__ import annotations

import datetime as dt
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    String,
    UniqueConstraint,
)
from sqlalchemy.orm import Mapped, mapped_column

from twisted.store import training as _training  # noqa: F401  (the models and training_runs tables named below)
from twisted.store.models import Base, utcnow

__all__ = ["IMPROVE_STATUSES", "ImproveGeneration", "lineage_labels"]

# planning (toward training goals) -> training -> scoring (tuning set) -> finished
IMPROVE_STATUSES = ("planning", "training", "scoring", "finished")


class ImproveGeneration(Base):
    """One generation of a lineage of expert iteration (module docstring)."""

    __tablename__ = "improve_generations"
    __table_args__ = (UniqueConstraint("lineage", "generation"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    lineage: Mapped[str] = mapped_column(String(64), index=True)
    generation: Mapped[int] = mapped_column(Integer)
    status: Mapped[str] = mapped_column(String(16))
    seed: Mapped[int] = mapped_column(BigInteger)
    parameters: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    parent_model_id: Mapped[int | None] = mapped_column(ForeignKey("models.id"))
    model_id: Mapped[int | None] = mapped_column(ForeignKey("models.id"), index=True)
    training_run_id: Mapped[int | None] = mapped_column(ForeignKey("training_runs.id"))
    training_goals: Mapped[list[Any]] = mapped_column(JSON, default=list)
    data: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)  # samples by source and side
    tune_set: Mapped[str | None] = mapped_column(String(64))
    tune_results: Mapped[list[Any]] = mapped_column(JSON, default=list)
    tune_runs: Mapped[int] = mapped_column(Integer, default=0)
    tune_solved: Mapped[int] = mapped_column(Integer, default=0)
    tune_calls: Mapped[int] = mapped_column(Integer, default=0)  # every call of every tuning run
    success_at_6: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    wall_s: Mapped[float] = mapped_column(Float, default=0.0)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    updated_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


def lineage_labels(session: Any) -> dict[int, str]:
    """``model id -> "LINEAGE gN (parent M)"`` for every model a generation made or started from."""
    from sqlalchemy import select

    out: dict[int, str] = {}
    rows = session.execute(
        select(
            ImproveGeneration.model_id,
            ImproveGeneration.lineage,
            ImproveGeneration.generation,
            ImproveGeneration.parent_model_id,
        ).order_by(ImproveGeneration.id)
    ).all()
    for model_id, lineage, generation, parent in rows:
        if model_id is None:
            continue
        parent_text = "" if generation == 0 or parent is None else f" (parent {parent})"
        label = f"{lineage} g{generation}{parent_text}"
        out[model_id] = f"{out[model_id]}, {label}" if model_id in out else label
    return out
