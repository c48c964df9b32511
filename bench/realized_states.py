"""Which states the rope reaches: the distinct states in stored search trees, by crossings and curls,
against every state there is.

    python bench/realized_states.py --db sqlite:///tune.db [--set tune-u5] [--label L] [--max-cross 5]

A search keeps every result with no fewer crossings than its parent and no more than its goal (DESIGN 8),
so its tree holds the states its curves happened to make on the way, most of them no step of a plan
asked for. Over the finished evaluation runs toward ``--set`` under ``--label`` (all when not given),
this prints per crossing count and number of curls (crossings whose two visits are neighbours along
the rope: ``bench/bottleneck.py``'s ``curl_segments``) how many distinct states the trees hold, how many
states ``twisted.moves.enumerate_states`` finds (the uniform goal sets are drawn from these; 5 crossings
take about half a minute), and the share; then per goal curl count the runs and the solved runs, and
the last step of each answer (the crossings it started from, and its move). Where the share falls with
every curl, the rope makes states with many curls seldom, whatever the search asks for.

Last, per goal (in the order of their first run; a knot goal by its representative state), the nodes
its own trees hold in its sub-states of one and two crossings fewer, against those the trees of the
other goals' runs hold (and the distinct planar sub-states of one fewer): what a search could start
from if it began with the configurations of earlier searches toward other goals.
"""

from __future__ import annotations

import argparse
from collections import Counter

from bottleneck import curl_segments  # bench/ is this script's folder
from step_moves import add_run_selection, finished_runs

from twisted.diagram import drawable
from twisted.moves import enumerate_states, explains, sub_states
from twisted.store import open_store
from twisted.store.search import load_run
from twisted.topology import PData


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap)
    ap.add_argument("--max-cross", type=int, default=5, help="enumerate the states up to this many crossings")
    args = ap.parse_args()
    if not 1 <= args.max_cross <= 5:
        ap.error("--max-cross must lie in [1, 5] (6 crossings do not fit in memory)")

    realized: set[PData] = set()
    goals: Counter[tuple[int, str]] = Counter()
    last: Counter[tuple[int, str]] = Counter()  # the answers' last steps: crossings of the start, move
    held: dict[PData, Counter[PData]] = {}  # per goal: its runs' nodes per state
    with open_store(args.db) as store:
        run_ids = [run_id for run_id, _ in finished_runs(store, args.sets, args.labels)]
        for run_id in run_ids:
            info = load_run(store, run_id)
            if info is None:
                continue
            realized.update(node.p_data for node in info.nodes)
            held.setdefault(info.goal.representative, Counter()).update(node.p_data for node in info.nodes)
            curls = len(curl_segments(info.goal.representative))
            goals[(curls, "runs")] += 1
            goals[(curls, "solved")] += info.outcome == "solved"
            end = next((node for node in info.nodes if node.id == info.goal_node_id), None)
            if end is not None and end.parent_seq is not None:
                parent = next(node for node in info.nodes if node.seq == end.parent_seq)
                move = explains(parent.p_data, end.p_data)
                last[(parent.p_data.cross, move.kind if move is not None else "no one move")] += 1
    print(f"{len(run_ids)} runs, {len(realized):,} distinct states in their trees")
    print("| crossings | curls | states | in the trees | share |")
    print("| --- | --- | --- | --- | --- |")
    every = enumerate_states(args.max_cross)
    for cross in range(1, args.max_cross + 1):
        there = Counter(len(curl_segments(p)) for p in every[cross])
        made = Counter(len(curl_segments(p)) for p in realized if p.cross == cross)
        for curls in sorted(there):
            share = made[curls] / there[curls]
            print(f"| {cross} | {curls} | {there[curls]:,} | {made[curls]:,} | {share:.2%} |")
    print("\n| goal's curls | runs | solved |")
    print("| --- | --- | --- |")
    for curls in sorted({c for c, _ in goals}):
        print(f"| {curls} | {goals[(curls, 'runs')]} | {goals[(curls, 'solved')]} |")
    print(
        "\nthe answers' last steps: "
        + ", ".join(f"{n} from {c} crossings by {k}" for (c, k), n in sorted(last.items()))
    )
    print(
        "\n| goal | curls | own nodes at c-2 / c-1 | other goals' nodes at c-2 / c-1 "
        "| sub-states at c-1: own / others' / all |"
    )
    print("| --- | --- | --- | --- | --- |")
    for number, goal in enumerate(held):
        near = (p for p in sub_states(goal) if goal.cross - 2 <= p.cross < goal.cross)
        subs = {p: p.cross for p in near if drawable(p)}
        own, others = [0, 0], [0, 0]
        own_states, other_states = set(), set()
        for other, counts in held.items():
            for p, n in counts.items():
                if p in subs:
                    level = subs[p] - goal.cross + 2  # 0: two fewer, 1: one fewer
                    (own if other == goal else others)[level] += n
                    if level == 1:
                        (own_states if other == goal else other_states).add(p)
        n_subs = sum(c == goal.cross - 1 for c in subs.values())
        print(
            f"| {number} | {len(curl_segments(goal))} | {own[0]:,} / {own[1]:,} "
            f"| {others[0]:,} / {others[1]:,} "
            f"| {len(own_states)} / {len(other_states)} / {n_subs} |"
        )


if __name__ == "__main__":
    main()
