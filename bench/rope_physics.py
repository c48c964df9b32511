"""Would another rope make the failed plan steps? The same curves on a softer, grippier or thinner rope.

    python bench/rope_physics.py --db sqlite:///tune.db --set tune-u5 --label L --from 3 --from 4 \
        [--pairs 150] [--k 6] [--variant stiffness=0.25] [--variant friction=1.5,stiffness=0.5] \
        [--variant radius=0.007] [--workers 2] [--seed 0]

Curls on inner segments are where the searches stall (docs/goals.md): a loop of the model's size takes
about 9 links, and the joint stiffness (``RopeParams.joint_stiffness``) is what opens a small loop again
once the gripper lets go, against the table's friction. If the rope itself were the wall, a softer or a
grippier rope (or a thinner one, whose loops can close tighter) would make the steps the searches asked
for more often, from the same configurations.

For ``--pairs`` (node, next state) pairs per crossing count drawn from the stored runs' plan steps
(``lib.steps.step_groups``: runs toward any goal, distinct adding steps), this takes
``--k`` of the planner's curves (``StepCurves`` with today's options, the shipped model) from the node's
configuration and simulates each on the default rope and on every ``--variant``: the hinge stiffness
times ``stiffness``, the friction times ``friction`` (``RopeSim(friction_scale=...)``), the link radius
set to ``radius`` metres (the compiled model's capsule sizes and bounds changed in place; the stored
configurations were settled on the default rope and settle again on the variant; the simulator's
validity limits, such as the deepest penetration of one radius, stay those of the 10 mm rope). The
curves and the starts are the same for every rope. Prints per rope and crossing count the curves that
reached the step's next state, the pairs with at least one such curve, the rejected curves and the
simulator steps per curve.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
from lib.steps import add_run_selection, planner_curves, pool_map, step_curves, step_groups

from twisted.sim import RopeSim
from twisted.sim.mjcf import LINK_HALF_LENGTH_M, link_name
from twisted.store import open_store

KNOBS = ("stiffness", "friction", "radius")
Variant = tuple[tuple[str, float], ...]  # sorted (knob, value) pairs; () is the default rope


def parse_variant(text: str) -> Variant:
    """``"stiffness=0.5,friction=1.5"`` -> (("friction", 1.5), ("stiffness", 0.5)); ValueError if bad."""
    pairs = []
    for part in text.split(","):
        name, _, value = part.partition("=")
        if name not in KNOBS:
            raise ValueError(f"unknown knob {name!r} in {text!r} (one of {', '.join(KNOBS)})")
        v = float(value)
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive number, got {value!r}")
        pairs.append((name, v))
    return tuple(sorted(pairs))


def variant_name(v: Variant) -> str:
    words = [f"radius {x:g} m" if k == "radius" else f"{k} x{x:g}" for k, x in v]
    return ", ".join(words) or "default rope"


def variant_sim(v: Variant) -> RopeSim:
    """A simulator of the default rope with the variant's knobs changed."""
    knobs = dict(v)
    sim = RopeSim(friction_scale=knobs.get("friction", 1.0))
    m = sim.model
    m.jnt_stiffness[m.jnt_type == 3] *= knobs.get("stiffness", 1.0)  # the hinges (3: mjJNT_HINGE)
    if "radius" in knobs:
        r = knobs["radius"]
        geoms = [m.geom(link_name(i)).id for i in range(len(sim.link_positions()))]
        m.geom_size[geoms, 0] = r
        m.geom_rbound[geoms] = LINK_HALF_LENGTH_M + r
        m.geom_aabb[geoms, 3:] = (r, r, LINK_HALF_LENGTH_M + r)  # local half-sizes, the capsule along z
    return sim


_SIMS: dict[Variant, RopeSim] = {}


def simulate(job: tuple[Variant, Any, Any, str]) -> tuple[str, int]:
    """("reached" / "rejected" / "other", steps) of one curve from ``q`` on the variant's rope."""
    v, q, curve, nxt = job
    if v not in _SIMS:
        _SIMS[v] = variant_sim(v)
    sim = _SIMS[v]
    sim.set_state(q)
    out = sim.apply(curve)
    if not out.ok:
        return "rejected", out.steps
    return ("reached" if sim.p_data().key == nxt else "other"), out.steps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap, required=True)
    ap.add_argument("--from", type=int, action="append", dest="levels", help="crossings of the steps' start")
    ap.add_argument("--pairs", type=int, default=150, help="pairs drawn per crossing count")
    ap.add_argument("--k", type=int, default=6, help="planner curves simulated per pair")
    ap.add_argument("--variant", action="append", default=[], help="knob=value[,knob=value] (repeatable)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.pairs < 1 or args.k < 1:
        ap.error("--pairs and --k must be at least 1")
    try:
        variants: list[Variant] = [(), *(parse_variant(t) for t in args.variant)]
    except ValueError as e:
        ap.error(f"--variant: {e}")
    levels = args.levels or [3, 4]
    rng = np.random.default_rng(args.seed)

    with open_store(args.db) as store:
        groups = step_groups(store, args.sets, args.labels, levels)

    planner = step_curves(args.db, None)
    jobs: list[tuple[int, int, Any, Any, str]] = []  # (crossings, pair, q, curve, next state's key)
    drawn = {}
    for level in levels:
        items = groups.get(level, [])
        picks = sorted(rng.choice(len(items), size=min(args.pairs, len(items)), replace=False))
        drawn[level] = (len(picks), len(items))
        for i in picks:
            node, nxt, move, _goal = items[int(i)]
            curves = planner_curves(planner, node, nxt, move, args.k, rng)
            jobs += [(level, int(i), node.q, c, nxt.key) for c in curves]

    print(f"{args.k} planner curves per pair, seed {args.seed}; the same curves and starts on every rope")
    print("| rope | from | pairs (of) | curves | reached | pairs reached | rejected | steps a curve |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for v in variants:
        results = pool_map(simulate, [(v, q, c, nk) for _, _, q, c, nk in jobs], args.workers)
        for level in levels:
            rows = [(j[1], r) for j, r in zip(jobs, results, strict=True) if j[0] == level]
            if not rows:
                continue
            n = len(rows)
            reached = sum(r[0] == "reached" for _, r in rows)
            hit = len({i for i, r in rows if r[0] == "reached"})
            rejected = sum(r[0] == "rejected" for _, r in rows)
            steps = float(np.mean([r[1] for _, r in rows]))
            pairs, of = drawn[level]
            print(
                f"| {variant_name(v)} | {level} | {pairs} ({of}) | {n} | {reached} ({reached / n:.1%}) "
                f"| {hit} | {rejected} ({rejected / n:.1%}) | {steps:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
