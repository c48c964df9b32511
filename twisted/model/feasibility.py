"""Which plan steps the rope allows: the odds that a step from a node's rope reaches the plan's next state.

Every stored search keeps, per (node, requested next state), the plan steps it tried and those that
reached the state (the ``pair`` statistics, DESIGN 8). Those are labelled data about the rope itself:
from this configuration, this move was made (or not) with K curves. :func:`pair_samples` reads them
from a store, :func:`train_feasibility` fits a small network to them, and the planner weighs its
choices of node, plan and state by the network's odds (``--feasibility``; DESIGN 8).

The input is what the inverse model sees of the rope (:func:`twisted.model.encoding.preprocess`: the
canonical-frame points, the crossing features and the per-link tokens) and of the step (the start
state's P-data, the new visits, the move). The output is a per-step success probability; the
planner uses it relative to the rate of its group (move kind, crossings of the start state) in the
training data, so that depth still decides between states as the crs heuristic says and the network
only says which nodes and plans of a state are the likely ones.

The loss is the binomial log-likelihood of (tried, reached) per pair. Validation holds out whole
runs (a run's nodes are correlated), and training keeps the epoch with the best validation loss.
"""

from __future__ import annotations

import io
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import torch
from sqlalchemy import select
from torch import nn

from twisted.model.encoding import encode_move, encode_new_visits, encode_p_data, preprocess
from twisted.moves import Move, explains
from twisted.store.db import Store
from twisted.store.experiments import Problem, ProblemSet
from twisted.store.payloads import UnsafePayloadError, load_tensors
from twisted.store.search import SearchRunRow, load_run
from twisted.topology import PData, parse_p_data

__all__ = [
    "DEFAULT_FEASIBILITY_FILE",
    "Feasibility",
    "FeasibilityNet",
    "auc",
    "default_feasibility_path",
    "geometry_features",
    "load_default_feasibility",
    "PairSamples",
    "pair_samples",
    "train_feasibility",
]

DEFAULT_FEASIBILITY_FILE = "default_feasibility.pt"
FORMAT_VERSION = 1
# the planner's weight of a node for a step: its odds over its group's rate, kept within these
RATIO_FLOOR = 0.05
RATIO_CAP = 5.0


def _group(kind: str, cross: int) -> str:
    return f"{kind}|{cross}"


def geometry_features(points: npt.ArrayLike) -> torch.Tensor:
    """(B, G) features of link points (B, N_POINTS, 3): the inverse model's, its link tokens flattened."""
    with torch.no_grad():
        pre = preprocess(np.asarray(points, dtype=np.float32))
        return torch.cat([pre.features, pre.link_tokens.flatten(1)], dim=1)


def step_features(p_from: PData, p_to: PData, move: Move) -> torch.Tensor:
    """(C,) features of a requested step: the start state, the new visits and the move."""
    return torch.cat(
        [
            torch.as_tensor(encode_p_data(p_from)),
            torch.as_tensor(encode_new_visits(p_from, p_to)),
            torch.as_tensor(encode_move(move)),
        ]
    ).float()


@dataclass
class PairSamples:
    """(node rope, requested step) pairs with the steps tried and reached, one row each."""

    points: np.ndarray  # (n, N_POINTS, 3)
    steps: torch.Tensor  # (n, C) step_features
    tried: np.ndarray  # (n,)
    reached: np.ndarray  # (n,)
    run: np.ndarray  # (n,) the run each pair comes from
    group: list[str] = field(default_factory=list)  # move kind | crossings of the start state

    def __len__(self) -> int:
        return len(self.tried)


def pair_samples(
    store: Store, exclude_sets: Sequence[str] = (), only_sets: Sequence[str] | None = None
) -> PairSamples:
    """The pair statistics of the stored searches, as samples (removing steps left out). Runs toward a
    goal of a set in ``exclude_sets`` (the evaluation sets) are left out; with ``only_sets``, only runs
    toward a goal of those sets are read."""

    def goals_of(names: Sequence[str]) -> set[str]:
        with store.session() as session:
            return set(
                session.scalars(
                    select(Problem.goal_key)
                    .join(ProblemSet, ProblemSet.id == Problem.set_id)
                    .where(ProblemSet.name.in_(list(names)))
                )
            )

    with store.session() as session:
        run_ids = list(session.scalars(select(SearchRunRow.run_id).order_by(SearchRunRow.run_id)))
    held = goals_of(exclude_sets)
    only = goals_of(only_sets) if only_sets is not None else None
    points: list[np.ndarray] = []
    steps: list[torch.Tensor] = []
    counts: list[tuple[float, float, int]] = []
    groups: list[str] = []
    for run_id in run_ids:
        info = load_run(store, run_id)
        if info is None or info.checkpoint is None or info.goal.spec in held:
            continue
        if only is not None and info.goal.spec not in only:
            continue
        nodes = {node.seq: node for node in info.nodes}
        for key, (tried, reached) in info.checkpoint.stats.get("pair", {}).items():
            seq, next_key = key.split("|", 1)
            node = nodes.get(int(seq))
            if node is None or tried <= 0:
                continue
            p_to = parse_p_data(json.loads(next_key))
            move = explains(node.p_data, p_to)
            if move is None or move.remove:
                continue
            points.append(np.asarray(node.points, dtype=np.float32))
            steps.append(step_features(node.p_data, p_to, move))
            counts.append((float(tried), float(reached), run_id))
            groups.append(_group(move.kind, node.p_data.cross))
    if not counts:
        return PairSamples(
            np.zeros((0, 0, 3), np.float32), torch.zeros(0, 0), np.zeros(0), np.zeros(0), np.zeros(0)
        )
    table = np.array(counts)
    return PairSamples(
        points=np.stack(points),
        steps=torch.stack(steps),
        tried=table[:, 0],
        reached=table[:, 1],
        run=table[:, 2].astype(np.int64),
        group=groups,
    )


class FeasibilityNet(nn.Module):
    """An MLP from (geometry, step) features, standardised, to the logit of a step's success."""

    mean: torch.Tensor
    scale: torch.Tensor

    def __init__(self, in_dim: int, hidden: int = 64) -> None:
        super().__init__()
        self.in_dim, self.hidden = in_dim, hidden
        self.register_buffer("mean", torch.zeros(in_dim))
        self.register_buffer("scale", torch.ones(in_dim))
        self.body = nn.Sequential(
            nn.Linear(in_dim, hidden),
            nn.ReLU(),
            nn.Dropout(0.3),
            nn.Linear(hidden, 128),
            nn.ReLU(),
            nn.Linear(128, 1),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.body((x - self.mean) / self.scale)[:, 0]


def _nll(logit: torch.Tensor, tried: torch.Tensor, reached: torch.Tensor) -> torch.Tensor:
    """Binomial negative log-likelihood per pair (without the constant)."""
    return -(reached * nn.functional.logsigmoid(logit) + (tried - reached) * nn.functional.logsigmoid(-logit))


@dataclass
class Feasibility:
    """A trained :class:`FeasibilityNet` with its groups' rates: what the planner asks."""

    net: FeasibilityNet
    rates: dict[str, float]  # per group: the training data's (reached + 1) / (tried + 2)
    metadata: dict[str, Any] = field(default_factory=dict)

    def odds(self, points: npt.ArrayLike, p_from: PData, p_to: PData, move: Move) -> np.ndarray:
        """Per rope of ``points`` (B, N_POINTS, 3): the probability that a step to ``p_to`` reaches it."""
        return self.odds_of(geometry_features(points), p_from, p_to, move)

    def odds_of(self, geometry: torch.Tensor, p_from: PData, p_to: PData, move: Move) -> np.ndarray:
        """As :meth:`odds`, from :func:`geometry_features` already computed."""
        step = step_features(p_from, p_to, move)
        x = torch.cat([geometry, step.expand(len(geometry), -1)], dim=1)
        self.net.eval()
        with torch.no_grad():
            return torch.sigmoid(self.net(x)).numpy().astype(np.float64)

    def ratios(self, odds: np.ndarray, p_from: PData, move: Move) -> np.ndarray:
        """``odds`` over the rate of the step's group, within [RATIO_FLOOR, RATIO_CAP]."""
        rate = self.rates.get(_group(move.kind, p_from.cross))
        if rate is None:  # a group the training data never had: the nodes' own mean
            rate = float(np.mean(odds)) if len(odds) else 1.0
        return np.clip(odds / max(rate, 1e-9), RATIO_FLOOR, RATIO_CAP)

    def to_bytes(self) -> bytes:
        buffer = io.BytesIO()
        torch.save(
            {
                "format_version": FORMAT_VERSION,
                "in_dim": self.net.in_dim,
                "hidden": self.net.hidden,
                "state_dict": self.net.state_dict(),
                "rates": dict(self.rates),
                "metadata": self.metadata,
            },
            buffer,
        )
        return buffer.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes) -> Feasibility:
        blob = load_tensors(data, "the feasibility model")  # tensors and plain data only (docs/security.md)
        if not isinstance(blob, dict) or not {"in_dim", "hidden", "state_dict", "rates"} <= set(blob):
            raise UnsafePayloadError("the feasibility model is not one written by twisted")
        version = int(blob.get("format_version", 0))
        if version != FORMAT_VERSION:
            raise ValueError(
                f"this feasibility model was saved in format {version}, this version of twisted reads "
                f"format {FORMAT_VERSION}: train a new one with `twisted train-feasibility`"
            )
        net = FeasibilityNet(int(blob["in_dim"]), int(blob["hidden"]))
        net.load_state_dict(blob["state_dict"])
        rates = {str(k): float(v) for k, v in blob["rates"].items()}
        return cls(net=net, rates=rates, metadata=dict(blob.get("metadata", {})))


def auc(score: np.ndarray, tried: np.ndarray, reached: np.ndarray) -> float | None:
    """The probability that a reaching step scores above a failing one (ties count half)."""
    pos, neg = reached, tried - reached
    if pos.sum() == 0 or neg.sum() == 0:
        return None
    order = np.argsort(score, kind="stable")
    s, p, n = score[order], pos[order], neg[order]
    # group ties
    _, start = np.unique(s, return_index=True)
    bounds = [*start.tolist(), len(s)]
    below = 0.0
    total = 0.0
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        pa, na = p[a:b].sum(), n[a:b].sum()
        total += pa * (below + 0.5 * na)
        below += na
    return float(total / (pos.sum() * neg.sum()))


def train_feasibility(
    samples: PairSamples,
    *,
    hidden: int = 64,
    epochs: int = 14,
    batch_size: int = 512,
    lr: float = 1e-3,
    weight_decay: float = 1e-4,
    val_share: float = 0.2,
    seed: int = 0,
) -> tuple[Feasibility, dict[str, Any]]:
    """Fit a :class:`Feasibility` to ``samples``; whole runs (a ``val_share`` of them, drawn with
    ``seed``) are held out for validation, and the epoch with the least validation loss is kept.
    Returns it and the figures: per epoch the losses, the group-rate baseline's validation loss, and
    per group the validation pairs, steps, reached and the network's AUC."""
    if len(samples) == 0:
        raise ValueError("no pair statistics to learn from: the store has no searches (run `twisted plan`)")
    rng = np.random.default_rng(seed)
    generator = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    runs = np.unique(samples.run)
    n_val = int(round(val_share * len(runs))) if len(runs) > 1 else 0
    val_runs = set(rng.choice(runs, size=n_val, replace=False).tolist()) if n_val else set()
    is_val = np.array([r in val_runs for r in samples.run])
    train_idx = np.flatnonzero(~is_val)
    val_idx = np.flatnonzero(is_val)
    x = torch.cat([geometry_features(samples.points), samples.steps], dim=1)
    tried = torch.as_tensor(samples.tried, dtype=torch.float32)
    reached = torch.as_tensor(samples.reached, dtype=torch.float32)
    groups = np.array(samples.group)

    rates: dict[str, float] = {}
    for g in np.unique(groups[train_idx]):
        m = train_idx[groups[train_idx] == g]
        rates[str(g)] = float((samples.reached[m].sum() + 1.0) / (samples.tried[m].sum() + 2.0))
    net = FeasibilityNet(x.shape[1], hidden)
    net.mean.copy_(x[train_idx].mean(dim=0))
    net.scale.copy_(x[train_idx].std(dim=0) + 1e-3)
    optimizer = torch.optim.Adam(net.parameters(), lr=lr, weight_decay=weight_decay)

    def val_loss(logit: torch.Tensor) -> float:
        t = tried[val_idx]
        return float(_nll(logit, t, reached[val_idx]).sum() / t.sum().clamp_min(1.0))

    base = torch.as_tensor([rates.get(str(g), 0.5) for g in groups[val_idx]], dtype=torch.float32)
    figures: dict[str, Any] = {
        "pairs": len(samples),
        "train_pairs": len(train_idx),
        "val_pairs": len(val_idx),
        "val_runs": len(val_runs),
        "baseline_val_loss": val_loss(torch.logit(base)) if len(val_idx) else None,
        "epochs": [],
    }
    best_loss, best_state = math.inf, None
    for epoch in range(epochs):
        net.train()
        order = train_idx[torch.randperm(len(train_idx), generator=generator).numpy()]
        total = 0.0
        for start in range(0, len(order), batch_size):
            j = torch.as_tensor(order[start : start + batch_size])
            loss = _nll(net(x[j]), tried[j], reached[j]).sum() / tried[j].sum()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            total += float(loss.detach()) * len(j)
        net.eval()
        with torch.no_grad():
            vl = val_loss(net(x[val_idx])) if len(val_idx) else total / max(len(train_idx), 1)
        figures["epochs"].append(
            {"epoch": epoch, "train_loss": total / max(len(train_idx), 1), "val_loss": vl}
        )
        if vl < best_loss:
            best_loss, best_state = vl, {k: v.clone() for k, v in net.state_dict().items()}
    assert best_state is not None
    net.load_state_dict(best_state)
    figures["best_epoch"] = min(figures["epochs"], key=lambda e: e["val_loss"])["epoch"]
    figures["val_loss"] = best_loss
    per_group = []
    if len(val_idx):
        with torch.no_grad():
            odds = torch.sigmoid(net(x[val_idx])).numpy()
        for g in sorted(set(groups[val_idx].tolist())):
            m = groups[val_idx] == g
            t, r = samples.tried[val_idx][m], samples.reached[val_idx][m]
            per_group.append(
                {
                    "group": g,
                    "pairs": int(m.sum()),
                    "tried": int(t.sum()),
                    "reached": int(r.sum()),
                    "auc": auc(odds[m], t, r),
                }
            )
    figures["groups"] = per_group
    metadata = {
        "seed": seed,
        "hidden": hidden,
        **{k: figures[k] for k in ("pairs", "val_loss", "baseline_val_loss", "best_epoch")},
    }
    return Feasibility(net=net, rates=rates, metadata=metadata), figures


def default_feasibility_path() -> Path:
    """The shipped feasibility model (package data)."""
    return Path(str(resources.files("twisted") / "data" / DEFAULT_FEASIBILITY_FILE))


def load_default_feasibility() -> Feasibility:
    """The shipped feasibility model; ValueError naming the file when it is missing or unreadable."""
    path = default_feasibility_path()
    try:
        return Feasibility.from_bytes(path.read_bytes())
    except OSError as exc:
        raise ValueError(f"the shipped feasibility model {path} cannot be read: {exc}") from None
