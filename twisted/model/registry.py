"""Models in the database, and the models shipped with the package.

``load_model(store)`` returns the newest model in the ``models`` table, or the one asked for by
id; when the database holds none it falls back to the model shipped for the process's rope (installed
as package data), so planning works right after installation: ``twisted/data/default_model.pt`` for
the default rope (21 links), ``twisted/data/model_<TWISTED_ROPE value>.pt`` for another rope a model
is shipped for (``model_31c7.pt``: 31 links, states of up to 7 crossings, for the knot table's
7-crossing knots). A process on a rope with no shipped model never falls back to another rope's, and a
stored model of another rope than the process's is refused (:class:`ModelError` naming both).
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
from twisted.rope import DEFAULT_ROPE, ROPE, RopeProfile, parse_rope
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
    "shipped_model_file",
    "shipped_model_path",
    "shipped_ropes",
]

DEFAULT_MODEL_FILE = "default_model.pt"
_SHIPPED_PREFIX = "model_"


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


def _data_dir() -> Path:
    return Path(str(resources.files("twisted") / "data"))


def shipped_model_file(rope: RopeProfile = ROPE) -> str:
    """The file name under ``twisted/data`` of the model shipped for ``rope``: ``default_model.pt`` for
    the default rope, ``model_<TWISTED_ROPE value>.pt`` for another (``model_31c7.pt``)."""
    return DEFAULT_MODEL_FILE if rope == DEFAULT_ROPE else f"{_SHIPPED_PREFIX}{rope.env_value}.pt"


def shipped_model_path(rope: RopeProfile = ROPE) -> Path:
    """Where the model shipped for ``rope`` (default: the process's) lives, whether or not it exists."""
    return _data_dir() / shipped_model_file(rope)


def default_model_path() -> Path:
    """Where the shipped model of the default rope lives (inside the installed package)."""
    return shipped_model_path(DEFAULT_ROPE)


def shipped_ropes() -> list[RopeProfile]:
    """The ropes a model is shipped for: the default rope's file first, then the others by name."""
    ropes = [DEFAULT_ROPE] if default_model_path().is_file() else []
    for path in sorted(_data_dir().glob(f"{_SHIPPED_PREFIX}*.pt")):
        try:
            rope = parse_rope(path.stem[len(_SHIPPED_PREFIX) :])
        except ValueError:
            continue  # a file of another name: not a shipped model
        if rope != DEFAULT_ROPE and path.name == shipped_model_file(rope):
            ropes.append(rope)
    return ropes


def load_default_model(why: str = "") -> InverseModel:
    """The model shipped with the package for the process's rope (``why``: what the message starts
    with when there is none, e.g. that the database holds no model)."""
    path = shipped_model_path()
    if not path.is_file():
        if ROPE != DEFAULT_ROPE:
            shipped = "; ".join(f"{rope.name} (TWISTED_ROPE={rope.env_value})" for rope in shipped_ropes())
            raise ModelError(
                f"{why}no model is shipped for this process's rope of {ROPE.name} (models are shipped "
                f"for: {shipped or 'none'}): train a model for this rope with `twisted train`"
            )
        raise ModelError(
            f"no trained model: the database holds none and the shipped default {path} is missing; "
            "train one with `twisted train`"
        )
    return _from_bytes(path.read_bytes(), None, f"the shipped model {path}")


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
