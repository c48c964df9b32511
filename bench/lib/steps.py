"""Plan steps of stored searches, for the benches that read them: which evaluation runs (``--db``,
``--set``, ``--label``), their (node, requested next state) pairs, the distinct adding steps by crossing
count, the planner's own curves for a step, and a map over worker processes.

Used by ``bench/step_moves.py``, ``bench/step_ceiling.py``, ``bench/rope_physics.py`` and
``bench/search_calls.py``; a script in ``bench/`` imports it as ``from lib.steps import ...`` (the
script's folder is first on ``sys.path``).
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

import numpy as np
from sqlalchemy import select

from twisted.moves import Move, explains
from twisted.planner.options import PlannerOptions
from twisted.planner.parts import StepCurves
from twisted.planner.tree import Node
from twisted.proposals import segment_bounds
from twisted.rope import N_LINKS
from twisted.store import open_store
from twisted.store.experiments import FINISHED_STATUSES, EvalResult, ProblemSet
from twisted.store.search_tree import SearchRunInfo, StoredNode, load_run
from twisted.topology import PData, parse_p_data

PLANNER_K = PlannerOptions().k  # the curves of one of the planner's steps (its default K)


def move_class(move: Move, p_data: PData) -> str:
    """The kind of ``move`` from ``p_data`` in words that mean the same in every state."""
    ends = (0, 2 * p_data.cross)
    if move.kind == "Cross":
        return f"Cross tip over {'other end' if move.other_segment in ends else 'inner'} segment"
    if move.kind == "R1":
        return f"R1 on {'end' if move.segment in ends else 'inner'} segment"
    return "R2"


def add_run_selection(ap: argparse.ArgumentParser, required: bool = False) -> None:
    """``--db``, and ``--set`` / ``--label`` (repeatable; all when not given, unless ``required``): which
    evaluation runs a bench reads (:func:`finished_runs`, :func:`stored_pairs`)."""
    default = "" if required else "; default all"
    ap.add_argument("--db", required=True, help="store with evaluation results")
    ap.add_argument(
        "--set", action="append", dest="sets", required=required, help=f"problem set (repeatable{default})"
    )
    ap.add_argument(
        "--label",
        action="append",
        dest="labels",
        required=required,
        help=f"result label (repeatable{default})",
    )


def finished_runs(
    store: Any, sets: Sequence[str] | None, labels: Sequence[str] | None
) -> list[tuple[int, str]]:
    """(plan run id, goal key) of the finished evaluation results toward ``sets`` under ``labels`` (all when
    None or empty), in run order."""
    with store.session() as session:
        q = (
            select(EvalResult.plan_run_id, EvalResult.goal_key)
            .join(ProblemSet, ProblemSet.id == EvalResult.set_id)
            .where(EvalResult.status.in_(FINISHED_STATUSES), EvalResult.plan_run_id.is_not(None))
            .order_by(EvalResult.plan_run_id)
        )
        if sets:
            q = q.where(ProblemSet.name.in_(sets))
        if labels:
            q = q.where(EvalResult.planner.in_(labels))
        return [(int(run_id), str(goal_key)) for run_id, goal_key in session.execute(q).all()]


def stored_pairs(
    store: Any,
    sets: Sequence[str] | None,
    labels: Sequence[str] | None,
    on_run: Callable[[SearchRunInfo], None] | None = None,
) -> Iterator[tuple[int, str, StoredNode, PData, Move | None, float, float]]:
    """Every (node, requested next state) pair of the finished evaluation runs toward ``sets`` under
    ``labels`` (all when None or empty), from the runs' ``pair`` statistics: run id, goal key, the node,
    the next state, the move that explains the step (None when no one move does), steps tried and
    reached. Runs made before the pair statistics were kept are skipped. ``on_run``, when given, is
    called with each run (its whole tree loaded) before its pairs are yielded."""
    for run_id, goal_key in finished_runs(store, sets, labels):
        info = load_run(store, run_id)
        if info is None or info.checkpoint is None or "pair" not in info.checkpoint.stats:
            continue  # a run made before the pair statistics were kept
        if on_run is not None:
            on_run(info)
        nodes = {node.seq: node for node in info.nodes}
        for key, (tried, reached) in info.checkpoint.stats["pair"].items():
            seq, next_key = key.split("|", 1)
            node = nodes[int(seq)]
            next_state = parse_p_data(json.loads(next_key))
            yield run_id, goal_key, node, next_state, explains(node.p_data, next_state), tried, reached


# A plan step of a stored search as the benches simulate it: (node, next state, move, goal key)
StepPair = tuple[Node, PData, Move, str]


def step_groups(
    store: Any,
    sets: Sequence[str] | None,
    labels: Sequence[str] | None,
    levels: Sequence[int],
    wanted: Callable[[Move, PData], bool] | None = None,
    on_run: Callable[[SearchRunInfo], None] | None = None,
) -> dict[int, list[StepPair]]:
    """The distinct adding plan steps of :func:`stored_pairs` (one move explains them and it adds
    crossings) whose node has a crossing count in ``levels`` and, when ``wanted`` is given, whose move and
    node's state it accepts, grouped by that count in the order met; the node as the planner's ``Node``."""
    groups: dict[int, list[StepPair]] = defaultdict(list)
    seen = set()
    for run_id, goal_key, stored, nxt, move, _, _ in stored_pairs(store, sets, labels, on_run):
        if move is None or move.remove or stored.p_data.cross not in levels:
            continue
        if wanted is not None and not wanted(move, stored.p_data):
            continue
        if (run_id, stored.seq, nxt.key) in seen:
            continue
        seen.add((run_id, stored.seq, nxt.key))
        node = Node(stored.seq, None, stored.q, stored.points, stored.p_data, None, 0, 0)
        groups[stored.p_data.cross].append((node, nxt, move, goal_key))
    return groups


J = TypeVar("J")
R = TypeVar("R")


def pool_map(fn: Callable[[J], R], jobs: Sequence[J], workers: int) -> list[R]:
    """``fn`` over ``jobs`` in order: in this process when ``workers`` is 1 or less, else in that many
    forkserver processes (as the planner's pool, ``twisted.sim.pool``; ``fn`` must be a module's top-level
    function, and the calling script must start its work under ``if __name__ == "__main__"``)."""
    if workers <= 1:
        return [fn(job) for job in jobs]
    import multiprocessing

    ctx = multiprocessing.get_context("forkserver")
    with ctx.Pool(workers) as pool:
        return pool.map(fn, jobs, chunksize=8)


def step_curves(db: str, model_id: int | None) -> StepCurves:
    """The planner's curve proposer for plan steps, with the stored model ``model_id`` (the shipped one
    when None), on one torch thread: the simulator workers own the cores (as a search's sampler does)."""
    import torch

    from twisted.model.registry import load_model
    from twisted.model.sampler import ModelCurves

    torch.set_num_threads(1)
    if model_id is None:
        model = load_model(None, None)
    else:
        with open_store(db) as store:
            model = load_model(store, model_id)
    return StepCurves(ModelCurves(model), share=PlannerOptions().cross_move)


def planner_curves(
    planner: StepCurves, node: Node, nxt: Any, move: Any, k: int, rng: np.random.Generator
) -> list[Any]:
    """``k`` curves the planner proposes for the step (as many of its K-curve steps as it takes)."""
    own: list[Any] = []
    while len(own) < k:
        own += planner.propose(node, nxt, move, PLANNER_K, rng)[0]
    return own[:k]


def pairs_from(db: str, sets: list[str], labels: list[str], cross: int) -> list[dict[str, Any]]:
    """Every (node, next state) pair the runs tried from states of ``cross`` crossings that one move
    explains, with its node."""
    with open_store(db) as store:
        return [
            {"run": run_id, "node": node, "next": nxt, "move": move, "tried": tried, "reached": reached}
            for run_id, _, node, nxt, move, tried, reached in stored_pairs(store, sets, labels)
            if node.p_data.cross == cross and move is not None
        ]


def choose(pairs: list[dict[str, Any]], n: int, rng: np.random.Generator) -> list[dict[str, Any]]:
    """Up to ``n`` never-reached pairs and ``n`` reached ones, drawn uniformly, in their stored order."""
    chosen = []
    for name, group in (
        ("failed", [p for p in pairs if p["reached"] == 0]),
        ("reached", [p for p in pairs if p["reached"] > 0]),
    ):
        picks = sorted(rng.choice(len(group), size=min(n, len(group)), replace=False)) if group else []
        chosen += [dict(group[int(i)], group=name) for i in picks]
    return chosen


def segment_link(
    rng: np.random.Generator, points: Any, segment: int, bounds: np.ndarray | None = None
) -> int:
    """A whole link inside P-data ``segment`` of the rope with these link points, uniformly drawn (the
    middle link when none is); ``bounds``: ``segment_bounds`` of the points, when known."""
    bounds = segment_bounds(points) if bounds is None else bounds
    lo, hi = bounds[segment], bounds[segment + 1]
    inside = [link for link in range(N_LINKS) if lo + 0.3 < link + 0.5 < hi - 0.3]
    return int(rng.choice(inside)) if inside else int(np.clip((lo + hi) / 2, 0, N_LINKS - 1))
