"""Uniform against across curves in the collector, one after the other in one run: kept per hour per core.

    python bench/bench_collect_curves.py --minutes 4 [--shares 0 0.8] [--seed 0]

Each setting of ``--across-share`` (0 = the old collector: uniform random curves only) runs the real
collector (:func:`twisted.collect.collect`, one worker process) for ``--minutes`` into its own fresh
SQLite database from the straight rope, with the same seed. Printed per setting: tried and kept
curves, the kept rate, kept transitions per wall hour and per CPU hour of the worker (a shared machine
makes wall rates understate a core), and the kept rate by start crossing count.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
from pathlib import Path

from twisted.collect import CollectOptions, collect, collection_stats
from twisted.store import open_store

TARGET_KEPT_PER_HOUR_PER_CORE = 5_400


def run_one(url: str, minutes: float, seed: int, share: float) -> dict[str, object]:
    options = CollectOptions(hours=minutes / 60, workers=1, seed=seed, across_share=share)
    cpu_before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load = os.getloadavg()[0]
    with open_store(url) as store:
        summary = collect(store, options)
        stats = collection_stats(store)
    cpu_after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = (cpu_after.ru_utime - cpu_before.ru_utime) + (cpu_after.ru_stime - cpu_before.ru_stime)
    return {
        "share": share,
        "tried": summary.tried,
        "kept": summary.kept,
        "wall_s": summary.wall_seconds,
        "cpu_s": cpu_s,
        "load": load,
        "by_cross": {
            int(r["from_cross"]): (int(r["tried"] or 0), int(r["kept"] or 0)) for r in stats["acceptance"]
        },
        "to_cross": summary.kept_by_to_cross,
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--minutes", type=float, default=4.0, help="collection time per setting")
    parser.add_argument(
        "--shares", type=float, nargs="+", default=[0.0, 0.8], help="across shares to compare"
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, share in enumerate(args.shares):
            rows.append(run_one(f"sqlite:///{Path(tmp) / f'bench{k}.db'}", args.minutes, args.seed, share))
            r = rows[-1]
            print(
                f"across share {share}: kept {r['kept']:,} of {r['tried']:,} ({r['wall_s']:.0f} s wall, "
                f"{r['cpu_s']:.0f} s worker CPU, load {r['load']:.1f})",
                flush=True,
            )
    print(
        f"\n{'share':>6} {'tried':>7} {'kept':>6} {'kept %':>7} {'kept/h/core wall':>17}"
        f" {'kept/h/core CPU':>16}"
        "  kept % by start crossings"
    )
    for r in rows:
        tried, kept = int(r["tried"]), int(r["kept"])  # type: ignore[call-overload]
        wall, cpu = float(r["wall_s"]), float(r["cpu_s"])  # type: ignore[arg-type]
        by = ", ".join(f"{c}: {100 * k / t:.1f}" for c, (t, k) in sorted(r["by_cross"].items()) if t)  # type: ignore[attr-defined]
        print(
            f"{r['share']:>6} {tried:>7,} {kept:>6,} {100 * kept / max(tried, 1):>7.1f} "
            f"{kept * 3600 / max(wall, 1e-9):>17,.0f} {kept * 3600 / max(cpu, 1e-9):>16,.0f}  {by}"
        )
    print(
        f"(target {TARGET_KEPT_PER_HOUR_PER_CORE:,} kept/h/core; one worker per setting, fresh D_Q, "
        f"seed {args.seed})"
    )


if __name__ == "__main__":
    main()
