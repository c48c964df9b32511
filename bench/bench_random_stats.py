"""Random-curve statistics of the simulator next to the reference's (docs/DESIGN.md section 3.5).

    python bench/bench_random_stats.py 1000 [--workers 2] [--seed 0] [--friction-scale 1.0]

D_Q-like: the start of each curve is a reached configuration with 0, 1 or 2 crossings (the count
drawn uniformly among those reached so far, then a configuration uniformly within it); every
accepted result joins the reached configurations. Prints, per start count, how often a uniform
random curve ends with each crossing count, next to the reference's 0->1 11 %, 1->2 7 %, 2->3 3 %,
and the rejections. Runs in batches on a SimPool, so the order of results, and with it every
figure, replays from the seed whatever the number of workers.
"""

from __future__ import annotations

import argparse
import collections
import os
import time

import numpy as np

from twisted.sim import SimPool, sample_curve
from twisted.sim.simulator import RopeSim

REFERENCE = {0: 0.11, 1: 0.07, 2: 0.03}
MAX_PER_COUNT = 5000  # reached configurations kept per crossing count (reservoir)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("curves", type=int, nargs="?", default=1000, help="random curves to simulate")
    parser.add_argument("--workers", type=int, default=1, help="processes (1: in this process)")
    parser.add_argument("--batch", type=int, default=64, help="curves per batch between D_Q updates")
    parser.add_argument("--friction-scale", type=float, default=1.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    rng = np.random.default_rng(args.seed)
    straight = RopeSim(args.friction_scale)
    reached: dict[int, list[np.ndarray]] = {0: [straight.state()]}
    seen: collections.Counter[int] = collections.Counter({0: 1})
    transitions: collections.Counter[tuple[int, int]] = collections.Counter()
    rejected: collections.Counter[str] = collections.Counter()
    starts_by_count: collections.Counter[int] = collections.Counter()
    steps = 0
    t0 = time.perf_counter()
    with SimPool(args.workers, args.friction_scale) as pool:
        done = 0
        while done < args.curves:
            n = min(args.batch, args.curves - done)
            counts = [c for c in (0, 1, 2) if reached.get(c)]
            start_counts = [int(rng.choice(counts)) for _ in range(n)]
            jobs = []
            for c in start_counts:
                bucket = reached[c]
                jobs.append((bucket[int(rng.integers(len(bucket)))], sample_curve(rng)))
            for c, result in zip(start_counts, pool.run(jobs), strict=True):
                starts_by_count[c] += 1
                steps += result.steps
                if not result.ok or result.p_data is None or result.state is None:
                    rejected[(result.reason or "?").split(" (")[0]] += 1
                    continue
                after = result.p_data.cross
                transitions[(c, after)] += 1
                if after <= 2:
                    # reservoir sampling keeps a uniform sample of everything reached with this count
                    seen[after] += 1
                    bucket = reached.setdefault(after, [])
                    if len(bucket) < MAX_PER_COUNT:
                        bucket.append(result.state)
                    elif (j := int(rng.integers(seen[after]))) < MAX_PER_COUNT:
                        bucket[j] = result.state
            done += n
    wall = time.perf_counter() - t0

    print(
        f"{args.curves} random curves, workers {args.workers}, seed {args.seed}, "
        f"friction x{args.friction_scale}, "
        f"{wall:.1f} s wall ({args.curves / wall:.1f} curves/s, {steps / wall:.0f} steps/s), "
        f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"
    )
    print(f"rejected {sum(rejected.values())} of {args.curves}:")
    for reason, k in rejected.most_common():
        print(f"  {k:5d}  {reason}")
    print("start -> end crossing counts (fractions of accepted curves from that start count):")
    for c in (0, 1, 2):
        total = sum(k for (a, _), k in transitions.items() if a == c)
        if not total:
            continue
        ends = sorted((b, k) for (a, b), k in transitions.items() if a == c)
        up = transitions[(c, c + 1)] / total
        print(
            f"  {c}->{c + 1}: {100 * up:5.1f} %  (reference {100 * REFERENCE[c]:.0f} %)   "
            f"of {total} curves from {c}; all ends: "
            + ", ".join(f"{b}: {100 * k / total:.1f} %" for b, k in ends)
        )


if __name__ == "__main__":
    main()
