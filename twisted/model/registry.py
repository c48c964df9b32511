"""Models in the database, and the default model shipped with the package.

``load_model(store)`` returns the newest model in the ``models`` table, or the one asked for by
id; when the database holds none it falls back to ``twisted/data/default_model.pt`` (installed as
package data), so planning works right after installation. The shipped model is for the default rope
(21 links): a process running another (``TWISTED_ROPE``) never falls back to it, and a stored model of
another rope than the process's is refused (:class:`ModelError` naming both).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from sqlalchemy import select

from twisted.model.config import ModelRopeError
from twisted.model.network import InverseModel
from twisted.rope import DEFAULT_ROPE, ROPE
from twisted.store.db import Store
from twisted.store.models import by_id_or_newest
from twisted.store.training import TrainedModel

__all__ = [
    "DEFAULT_MODEL_FILE",
    "ModelError",
    "ModelInfo",
    "default_model_path",
    "list_models",
    "load_default_model",
    "load_model",
    "load_model_file",
    "save_model",
]

DEFAULT_MODEL_FILE = "default_model.pt"


class ModelError(LookupError):
    """No usable model (the message says what to do)."""


@dataclass(frozen=True)
class ModelInfo:
    """A row of ``models`` without its weights."""

    id: int
    name: str
    training_run_id: int | None
    data_size: int
    size_bytes: int
    metrics: dict[str, Any]
    created_at: dt.datetime


def save_model(store: Store, model: InverseModel, *, name: str, training_run_id: int | None = None) -> int:
    """Store ``model`` (weights, architecture, metadata) in ``models``; returns its id."""
    blob = model.to_bytes()
    with store.session(write=True) as session:
        row = TrainedModel(
            training_run_id=training_run_id,
            name=name,
            data_size=int(model.metadata.get("data_size", 0)),
            metrics=dict(model.metadata.get("metrics", {})),
            config=model.net.config.to_dict(),
            size_bytes=len(blob),
            weights=blob,
        )
        session.add(row)
        session.flush()
        model.model_id = row.id
        return row.id


def list_models(store: Store) -> list[ModelInfo]:
    """Every stored model, newest first (weights not loaded)."""
    cols = (
        TrainedModel.id,
        TrainedModel.name,
        TrainedModel.training_run_id,
        TrainedModel.data_size,
        TrainedModel.size_bytes,
        TrainedModel.metrics,
        TrainedModel.created_at,
    )
    with store.session() as session:
        rows = session.execute(select(*cols).order_by(TrainedModel.id.desc())).all()
    return [ModelInfo(*row) for row in rows]


def default_model_path() -> Path:
    """Where the shipped default model lives (inside the installed package)."""
    return Path(str(resources.files("twisted") / "data" / DEFAULT_MODEL_FILE))


def load_default_model(why: str = "") -> InverseModel:
    """The model shipped with the package (for the default rope only; ``why``: what the message of a
    process on another rope starts with, e.g. that the database holds no model)."""
    path = default_model_path()
    if ROPE != DEFAULT_ROPE:
        raise ModelError(
            f"{why}the shipped default model is for the default rope of {DEFAULT_ROPE.name}, not this "
            f"process's rope of {ROPE.name}: train a model for this rope with `twisted train`"
        )
    if not path.is_file():
        raise ModelError(
            f"no trained model: the database holds none and the shipped default {path} is missing; "
            "train one with `twisted train`"
        )
    return _from_bytes(path.read_bytes(), None, f"the shipped default {path}")


def load_model_file(path: Path) -> InverseModel:
    """A model from a file written by ``twisted models --export`` (or a shipped default)."""
    if not path.is_file():
        raise ModelError("no such file" if not path.exists() else "not a file")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ModelError(f"cannot be read: {exc.strerror or exc}") from exc
    try:
        return InverseModel.from_bytes(data)
    except ModelRopeError as exc:
        raise ModelError(str(exc)) from exc
    except Exception as exc:  # noqa: BLE001 (any file may be given: torch.load raises many kinds)
        raise ModelError(
            f"not an inverse model written by `twisted models --export` ({type(exc).__name__}: {exc})"
        ) from exc


def _from_bytes(data: bytes, model_id: int | None, what: str) -> InverseModel:
    try:
        return InverseModel.from_bytes(data, model_id=model_id)
    except (ValueError, RuntimeError, KeyError) as exc:
        raise ModelError(f"{what} cannot be loaded: {exc}") from exc


def load_model(store: Store | None = None, model_id: int | None = None) -> InverseModel:
    """Model ``model_id`` from the store, else the newest stored one, else the shipped default."""
    if store is not None:
        with store.session() as session:
            row = by_id_or_newest(
                session, TrainedModel, model_id, what="model", see="twisted models", error=ModelError
            )
            if row is not None:
                return _from_bytes(row.weights, row.id, f"model {row.id} of the database")
        return load_default_model("the database holds no model, and ")
    elif model_id is not None:
        raise ModelError(f"model {model_id} was asked for but no database was given")
    return load_default_model()
