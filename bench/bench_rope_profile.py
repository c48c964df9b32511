"""Valid rate and wall time of random curves on the rope this process runs (``TWISTED_ROPE``).

    python bench/bench_rope_profile.py --curves 50 [--seed 0]
    TWISTED_ROPE=31 python bench/bench_rope_profile.py --curves 50

From the straight rope, a random walk of uniform random curves (``sample_curve``): each curve starts
from the state the last valid one reached (a rejected curve is undone). Prints the rope, the share of
curves that ended in a valid configuration, the rejections by reason and the mean wall time per curve.
The CPU may be shared: compare figures from the same machine and load only.
"""

from __future__ import annotations

import argparse
import collections
import os
import time

import numpy as np

from twisted.rope import ROPE
from twisted.sim import RopeSim, sample_curve


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--curves", type=int, default=50, help="random curves in the walk")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    rng = np.random.default_rng(args.seed)
    sim = RopeSim()
    sim.reset()
    state = sim.state()
    wall: list[float] = []
    rejected: collections.Counter[str] = collections.Counter()
    crossings = []
    for _ in range(args.curves):
        sim.set_state(state)
        curve = sample_curve(rng)
        started = time.perf_counter()
        outcome = sim.apply(curve)
        wall.append(time.perf_counter() - started)
        if outcome.ok:
            state = sim.state()
            crossings.append(sim.p_data().cross)
        else:
            rejected[(outcome.reason or "?").split(" (")[0]] += 1
    ok = args.curves - sum(rejected.values())
    print(
        f"rope {ROPE.name}: {args.curves} random curves (seed {args.seed}), load average "
        f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"
    )
    print(f"  valid: {ok} of {args.curves} ({ok / args.curves:.0%})")
    print(f"  wall per curve: mean {np.mean(wall):.3f} s, median {np.median(wall):.3f} s")
    if crossings:
        print(f"  crossings after valid curves: mean {np.mean(crossings):.1f}, max {max(crossings)}")
    for reason, n in rejected.most_common():
        print(f"    {n:4d}  {reason}")


if __name__ == "__main__":
    main()
