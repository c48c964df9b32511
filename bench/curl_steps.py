"""The scripted curl against the inverse model and random curves on the R1 steps of planner trees.

    python bench/curl_steps.py --db sqlite:///tune.db --tree-sets tune-u5 \
        --steps 1->2 2->3 3->4 4->5 --per-step 120 [--model-file new.pt] [--json out.json]

The steps are tree edges that add one crossing and that one R1 move explains, from the trees of the
stored runs towards the goals of the named problem sets (``twisted.model.success.tree_steps``: a
uniform draw of ``--draw`` edges per step, of which the R1 ones are kept, at most ``--per-step``).
For each, ``k`` curves of the scripted curl (``twisted.proposals.curl_move_curve``), ``k`` of the
model (the shipped one unless ``--model-file``) and ``k`` uniform random curves are simulated from
the parent's configuration; a step is solved by a proposer when one of its curves reaches the
child's state. Prints success@k and the share of curves that reached it, per proposer and step, and
success@k of the planner's mix: the first ``round(share * k)`` scripted curves and the first
``k - round(share * k)`` of the model's (``--curl-move share``).

Every edge was made once by the search that grew the tree (its model, its scripted Cross curve or a
random expansion), which favours that search's proposers over the scripted curl.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from twisted.model.network import InverseModel
from twisted.model.registry import load_model
from twisted.model.success import HeldOut, tree_steps
from twisted.moves import Move, explains
from twisted.proposals import curl_move_curve
from twisted.sim import sample_curve
from twisted.sim.pool import SimPool
from twisted.store import open_store

PROPOSERS = ("script", "model", "random")


def r1_steps(
    store_url: str, sets: list[str], steps: list[str], draw: int, per_step: int, rng: np.random.Generator
) -> dict[str, list[tuple[HeldOut, Move]]]:
    """At most ``per_step`` R1 steps of each step kind among ``draw`` tree edges drawn per step."""
    edges = tree_steps(open_store(store_url), sets, draw, rng, steps)
    out: dict[str, list[tuple[HeldOut, Move]]] = {step: [] for step in steps}
    for t in edges:
        move = explains(t.p_from, t.p_to)
        if move is not None and move.kind == "R1" and len(out[t.step]) < per_step:
            out[t.step].append((t, move))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--db", required=True, help="store with the planner runs")
    ap.add_argument(
        "--tree-sets", nargs="+", required=True, help="problem sets whose evaluations made the trees"
    )
    ap.add_argument("--steps", nargs="+", default=["2->3", "3->4", "4->5"])
    ap.add_argument("--per-step", type=int, default=120)
    ap.add_argument("--draw", type=int, default=2500, help="tree edges drawn per step before keeping R1 ones")
    ap.add_argument("--k", type=int, default=6)
    ap.add_argument(
        "--share", type=float, default=0.67, help="scripted share of the mix column (--curl-move)"
    )
    ap.add_argument("--model-file", help="the model saved in this file (default: the shipped model)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", help="write the figures to this file")
    args = ap.parse_args()

    if args.model_file:
        from pathlib import Path

        model = InverseModel.from_bytes(Path(args.model_file).read_bytes())
    else:
        model = load_model(None)
    rng = np.random.default_rng(args.seed)
    by_step = r1_steps(args.db, args.tree_sets, args.steps, args.draw, args.per_step, rng)
    k, rows = args.k, []
    print(f"R1 tree steps of {', '.join(args.tree_sets)} in {args.db}; k = {k}")
    scripted = int(round(args.share * k))
    heads = "".join(f" {p + '@' + str(k):>10s} {'per curve':>9s}" for p in PROPOSERS)
    mix = f"{'mix@' + str(k):>8s}  (mix: {scripted} scripted, {k - scripted} model)"
    print(f"{'step':6s} {'n':>4s}{heads} {mix}")
    t0 = time.perf_counter()
    with SimPool(args.workers) as pool:
        for step in args.steps:
            items = by_step[step]
            jobs = []
            for t, move in items:
                jobs += [(t.q, curl_move_curve(rng, t.points, move)) for _ in range(k)]
                jobs += [(t.q, c) for c in model.sample(t.points, t.q, t.p_to, k, rng, p_data=t.p_from)]
                jobs += [(t.q, sample_curve(rng)) for _ in range(k)]
            results = pool.run(jobs)
            solved = dict.fromkeys(PROPOSERS, 0)
            curves = dict.fromkeys(PROPOSERS, 0)
            mixed = 0
            for n, (t, _) in enumerate(items):
                block = results[3 * k * n : 3 * k * (n + 1)]
                hit = [r.ok and r.p_data == t.p_to for r in block]
                for j, name in enumerate(PROPOSERS):
                    solved[name] += any(hit[j * k : (j + 1) * k])
                    curves[name] += sum(hit[j * k : (j + 1) * k])
                # the planner's mix (--curl-move S): round(S * k) scripted curves, the rest the model's
                mixed += any(hit[:scripted]) or any(hit[k : 2 * k - scripted])
            n = max(len(items), 1)
            row: dict[str, object] = {"step": step, "n": len(items), "mix_at_k": mixed / n}
            for name in PROPOSERS:
                row[f"{name}_at_k"], row[f"{name}_per_curve"] = solved[name] / n, curves[name] / (k * n)
            rows.append(row)
            print(
                f"{step:6s} {len(items):4d}"
                + "".join(f" {row[f'{p}_at_k']:10.3f} {row[f'{p}_per_curve']:9.3f}" for p in PROPOSERS)
                + f" {mixed / n:8.3f}",
                flush=True,
            )
    print(f"{time.perf_counter() - t0:.0f} s")
    if args.json:
        with open(args.json, "w") as f:
            figures = {"db": args.db, "sets": args.tree_sets, "k": k, "share": args.share, "seed": args.seed}
            figures["rows"] = rows
            json.dump(figures, f, indent=1)


if __name__ == "__main__":
    main()
