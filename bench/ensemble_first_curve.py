"""Does choosing a step's curve over an ensemble of imagined ropes raise its odds in a world? (issue 64)

    python bench/ensemble_first_curve.py --db sqlite:///rob.db --run 1 [--level moderate] [--draws 20]
        [--k 32] [--ensemble 8] [--prior moderate] [--seed 0]

The closed loop's bound is the odds that one curve, chosen in the model from the fitted rope, reaches its
planned state in the world (about one in two, docs/log/2026-12-06.md). This measures, on the states a
world really passes through, whether a curve chosen for reaching the next state in most of ``--ensemble``
ropes drawn from ``--prior`` (physics and gripper noise; the planner's own imagination, never the world's
draw) does better there than the curve the planner takes today.

For each of ``--draws`` worlds (seeds 0 ..) of ``--level`` (overrides allowed, e.g.
``none,observation_noise_m=0.002``) the solved run ``--run``'s plan is followed state by state: at each,
the observed rope is fitted and rested in the model as a replan does (``--track``: near the model's
outcome of the last curve sent, :meth:`twisted.world.ChainFit.fit`), ``--k`` curves toward the plan's next
state are drawn from the inverse model and simulated in the model from the fit. Two curves are then sent
to the world from the same world state and with the same gripper noise (the world is restored between
them):

- ``first``: the first of the k that reaches the next state in the model (what a search keeps);
- ``ensemble``: of those that reach it in the model, the one that reaches it in most ensemble ropes.

A hit is the world's true rope (no camera noise) in the next state. The world goes on with the first of
ensemble, first that hit; a world where neither hit, or whose fit is not the plan's state, stops. Prints
the hits of each, by the next state's crossings, and the simulator time the ensemble costs per decision.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from twisted.experiments.episodes import plan_of_run
from twisted.model.registry import load_model
from twisted.model.sampler import ModelCurves
from twisted.moves import explains
from twisted.sim import RopeSim
from twisted.store import open_store
from twisted.topology import top
from twisted.world import LEVELS, ChainFit, SimWorld, draw_physics, noisy_curve, parse_level


class _Node:
    def __init__(self, q: np.ndarray, points: np.ndarray, p_data: object) -> None:
        self.q, self.points, self.p_data = q, points, p_data


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--db", required=True, help="the store holding the plan's run")
    ap.add_argument("--run", type=int, required=True, help="a solved planner run")
    ap.add_argument("--level", default="moderate", type=parse_level, help="the worlds' level (overrides too)")
    ap.add_argument("--prior", default="moderate", choices=sorted(LEVELS), help="the ensemble's level")
    ap.add_argument("--draws", type=int, default=20, help="worlds (seeds 0 ..)")
    ap.add_argument("--k", type=int, default=32, help="model curves per step")
    ap.add_argument("--rounds", type=int, default=4, help="draws of k while none reaches")
    ap.add_argument("--ensemble", type=int, default=8, help="imagined ropes per curve")
    ap.add_argument(
        "--track", action="store_true", help="fit each observation near the model's prediction of it"
    )
    ap.add_argument("--seed", type=int, default=0, help="seed of the model's draws and the ensemble")
    args = ap.parse_args()
    with open_store(args.db) as store:
        plan = plan_of_run(store, args.run)
        model = load_model(store)
    sampler = ModelCurves(model)
    prior = LEVELS[args.prior]
    rng = np.random.default_rng(args.seed)
    ropes = [
        RopeSim(params=draw_physics(prior, np.random.default_rng([args.seed, r])).rope_params())
        for r in range(args.ensemble)
    ]
    nominal = RopeSim()
    fitter = ChainFit()
    hits = {"first": 0, "ensemble": 0}
    decisions, ensemble_s, reaching_total = 0, 0.0, 0
    by_cross: dict[int, list[int]] = {}
    print(f"plan of run {args.run}: {len(plan.steps)} steps; {args.draws} worlds at {args.level.to_dict()}")
    states: list = []
    for step in plan.steps:  # the plan's states in order, a state kept once however many nodes it has
        if step.curve is not None and (not states or step.p_data.key != states[-1].key):
            states.append(step.p_data)
    for seed in range(args.draws):
        world = SimWorld(args.level, seed)
        seen = world.reset(plan.root_q)
        like = plan.root_q if args.track else None  # the model's expectation of the world's rope
        for i, target in enumerate(states):
            _, rest = fitter.rest_configuration(seen.points, like)
            if rest is None:
                print(f"world {seed} step {i + 1}: the model rejects the fit")
                break
            q, points, p_data = rest
            if i and p_data.key != states[i - 1].key:
                print(f"world {seed} step {i + 1}: the fit is {p_data.key}, not {states[i - 1].key}")
                break
            move = explains(p_data, target)
            reaching: list = []
            for _ in range(args.rounds):  # another k when none of the first reach (a search retries too)
                for c in sampler.sample(_Node(q, points, p_data), target, move, args.k, rng):
                    nominal.set_state(q)
                    if nominal.apply(c).ok and nominal.p_data().key == target.key:
                        reaching.append(c)
                if reaching:
                    break
            if not reaching:
                print(
                    f"world {seed} step {i + 1}: none of {args.rounds} x {args.k} curves reaches in the model"
                )
                break
            started = time.perf_counter()
            scores = []
            for j, c in enumerate(reaching):
                score = 0
                for r, sim in enumerate(ropes):
                    done = noisy_curve(c, prior, np.random.default_rng([args.seed, seed, i, j, r]))
                    sim.set_state(q)
                    score += bool(sim.apply(done).ok and sim.p_data().key == target.key)
                scores.append(score)
            ensemble_s += time.perf_counter() - started
            best = reaching[int(np.argmax(scores))]
            checkpoint = world.checkpoint()
            outcome = {}
            for name, c in (("ensemble", best), ("first", reaching[0])):
                world.restore(checkpoint)
                world.execute(c)
                outcome[name] = (top(world.true_points()).key == target.key, world.checkpoint())
            decisions += 1
            reaching_total += len(reaching)
            row = by_cross.setdefault(target.cross, [0, 0, 0])
            row[0] += 1
            for n, name in enumerate(("first", "ensemble")):
                hits[name] += outcome[name][0]
                row[n + 1] += outcome[name][0]
            print(
                f"world {seed} step {i + 1}: {len(reaching)}/{args.k} reach in the model, best "
                f"{max(scores)}/{args.ensemble}, first {scores[0]}/{args.ensemble}; world hits: "
                + ", ".join(f"{k} {int(v[0])}" for k, v in outcome.items()),
                flush=True,
            )
            going = next((name for name in ("ensemble", "first") if outcome[name][0]), None)
            if going is None:
                break
            world.restore(outcome[going][1])
            seen = world.observe()
            if args.track:
                nominal.set_state(q)
                nominal.apply(best if going == "ensemble" else reaching[0])
                like = nominal.state()
    print(f"\n{decisions} decisions; mean {reaching_total / max(decisions, 1):.1f} of {args.k} curves reach")
    for name, v in hits.items():
        print(f"{name:9s} {v:4d} / {decisions} = {v / max(decisions, 1):.2f}")
    print("by the next state's crossings (decisions, first, ensemble):")
    for cross, row in sorted(by_cross.items()):
        print(f"  {cross}: {row}")
    print(f"ensemble simulation: {ensemble_s / max(decisions, 1):.2f} s per decision")


if __name__ == "__main__":
    main()
