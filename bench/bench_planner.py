"""Run the planner on a set of goals with a timeout; print per goal solved / time / simulator calls; medians.

    python bench/bench_planner.py --db sqlite:///twisted.db --problem-set easy3 --timeout 1800
    python bench/bench_planner.py --goal '[[1,"O",2,"+"],[2,"U",1,"+"]]' --goal '...' --planner random-low
    python bench/bench_planner.py --goals-file goals.txt      # one P-data JSON per line (or one JSON list)

Each goal is a fresh planner run in the given database (``runs.kind = 'plan'``, its tree in
``search_nodes``), one after the other, each with ``--workers`` simulator processes. "time" is the
search time at which the goal entered the tree; an unsolved goal counts as slower than any solved
one in the median (printed as ">timeout" when the median falls on one).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path
from typing import Any

from twisted.goals import check_goal
from twisted.planner import HEURISTICS, PLANNERS, SearchRequest, curve_sampler, run_search
from twisted.store import open_store
from twisted.topology import PData


def _goals(args: argparse.Namespace, store: Any) -> list[tuple[str, PData]]:
    goals: list[tuple[str, PData]] = []
    for text in args.goal or []:
        goals.append(("cli", check_goal(text)))
    if args.goals_file:
        text = Path(args.goals_file).read_text()
        try:
            data = json.loads(text)
            # a list of goals, or a single goal (a list of visits)
            many = bool(data) and isinstance(data[0], list) and bool(data[0]) and isinstance(data[0][0], list)
            entries = data if many else [data]
        except json.JSONDecodeError:
            entries = [line for line in text.splitlines() if line.strip() and not line.startswith("#")]
        goals.extend(("file", check_goal(e)) for e in entries)
    if args.problem_set:
        from twisted.store.experiments import load_problem_set

        with store.session() as session:
            record = load_problem_set(session, args.problem_set)
        if record is None:
            sys.exit(f"error: no problem set {args.problem_set!r} in {args.db}")
        goals.extend((f"{record.name}#{p.idx}", check_goal(p.p_data)) for p in record.problems)
    if args.limit:
        goals = goals[: args.limit]
    if not goals:
        sys.exit("error: give --goal, --goals-file or --problem-set")
    return goals


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--db", default="sqlite:///twisted.db")
    parser.add_argument("--goal", action="append", help="P-data JSON (repeatable)")
    parser.add_argument("--goals-file")
    parser.add_argument("--problem-set", help="name of a stored problem set (twisted eval)")
    parser.add_argument("--limit", type=int, default=0, help="only the first N goals")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds of search per goal")
    parser.add_argument("--planner", choices=PLANNERS, default="twisted")
    parser.add_argument("--heuristic", choices=HEURISTICS, default="crs")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--model", type=int, default=None)
    args = parser.parse_args()

    store = open_store(args.db)
    goals = _goals(args, store)
    sampler, model_id = curve_sampler(store, args.planner, args.model)
    print(
        f"# planner={args.planner} heuristic={args.heuristic} timeout={args.timeout:.0f}s "
        f"workers={args.workers} seed={args.seed} model={model_id if model_id is not None else '-'} "
        f"goals={len(goals)} db={args.db}"
    )
    print(
        f"{'goal':<12} {'x':>2} {'run':>5} {'solved':>6} {'time_s':>8} {'sims':>7} {'iters':>6} "
        f"{'nodes':>6} {'wall_s':>7}  p_data"
    )
    rows = []
    options = {"planner": args.planner, "heuristic": args.heuristic, "seed": args.seed}
    for label, goal in goals:
        t0 = time.perf_counter()
        request = SearchRequest(
            goal=goal.key, options=options, model_id=model_id, workers=args.workers, timeout_s=args.timeout,
            timed_setup=False,  # the search time alone, as before the set-up was timed
        )  # fmt: skip
        result = run_search(store, request)
        wall_s = time.perf_counter() - t0
        solve_s = result.path[-1].created_s if result.solved else math.inf
        sims = result.path[-1].sim_call if result.solved else result.sim_calls
        rows.append((result.solved, solve_s, sims))
        shown = f"{solve_s:8.1f}" if result.solved else f"{'>' + format(args.timeout, '.0f'):>8}"
        print(
            f"{label:<12} {goal.cross:>2} {result.run_id:>5} {'yes' if result.solved else 'no':>6} "
            f"{shown} {sims:>7} {result.iterations:>6} {result.nodes:>6} {wall_s:7.1f}  {goal.key}",
            flush=True,
        )
    solved = sum(r[0] for r in rows)
    median_s = statistics.median(r[1] for r in rows)
    median_sims = statistics.median(r[2] if r[0] else math.inf for r in rows)
    median_text = f"{median_s:.1f} s" if math.isfinite(median_s) else f">{args.timeout:.0f} s"
    sims_text = f"{median_sims:.0f}" if math.isfinite(median_sims) else "-"
    print(f"# solved {solved}/{len(rows)}  median time {median_text}  median simulator calls {sims_text}")


if __name__ == "__main__":
    main()
