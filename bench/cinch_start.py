"""Why the planner cinches: searches for a granny started from a loose overhand and from the same overhand
cinched (pulled tight, let go, settled: twisted.tighten.cinch).

    python bench/cinch_start.py --dir /tmp/cinch [--overhands 0-7] [--timeout 240] [--seed 0] [--model FILE]

1. For each seed of --overhands, `twisted plan --knot overhand --workers 1` from the straight rope (one
   database, DIR/overhands.db); the rope each solved run ends in is a loose overhand.
2. Each of those ropes is cinched; a rope whose knot comes undone or changes is skipped (it is listed).
3. Both ropes of each pair become configurations of DIR/granny.db, and
   `twisted plan --knot granny --tighten --start-config ID --no-cinch --workers 1 --seed S --timeout T`
   runs from each, two searches at a time (one core each; the pairs alternate loose / cinched, so both
   see the same load). --no-cinch: the search itself cinches nothing, so the two starts differ only in
   the rope they start from. With --model FILE the granny searches use that model (`twisted models
   --import FILE` into DIR/granny.db), the overhands the shipped one, so models compare on the same ropes.

Prints per pair the overhand's knot, the ends' distance before and after the cinch, and each search's
outcome, search time and simulator calls; then the medians. Deterministic given the seeds, but a
search's wall time depends on the machine and its load: compare calls first.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np


def _cli(db: Path, *args: str) -> dict[str, Any]:
    """``twisted --db sqlite:///DB ARGS --json`` in a child process; its JSON (exit 0 or 3: not solved)."""
    cmd = [sys.executable, "-m", "cli.main", "--db", f"sqlite:///{db}", *args, "--json"]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode not in (0, 3):
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr[-2000:]}")
    out = done.stdout
    return dict(json.loads(out[out.index("{") : out.rindex("}") + 1]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dir", required=True, type=Path, help="folder for the two databases (made if absent)")
    ap.add_argument("--overhands", default="0-7", help="overhand seeds, as --seeds: 0-7, '0 3 5'")
    ap.add_argument("--timeout", type=float, default=240.0, help="search time limit of each granny search")
    ap.add_argument("--seed", type=int, default=0, help="seed of the granny searches")
    ap.add_argument("--model", type=Path, help="model file of the granny searches (default: the shipped one)")
    args = ap.parse_args()

    from cli.options import parse_seeds
    from twisted.knots import identify
    from twisted.store import open_store
    from twisted.store.queries import add_configuration
    from twisted.store.search_tree import solved_run
    from twisted.tighten import cinch, tightening_sim
    from twisted.topology import top

    args.dir.mkdir(parents=True, exist_ok=True)
    overhands, granny = args.dir / "overhands.db", args.dir / "granny.db"
    for path in (overhands, granny):
        for suffix in ("", "-wal", "-shm"):
            Path(f"{path}{suffix}").unlink(missing_ok=True)

    if args.model is not None:
        cmd = [
            sys.executable,
            "-m",
            "cli.main",
            "--db",
            f"sqlite:///{granny}",
            "models",
            "--import",
            str(args.model),
        ]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr[-2000:]}")
        print(done.stdout.strip())

    ropes = []
    for seed in parse_seeds(args.overhands):
        result = _cli(
            overhands, "plan", "--knot", "overhand", "--workers", "1", "--seed", str(seed), "--timeout", "120"
        )
        if not result["solved"]:
            print(f"overhand seed {seed}: not solved, skipped")
            continue
        with open_store(f"sqlite:///{overhands}") as store:
            end = solved_run(store, result["run_id"])[1][-1]  # the goal node: a loose overhand
        ropes.append((seed, end.q, end.points))

    def apart(points: np.ndarray) -> float:
        return float(np.linalg.norm(points[-1, :2] - points[0, :2]))

    sim = tightening_sim()
    pairs = []
    with open_store(f"sqlite:///{granny}") as store, store.session(write=True) as session:
        for seed, q, points in ropes:
            knot = identify(top(points)).name
            done = cinch(sim, q)
            if not done.ok or done.p_data is None or identify(done.p_data).name != knot:
                after = done.reason if not done.ok else identify(done.p_data).name if done.p_data else "?"
                print(f"overhand seed {seed}: {knot}, cinched: {after}; skipped")
                continue
            loose = add_configuration(session, run_id=None, p_data=top(points), q=q, points=points).id
            tight = add_configuration(
                session, run_id=None, p_data=done.p_data, q=done.state, points=done.points
            )
            pairs.append((seed, knot, apart(points), apart(done.points), loose, tight.id))

    def search(config_id: int) -> dict[str, Any]:
        return _cli(
            granny,
            "plan",
            "--knot",
            "granny",
            "--tighten",
            "--no-cinch",
            "--start-config",
            str(config_id),
            "--workers",
            "1",
            "--seed",
            str(args.seed),
            "--timeout",
            str(args.timeout),
        )

    order = [config for pair in pairs for config in pair[4:]]
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = dict(zip(order, pool.map(search, order), strict=True))

    def cell(r: dict[str, Any]) -> str:
        return (
            f"{'solved' if r['solved'] else r['outcome']:>8} {r['search_time_s']:7.1f} s {r['sim_calls']:6,}"
        )

    print(f"{'seed':>4} {'knot':6} {'apart':>13} | {'loose start':>26} | {'cinched start':>26}")
    for seed, knot, before, after, loose, tight in pairs:
        ends = f"{before:.2f}->{after:.2f} m"
        print(f"{seed:>4} {knot:6} {ends:>13} | {cell(results[loose])} | {cell(results[tight])}")
    for name, column in (("loose", 4), ("cinched", 5)):
        rs = [results[pair[column]] for pair in pairs]
        solved = [r for r in rs if r["solved"]]
        times = [r["search_time_s"] if r["solved"] else float("inf") for r in rs]
        print(
            f"{name}: solved {len(solved)} / {len(rs)}, median search time {statistics.median(times):.1f} s, "
            f"median calls {statistics.median(r['sim_calls'] for r in rs):,.0f}"
        )


if __name__ == "__main__":
    main()
