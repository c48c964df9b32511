"""Benchmark of the high level: enumeration counts and time, BFS plan queries cold and cached.

    python bench/bench_moves.py [--goals 20] [--seed 0] [--limit 100] [--five] [--knot granny]

Prints the number of states reached from the empty rope per crossing count next to the reference's
(4 / 40 / 528 / 7,968), the time to enumerate up to 4 crossings (caches cleared), and the time of a plan
query from the empty rope to random 3- and 4-crossing goals: the BFS alone with cold caches, through
the plan cache in a new temporary SQLite store (miss: BFS + write), and again (hit: read). With
``--knot NAME``, also the BFS toward every state of that knot (a knot goal, as ``plan --knot`` asks)
from random states a search toward it can reach, with the move caches warm as in a search: the first
query (which builds the goals' sub-state union) and the later ones.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from twisted.diagram import diagram
from twisted.knots.states import states_tying
from twisted.moves import _allowed_states, _successors, enumerate_states, plans, plans_to_any, sub_states
from twisted.store import open_store
from twisted.store.plans import cached_plans
from twisted.topology import EMPTY, PData, PDataError

REFERENCE = {1: 4, 2: 40, 3: 528, 4: 7968}


def clear_caches() -> None:
    _successors.cache_clear()
    diagram.cache_clear()
    _allowed_states.cache_clear()


def ms(values: list[float]) -> str:
    return f"median {statistics.median(values) * 1e3:7.2f} ms, max {max(values) * 1e3:7.2f} ms"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--goals", type=int, default=20, help="random goals per crossing count")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--limit", type=int, default=100, help="plan limit of each query")
    parser.add_argument("--five", action="store_true", help="also enumerate up to 5 crossings")
    parser.add_argument("--knot", help="also time plan queries toward this knot's states (e.g. granny)")
    args = parser.parse_args()

    clear_caches()
    t0 = time.perf_counter()
    layers = enumerate_states(4)
    enumerate_s = time.perf_counter() - t0
    print("states reached from the empty rope by moves")
    print("  cross     ours  reference")
    for c in range(1, 5):
        print(f"  {c:5d} {len(layers[c]):8d} {REFERENCE[c]:10d}")
    print(f"enumerate to 4 crossings (cold caches): {enumerate_s:.2f} s")
    if args.five:
        clear_caches()
        t0 = time.perf_counter()
        five = enumerate_states(5)
        print(
            f"enumerate to 5 crossings (cold caches): {time.perf_counter() - t0:.2f} s, {len(five[5])} states"
        )

    rng = np.random.default_rng(args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        store = open_store(f"sqlite:///{Path(tmp) / 'bench.db'}")
        for c in (3, 4):
            picks = rng.choice(len(layers[c]), size=min(args.goals, len(layers[c])), replace=False)
            goals = [layers[c][int(i)] for i in picks]
            bfs, miss, hit, counts, lengths = [], [], [], [], []
            for goal in goals:
                clear_caches()
                t0 = time.perf_counter()
                found = plans(EMPTY, goal, args.limit)
                bfs.append(time.perf_counter() - t0)
                counts.append(len(found))
                lengths.append(found[0].length if found else -1)
                clear_caches()
                t0 = time.perf_counter()
                assert cached_plans(store, EMPTY, goal, args.limit) == found
                miss.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                assert cached_plans(store, EMPTY, goal, args.limit) == found
                hit.append(time.perf_counter() - t0)
            print(f"plan queries [] -> {len(goals)} random {c}-crossing goals (limit {args.limit}):")
            print(
                f"  plans per goal: min {min(counts)}, median {statistics.median(counts)}, max {max(counts)};"
                f" shortest plan length: {sorted(set(lengths))}"
            )
            print(f"  BFS, cold caches:         {ms(bfs)}")
            print(f"  cached_plans, miss:       {ms(miss)}")
            print(f"  cached_plans, hit:        {ms(hit)}")
        store.close()
    if args.knot:
        knot_queries(args.knot, args.goals, args.limit, rng)


def _drawable(p: PData) -> bool:
    try:
        diagram(p)
    except PDataError:
        return False  # a sub-state of a goal need not be a diagram a rope can have
    return True


def knot_queries(name: str, n: int, limit: int, rng: np.random.Generator) -> None:
    """Time ``plans_to_any`` toward every state of knot ``name`` from ``n`` random states on the way."""
    goals = states_tying(name)
    on_the_way = sorted(
        {p for g in goals for p in sub_states(g) if 0 < p.cross < g.cross and _drawable(p)},
        key=lambda p: p.key,
    )
    starts = [
        on_the_way[int(i)] for i in rng.choice(len(on_the_way), size=min(n, len(on_the_way)), replace=False)
    ]
    clear_caches()
    for p in starts:  # the move caches warm, as in a search that has expanded these states before
        plans_to_any(p, goals, limit)
    _allowed_states.cache_clear()
    times = []
    for p in starts:
        t0 = time.perf_counter()
        plans_to_any(p, goals, limit)
        times.append(time.perf_counter() - t0)
    print(
        f"plan queries toward {name} ({len(goals)} states of {goals[0].cross} crossings) from {len(starts)} "
        f"random states on the way (limit {limit}, move caches warm):"
    )
    print(f"  first query:              {times[0] * 1e3:7.2f} ms")
    print(f"  later queries:            {ms(times[1:])}")


if __name__ == "__main__":
    main()
