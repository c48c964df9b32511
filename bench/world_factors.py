"""Which difference between the world and the model throws a plan off? One factor of a level at a time.

    python bench/world_factors.py --db sqlite:///rob.db --run 1 [--level moderate] [--draws 20]

Runs the solved planner run ``--run``'s plan open loop in ``--draws`` worlds (seeds 0 ..) for each factor
of the level alone (its friction, stiffness, damping, mass or radius range, its grasp, carry, lift or
observation noise; everything else as in the model), then in the level itself. Prints, per factor, the
share of actions whose true outcome (the world's rope without the camera's noise) is the plan's next
state, and in how many worlds the rope stayed on the plan's states to the end, with the count still on
track after each step. A plan stored by ``twisted tie`` / ``robustness`` is such a run (its run id is
printed as "plan run N"). Each episode takes well under a second (docs/DESIGN.md section 15).
"""

from __future__ import annotations

import argparse
import dataclasses

from twisted.experiments.episodes import plan_of_run
from twisted.sim import Curve
from twisted.store import open_store
from twisted.topology import top
from twisted.world import LEVELS, SimWorld

FACTORS = (
    "friction",
    "stiffness",
    "damping",
    "mass",
    "radius_m",
    "grasp_off_by_one_p",
    "carry_noise_m",
    "lift_noise_m",
    "observation_noise_m",
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--db", required=True, help="the store holding the plan's run")
    ap.add_argument("--run", type=int, required=True, help="a solved planner run")
    ap.add_argument("--level", default="moderate", choices=sorted(LEVELS), help="the level split up")
    ap.add_argument("--draws", type=int, default=20, help="worlds per factor (seeds 0 ..)")
    args = ap.parse_args()
    with open_store(args.db) as store:
        plan = plan_of_run(store, args.run)
    level, none = LEVELS[args.level], LEVELS["none"]
    rows = [("none", none)]
    for factor in FACTORS:
        rows.append((factor, dataclasses.replace(none, name=args.level, **{factor: getattr(level, factor)})))
    rows.append((f"all of {args.level}", level))
    print(f"plan of run {args.run}: {len(plan.steps)} steps; {args.draws} worlds per row")
    print(f"{'factor':22s} {'actions on plan':>15s} {'worlds on track':>15s}  on track after each step")
    for name, lv in rows:
        agree, on_track, after = 0, 0, [0] * len(plan.steps)
        for seed in range(args.draws):
            world = SimWorld(lv, seed)
            world.reset(plan.root_q)
            still = True
            for i, step in enumerate(plan.steps):
                _ = world.cinch() if step.curve is None else world.execute(Curve(*step.curve))
                hit = top(world.true_points()) == step.p_data
                agree += hit
                still = still and hit
                after[i] += still
            on_track += still
        share = agree / (args.draws * len(plan.steps))
        print(f"{name:22s} {share:15.2f} {on_track:>9d} / {args.draws:<3d}  {after}", flush=True)


if __name__ == "__main__":
    main()
