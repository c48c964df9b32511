"""Untie and retie: searches from the end configurations of stored plans, one core, in this process.

    # 1. tie some ropes into a scratch store (the shipped model; knots pass the pull test)
    python bench/untie.py make --db sqlite:////work/scratch34/bench.db --overhand-seeds 0 1 2 \\
        --states 4 4 5 5 --timeout 300
    # 2. untie every solved run there to the straight rope, per proposer of the removing steps
    python bench/untie.py run --db sqlite:////work/scratch34/bench.db --removal-curves random model \\
        --timeout 120
    # 3. retie: from the end of every solved overhand run to a figure-eight, a few seeds
    python bench/untie.py retie --db sqlite:////work/scratch34/bench.db --knot figure-eight \\
        --seeds 0 1 --timeout 300

``make`` ties the overhand knot (``--knot overhand --tighten``, one run per seed), another knot
(``--knot figure-eight --knot-seeds 0 1``, likewise) and states drawn
at random (seeded) among all states of the given crossing counts (``--states 4 5``: one 4- and one
5-crossing state), each a plan run with the shipped model. ``run`` starts an untie search
(:func:`twisted.planner.run_search` with ``from_run``, goal ``[]``) from every solved run that is
not itself a both-ways search, once per proposer of the removing steps' curves (``random``: uniform
random curves; ``model``: the inverse model conditioned on the removing move), with the planner's
default options otherwise (``--seed``). ``retie`` searches from the end of each solved overhand run
to the knot given. Each search runs with one simulator in this process (one core) and torch on one
thread. Prints one line per search and, per proposer, solved / searched, the median search time and
simulator calls of the solved ones, and all calls; ``--json FILE`` writes the rows.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from typing import Any

import numpy as np
from sqlalchemy import select

from twisted.goals import knot_goal, state_goal
from twisted.moves import enumerate_states
from twisted.planner import PlannerOptions, SearchProgress, SearchRequest, run_search
from twisted.planner.untie import REMOVAL_CURVES
from twisted.store import open_store
from twisted.store.search import SearchRunRow, load_run
from twisted.topology import EMPTY


def _search(store: Any, goal: Any, options: PlannerOptions, timeout: float, **kw: Any) -> Any:
    """One search with the shipped model and one simulator in this process (the search time timed)."""
    started = time.perf_counter()
    request = SearchRequest(
        goal=goal.spec, options=options.to_dict(), workers=1, timeout_s=timeout, timed_setup=False, **kw
    )
    progress = SearchProgress()
    result = run_search(store, request, progress=progress)
    return progress.search, result, time.perf_counter() - started


def make(args: argparse.Namespace) -> None:
    rng = np.random.default_rng(args.draw_seed)
    tied = [("overhand", s) for s in args.overhand_seeds] + [(args.knot, s) for s in args.knot_seeds]
    goals: list[tuple[str, Any, PlannerOptions]] = [
        (f"{knot} seed {s}", knot_goal(knot), PlannerOptions(seed=s, tighten=True)) for knot, s in tied
    ]
    if args.states:
        layers = enumerate_states(max(args.states))
        for i, n in enumerate(args.states):
            state = layers[n][int(rng.integers(len(layers[n])))]
            goals.append((f"{n}-crossing {state.key}", state_goal(state), PlannerOptions(seed=i)))
    with open_store(args.db) as store:
        for label, goal, options in goals:
            search, result, wall = _search(store, goal, options, args.timeout)
            print(
                f"run {result.run_id}: {label}: {result.status}, {result.elapsed_s:.1f} s, "
                f"{result.sim_calls} calls ({wall:.1f} s wall)",
                flush=True,
            )


def _tied_runs(store: Any, knot: str | None = None) -> list[int]:
    """Solved runs that are not both-ways searches (their ends are what gets untied), by id."""
    with store.session() as session:
        ids = session.scalars(select(SearchRunRow.run_id).where(SearchRunRow.outcome == "solved")).all()
    out = []
    for run_id in sorted(ids):
        info = load_run(store, run_id, with_nodes=False)
        if info is None or info.parameters.get("both_ways"):
            continue
        if knot is not None and info.goal.knot != knot:
            continue
        out.append(run_id)
    return out


def _summary(rows: list[dict[str, Any]], key: str) -> None:
    for value in sorted({r[key] for r in rows}):
        group = [r for r in rows if r[key] == value]
        solved = [r for r in group if r["solved"]]
        med_t = statistics.median(r["search_s"] for r in solved) if solved else float("nan")
        med_c = statistics.median(r["sim_calls"] for r in solved) if solved else float("nan")
        print(
            f"{key} {value}: solved {len(solved)}/{len(group)}, median search time {med_t:.1f} s, "
            f"median calls {med_c:g} (solved), calls all {sum(r['sim_calls'] for r in group)}",
            flush=True,
        )


def untie(args: argparse.Namespace) -> list[dict[str, Any]]:
    rows = []
    with open_store(args.db) as store:
        runs = args.runs or _tied_runs(store)
        for run_id in runs:
            start = load_run(store, run_id, with_nodes=False)
            assert start is not None
            for proposer in args.removal_curves:
                options = PlannerOptions(seed=args.seed)
                search, result, wall = _search(
                    store, state_goal(EMPTY), options, args.timeout, from_run=run_id, removal_curves=proposer
                )
                row = _row(run_id, start.goal.spec, search, result, wall, proposer=proposer)
                rows.append(row)
                print(json.dumps(row), flush=True)
    _summary(rows, "proposer")
    return rows


def retie(args: argparse.Namespace) -> list[dict[str, Any]]:
    rows = []
    goal = knot_goal(args.knot)
    with open_store(args.db) as store:
        for run_id in args.runs or _tied_runs(store, knot=args.from_knot):
            for seed in args.seeds:
                options = PlannerOptions(seed=seed, tighten=args.tighten, cinch=not args.no_cinch)
                search, result, wall = _search(
                    store, goal, options, args.timeout, from_run=run_id, removal_curves=args.removal_curves[0]
                )
                row = _row(run_id, args.from_knot or "", search, result, wall, seed=seed, cinch=options.cinch)
                rows.append(row)
                print(json.dumps(row), flush=True)
    _summary(rows, "goal")
    return rows


def _row(run_id: int, start_goal: str, search: Any, result: Any, wall: float, **extra: Any) -> dict[str, Any]:
    return {
        "from_run": run_id,
        "from_goal": start_goal,
        "start_cross": search.tree.nodes[0].p_data.cross,
        "goal": search.goal.spec,
        **extra,
        "run_id": result.run_id,
        "solved": result.solved,
        "search_s": round(result.elapsed_s, 2),
        "wall_s": round(wall, 2),
        "sim_calls": result.sim_calls,
        "iterations": result.iterations,
        "steps_by_move": {k: list(v) for k, v in result.steps_by_move().items()},
        "calls_by_source": result.calls_by_source(),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    m = sub.add_parser("make", help="tie ropes into the store")
    m.add_argument("--overhand-seeds", type=int, nargs="*", default=[0, 1])
    m.add_argument("--knot", default="figure-eight", help="another knot to tie (with --knot-seeds)")
    m.add_argument("--knot-seeds", type=int, nargs="*", default=[])
    m.add_argument("--states", type=int, nargs="*", default=[], help="crossing counts of drawn states")
    m.add_argument("--draw-seed", type=int, default=0)
    for name in ("run", "retie"):
        p = sub.add_parser(name)
        p.add_argument("--runs", type=int, nargs="*", help="the solved runs to start from (default: all)")
        p.add_argument("--removal-curves", nargs="+", choices=REMOVAL_CURVES, default=["random"])
        p.add_argument("--json", help="write the rows to this file")
    sub.choices["run"].add_argument("--seed", type=int, default=0)
    sub.choices["retie"].add_argument("--knot", default="figure-eight")
    sub.choices["retie"].add_argument("--from-knot", default="overhand")
    sub.choices["retie"].add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    sub.choices["retie"].add_argument("--tighten", action="store_true")
    sub.choices["retie"].add_argument(
        "--no-cinch", action="store_true", help="the planner's --no-cinch (toward a granny or a square)"
    )
    for p in sub.choices.values():
        p.add_argument("--db", required=True)
        p.add_argument("--timeout", type=float, default=120.0, help="seconds per search")
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    if args.command == "make":
        make(args)
        return
    rows = untie(args) if args.command == "run" else retie(args)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
