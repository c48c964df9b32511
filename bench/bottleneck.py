"""Where searches stall: plan-step success per move kind and crossing count; how cramped the goals are.

    python bench/bottleneck.py --db sqlite:///improve.db [--set tune-u4] [--phase tune] [--json out.json]

Reads stored planner runs (every run; ``--set NAME``: those toward a goal of that stored set;
``--phase``: runs of ``twisted improve`` of that phase, ``train`` or ``tune``) and prints

1. the ``follow_plan`` steps per move kind (R1 / R2 / Cross) and crossing count of the state they start
   from: tried, reached the plan's next state, rate (each run's ``pair`` statistics, the move named by
   ``twisted.moves.explains``, as in ``bench/step_moves.py``);
2. the rope the moves take, measured on every node of the runs' trees: the links of the loop of each
   curl (the segment between a crossing's two adjacent visits; ``twisted.proposals.segment_bounds``) and of
   every other inner segment, as percentiles;
3. per goal: its crossings and curls, whether a run reached it, the deepest sub-state of it that a run
   reached, and its demand on the rope (N_LINKS links: 21 unless TWISTED_ROPE says otherwise): curls
   times the curl loop plus the other inner segments times the inner segment, at the 5th percentiles
   (the tightest the searches made them) and at the medians (as they usually make them). A goal
   whose 5th-percentile demand exceeds the rope's links is cramped: there is no room to make it the
   way the searches make curls; one over the rope at the medians needs curls tighter than the
   searches usually make.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from typing import Any

import numpy as np
from sqlalchemy import select

from twisted.moves import explains, sub_states
from twisted.proposals import segment_bounds
from twisted.rope import N_LINKS
from twisted.store import open_store
from twisted.store.experiments import Problem, ProblemSet
from twisted.store.search_tree import SearchRunRow, load_run
from twisted.topology import PData, parse_p_data


def curl_segments(p: PData) -> set[int]:
    """Segments that are a curl's loop: between visits k and k + 1 of one crossing (segment k)."""
    return {min(o, u) for o, u, _ in p.crossings() if abs(o - u) == 1}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--db", required=True)
    ap.add_argument("--set", action="append", dest="sets", help="runs toward this stored set's goals")
    ap.add_argument("--phase", choices=("train", "tune"), help="twisted improve runs of this phase only")
    ap.add_argument("--json", help="write the figures to this file")
    args = ap.parse_args()

    steps: dict[tuple[int, str], list[float]] = defaultdict(lambda: [0.0, 0.0])
    curl_links: list[float] = []
    inner_links: list[float] = []
    goals: dict[str, dict[str, Any]] = {}
    with open_store(args.db) as store:
        with store.session() as session:
            run_ids = list(session.scalars(select(SearchRunRow.run_id).order_by(SearchRunRow.run_id)))
            wanted: set[str] | None = None
            if args.sets:
                wanted = set(
                    session.scalars(
                        select(Problem.goal_key)
                        .join(ProblemSet, ProblemSet.id == Problem.set_id)
                        .where(ProblemSet.name.in_(args.sets))
                    )
                )
        for run_id in run_ids:
            info = load_run(store, run_id)
            if info is None or info.checkpoint is None:
                continue
            if args.phase and info.parameters.get("phase") != args.phase:
                continue
            if wanted is not None and info.goal.spec not in wanted:
                continue
            nodes = {node.seq: node for node in info.nodes}
            for key, (tried, reached) in info.checkpoint.stats.get("pair", {}).items():
                seq, next_key = key.split("|", 1)
                node = nodes.get(int(seq))
                if node is None:
                    continue
                move = explains(node.p_data, parse_p_data(json.loads(next_key)))
                if move is None:
                    continue
                entry = steps[(node.p_data.cross, move.kind)]
                entry[0] += tried
                entry[1] += reached
            for node in info.nodes:
                if node.p_data.cross == 0:
                    continue
                bounds = segment_bounds(node.points)
                if len(bounds) != 2 * node.p_data.cross + 2:
                    continue  # a tie in the projection: the bounds do not match the state
                loops = curl_segments(node.p_data)
                for s in range(1, 2 * node.p_data.cross):  # inner segments
                    (curl_links if s in loops else inner_links).append(float(bounds[s + 1] - bounds[s]))
            goal = info.goal
            g = goals.setdefault(
                goal.spec,
                {"goal": goal, "runs": 0, "solved": 0, "deepest": 0, "calls": 0},
            )
            g["runs"] += 1
            g["solved"] += info.outcome == "solved"
            g["calls"] += info.checkpoint.sim_calls
            subs = set().union(*(sub_states(member) for member in goal.states))
            reached = [n.p_data.cross for n in info.nodes if n.p_data in subs]
            g["deepest"] = max(g["deepest"], max(reached, default=0))

    print("1. follow_plan steps per move kind and crossings of the state they start from")
    print("| from | move | steps | reached | rate |")
    print("| --- | --- | --- | --- | --- |")
    step_rows = []
    for (level, kind), (tried, reached) in sorted(steps.items()):
        rate = reached / tried if tried else 0.0
        print(f"| {level} | {kind} | {int(tried):,} | {int(reached):,} | {rate:.1%} |")
        step_rows.append({"level": level, "move": kind, "steps": tried, "reached": reached})
    print()
    pct = (5, 25, 50, 75)
    curl_p = np.percentile(curl_links, pct) if curl_links else np.full(len(pct), np.nan)
    inner_p = np.percentile(inner_links, pct) if inner_links else np.full(len(pct), np.nan)
    print("2. links per segment on the tree nodes (percentiles 5 / 25 / 50 / 75)")
    print(f"curl loops:           {' / '.join(f'{x:.2f}' for x in curl_p)}  ({len(curl_links):,} loops)")
    print(f"other inner segments: {' / '.join(f'{x:.2f}' for x in inner_p)}  ({len(inner_links):,} segments)")
    print()
    print(
        f"3. goals on a {N_LINKS}-link rope; demand: curls x curl loop + other inner segments x segment, "
        f"at the 5th percentiles ({curl_p[0]:.2f}, {inner_p[0]:.2f}) and the medians ({curl_p[2]:.2f}, "
        f"{inner_p[2]:.2f})"
    )
    print("| goal | crossings | curls | runs | solved | deepest sub-state | calls | demand p5 | demand p50 |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    goal_rows = []
    for spec, g in goals.items():
        goal = g["goal"]
        p = goal.representative
        n_curls = len(curl_segments(p))
        others = 2 * p.cross - 1 - n_curls
        demand = n_curls * curl_p[0] + others * inner_p[0]
        typical = n_curls * curl_p[2] + others * inner_p[2]
        cramped = bool(demand > N_LINKS)
        short = spec if len(spec) <= 40 else f"{spec[:37]}..."
        print(
            f"| {short} | {p.cross} | {n_curls} | {g['runs']} | {g['solved']} | {g['deepest']} "
            f"| {g['calls']:,} | {demand:.1f}{' (cramped)' if cramped else ''} | {typical:.1f}"
            f"{' (over the rope)' if typical > N_LINKS else ''} |"
        )
        goal_rows.append(
            {
                "goal": spec,
                "crossings": p.cross,
                "curls": n_curls,
                "runs": g["runs"],
                "solved": g["solved"],
                "deepest": g["deepest"],
                "calls": g["calls"],
                "demand_links_p5": demand,
                "demand_links_p50": typical,
                "cramped": cramped,
            }
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(
                {
                    "steps": step_rows,
                    "curl_links_percentiles": dict(zip(map(str, pct), curl_p.tolist(), strict=True)),
                    "inner_links_percentiles": dict(zip(map(str, pct), inner_p.tolist(), strict=True)),
                    "goals": goal_rows,
                },
                f,
                indent=1,
            )


if __name__ == "__main__":
    main()
