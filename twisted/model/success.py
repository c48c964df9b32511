"""success@k of the inverse model on held-out transitions, next to k random curves.

For a held-out transition ``(q, s, c, q', s')`` the model samples ``k`` curves for ``(q, s')``;
each is simulated from ``q`` and the transition counts as solved when any result has P-data
``s'``. The same is done with ``k`` uniform random curves on the same transitions. Results are
grouped by crossing step: ``0->1``, ``1->2``, ``2->3`` (and deeper ``+1`` steps) and ``+2``; the
transitions that remove crossings (``collect --remove-share``) as ``3->2`` (``-1`` steps) and ``-2``.

Held-out means: the validation side of the model's own split (same seed and fraction, by start
configuration), plus transitions newer than its data snapshot whose start configuration it never
trained on. A model trained on another database (the shipped default) sees every transition as
held out; that is only true when the databases share no configurations, which callers must judge.
Every 0->1 transition starts from the straight rope, one configuration, so 0->1 steps are either
all trained on or all held out.

:func:`tree_steps` takes the steps from planner trees instead: the edges of the trees of runs
towards the goals of named problem sets that add crossings (the parent node's configuration, the
state its child reached). They are held out from a model whose training left those sets out
(``train --hold-out-set``, ``improve``) or never saw that database. Each was made at least once by
the search that grew the tree, with its own model or a random expansion, which favours that model.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from sqlalchemy import select
from sqlalchemy.orm import aliased

from twisted.model.data import check_hold_out_sets, split_by_start
from twisted.model.network import InverseModel
from twisted.moves import explains
from twisted.rope import MAX_CROSSINGS
from twisted.sim import Curve, sample_curve
from twisted.sim.pool import SimPool
from twisted.store.db import Store
from twisted.store.experiments import EvalResult, Problem, ProblemSet
from twisted.store.models import Configuration, TopologicalState, Transition, blob_to_array
from twisted.store.search_tree import SearchNode
from twisted.topology import PData, parse_p_data

__all__ = ["HeldOut", "StepResult", "held_out_transitions", "step_name", "success_at_k", "tree_steps"]


def step_name(from_cross: int, to_cross: int) -> str:
    """``"0->1"`` style for +1 and -1 steps (``"3->2"``), ``"+2"`` / ``"-2"`` for two crossings at once..."""
    change = to_cross - from_cross
    return f"{from_cross}->{to_cross}" if abs(change) == 1 else f"{change:+d}"


@dataclass(frozen=True)
class HeldOut:
    """One held-out transition, ready to replay."""

    transition_id: int
    step: str
    q: npt.NDArray[np.float64]
    points: npt.NDArray[np.float64]
    p_from: PData
    p_to: PData


def held_out_transitions(
    store: Store,
    model: InverseModel,
    per_step: int,
    rng: np.random.Generator,
    steps: Sequence[str] = ("0->1", "1->2", "2->3", "+2"),
    max_cross: int = MAX_CROSSINGS,
    side: str = "held_out",
) -> list[HeldOut]:
    """Up to ``per_step`` held-out transitions of each step kind, drawn uniformly (see module doc).

    ``side="train"`` takes the model's training transitions instead (a check that the model can
    reproduce what it was fitted on), ``side="all"`` every transition.
    """
    if side not in ("held_out", "train", "all"):
        raise ValueError(f"side must be held_out, train or all, got {side!r}")
    params = model.metadata.get("parameters", {})
    max_id = model.metadata.get("max_transition_id")
    with store.session() as session:
        rows = session.execute(
            select(
                Transition.id, Transition.from_configuration_id, Transition.from_cross, Transition.to_cross
            )
            .where(
                Transition.to_cross != Transition.from_cross,
                Transition.to_cross <= max_cross,
                Transition.from_cross <= max_cross,
            )
            .order_by(Transition.id)
        ).all()
    ids = np.array([r[0] for r in rows], dtype=np.int64)
    starts = np.array([r[1] for r in rows], dtype=np.int64)
    names = np.array([step_name(r[2], r[3]) for r in rows])
    held = np.ones(len(ids), dtype=bool)
    if max_id is not None and "seed" in params:
        _, val = split_by_start(starts, float(params.get("val_fraction", 0.1)), int(params["seed"]))
        val_side = np.zeros(len(ids), dtype=bool)
        val_side[val] = True  # the side of the split a start configuration falls on depends on it alone
        in_snapshot = ids <= int(max_id)
        training_starts = np.unique(starts[in_snapshot & ~val_side])
        # the validation side, and newer transitions from start configurations never trained on
        held = val_side | (~in_snapshot & ~np.isin(starts, training_starts))
    if side == "train":
        held = ~held
    elif side == "all":
        held[:] = True
    chosen = _draw_per_step(np.where(held, names, ""), steps, per_step, rng)
    out = []
    with store.session() as session:
        for i in chosen:
            t = session.get(Transition, int(ids[i]))
            assert t is not None
            c = session.get(Configuration, t.from_configuration_id)
            assert c is not None
            p_from = session.get_one(TopologicalState, t.from_state_id).p_data
            p_to = session.get_one(TopologicalState, t.to_state_id).p_data
            points = blob_to_array(c.points, (-1, 3))
            out.append(
                HeldOut(t.id, str(names[i]), c.q_array(), points, parse_p_data(p_from), parse_p_data(p_to))
            )
    return out


def _draw_per_step(
    names: npt.NDArray[np.str_], steps: Sequence[str], per_step: int, rng: np.random.Generator
) -> list[int]:
    """Up to ``per_step`` indices of each step kind of ``names``, drawn uniformly, in index order."""
    chosen: list[int] = []
    for step in steps:
        candidates = np.flatnonzero(names == step)
        if len(candidates) > per_step:
            candidates = np.sort(rng.choice(candidates, per_step, replace=False))
        chosen.extend(int(i) for i in candidates)
    return chosen


def tree_steps(
    store: Store,
    set_names: Sequence[str],
    per_step: int,
    rng: np.random.Generator,
    steps: Sequence[str] = ("3->4", "4->5", "5->6"),
    max_cross: int = MAX_CROSSINGS,
    explained: bool = False,
) -> list[HeldOut]:
    """Up to ``per_step`` tree edges of each step kind, drawn uniformly from the trees of the stored
    runs towards the goals of ``set_names`` (the runs their evaluations made); see the module doc.
    ``explained``: only edges one high-level move explains (the steps a plan asks the model for).
    ``transition_id`` is then the child node's id. Raises ``UnknownProblemSetError`` (a ValueError)
    naming a set the store lacks."""
    check_hold_out_sets(store, set_names)
    parent = aliased(SearchNode)
    with store.session() as session:
        runs = (
            select(EvalResult.plan_run_id)
            .join(Problem, Problem.id == EvalResult.problem_id)
            .join(ProblemSet, ProblemSet.id == Problem.set_id)
            .where(ProblemSet.name.in_(list(set_names)), EvalResult.plan_run_id.is_not(None))
        )
        rows = session.execute(
            select(
                SearchNode.id, parent.id, parent.cross, SearchNode.cross, parent.state_id, SearchNode.state_id
            )
            .join(parent, parent.id == SearchNode.parent_id)
            .where(
                SearchNode.run_id.in_(runs),
                SearchNode.link.is_not(None),
                SearchNode.cross > parent.cross,
                SearchNode.cross <= max_cross,
            )
            .order_by(SearchNode.id)
        ).all()
        state_ids = sorted({r[4] for r in rows} | {r[5] for r in rows})
        p_data = {
            i: parse_p_data(p)
            for i, p in session.execute(
                select(TopologicalState.id, TopologicalState.p_data).where(TopologicalState.id.in_(state_ids))
            )
        }
        if explained:
            rows = [r for r in rows if explains(p_data[r[4]], p_data[r[5]]) is not None]
        names = np.array([step_name(r[2], r[3]) for r in rows], dtype=np.str_)
        out = []
        for i in _draw_per_step(names, steps, per_step, rng):
            child_id, parent_id, _, _, from_state, to_state = rows[i]
            node = session.get_one(SearchNode, parent_id)
            q, points = blob_to_array(node.q), blob_to_array(node.points, (-1, 3))
            out.append(HeldOut(child_id, str(names[i]), q, points, p_data[from_state], p_data[to_state]))
    return out


@dataclass
class StepResult:
    """success@k per step kind: ``solved_model`` / ``solved_random`` out of ``n``.

    ``random_expected`` is the random baseline with less noise: each transition's per-curve hit
    rate p is estimated from all its random curves, and success@k = mean(1 - (1 - p)^k).
    """

    step: str
    n: int = 0
    solved_model: int = 0
    solved_random: int = 0
    random_expected_sum: float = 0.0
    random_curves: int = 0

    @property
    def model_rate(self) -> float:
        return self.solved_model / self.n if self.n else float("nan")

    @property
    def random_rate(self) -> float:
        return self.solved_random / self.n if self.n else float("nan")

    @property
    def random_expected(self) -> float:
        return self.random_expected_sum / self.n if self.n else float("nan")


def success_at_k(
    model: InverseModel,
    transitions: Sequence[HeldOut],
    pool: SimPool,
    rng: np.random.Generator,
    k: int = 6,
    random_curves: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, StepResult]:
    """Simulate ``k`` model curves and ``random_curves`` (default ``k``, at least ``k``; 0: none) random
    curves per transition; solved = any of the k reaches ``p_to`` (the first k random curves for random)."""
    r = 0 if random_curves == 0 else max(k, random_curves or k)
    jobs: list[tuple[npt.NDArray[np.float64], Curve]] = []
    for t in transitions:
        jobs += [(t.q, c) for c in model.sample(t.points, t.q, t.p_to, k, rng, p_data=t.p_from)]
        jobs += [(t.q, sample_curve(rng)) for _ in range(r)]
    results = []
    for i, res in enumerate(pool.imap(jobs)):
        results.append(res)
        if progress is not None and (i + 1) % k == 0:
            progress(i + 1, len(jobs))
    out: dict[str, StepResult] = {}
    for n, t in enumerate(transitions):
        block = results[(k + r) * n : (k + r) * (n + 1)]
        hit = [res.ok and res.p_data == t.p_to for res in block]
        step = out.setdefault(t.step, StepResult(t.step, random_curves=r))
        step.n += 1
        step.solved_model += any(hit[:k])
        if r:
            step.solved_random += any(hit[k : 2 * k])
            p = sum(hit[k:]) / r
            step.random_expected_sum += 1.0 - (1.0 - p) ** k
    return out
