"""Train SAC+HER on RopeKnotEnv and print the success rate per goal crossing count during training.

The paper's baseline: during training it "consistently" solved 1-crossing goals, 2-crossing goals
"near zero". This script trains from the straight rope towards goals drawn uniformly over 1, 2
and 3 crossings (every enumerated state of each count), prints the training episodes' success
per interval and count, and at the end evaluates the deterministic policy alone on fresh
episodes. The run (and its checkpoints: the policy id for ``twisted plan --planner sac``) is
kept in the database given by --db.

    python bench/bench_rl.py --steps 20000 --minutes 25 --db sqlite:////work/data/rl.db
"""

from __future__ import annotations

import argparse
import time

import torch


def _rate(counts: dict[int, tuple[int, int]], cross: int) -> str:
    episodes, hits = counts.get(cross, (0, 0))
    return f"{hits:4d}/{episodes:<4d} {100.0 * hits / episodes:5.1f}%" if episodes else f"{'-':>16s}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", default="sqlite:///rl_bench.db")
    parser.add_argument("--steps", type=int, default=20_000, help="environment steps (curves)")
    parser.add_argument("--minutes", type=float, default=25.0, help="stop training after this time")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-curves", type=int, default=10)
    parser.add_argument("--log-every", type=int, default=1_000)
    parser.add_argument("--checkpoint-every", type=int, default=4_000)
    parser.add_argument("--learning-starts", type=int, default=1_000)
    parser.add_argument("--eval-episodes", type=int, default=20, help="per crossing count, at the end")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    args = parser.parse_args()

    torch.set_num_threads(args.threads)
    from twisted.rl import SacConfig, train_sac
    from twisted.rl.sac import evaluate_policy
    from twisted.rl.sampler import load_policy
    from twisted.store import open_store

    config = SacConfig(
        total_steps=args.steps,
        seed=args.seed,
        max_curves=args.max_curves,
        log_every=args.log_every,
        checkpoint_every=args.checkpoint_every,
        learning_starts=args.learning_starts,
    )
    store = open_store(args.db)
    print(
        f"SAC+HER on twisted/RopeKnot-v0: goals 1/2/3 crossings, {config.max_curves} curves per episode, "
        f"{config.total_steps} steps max, {args.minutes} min max, seed {config.seed}, "
        f"{args.threads} torch thread(s)"
    )
    print(
        f"{'steps':>7s} {'episodes':>8s} {'min':>6s}   "
        + " ".join(f"{f'{c}-crossing':>16s}" for c in (1, 2, 3))
    )

    def show(p) -> None:  # noqa: ANN001 - RlProgress
        print(
            f"{p.steps:7d} {p.episodes:8d} {p.elapsed_s / 60:6.1f}   "
            + " ".join(_rate(p.interval, c) for c in (1, 2, 3)),
            flush=True,
        )

    started = time.perf_counter()
    outcome = train_sac(store, config, progress=show, time_limit_s=60.0 * args.minutes)
    wall = time.perf_counter() - started
    print(
        f"run {outcome.run_id} {outcome.status}: {outcome.steps} steps, {outcome.episodes} episodes in "
        f"{wall:.0f} s ({1000 * wall / max(outcome.steps, 1):.0f} ms/step); policy (checkpoint) id "
        f"{outcome.checkpoint_id}"
    )
    print("whole run, training episodes:  " + " ".join(_rate(outcome.success, c) for c in (1, 2, 3)))

    model, _ = load_policy(store, outcome.checkpoint_id)
    t0 = time.perf_counter()
    final = evaluate_policy(model, config, args.eval_episodes, seed=10_000 + args.seed)
    print(
        f"deterministic policy alone, {args.eval_episodes} fresh episodes per count "
        f"({time.perf_counter() - t0:.0f} s): " + " ".join(_rate(final, c) for c in (1, 2, 3))
    )
    store.close()


if __name__ == "__main__":
    main()
