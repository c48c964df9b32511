"""The overhead of Ray: kept transitions per hour, `collect --ray` against the plain multiprocess collector.

    python bench/bench_ray.py --seconds 120 [--workers 2] [--seed 0] [--postgres] [--order mp,ray]

Each collector runs for the same time, with the same seed and number of workers, into its own fresh
SQLite file (the straight rope as the only start, so every run climbs the same D_Q from scratch):

- ``multiprocess``: ``twisted.collect.collect`` (worker processes, the main process commits);
- ``ray``: ``twisted.distributed.collect_on_ray`` on a local Ray cluster of ``--workers`` CPUs (actors,
  the driver commits). The cluster is started once, before the timed runs; its start-up is printed.
- ``ray+postgres`` (``--postgres``): the same on a throwaway PostgreSQL server, the actors committing
  their own batches.

Prints kept and tried curves per hour and the share of worker time spent in the simulator for each,
and the Ray figures relative to the multiprocess ones. The kept rate depends on the D_Q a run has
built (a run that climbed to more crossings keeps fewer of its curves: 1-3 % from 4-5 crossings
against 5-8 % from 1-3), so tried curves per hour is the steadier measure of the overhead; the new
configurations by crossing count are printed to show how far each run climbed. The machine is
shared: the load average is printed with each run.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.postgres_server for --postgres

from twisted.collect import CollectOptions, CollectSummary, collect  # noqa: E402
from twisted.store import open_store  # noqa: E402


@dataclass
class Row:
    name: str
    summary: CollectSummary
    load: tuple[float, float]

    @property
    def tried_per_hour(self) -> float:
        return self.summary.tried * 3600 / self.summary.wall_seconds

    @property
    def sim_share(self) -> float:
        return self.summary.sim_seconds / (self.summary.wall_seconds * self.summary.workers)


def run(name: str, url: str, fn: Any, options: CollectOptions) -> Row:
    load_before = os.getloadavg()[0]
    with open_store(url) as store:
        summary = fn(store, options)
    if summary.status != "finished":
        raise SystemExit(f"{name}: run {summary.run_id} {summary.status}: {summary.message}")
    return Row(name, summary, (load_before, os.getloadavg()[0]))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=120.0, help="collection time of each run")
    parser.add_argument("--workers", type=int, default=2, help="workers (processes / actors) of each run")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--postgres", action="store_true", help="also Ray with workers writing PostgreSQL")
    parser.add_argument("--order", default="mp,ray", help="order of the runs: mp,ray or ray,mp")
    args = parser.parse_args()

    import ray

    from twisted.distributed import collect_on_ray

    options = CollectOptions(hours=args.seconds / 3600, workers=args.workers, seed=args.seed)
    started = time.monotonic()
    ray.init(address="local", num_cpus=args.workers, include_dashboard=False, logging_level=logging.WARNING)
    ray_start_s = time.monotonic() - started
    rows: list[Row] = []
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for name in args.order.split(","):
                url = f"sqlite:///{Path(tmp) / f'{name}.db'}"
                if name == "mp":
                    rows.append(run("multiprocess", url, collect, options))
                elif name == "ray":
                    rows.append(run("ray (driver writes SQLite)", url, collect_on_ray, options))
                else:
                    raise SystemExit(f"--order: unknown run {name!r} (mp or ray)")
            if args.postgres:
                from tests.postgres_server import PostgresServer

                with PostgresServer() as server:
                    rows.append(run("ray+postgres (workers write)", server.url, collect_on_ray, options))
    finally:
        ray.shutdown()

    print(
        f"{args.workers} workers, {args.seconds:.0f} s per run, seed {args.seed}, {os.cpu_count()} cores; "
        f"local Ray cluster start-up {ray_start_s:.1f} s (not in the runs)"
    )
    print(
        f"{'collector':<30} {'wall s':>7} {'tried':>6} {'kept':>5} {'kept/h':>8} {'tried/h':>8} "
        f"{'sim %':>6} load"
    )
    for row in rows:
        s = row.summary
        print(
            f"{row.name:<30} {s.wall_seconds:>7.1f} {s.tried:>6,} {s.kept:>5,} {s.kept_per_hour:>8,.0f} "
            f"{row.tried_per_hour:>8,.0f} {100 * row.sim_share:>5.0f}% {row.load[0]:.1f}->{row.load[1]:.1f}"
        )
    for row in rows:
        print(f"  {row.name}: new configurations by crossing count {row.summary.kept_by_to_cross}")
    base = next((r for r in rows if r.name == "multiprocess"), None)
    if base is not None:
        for row in rows:
            if row is not base and base.summary.kept and base.tried_per_hour:
                print(
                    f"{row.name}: {row.summary.kept_per_hour / base.summary.kept_per_hour:.2f}x the kept/h, "
                    f"{row.tried_per_hour / base.tried_per_hour:.2f}x the tried/h of the multiprocess one"
                )


if __name__ == "__main__":
    main()
