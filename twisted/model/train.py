"""Training of the inverse model: the loop on in-memory tensors, and the store-backed resumable run.

Replay from the seed: the sample order of epoch ``e`` is a permutation drawn from a generator
seeded with ``(seed, e)``, and the augmentation variants of batch ``b`` from ``(seed, e, b)``.
A checkpoint therefore only needs the weights, the optimiser, ``(epoch, batch_index)`` and the
elapsed time for a resumed run to draw exactly the batches an uninterrupted run would have drawn
(torch's global RNG state is saved as well, for anything that might draw from it).

:func:`train` is what ``twisted train`` calls: it creates (or with ``resume=True`` continues) a
``training_runs`` row, checkpoints into the database every epoch and every ``checkpoint_every_s``,
and stores the finished model in ``models`` with its data size and validation metrics. The model
stored is the weights of the epoch with the lowest validation loss (small data overfits).
"""

from __future__ import annotations

import io
import logging
import math
import shlex
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import torch
from sqlalchemy import delete, select

from twisted.model.augment import VARIANTS, apply_variant
from twisted.model.config import SOURCES, TrainConfig
from twisted.model.data import (
    NoTrainingDataError,
    TransitionData,
    check_hold_out_sets,
    load_samples,
    load_transitions,
    max_search_node_id,
    max_transition_id,
    split_by_start,
)
from twisted.model.encoding import preprocess
from twisted.model.network import Condition, InverseModel, InverseNet
from twisted.store.db import Store
from twisted.store.models import utcnow
from twisted.store.payloads import UnsafePayloadError, load_tensors
from twisted.store.training import Checkpoint, TrainingRun

__all__ = [
    "NoTrainingDataError",
    "TrainOutcome",
    "Trainer",
    "train",
]

logger = logging.getLogger(__name__)

KEEP_CHECKPOINTS = 2
EVAL_BATCH = 4096


def _generator(*parts: int) -> torch.Generator:
    """A torch generator seeded from integers (stable across processes and versions of Python)."""
    seed = int(np.random.SeedSequence([p & 0xFFFFFFFF for p in parts]).generate_state(1, np.uint64)[0])
    return torch.Generator().manual_seed(seed & 0x7FFF_FFFF_FFFF_FFFF)


class Trainer:
    """The loop on in-memory tensors: batches, loss, Adam, evaluation, and its checkpointable state."""

    def __init__(
        self,
        train_data: TransitionData,
        config: TrainConfig,
        device: str | torch.device = "cpu",
        init: dict[str, torch.Tensor] | None = None,
    ) -> None:
        """``init``: starting weights (fine-tuning; they must fit ``config.net``), else seeded ones."""
        if len(train_data) == 0:
            raise NoTrainingDataError(
                "no training samples left after the validation split: collect more data"
            )
        self.config = config
        self.device = torch.device(device)
        self.data = train_data.to(self.device)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(config.seed)  # weight initialisation replays from the seed
            self.net = InverseNet(config.net)
        if init is not None:
            self.net.load_state_dict(init)
        self.net = self.net.to(self.device)
        self.optimizer = torch.optim.AdamW(
            self.net.parameters(), lr=config.lr, weight_decay=config.weight_decay
        )
        self.epoch = 0
        self.batch_index = 0  # batches of `epoch` already trained
        # the weights of the epoch with the lowest validation loss: what a finished run stores
        self.best_val_loss = math.inf
        self.best_epoch = -1
        self.best_net: dict[str, torch.Tensor] | None = None

    @property
    def batches_per_epoch(self) -> int:
        return math.ceil(len(self.data) / self.config.batch_size)

    def epoch_order(self, epoch: int) -> torch.Tensor:
        return torch.randperm(len(self.data), generator=_generator(self.config.seed, epoch))

    def batch_indices(self, epoch: int, batch_index: int) -> torch.Tensor:
        """The sample indices of batch ``batch_index`` of ``epoch`` (a pure function of the seed)."""
        b = self.config.batch_size
        return self.epoch_order(epoch)[batch_index * b : (batch_index + 1) * b]

    def batch_variants(self, epoch: int, batch_index: int, size: int) -> torch.Tensor:
        if not self.config.augment:
            return torch.zeros(size, dtype=torch.long)
        return torch.randint(
            0, len(VARIANTS), (size,), generator=_generator(self.config.seed, epoch, batch_index)
        )

    def step(self, index: torch.Tensor, variant: torch.Tensor) -> dict[str, float]:
        """One optimiser step on the samples ``index`` under the symmetry ``variant`` per sample."""
        self.net.train()
        terms = batch_losses(self.net, self.data, index.to(self.device), variant.to(self.device))
        loss = terms["loss"].mean()
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        return {k: float(v.detach().mean()) for k, v in terms.items()}

    def run_epoch_batches(
        self, on_batch: Callable[[torch.Tensor, dict[str, float]], bool] | None = None
    ) -> bool:
        """Train the remaining batches of the current epoch; ``on_batch`` returning True stops early.

        Returns True when the epoch completed (the position then moves to the next epoch).
        """
        order = self.epoch_order(self.epoch)
        b = self.config.batch_size
        while self.batch_index < self.batches_per_epoch:
            index = order[self.batch_index * b : (self.batch_index + 1) * b]
            variant = self.batch_variants(self.epoch, self.batch_index, len(index))
            figures = self.step(index, variant)
            self.batch_index += 1
            if on_batch is not None and on_batch(index, figures):
                return self.batch_index >= self.batches_per_epoch and self._next_epoch()
        return self._next_epoch()

    def _next_epoch(self) -> bool:
        self.epoch += 1
        self.batch_index = 0
        return True

    def note_validation(self, epoch: int, val_loss: float) -> None:
        """Keep a copy of the weights when ``val_loss`` is the best so far."""
        if val_loss < self.best_val_loss:
            self.best_val_loss, self.best_epoch = val_loss, epoch
            self.best_net = {k: v.detach().clone() for k, v in self.net.state_dict().items()}

    def state_dict(self) -> dict[str, Any]:
        return {
            "net": self.net.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "epoch": self.epoch,
            "batch_index": self.batch_index,
            "torch_rng": torch.get_rng_state(),
            "best_val_loss": self.best_val_loss,
            "best_epoch": self.best_epoch,
            "best_net": self.best_net,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.net.load_state_dict(state["net"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.epoch = int(state["epoch"])
        self.batch_index = int(state["batch_index"])
        torch.set_rng_state(state["torch_rng"])
        self.best_val_loss = float(state.get("best_val_loss", math.inf))
        self.best_epoch = int(state.get("best_epoch", -1))
        self.best_net = state.get("best_net")


def batch_losses(
    net: InverseNet, data: TransitionData, index: torch.Tensor, variant: torch.Tensor
) -> dict[str, torch.Tensor]:
    """Per-sample loss terms of samples ``index`` of ``data`` with symmetry ``variant`` (B,) applied."""
    points, curves = apply_variant(data.points[index], data.curves[index], variant)
    return net.losses(preprocess(points), batch_condition(data, index, variant), curves)


def batch_condition(data: TransitionData, index: torch.Tensor, variant: torch.Tensor) -> Condition:
    """The encoded condition of samples ``index`` under symmetry ``variant``."""
    return Condition(
        p_now=data.state_enc[data.from_state[index], variant],
        p_next=data.state_enc[data.to_state[index], variant],
        new=data.pair_enc[data.pair[index], variant],
        move=data.move_enc[data.pair[index], variant],
    )


@torch.no_grad()
def evaluate(
    net: InverseNet, data: TransitionData, device: str | torch.device = "cpu", prefix: str = "val"
) -> dict[str, float]:
    """Mean NLL terms (no augmentation), link accuracy and top-3 accuracy, keys ``<prefix>_...``."""
    net.eval()
    data = data.to(device)
    sums: dict[str, float] = {}
    correct = top3 = 0
    for start in range(0, len(data), EVAL_BATCH):
        index = torch.arange(start, min(start + EVAL_BATCH, len(data)), device=device)
        variant = torch.zeros(len(index), dtype=torch.long, device=device)
        for k, v in batch_losses(net, data, index, variant).items():
            sums[k] = sums.get(k, 0.0) + float(v.sum())
        pre = preprocess(data.points[index])
        logits = net.link_logits(pre, batch_condition(data, index, variant))
        link = data.curves[index, 0].round().long()
        correct += int((logits.argmax(dim=1) == link).sum())
        top3 += int((logits.topk(3, dim=1).indices == link[:, None]).any(dim=1).sum())
    n = max(len(data), 1)
    out = {f"{prefix}_{k}": v / n for k, v in sums.items()}
    out[f"{prefix}_link_accuracy"] = correct / n
    out[f"{prefix}_link_top3"] = top3 / n
    out[f"n_{prefix}"] = len(data)
    return out


# ---- the store-backed run ------------------------------------------------------------------------


@dataclass
class TrainOutcome:
    """What :func:`train` did: the run, its status, and the stored model (None unless finished)."""

    training_run_id: int
    status: str  # "finished" or "interrupted"
    model_id: int | None
    metrics: dict[str, Any]
    n_train: int
    n_val: int


@dataclass
class Progress:
    """Figures passed to the progress callback after every batch and every epoch."""

    epoch: int
    epochs: int
    batch_index: int
    batches_per_epoch: int
    loss: float
    elapsed_s: float
    val: dict[str, float] | None = None


def _to_bytes(obj: Any) -> bytes:
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    return buffer.getvalue()


def _newest_resumable(store: Store) -> TrainingRun | None:
    with store.session() as session:
        return session.scalars(
            select(TrainingRun)
            .where(TrainingRun.status.in_(("running", "interrupted")))
            .order_by(TrainingRun.id.desc())
        ).first()


def _save_checkpoint(
    store: Store, run_id: int, trainer: Trainer, elapsed_s: float, history: list[Any]
) -> None:
    payload = _to_bytes(trainer.state_dict())
    with store.session(write=True) as session:
        session.add(
            Checkpoint(
                training_run_id=run_id,
                epoch=trainer.epoch,
                batch_index=trainer.batch_index,
                elapsed_s=elapsed_s,
                payload=payload,
            )
        )
        run = session.get(TrainingRun, run_id)
        assert run is not None
        run.epochs_done = trainer.epoch
        run.elapsed_s = elapsed_s
        run.metrics = {"history": history}
        run.updated_at = utcnow()
        session.flush()
        keep = session.scalars(
            select(Checkpoint.id)
            .where(Checkpoint.training_run_id == run_id)
            .order_by(Checkpoint.id.desc())
            .limit(KEEP_CHECKPOINTS)
        ).all()
        session.execute(
            delete(Checkpoint).where(Checkpoint.training_run_id == run_id, Checkpoint.id.not_in(keep))
        )


CHECKPOINT_KEYS = ("net", "optimizer", "epoch", "batch_index", "torch_rng")


def _checkpoint_state(ckpt: Checkpoint, run_id: int, device: str) -> dict[str, Any]:
    """The trainer state in ``ckpt``, read as tensors and plain data only (a crafted pickle is refused:
    :class:`UnsafePayloadError`, a ValueError), with the entries a resume needs."""
    what = f"checkpoint {ckpt.id} of training run {run_id}"
    state = load_tensors(ckpt.payload, what, map_location=device)
    missing = [k for k in CHECKPOINT_KEYS if k not in state] if isinstance(state, dict) else CHECKPOINT_KEYS
    if missing:
        raise UnsafePayloadError(f"{what} is not a trainer state (it lacks {', '.join(missing)})")
    return state


def _latest_checkpoint(store: Store, run_id: int) -> Checkpoint | None:
    with store.session() as session:
        return session.scalars(
            select(Checkpoint).where(Checkpoint.training_run_id == run_id).order_by(Checkpoint.id.desc())
        ).first()


def train(
    store: Store,
    config: TrainConfig | None = None,
    *,
    resume: bool = False,
    device: str = "cpu",
    progress: Callable[[Progress], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
    on_batch: Callable[[torch.Tensor], None] | None = None,
    command: str | None = None,
    log: Callable[[str], None] | None = None,
) -> TrainOutcome:
    """Train (or with ``resume`` continue the newest unfinished run) and store the finished model.

    ``config`` is ignored when resuming (the run's stored parameters are used). ``should_stop``
    is polled after every batch: True checkpoints and returns status "interrupted" (so does
    KeyboardInterrupt, which is then re-raised). ``on_batch`` sees every batch's sample indices.
    Raises :class:`NoTrainingDataError` on an empty database, ValueError when there is no run to
    resume.
    """
    say = log or (lambda _msg: None)
    command = command or " ".join(shlex.quote(a) for a in sys.argv)
    start_net: InverseNet | None = None  # the model a fine-tuning run starts from, read once
    if resume:
        run = _newest_resumable(store)
        if run is None:
            raise ValueError("there is no unfinished training run to resume: start one without --resume")
        config = TrainConfig.from_dict(run.parameters)
        max_id, run_id = run.max_transition_id, run.id
        history: list[Any] = list((run.metrics or {}).get("history", []))
        ckpt = _latest_checkpoint(store, run_id)
        # read (tensors and plain data only) and checked before anything is written
        saved = None if ckpt is None else _checkpoint_state(ckpt, run_id, device)
        say(f"resuming training run {run_id} (epoch {run.epochs_done}, {run.elapsed_s:.0f} s done)")
    else:
        config = config or TrainConfig()
        unknown = [s for s in config.sources if s not in SOURCES]
        if unknown or not config.sources:
            raise ValueError(f"sources must be among {', '.join(SOURCES)}, got {', '.join(config.sources)}")
        if config.init_model_id is not None:  # checked (and its architecture taken) before any write
            start_net = _init_model(store, config.init_model_id).net
            config = replace(config, net=start_net.config)
        found = max_transition_id(store, removing=config.removing) if "collect" in config.sources else None
        if "search" in config.sources:
            config = replace(config, max_search_node_id=max_search_node_id(store) or 0)
        check_hold_out_sets(store, config.hold_out_sets)
        if found is None and "search" not in config.sources:
            # load_transitions raises the actionable "collect first" error
            load_transitions(store, max_id=0)
        max_id = found or 0
        history = []
        with store.session(write=True) as session:
            run = TrainingRun(
                seed=config.seed,
                parameters=config.to_dict(),
                max_transition_id=max_id,
                status="running",
                n_train=0,
                n_val=0,
                epochs_done=0,
                elapsed_s=0.0,
                metrics={},
                message=command,
            )
            session.add(run)
            session.flush()
            run_id = run.id

    data = load_samples(
        store,
        config.sources,
        max_id=max_id,
        max_node_id=config.max_search_node_id,
        hold_out_sets=config.hold_out_sets,
        removing=config.removing,
    )
    train_idx, val_idx = split_by_start(data.start_ids, config.val_fraction, config.seed)
    train_data, val_data = data.subset(train_idx), data.subset(val_idx)
    del data
    by_source = {
        **{f"n_train_{k}": v for k, v in train_data.count_by_source().items()},
        **{f"n_val_{k}": v for k, v in val_data.count_by_source().items()},
    }
    with store.session(write=True) as session:
        row = session.get(TrainingRun, run_id)
        assert row is not None
        row.n_train, row.n_val, row.status = len(train_data), len(val_data), "running"
    say(
        f"training run {run_id}: {len(train_data)} training / {len(val_data)} validation samples ("
        + ", ".join(f"{k} {v}" for k, v in by_source.items())
        + ")"
    )

    logger.info(
        "training run %d %s on %s: %d training / %d validation samples; parameters %s",
        run_id,
        "resumed" if resume else "started",
        device,
        len(train_data),
        len(val_data),
        config.to_dict(),
    )
    if not resume:
        ckpt, saved = None, None
    init = None
    if ckpt is None and config.init_model_id is not None:
        if start_net is None:  # a resumed run that stopped before its first checkpoint
            start_net = _init_model(store, config.init_model_id).net
        init = start_net.state_dict()
    trainer = Trainer(train_data, config, device, init=init)
    elapsed_before = 0.0
    if ckpt is not None and saved is not None:
        try:
            trainer.load_state_dict(saved)
        except (KeyError, TypeError, ValueError, RuntimeError, AttributeError, IndexError) as exc:
            what = f"checkpoint {ckpt.id} of training run {run_id}"
            raise UnsafePayloadError(f"{what} does not fit the run ({type(exc).__name__}: {exc})") from None
        elapsed_before = ckpt.elapsed_s
    elif init is not None and len(val_data):
        # the starting weights compete for "best": a fine-tuning that only gets worse on the new
        # validation samples stores them unchanged (best epoch -1)
        start_val = evaluate(trainer.net, val_data, trainer.device)
        history.append({"epoch": -1, "elapsed_s": 0.0, "init_model_id": config.init_model_id, **start_val})
        trainer.note_validation(-1, start_val["val_loss"])
        logger.info(
            "training run %d starts from model %d: val NLL %s, link accuracy %s",
            run_id,
            config.init_model_id,
            _figure(start_val.get("val_loss")),
            _figure(start_val.get("val_link_accuracy")),
        )
        say(
            f"starting from model {config.init_model_id}: validation NLL {start_val['val_loss']:.3f}, "
            f"link accuracy {start_val['val_link_accuracy']:.3f}"
        )
    started = time.monotonic()
    last_checkpoint = started
    budget_s = config.hours * 3600.0 if config.hours is not None else math.inf

    def elapsed() -> float:
        return elapsed_before + time.monotonic() - started

    stopped = False
    epoch_loss = [0.0, 0]  # sum and count of the batch losses of this epoch (since a resume)

    def after_batch(index: torch.Tensor, figures: dict[str, float]) -> bool:
        nonlocal last_checkpoint, stopped
        if on_batch is not None:
            on_batch(index)
        epoch_loss[0] += figures["loss"]
        epoch_loss[1] += 1
        if progress is not None:
            progress(
                Progress(
                    trainer.epoch,
                    config.epochs,
                    trainer.batch_index,
                    trainer.batches_per_epoch,
                    epoch_loss[0] / epoch_loss[1],
                    elapsed(),
                )
            )
        if time.monotonic() - last_checkpoint >= config.checkpoint_every_s:
            _save_checkpoint(store, run_id, trainer, elapsed(), history)
            last_checkpoint = time.monotonic()
        if (should_stop is not None and should_stop()) or elapsed() >= budget_s:
            stopped = True
        return stopped

    try:
        while trainer.epoch < config.epochs and not stopped:
            epoch = trainer.epoch
            completed = trainer.run_epoch_batches(after_batch)
            if completed:
                val = evaluate(trainer.net, val_data, trainer.device) if len(val_data) else {}
                mean_loss = epoch_loss[0] / max(epoch_loss[1], 1)
                history.append(
                    {"epoch": epoch, "elapsed_s": round(elapsed(), 1), "train_batch_loss": mean_loss, **val}
                )
                epoch_loss[:] = [0.0, 0]
                logger.info(
                    "training run %d epoch %d/%d: train loss %.4f, val NLL %s, link accuracy %s (%.0f s)",
                    run_id,
                    epoch + 1,
                    config.epochs,
                    mean_loss,
                    _figure(val.get("val_loss")),
                    _figure(val.get("val_link_accuracy")),
                    elapsed(),
                )
                if val:
                    trainer.note_validation(epoch, val["val_loss"])
                if progress is not None:
                    progress(
                        Progress(
                            trainer.epoch,
                            config.epochs,
                            0,
                            trainer.batches_per_epoch,
                            mean_loss,
                            elapsed(),
                            val,
                        )
                    )
            _save_checkpoint(store, run_id, trainer, elapsed(), history)
            last_checkpoint = time.monotonic()
    except KeyboardInterrupt:
        _save_checkpoint(store, run_id, trainer, elapsed(), history)
        _set_status(store, run_id, "interrupted", elapsed())
        logger.warning("training run %d interrupted at epoch %d: checkpoint saved", run_id, trainer.epoch)
        raise

    out_of_time = elapsed() >= budget_s
    if stopped and not out_of_time:
        _set_status(store, run_id, "interrupted", elapsed())
        logger.info("training run %d stopped at epoch %d: checkpoint saved", run_id, trainer.epoch)
        return TrainOutcome(run_id, "interrupted", None, {"history": history}, len(train_data), len(val_data))

    if trainer.best_net is not None:
        trainer.net.load_state_dict(trainer.best_net)  # the epoch with the lowest validation loss
    metrics = evaluate(trainer.net, val_data, trainer.device) if len(val_data) else {}
    # the same figures on (up to EVAL_BATCH) training samples, to judge over-fitting
    seen = train_data.subset(np.arange(min(len(train_data), EVAL_BATCH)))
    metrics.update(
        {k: v for k, v in evaluate(trainer.net, seen, trainer.device, "train").items() if k != "n_train"}
    )
    metrics.update(
        {
            "epochs": trainer.epoch,
            "best_epoch": trainer.best_epoch,
            "elapsed_s": round(elapsed(), 1),
            "n_train": len(train_data),
            **by_source,
            **({} if config.init_model_id is None else {"init_model_id": config.init_model_id}),
        }
    )
    net = trainer.net.to("cpu")
    model = InverseModel(
        net,
        metadata={
            "training_run_id": run_id,
            "data_size": len(train_data),
            "data_sources": train_data.count_by_source(),
            "n_val": len(val_data),
            "max_transition_id": max_id,
            "init_model_id": config.init_model_id,
            "metrics": metrics,
            "parameters": config.to_dict(),
            "command": command,
            "created_at": utcnow().isoformat(),
        },
    )
    from twisted.model.registry import save_model

    model_id = save_model(store, model, name=f"run-{run_id}", training_run_id=run_id)
    with store.session(write=True) as session:
        row = session.get(TrainingRun, run_id)
        assert row is not None
        row.status, row.ended_at, row.elapsed_s = "finished", utcnow(), elapsed()
        row.epochs_done = trainer.epoch
        row.metrics = {"history": history, "final": metrics}
    logger.info(
        "training run %d finished after %d epochs (%.0f s): model %d stored (best epoch %s, val NLL %s)",
        run_id,
        trainer.epoch,
        elapsed(),
        model_id,
        trainer.best_epoch,
        _figure(metrics.get("val_loss")),
    )
    return TrainOutcome(run_id, "finished", model_id, metrics, len(train_data), len(val_data))


def _init_model(store: Store, model_id: int) -> InverseModel:
    """The stored model a fine-tuning run starts from (ValueError naming it when it cannot be used)."""
    from twisted.model.registry import ModelError, load_model

    try:
        return load_model(store, model_id)
    except ModelError as exc:
        raise ValueError(f"--init-model {model_id}: {exc}") from exc


def _figure(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f}"


def _set_status(store: Store, run_id: int, status: str, elapsed_s: float) -> None:
    with store.session(write=True) as session:
        row = session.get(TrainingRun, run_id)
        assert row is not None
        row.status, row.elapsed_s, row.updated_at = status, elapsed_s, utcnow()
