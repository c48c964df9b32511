"""Can the model jump two crossings straight to the goal? Curves toward the goal against the plan's step.

    python bench/jump_steps.py --db sqlite:///tune.db --set tune-u5 [--label L] [--per-run 40] [--k 6]
        [--workers 2] [--seed 0] [--model-id N]

Curves from a state of ``Cross(goal) - 2`` crossings often add two crossings at once (a +2 result), and
the inverse model is trained on such transitions too (``twisted.model.encoding.new_visits`` encodes up
to two new crossings, the move is then unknown). So instead of the two plan steps that remain, a search
could ask the model for the goal itself. This draws, from every stored run toward a goal of ``--set``,
up to ``--per-run`` tree nodes of ``Cross(goal) - 2`` crossings whose state has a two-move plan to the
goal, and simulates from each ``--k`` model curves conditioned on the goal (no move: a jump) and ``--k``
conditioned on the first step of one of those plans (what the planner asks now). Prints the curves and
nodes that reached the goal, those that reached the plan's next state, and where the curves of each
kind landed (crossing counts; -1: the simulator rejected the curve).
"""

from __future__ import annotations

import argparse
import time
from collections import Counter

import numpy as np
from sqlalchemy import select

from twisted.model.registry import load_model
from twisted.moves import parse_state, plans
from twisted.sim.pool import SimPool
from twisted.store import open_store
from twisted.store.experiments import EvalResult, Problem, ProblemSet
from twisted.store.models import TopologicalState, blob_to_array
from twisted.store.search import SearchNode
from twisted.topology import parse_p_data


def _items(store, set_name: str, label: str | None, per_run: int, rng: np.random.Generator) -> list[tuple]:
    """(q, points, state, goal, plan) of up to ``per_run`` nodes a run, two plan moves below its goal."""
    items = []
    with store.session() as session:
        query = (
            select(EvalResult.plan_run_id, Problem.p_data, Problem.cross)
            .join(Problem, Problem.id == EvalResult.problem_id)
            .join(ProblemSet, ProblemSet.id == Problem.set_id)
            .where(ProblemSet.name == set_name, EvalResult.plan_run_id.is_not(None))
            .order_by(EvalResult.id)
        )
        if label is not None:
            query = query.where(EvalResult.planner == label)
        runs = session.execute(query).all()
        if not runs:
            raise SystemExit(f"no stored runs toward set {set_name!r} (label {label}) in this database")
        for run_id, goal_data, goal_cross in runs:
            goal = parse_state(goal_data)
            rows = session.execute(
                select(SearchNode.id, SearchNode.state_id)
                .where(SearchNode.run_id == run_id, SearchNode.cross == goal_cross - 2)
                .order_by(SearchNode.id)
            ).all()
            two_moves: dict[int, tuple] = {}
            for _, state_id in rows:
                if state_id not in two_moves:
                    p = parse_p_data(session.get_one(TopologicalState, state_id).p_data)
                    two_moves[state_id] = (p, [pl for pl in plans(p, goal, 100) if len(pl.moves) == 2])
            good = [(node_id, state_id) for node_id, state_id in rows if two_moves[state_id][1]]
            print(
                f"run {run_id}: {len(rows)} nodes of {goal_cross - 2} crossings, {len(good)} with a two-move "
                f"plan to the goal ({sum(1 for v in two_moves.values() if v[1])} of {len(two_moves)} states)"
            )
            if not good:
                continue
            for i in sorted(rng.choice(len(good), min(per_run, len(good)), replace=False)):
                node_id, state_id = good[int(i)]
                node = session.get_one(SearchNode, node_id)
                p, two = two_moves[state_id]
                plan = two[int(rng.integers(len(two)))]
                q, points = blob_to_array(node.q), blob_to_array(node.points, (-1, 3))
                items.append((q, points, p, goal, plan))
    return items


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--db", required=True, help="store with planner runs of --set (twisted eval)")
    ap.add_argument("--set", required=True, help="problem set whose runs' trees are read")
    ap.add_argument("--label", default=None, help="only the runs of this eval label (default: all)")
    ap.add_argument("--per-run", type=int, default=40)
    ap.add_argument("--k", type=int, default=6, help="curves of each kind per node")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--model-id", type=int, default=None, help="model in the store (default: shipped)")
    args = ap.parse_args()
    store = open_store(args.db)
    rng = np.random.default_rng(args.seed)
    model = load_model(store if args.model_id is not None else None, args.model_id)
    items = _items(store, args.set, args.label, args.per_run, rng)
    k = args.k
    jobs = []
    for q, points, p, goal, plan in items:
        jobs += [(q, c) for c in model.sample(points, q, goal, k, rng, p_data=p, move=None)]
        step = model.sample(points, q, plan.states[1], k, rng, p_data=p, move=plan.moves[0])
        jobs += [(q, c) for c in step]
    t0 = time.perf_counter()
    with SimPool(args.workers) as pool:
        results = pool.run(jobs)
    wall = time.perf_counter() - t0
    jump_curves = jump_nodes = step_curves = step_nodes = 0
    landed: dict[str, Counter[int]] = {"jump": Counter(), "step": Counter()}
    for i, (_, _, _, goal, plan) in enumerate(items):
        block = results[2 * k * i : 2 * k * (i + 1)]
        jump = [r.ok and r.p_data == goal for r in block[:k]]
        step = [r.ok and r.p_data == plan.states[1] for r in block[k:]]
        jump_curves, jump_nodes = jump_curves + sum(jump), jump_nodes + any(jump)
        step_curves, step_nodes = step_curves + sum(step), step_nodes + any(step)
        for name, part in (("jump", block[:k]), ("step", block[k:])):
            landed[name].update(r.p_data.cross if r.ok else -1 for r in part)
    n = len(items)
    print(f"{n} nodes, {len(jobs)} simulations in {wall:.0f} s on {args.workers} workers")
    print(f"conditioned on the goal (jump): {jump_curves} / {n * k} curves, {jump_nodes} / {n} nodes reached")
    print(
        f"conditioned on the plan's step: {step_curves} / {n * k} curves, {step_nodes} / {n} nodes reached "
        "its next state"
    )
    for name, counts in landed.items():
        where = ", ".join(f"{c}: {m}" for c, m in sorted(counts.items()))
        print(f"{name} curves landed at crossings: {where}")


if __name__ == "__main__":
    main()
