"""How close the 6-crossing goal sampler comes to uniform, measured at 5 crossings against the enumeration.

    python bench/sampler_tv.py [--crossings 5] [--draws 2000] [--pool 40] [--seed 0]

The sampler (``twisted.experiments.goalsets.sample_states``: walks down the head tree, importance-
resampled toward uniform) draws ``--draws`` states of ``--crossings`` crossings; so do an exact uniform
draw from the enumeration (the noise floor of ``--draws`` samples), the same walks without their
weights, and a plain forward walk (a uniform choice among the distinct states one move away with one more
crossing, no correction). A state space of 130,304 states cannot be compared state by state with a few
thousand draws, so the total variation distance (TV, half the L1 distance) is taken between the
distributions of three statistics over the draws and over the whole enumeration: the state's head
ancestor at 3 crossings (528 values at 5: where in the tree it lies), its number of curls (crossings
whose two visits are adjacent along the rope: what makes goals hard, issue 36), and the crossings met
before the first curl. The script also prints Knuth's estimate of the number of states (the mean walk
weight) against the true count, and the estimate at 6 crossings.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from collections.abc import Callable, Sequence

import numpy as np

from twisted.experiments.goalsets import head_parent, sample_states, walk
from twisted.moves import enumerate_states, successor_states
from twisted.topology import EMPTY, PData


def curls(p: PData) -> int:
    return sum(1 for o, u, _ in p.crossings() if abs(o - u) == 1)


def first_curl(p: PData) -> int:
    for v in p.visits:
        if abs(v.position - v.partner) == 1:
            return v.position
    return 0


def ancestor(level: int) -> Callable[[PData], str]:
    def of(p: PData) -> str:
        while p.cross > level:
            p = head_parent(p)
        return p.key

    return of


def tv(
    sample: Sequence[PData], exact: Counter[object], total: int, feature: Callable[[PData], object]
) -> float:
    counts = Counter(feature(p) for p in sample)
    keys = set(counts) | set(exact)
    return 0.5 * sum(abs(counts[k] / len(sample) - exact[k] / total) for k in keys)


def forward_walk(crossings: int, rng: np.random.Generator) -> PData:
    p = EMPTY
    while p.cross < crossings:
        options = [q for q in successor_states(p) if q.cross == p.cross + 1]
        p = options[int(rng.integers(len(options)))]
    return p


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--crossings", type=int, default=5)
    ap.add_argument("--draws", type=int, default=2000)
    ap.add_argument("--pool", type=int, default=40, help="walks per draw (the sampler's pool)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--six-walks", type=int, default=2000, help="walks for the 6-crossing count estimate")
    args = ap.parse_args()
    c = args.crossings
    t0 = time.perf_counter()
    states = enumerate_states(c)[c]
    print(f"enumeration: {len(states):,} states of {c} crossings ({time.perf_counter() - t0:.0f} s)")
    features: dict[str, Callable[[PData], object]] = {
        "head ancestor at 3": ancestor(3),
        "curls": curls,
        "first curl at": first_curl,
    }
    exact = {name: Counter(f(p) for p in states) for name, f in features.items()}
    rng = np.random.default_rng(args.seed)

    t0 = time.perf_counter()
    sampled: list[PData] = []
    while len(sampled) < args.draws:  # the sampler's draws are distinct within a call: many calls of 10
        sampled.extend(sample_states(c, 10, rng, pool=args.pool))
    sampled = sampled[: args.draws]
    sampler_s = time.perf_counter() - t0
    walks = [walk(c, rng) for _ in range(args.draws)]
    draws: dict[str, list[PData]] = {
        "uniform (exact, noise floor)": [states[int(i)] for i in rng.integers(len(states), size=args.draws)],
        f"sampler (pool {args.pool})": sampled,
        "head-tree walks, unweighted": [w.state for w in walks],
        "forward walk, unweighted": [forward_walk(c, rng) for _ in range(args.draws)],
    }
    print(
        f"{args.draws:,} draws each; sampler {1000 * sampler_s / args.draws:.0f} ms a draw; seed {args.seed}"
    )
    print()
    names = list(features)
    print(f"| draws | {' | '.join('TV ' + n for n in names)} | mean curls |")
    print(f"| --- | {' | '.join('---' for _ in names)} | --- |")
    exact_curls = sum(k * n for k, n in exact["curls"].items()) / len(states)
    print(f"| enumeration | {' | '.join('0' for _ in names)} | {exact_curls:.3f} |")
    for label, sample in draws.items():
        figures = [tv(sample, exact[n], len(states), features[n]) for n in names]
        mean_curls = float(np.mean([curls(p) for p in sample]))
        print(f"| {label} | {' | '.join(f'{x:.3f}' for x in figures)} | {mean_curls:.3f} |")
    print()
    estimate = float(np.mean([w.weight for w in walks]))
    print(
        f"Knuth's estimate of the {c}-crossing states from {len(walks):,} walks: {estimate:,.0f} "
        f"(true {len(states):,})"
    )
    six = [walk(6, rng) for _ in range(args.six_walks)]
    weights = np.array([w.weight for w in six])
    print(
        f"estimate at 6 crossings from {len(six):,} walks: {weights.mean():,.0f} "
        f"(standard error {weights.std(ddof=1) / np.sqrt(len(six)):,.0f})"
    )


if __name__ == "__main__":
    main()
