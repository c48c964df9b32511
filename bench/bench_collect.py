"""Throughput of `twisted collect` with every core busy: kept transitions per hour per core.

    python bench/bench_collect.py --minutes 5 [--workers N] [--db sqlite:///bench.db] [--seed 0]

Runs the real collector (``twisted.collect.collect``: worker processes, one writer, SQLite in WAL
mode) into a fresh temporary database unless ``--db`` is given (then it continues that D_Q). Prints
kept transitions per hour per core (paper: 537; target: at least 5,400), the tried/kept rates per
start crossing count next to the reference's random-curve rates, and where the time goes: simulation
time per tried curve, the share of worker time spent simulating, the writer's commit time, and the
kept rate the bias toward more crossings produces. Per-CPU-second figures (from the children's CPU
time) are given too, because on a shared machine wall-clock rates understate what a core does.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

from twisted.collect import CollectOptions, collect, collection_stats
from twisted.runtime import cpu_cores
from twisted.store import open_store

PAPER_KEPT_PER_HOUR_PER_CORE = 537
TARGET_KEPT_PER_HOUR_PER_CORE = 5_400


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--minutes", type=float, default=5.0, help="collection time")
    parser.add_argument("--workers", type=int, default=cpu_cores(), help="default: all cores")
    parser.add_argument("--db", default=None, help="database URL (default: a fresh temporary SQLite file)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cross-bias", type=float, default=1.0)
    parser.add_argument("--max-cross", type=int, default=6)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        url = args.db or f"sqlite:///{Path(tmp) / 'bench.db'}"
        options = CollectOptions(
            hours=args.minutes / 60,
            workers=args.workers,
            seed=args.seed,
            cross_bias=args.cross_bias,
            max_cross=args.max_cross,
        )
        load_before = os.getloadavg()
        cpu_before = resource.getrusage(resource.RUSAGE_CHILDREN)
        started = time.monotonic()
        with open_store(url) as store:
            summary = collect(store, options)
            stats = collection_stats(store)
        wall_s = time.monotonic() - started
        cpu_after = resource.getrusage(resource.RUSAGE_CHILDREN)
        load_after = os.getloadavg()

    workers_cpu_s = (cpu_after.ru_utime - cpu_before.ru_utime) + (cpu_after.ru_stime - cpu_before.ru_stime)
    print(
        f"collect: {args.workers} workers for {summary.wall_seconds / 60:.2f} min (cores: {os.cpu_count()}),"
    )
    print(
        f"  load average before/after: {load_before[0]:.1f} / {load_after[0]:.1f} "
        "(other processes share the CPU)"
    )
    print(
        f"  tried {summary.tried:,} curves, kept {summary.kept:,}, "
        f"rejected by the simulator {summary.rejected:,}"
    )
    print(f"  kept per hour: {summary.kept_per_hour:,.0f}")
    print(
        f"  kept per hour per core: {summary.kept_per_hour_per_worker:,.0f} "
        f"(paper {PAPER_KEPT_PER_HOUR_PER_CORE}, target {TARGET_KEPT_PER_HOUR_PER_CORE:,})"
    )
    if workers_cpu_s > 0:
        print(
            f"  kept per CPU-hour of the workers: {summary.kept * 3600 / workers_cpu_s:,.0f} "
            f"({workers_cpu_s:.0f} CPU s over {summary.wall_seconds * args.workers:.0f} worker wall s)"
        )
    print("rates by start crossing count (this database):")
    print("  from   tried    kept  kept rate  c->c+1  reference c->c+1")
    for row in stats["acceptance"]:
        ref = row["reference_plus_one_rate"]
        print(
            f"  {row['from_cross']:>4} {row['tried']:>7,} {row['kept']:>7,}"
            f" {100 * (row['kept_rate'] or 0):>9.1f}%"
            f" {100 * (row['plus_one_rate'] or 0):>6.1f}%  {'-' if ref is None else f'{100 * ref:.0f}%':>6}"
        )
    print("new configurations by crossing count (this run):", summary.kept_by_to_cross)
    print("where the time goes:")
    if summary.tried:
        per_try = summary.sim_seconds / summary.tried
        kept_rate = summary.kept / summary.tried
        busy = summary.sim_seconds / max(1e-9, summary.wall_seconds * args.workers)
        print(f"  simulation wall time per tried curve: {1000 * per_try:.0f} ms")
        print(f"  overall kept rate of the tried curves: {100 * kept_rate:.1f} %")
        print(f"  share of worker wall time inside the simulator: {100 * busy:.0f} %")
        print(f"  writer: {summary.commit_seconds:.1f} s committing {summary.batches} batches")
        print(
            f"  => {3600 * kept_rate / per_try:,.0f} kept/h per core at this wall time per curve "
            "(kept/h/core = 3600 x kept rate / seconds per curve)"
        )
        if workers_cpu_s > 0:
            cpu_per_try = workers_cpu_s / summary.tried
            print(
                "  worker CPU time per tried curve (simulation, P-data, store reads, start-up): "
                f"{1000 * cpu_per_try:.0f} ms => {3600 * kept_rate / cpu_per_try:,.0f} kept/h on an "
                "unshared core; reaching "
                f"{TARGET_KEPT_PER_HOUR_PER_CORE:,} needs a kept rate of "
                f"{100 * TARGET_KEPT_PER_HOUR_PER_CORE * cpu_per_try / 3600:.1f} % at this cost"
            )
    print(f"(bench wall time {wall_s:.0f} s, including worker start-up)")


if __name__ == "__main__":
    main()
