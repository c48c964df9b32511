"""Expert iteration's generations (Alembic revision 0011): one row per generation of ``twisted improve``.

``improve_generations``: a lineage (``--name``) is a chain of generations; generation 0 is the model
the loop starts from (scored only), generation ``g >= 1`` plans toward training goals with its
parent's model, fine-tunes the parent on the planner trees (and collected transitions, if any) and is
scored on the tuning set. The row holds the models (parent and new), the training run, what the
generation planned (``training_goals``: per goal its key, run, outcome and calls), the data counts and
the tuning-set scores (``tune_results``: per goal and seed); ``status`` says which phase a resumed loop
continues with.

The queries of ``twisted improve`` (:mod:`twisted.experiments.improve`) are the named functions
below: the lineage's rows (:func:`lineage_rows`, :func:`add_generation`, :func:`update_generation`),
the sets whose goals it never trains on (:func:`problem_set_names`, :func:`set_goal_specs`), and the
models it starts from and makes (:func:`shipped_model_id`, :func:`training_run_status`,
:func:`model_of_training_run`).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
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
    func,
    select,
)
from sqlalchemy.orm import Mapped, mapped_column

from twisted.store.experiments import EvalResult, Problem, ProblemSet
from twisted.store.models import Base, utcnow
from twisted.store.training import TrainedModel, TrainingRun

__all__ = [
    "IMPROVE_STATUSES",
    "ImproveGeneration",
    "add_generation",
        "lineage_labels",
    "lineage_rows",
    "model_of_training_run",
    "problem_set_names",
    "set_goal_specs",
    "shipped_model_id",
    "training_run_status",
    "update_generation",
]

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


def lineage_rows(store: Any, lineage: str) -> list[ImproveGeneration]:
    """The generations of ``lineage`` in order (detached rows)."""
    with store.session() as session:
        rows = session.scalars(
            select(ImproveGeneration)
            .where(ImproveGeneration.lineage == lineage)
            .order_by(ImproveGeneration.generation)
        ).all()
        session.expunge_all()
        return list(rows)


def add_generation(store: Any, **values: Any) -> ImproveGeneration:
    """Store a new generation row with ``values`` (its columns); the detached row."""
    with store.session(write=True) as session:
        row = ImproveGeneration(**values, created_at=utcnow(), updated_at=utcnow())
        session.add(row)
        session.flush()
        session.expunge(row)
        return row


def update_generation(store: Any, row_id: int, **values: Any) -> None:
    """Set columns of the generation ``row_id`` (and its ``updated_at``)."""
    with store.session(write=True) as session:
        row = session.get(ImproveGeneration, row_id)
        if row is None:
            raise LookupError(f"no improve generation {row_id}")
        for k, v in values.items():
            setattr(row, k, v)
        row.updated_at = utcnow()


def problem_set_names(session: Any, evaluated: bool = False) -> list[str]:
    """The names of the stored problem sets (``evaluated``: only those with evaluation results), sorted."""
    query = select(ProblemSet.name).distinct().order_by(ProblemSet.name)
    if evaluated:
        query = query.join(EvalResult, EvalResult.set_id == ProblemSet.id)
    return list(session.scalars(query))


def set_goal_specs(session: Any, names: Sequence[str]) -> list[str]:
    """The goal specs of the stored sets ``names``, set by set in each set's order."""
    return list(
        session.scalars(
            select(Problem.goal_key)
            .join(ProblemSet, ProblemSet.id == Problem.set_id)
            .where(ProblemSet.name.in_(list(names)))
            .order_by(ProblemSet.name, Problem.idx)
        )
    )


def shipped_model_id(session: Any) -> int | None:
    """The id of the shipped model stored as ``shipped`` (not made by a training run), if it is."""
    found = session.scalar(
        select(func.min(TrainedModel.id)).where(
            TrainedModel.name == "shipped", TrainedModel.training_run_id.is_(None)
        )
    )
    return None if found is None else int(found)


def training_run_status(session: Any, training_run_id: int) -> str | None:
    """The status of a training run (None when there is no such run)."""
    run = session.get(TrainingRun, training_run_id)
    return None if run is None else str(run.status)


def model_of_training_run(session: Any, training_run_id: int) -> tuple[int, dict[str, Any]] | None:
    """(id, metrics) of the model a training run made, or None."""
    model = session.scalar(select(TrainedModel).where(TrainedModel.training_run_id == training_run_id))
    return None if model is None else (int(model.id), dict(model.metrics or {}))
