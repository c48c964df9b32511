"""Catalogue counts: how many enumerated states of each crossing count really tie each named knot (both
closures agree) or are knotoids, the (under, over) classes, the smallest count per knot, how long
identify() takes per state, and (with --db) how often the data visited them.

    python bench/bench_knots.py [--max-crossings 4] [--db sqlite:////tmp/copy.db]
    python bench/bench_knots.py --setup [--plan] [--knots 6_1+ 3_1+#3_1+ ...]

--db opens (and so migrates) the database: point it at a copy, not at data you must keep unchanged.

--setup: the set-up of every knot goal of the table (issue 65, target 1 s each): in a fresh process
per knot, the import of the goals and the KnotInfo table, then ``knot_goal(name)`` (the states cut from
the knot's diagrams; nothing enumerated, nothing cached before). ``--plan`` also runs the first plan of
each knot on a fresh database (``plan --knot K --max-iterations 1 --workers 1``) and prints its
``setup_s`` (database created, model loaded, a simulator worker started, the goal made); a 7-crossing
goal is refused there (the model encodes at most 6 crossings).
"""

from __future__ import annotations

import argparse
import time
from collections import Counter

from twisted.knots import CATALOGUE, RopeKnot, crossing_number, identify, identify_points
from twisted.moves import enumerate_states
from twisted.topology import parse_p_data


def _class(k: RopeKnot) -> str:
    if k.is_knot:
        return f"both {k.name}"
    return "knotoid " + "/".join(sorted((k.under.name, k.over.name)))


_GOAL_SETUP = """
import json, sys, time
t0 = time.perf_counter()
from twisted.goals import knot_goal
t1 = time.perf_counter()
goal = knot_goal(sys.argv[1])
t2 = time.perf_counter()
made = {"import_s": t1 - t0, "goal_s": t2 - t1, "states": len(goal.states), "crossings": goal.crossings}
print(json.dumps(made))
"""


def goal_setup(plan: bool, only: list[str] | None = None) -> None:
    """Set-up of every knot goal of the table, each in a fresh process (see the module docstring)."""
    import json
    import os
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(root)}
    header = f"{'knot':<10} {'crossings':>9} {'states':>6} {'import s':>9} {'goal s':>7}"
    print(header + ("  first plan setup_s (fresh database)" if plan else ""))
    worst = 0.0
    for name in only or CATALOGUE:
        if name == "0_1":
            continue
        command = [sys.executable, "-c", _GOAL_SETUP, name]
        out = subprocess.run(command, env=env, cwd=root, capture_output=True, text=True, check=True)
        made = json.loads(out.stdout)
        worst = max(worst, made["goal_s"])
        row = f"{name:<10} {made['crossings']:>9} {made['states']:>6} {made['import_s']:>9.3f}"
        row += f" {made['goal_s']:>7.3f}"
        if plan:
            with tempfile.TemporaryDirectory() as tmp:
                ran = subprocess.run(
                    [sys.executable, "-m", "cli.main", "--db", f"sqlite:///{tmp}/fresh.db", "plan", "--knot",
                     name, "--max-iterations", "1", "--workers", "1", "--seed", "0", "--json"],
                    env=env, cwd=root, capture_output=True, text=True, check=False,
                )  # fmt: skip
            if ran.returncode == 2:
                row += "  refused: " + " ".join((ran.stdout + ran.stderr).split())[-90:]
            else:
                row += f"  {json.loads(ran.stdout)['setup_s']:.2f}"
        print(row, flush=True)
    print(f"slowest goal: {worst:.3f} s (target 1 s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--max-crossings", type=int, default=4, help="enumerate up to this count (5: ~1 min)")
    parser.add_argument("--db", help="database URL (a copy: opening migrates it)")
    parser.add_argument("--setup", action="store_true", help="time every table knot goal's set-up instead")
    parser.add_argument("--plan", action="store_true", help="with --setup: also a first plan on a fresh db")
    parser.add_argument("--knots", nargs="+", help="with --setup: only these table knots (default: all)")
    args = parser.parse_args()
    if args.setup:
        goal_setup(args.plan, args.knots)
        return

    t0 = time.perf_counter()
    states = enumerate_states(args.max_crossings)
    print(f"enumeration to {args.max_crossings} crossings: {time.perf_counter() - t0:.1f} s")
    names = ["0_1", "3_1+", "3_1-", "4_1", "5_1+", "5_1-", "5_2+", "5_2-", "knotoid", "unknown"]
    by_state: dict[str, str] = {}
    print("knot type per state: the knot when both closures (under and over the table) agree, else knotoid")
    print(f"{'cross':>5} {'states':>7} " + " ".join(f"{n:>7}" for n in names) + "  us/identify")
    classes: dict[int, Counter[str]] = {}
    for c in range(args.max_crossings + 1):
        identify.cache_clear()
        t0 = time.perf_counter()
        knots = [identify(p) for p in states[c]]
        per_state_us = 1e6 * (time.perf_counter() - t0) / max(len(knots), 1)
        types = [k.name for k in knots]
        by_state.update({p.key: t for p, t in zip(states[c], types, strict=True)})
        counts = Counter(types)
        row = " ".join(f"{counts.get(n, 0):>7}" for n in names)
        print(f"{c:>5} {len(types):>7} {row}  {per_state_us:8.0f}")
        classes[c] = Counter(_class(k) for k in knots)
    print("\n(under, over) classes per crossing count (a pair in either order; 'both X': a knot)")
    for c, counter in classes.items():
        print(f"{c:>5}: " + ", ".join(f"{name} {n:,}" for name, n in counter.most_common()))
    print("\nsmallest crossing count at which a state ties each catalogue knot (both closures):")
    for t in CATALOGUE:
        counts_with = [
            c for c in range(args.max_crossings + 1) if any(by_state[p.key] == t for p in states[c])
        ]
        least = counts_with[0] if counts_with else None
        print(f"  {t:<10} crossing number {crossing_number(t)}: " + ("-" if least is None else str(least)))

    if not args.db:
        return
    from sqlalchemy import select

    from twisted.store import Configuration, TopologicalState, blob_to_array, open_store

    with open_store(args.db) as store, store.session() as session:
        rows = session.execute(
            select(
                TopologicalState.key, TopologicalState.cross, TopologicalState.knot_type, Configuration.points
            ).join(Configuration, Configuration.state_id == TopologicalState.id)
        ).all()
    print(f"\ndatabase: {len(rows)} configurations")
    visited: dict[tuple[int, str | None], set[str]] = {}
    configs: Counter[tuple[int, str | None]] = Counter()
    agree = 0
    t0 = time.perf_counter()
    for key, cross, knot_type, points in rows:
        configs[(cross, knot_type)] += 1
        visited.setdefault((cross, knot_type), set()).add(key)
        agree += identify(parse_p_data(key)) == identify_points(blob_to_array(points, (-1, 3)))
    point_us = 1e6 * (time.perf_counter() - t0) / max(len(rows), 1)
    print(
        f"P-data route == link-point route on {agree} of {len(rows)} configurations ({point_us:.0f} us each)"
    )
    print(f"{'cross':>5} {'knot':>8} {'visited states':>15} {'of enumerated':>14} {'configurations':>15}")
    for (cross, knot_type), n in sorted(configs.items(), key=lambda kv: (kv[0][0], str(kv[0][1]))):
        if knot_type == "0_1":
            continue
        enumerated = (
            sum(1 for k, t in by_state.items() if t == knot_type and parse_p_data(k).cross == cross)
            if cross <= args.max_crossings
            else None
        )
        of = "-" if enumerated is None else str(enumerated)
        print(f"{cross:>5} {knot_type:>8} {len(visited[(cross, knot_type)]):>15} {of:>14} {n:>15}")
    totals: Counter[str] = Counter()
    for (_, knot_type), n in configs.items():
        totals[str(knot_type)] += n
    print("configurations per knot type:", dict(totals.most_common()))


if __name__ == "__main__":
    main()
