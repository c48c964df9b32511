"""Where a planner's simulator calls go, from the evaluation runs in a store.

    python bench/search_calls.py --db sqlite:///collect.db [--set u17-4 --set u17-5] [--label twisted]

For every finished evaluation result (grouped by set, label and seed) it reads the plan run's last
checkpoint: the simulator calls per source of curves (follow_plan: the sampler following a
high-level plan; random_expand: the random curves of RandomExpand; low_level_only: the baseline)
with the results kept in T, and per move kind how many follow_plan steps were tried and how many
reached the plan's next state (K curves per step), and the share of steps that retried a (node,
next state) pair tried before (what the planner's retry weight holds down), and for the steps
toward a Cross move how many curves each proposer made and how many reached the plan's next state
(`script`: ``--cross-move``'s scripted curves, `model`: the sampler's). Runs made before these
counts were kept show only their totals. Prints one table; --json writes the figures.
"""

from __future__ import annotations

import argparse
import json
import statistics
from collections import defaultdict
from typing import Any

from lib.steps import add_run_selection
from sqlalchemy import select

from twisted.experiments.report import load_results
from twisted.store import open_store
from twisted.store.experiments import EvalResult, ProblemSet
from twisted.store.search_tree import SearchCheckpoint


def _add(into: dict[str, list[float]], table: dict[str, list[float]]) -> None:
    for key, (first, second) in table.items():
        entry = into.setdefault(key, [0.0, 0.0])
        entry[0] += first
        entry[1] += second


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap)
    ap.add_argument("--json", help="write the figures to this file")
    args = ap.parse_args()

    store = open_store(args.db)

    def group() -> dict[str, Any]:
        return {
            "runs": 0,
            "counted": 0,
            "solved": 0,
            "calls": 0,
            "to_solve": [],
            "calls_by": {},
            "moves": {},
            "cross": {},
            "pairs": None,
        }

    groups: dict[tuple[str, str, int], dict[str, Any]] = defaultdict(group)
    with store.session() as session:
        to_solve = {
            (r.set_name, r.planner, r.goal_key, r.seed): r.sim_calls_to_solve
            for r in load_results(session, args.sets)
        }
        q = (
            select(EvalResult, ProblemSet.name, SearchCheckpoint.stats)
            .join(ProblemSet, ProblemSet.id == EvalResult.set_id)
            .outerjoin(SearchCheckpoint, SearchCheckpoint.run_id == EvalResult.plan_run_id)
            .where(EvalResult.status.in_(("solved", "timeout")))
            .order_by(ProblemSet.name, EvalResult.planner, EvalResult.seed)
        )
        if args.sets:
            q = q.where(ProblemSet.name.in_(args.sets))
        if args.labels:
            q = q.where(EvalResult.planner.in_(args.labels))
        for result, set_name, stats in session.execute(q):
            g = groups[(set_name, result.planner, result.seed)]
            g["runs"] += 1
            g["calls"] += result.sim_calls or 0
            if result.solved:
                g["solved"] += 1
                calls = to_solve.get((set_name, result.planner, result.goal_key, result.seed))
                if calls is not None:
                    g["to_solve"].append(calls)
            stats = stats or {}
            if "calls" in stats:
                g["counted"] += 1
                _add(g["calls_by"], stats["calls"])
                _add(g["moves"], stats.get("move", {}))
                _add(g["cross"], stats.get("cross", {}))
            if "pair" in stats:
                tries = [entry[0] for entry in stats["pair"].values()]
                steps, retries = g["pairs"] or (0.0, 0.0)
                g["pairs"] = (steps + sum(tries), retries + sum(max(n - 1.0, 0.0) for n in tries))

    header = (
        f"{'set':8} {'label':22} {'seed':>4} {'solved':>7} {'calls/solved':>12} {'calls':>8} "
        f"{'follow':>7} {'expand':>7} {'kept f/e':>9} {'retried':>7}  steps reached/tried per move kind"
    )
    print(header)
    figures = []
    for (set_name, label, seed), g in sorted(groups.items()):
        mean_to_solve = statistics.mean(g["to_solve"]) if g["to_solve"] else float("nan")
        by = g["calls_by"]
        counted = g["counted"] == g["runs"]
        follow, expand = by.get("follow_plan", [0.0, 0.0]), by.get("random_expand", [0.0, 0.0])
        total = follow[0] + expand[0] + by.get("low_level_only", [0.0, 0.0])[0]
        share = (
            f"{follow[0] / total:7.0%} {expand[0] / total:7.0%} "
            f"{follow[1] / max(follow[0], 1):4.0%}/{expand[1] / max(expand[0], 1):<4.0%}"
            if counted and total
            else f"{'-':>7} {'-':>7} {'-':>9}"
        )
        pairs = g["pairs"] if counted else None
        retried = f"{pairs[1] / pairs[0]:7.0%}" if pairs and pairs[0] else f"{'-':>7}"
        moves = "  ".join(
            f"{kind} {int(reached)}/{int(tried)} ({reached / tried:.0%})"
            for kind, (tried, reached) in sorted(g["moves"].items())
            if tried
        )
        cross = "  ".join(
            f"{name} {int(reached)}/{int(tried)} ({reached / tried:.1%})"
            for key, name in (("cross_move", "script"), ("sampler", "model"))
            for tried, reached in [g["cross"].get(key, (0.0, 0.0))]
            if tried
        )
        if cross:
            moves += f"  | Cross curves: {cross}"
        print(
            f"{set_name:8} {label:22} {seed:>4} {g['solved']:>3}/{g['runs']:<3} {mean_to_solve:>12,.0f} "
            f"{g['calls']:>8,} {share} {retried}  {moves if counted else '(run before the counts were kept)'}"
        )
        figures.append(
            {
                "set": set_name,
                "label": label,
                "seed": seed,
                "runs": g["runs"],
                "solved": g["solved"],
                "calls_per_solved": mean_to_solve if g["to_solve"] else None,
                "calls": g["calls"],
                "calls_by_source": by if counted else None,
                "steps_by_move": g["moves"] if counted else None,
                "cross_curves": g["cross"] if counted else None,
                "retried_step_share": pairs[1] / pairs[0] if pairs and pairs[0] else None,
            }
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(figures, f, indent=1)


if __name__ == "__main__":
    main()
