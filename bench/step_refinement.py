"""Refining a plan step's failing curves in the simulator against asking the model for more curves.

    python bench/step_refinement.py --db sqlite:///final.db --tree-sets final-u4 final-u5 \
        [--steps 3->4 4->5] [--per-step 30] [--sigma 0.03] [--seed 0]

The steps are the explained planner-tree edges of the runs toward the sets' goals
(:func:`twisted.model.success.tree_steps`, as ``bench/success_at_6.py --tree-sets --explained``), one
worker. Per step, with the shipped model:

* ``more``: 18 model curves (``@6`` counts the first 6, ``@18`` all 18);
* ``refine``: the same first 6, then up to two rounds of 6 curves, each a Gaussian perturbation
  (x, y: ``--sigma`` m, z_max: 0.01 m, the grasped link moved by one with probability 0.3) of one of the
  two best curves so far, ranked by a score toward the step's next state: the result's distance in
  crossings from it, plus one when one move of the step's kind explains the result. Both spend at most
  18 simulator calls a step.

It also classifies what the first 6 model curves of each step made: the next state (hit), the parent's
state (unchanged), another state of the next state's crossing count reached by a move of the step's
kind (same kind) or of another kind, fewer or more crossings, or a result the simulator rejected.
"""

from __future__ import annotations

import argparse
import collections

import numpy as np

from twisted.model.registry import load_model
from twisted.model.success import HeldOut, tree_steps
from twisted.moves import explains
from twisted.sim import N_LINKS
from twisted.sim.pool import SimPool
from twisted.sim.rope import Curve
from twisted.store import open_store

CLASSES = ("hit", "unchanged", "same kind", "other kind", "fewer", "more", "rejected")


def score(step: HeldOut, result: object) -> float:
    """Higher is nearer the step's next state (a hit scores highest)."""
    if not result.ok:  # type: ignore[attr-defined]
        return -9.0
    p = result.p_data  # type: ignore[attr-defined]
    if p == step.p_to:
        return 9.0
    value = -float(abs(p.cross - step.p_to.cross))
    want = explains(step.p_from, step.p_to)
    got = explains(step.p_from, p) if p.cross > step.p_from.cross else None
    if got is not None and want is not None and got.kind == want.kind:
        value += 1.0
    return value


def classify(step: HeldOut, result: object) -> str:
    if not result.ok:  # type: ignore[attr-defined]
        return "rejected"
    p = result.p_data  # type: ignore[attr-defined]
    if p == step.p_to:
        return "hit"
    if p == step.p_from:
        return "unchanged"
    if p.cross != step.p_to.cross:
        return "fewer" if p.cross < step.p_to.cross else "more"
    got, want = explains(step.p_from, p), explains(step.p_from, step.p_to)
    return "same kind" if got is not None and want is not None and got.kind == want.kind else "other kind"


def perturb(curve: Curve, sigma: float, rng: np.random.Generator) -> Curve:
    link = curve.link + (int(rng.choice([-1, 1])) if rng.random() < 0.3 else 0)
    return Curve(
        min(max(link, 0), N_LINKS - 1),
        max(0.0, curve.z_max_m + rng.normal(0.0, 0.01)),
        curve.x_m + rng.normal(0.0, sigma),
        curve.y_m + rng.normal(0.0, sigma),
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--db", required=True, help="store with the eval runs toward the sets")
    ap.add_argument("--tree-sets", nargs="+", required=True)
    ap.add_argument("--steps", nargs="+", default=["3->4", "4->5"])
    ap.add_argument("--per-step", type=int, default=30)
    ap.add_argument("--sigma", type=float, default=0.03, help="x, y perturbation (m)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    store = open_store(args.db)
    model = load_model(None)
    rng = np.random.default_rng(args.seed)
    steps = tree_steps(store, args.tree_sets, args.per_step, rng, args.steps, explained=True)
    counts: dict[str, collections.Counter[str]] = collections.defaultdict(collections.Counter)
    made: dict[str, collections.Counter[str]] = collections.defaultdict(collections.Counter)
    with SimPool(1) as pool:
        for step in steps:
            kind = str(explains(step.p_from, step.p_to).kind)  # type: ignore[union-attr]
            curves = model.sample(step.points, step.q, step.p_to, 18, rng, p_data=step.p_from)
            results = pool.run([(step.q, c) for c in curves])
            hits = [r.ok and r.p_data == step.p_to for r in results]
            made[step.step].update(classify(step, r) for r in results[:6])
            population = list(zip(curves[:6], results[:6], strict=True))
            refined = any(hits[:6])
            for _ in range(2):
                if refined:
                    break
                ranked = sorted(
                    population, key=lambda cr: score(step, cr[1]) + 1e-3 * rng.random(), reverse=True
                )
                elite = [c for c, _ in ranked[:2]]
                new = [perturb(elite[i % 2], args.sigma, rng) for i in range(6)]
                out = pool.run([(step.q, c) for c in new])
                population += list(zip(new, out, strict=True))
                refined = any(r.ok and r.p_data == step.p_to for r in out)
            for key in (step.step, f"{step.step} {kind}"):
                c = counts[key]
                c["n"] += 1
                c["more@6"] += any(hits[:6])
                c["more@18"] += any(hits)
                c["refine@18"] += refined
    print(
        f"shipped model; sigma {args.sigma} m; seed {args.seed}; "
        f"{len(steps)} steps from {', '.join(args.tree_sets)}"
    )
    print("| step | n | model@6 | 18 model curves | 6 model + 12 refined |")
    print("| --- | --- | --- | --- | --- |")
    for key in sorted(counts):
        c = counts[key]
        print(f"| {key} | {c['n']} | {c['more@6']} | {c['more@18']} | {c['refine@18']} |")
    print()
    print("| step | " + " | ".join(CLASSES) + " |")
    print("| --- |" + " --- |" * len(CLASSES))
    for step_name in args.steps:
        m = made[step_name]
        print(f"| {step_name} | " + " | ".join(str(m[c]) for c in CLASSES) + " |")


if __name__ == "__main__":
    main()
