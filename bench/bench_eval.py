"""Print what an evaluation costs beyond the planners' search time, and the 1-crossing success rate.

Runs `random-low` on the four 1-crossing goals (imported as a set) for a few seeds in a throwaway
database and prints, per (goal, seed), the search time, the wall time of the task process and the
difference (process start, imports, store writes), then the totals.

    python bench/bench_eval.py [--timeout 10] [--seeds 3] [--parallel 2]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from sqlalchemy import select

from twisted.experiments import EvalOptions, import_problem_sets, run_eval
from twisted.moves import enumerate_states
from twisted.store import open_store
from twisted.store.experiments import EvalResult


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--timeout", type=float, default=10.0, help="search time per goal (s)")
    parser.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1 per goal")
    parser.add_argument("--parallel", type=int, default=2, help="goals at once")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        url = f"sqlite:///{Path(tmp) / 'bench.db'}"
        with open_store(url) as store:
            goals = [p.to_list() for p in enumerate_states(1)[1]]
            import_problem_sets(store, json.dumps(goals), "one-crossing")
            t0 = time.perf_counter()
            request = EvalOptions(
                "one-crossing",
                "random-low",
                timeout_s=args.timeout,
                seeds=list(range(args.seeds)),
                parallel=args.parallel,
            )
            summary = run_eval(store, url, request)
            wall = time.perf_counter() - t0
            with store.session() as session:
                rows = session.scalars(select(EvalResult).order_by(EvalResult.id)).all()
    print(f"{'goal':<34} seed status   search_s  wall_s  overhead_s  sim_calls")
    for r in rows:
        print(
            f"{r.goal_key:<34} {r.seed:>4} {r.status:<8} {r.elapsed_s or 0:>8.1f} {r.wall_s or 0:>7.1f} "
            f"{(r.wall_s or 0) - (r.elapsed_s or 0):>11.1f} {r.sim_calls or 0:>10}"
        )
    overhead = np.array([(r.wall_s or 0) - (r.elapsed_s or 0) for r in rows])
    solved = [r for r in rows if r.solved]
    share = len(solved) / max(len(rows), 1)
    median = np.median([r.time_to_solve_s for r in solved]) if solved else float("nan")
    print(
        f"\n{len(rows)} tasks, {len(solved)} solved ({share:.0%}) within {args.timeout:g} s; "
        f"median time to solve {median:.1f} s"
    )
    print(
        f"per-task overhead (process start + imports + store): median {np.median(overhead):.1f} s, "
        f"max {overhead.max():.1f} s; whole eval {wall:.1f} s with --parallel {args.parallel} "
        f"({summary.solved} solved)"
    )


if __name__ == "__main__":
    main()
