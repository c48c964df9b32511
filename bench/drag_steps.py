"""How good is the kinematic drag prediction (twisted.drag)? Tree edges, and plan steps with and without it.

    python bench/drag_steps.py --db sqlite:///tune.db --set tune-u5 --label base50 \
        [--from 2 --from 3 --from 4] [--pairs 60] [--pool 1000] [--k 6] [--workers 2] [--seed 0]

1. Every kept edge of the stored runs' trees (a node, the curve simulated from it, the child it made):
   how often the predicted state is the child's, per crossings of the node; and, among the curves
   predicted to add one crossing, how often the child is the predicted state (the precision that
   matters when the prediction picks curves for a step).
2. ``--pairs`` (node, requested next state) pairs per ``--from`` level, drawn uniformly from the runs'
   ``pair`` statistics (one adding move explains each). For each pair, ``--k`` curves of the planner's
   own (``StepCurves`` with the default options and the shipped model) and up to ``--k`` of a pool of
   ``--pool`` uniform random curves that the prediction says reach the next state (``DragPool``) are
   simulated from the node's configuration. Prints, per level and class of
   move (``bench/step_moves.py``'s classes), the pairs, those with a predicted curve, and the share of
   curves that reached the next state: the planner's over all pairs, and over the pairs with a
   predicted curve, next to the predicted curves'.
"""

from __future__ import annotations

import argparse
from collections import Counter, defaultdict
from typing import Any

import numpy as np
from step_moves import add_run_selection, move_class, step_groups  # bench/ is this script's folder

from twisted.drag import DragPool, predicted_states
from twisted.model.registry import load_model
from twisted.model.sampler import ModelCurves
from twisted.planner.options import PlannerOptions
from twisted.planner.strategies import StepCurves
from twisted.sim.pool import SimPool
from twisted.store import open_store
from twisted.store.search import SearchRunInfo


def count_edges(table: dict[int, Counter[str]], info: SearchRunInfo) -> None:
    """Add the kept curve edges of one run's tree to ``table`` (per parent crossings): edges, the child's
    state predicted right, predicted one crossing on, and of those right."""
    nodes = {n.seq: n for n in info.nodes}
    by_parent: dict[int, list[Any]] = defaultdict(list)
    for n in info.nodes:
        if n.parent_seq is not None and n.curve is not None and n.action == "curve":
            by_parent[n.parent_seq].append(n)
    for seq, children in by_parent.items():
        parent = nodes[seq]
        predicted = predicted_states(parent.points, np.array([c.curve for c in children]))
        row = table[parent.p_data.cross]
        for child, p in zip(children, predicted, strict=True):
            row["edges"] += 1
            row["right"] += p == child.p_data
            if p.cross == parent.p_data.cross + 1:
                row["+1"] += 1
                row["+1 right"] += p == child.p_data


def print_edge_accuracy(table: dict[int, Counter[str]]) -> None:
    print("tree edges: the predicted state against the child's")
    print("| from | edges | predicted right | predicted +1 | of those right |")
    print("| --- | --- | --- | --- | --- |")
    for cross, row in sorted(table.items()):
        print(
            f"| {cross} | {row['edges']} | {row['right'] / row['edges']:.1%} | {row['+1']} | "
            f"{row['+1 right'] / max(row['+1'], 1):.1%} |"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap, required=True)
    ap.add_argument("--from", type=int, action="append", dest="levels", help="crossings of the steps' start")
    ap.add_argument("--pairs", type=int, default=60, help="pairs drawn per level")
    ap.add_argument("--pool", type=int, default=1000, help="random curves per node looked through")
    ap.add_argument("--k", type=int, default=6, help="curves simulated per pair and proposer")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.pairs < 1 or args.pool < 1 or args.k < 1:
        ap.error("--pairs, --pool and --k must be at least 1")
    levels = args.levels or [2, 3, 4]
    rng = np.random.default_rng(args.seed)

    edges: dict[int, Counter[str]] = defaultdict(Counter)
    with open_store(args.db) as store:
        groups = step_groups(
            store, args.sets, args.labels, levels, on_run=lambda info: count_edges(edges, info)
        )
    print_edge_accuracy(edges)

    import torch

    torch.set_num_threads(1)  # the simulator workers own the cores
    options = PlannerOptions()
    planner = StepCurves(ModelCurves(load_model(None, None)), share=options.cross_move)
    jobs, owner = [], []
    found: Counter[tuple[int, str, str]] = Counter()
    for level in levels:
        items = groups[level]
        for i in sorted(rng.choice(len(items), size=min(args.pairs, len(items)), replace=False)):
            node, nxt, move, _ = items[int(i)]
            cls = move_class(move, node.p_data)
            drag = DragPool(node.points, args.pool, rng)
            predicted = [drag.curve(m) for m in drag.reaching(nxt)[: args.k]]
            for key in (cls, "all"):
                found[(level, key, "pairs")] += 1
                found[(level, key, "with")] += bool(predicted)
            own: list[Any] = []
            while len(own) < args.k:
                own += planner.propose(node, nxt, move, options.k, rng)[0]
            for name, curves in (("planner", own[: args.k]), ("predicted", predicted)):
                jobs += [(node.q, c) for c in curves]
                owner += [(level, cls, name, bool(predicted), nxt)] * len(curves)
    rows: dict[tuple[int, str], Counter[str]] = defaultdict(Counter)
    with SimPool(args.workers) as pool:
        for (level, cls, name, with_pred, nxt), result in zip(owner, pool.run(jobs), strict=True):
            hit = bool(result.ok and result.p_data == nxt)
            for group in ((level, cls), (level, "all")):
                rows[group][name] += 1
                rows[group][name + " hit"] += hit
                if with_pred and name == "planner":
                    rows[group]["planner|pred"] += 1
                    rows[group]["planner|pred hit"] += hit
    print(f"\nplan steps: {args.k} curves per pair and proposer, pool {args.pool}, seed {args.seed}")
    print("| from | move | pairs | with a predicted curve | planner's | planner's, same pairs | predicted |")
    print("| --- | --- | --- | --- | --- | --- | --- |")

    def rate(row: Counter[str], name: str) -> str:
        n, h = row[name], row[name + " hit"]
        return f"{h} / {n}" + (f" ({h / n:.1%})" if n else "")

    for (level, cls), row in sorted(rows.items()):
        print(
            f"| {level} | {cls} | {found[(level, cls, 'pairs')]} | {found[(level, cls, 'with')]} | "
            f"{rate(row, 'planner')} | {rate(row, 'planner|pred')} | {rate(row, 'predicted')} |"
        )


if __name__ == "__main__":
    main()
