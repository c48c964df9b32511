"""success@6 of the inverse model on held-out transitions, per crossing step, next to 6 random curves.

    python bench/success_at_6.py --db sqlite:///collect.db [--model-id N] [--per-step 60] [--workers 2]
        [--steps 0->1 1->2 2->3 3->4 4->5 5->6] [--compare-default]
    python bench/success_at_6.py --db sqlite:///final.db --tree-sets final-u4 final-u5 \
        --model-file new.pt --compare-default --steps 3->4 4->5 5->6 --explained

For every held-out transition (the validation side of the model's split, plus transitions newer
than its data snapshot) 6 curves are sampled from the model for (q, next state) and 6 uniform
random curves are drawn; each is simulated from q (SimPool); the transition is solved when any
result has the next P-data. With --tree-sets the steps are instead the edges that add crossings of
the planner trees of the stored runs towards those sets' goals (twisted.model.success.tree_steps;
held out from any model trained elsewhere or with the sets held out).
With --compare-default the shipped default model samples 6 curves for
the same transitions too (its own column; the held-out set is the evaluated model's). Prints the
table and, with --json, writes the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from twisted.model.registry import load_model
from twisted.model.success import held_out_transitions, success_at_k, tree_steps
from twisted.sim.pool import SimPool
from twisted.store import open_store


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--db", required=True, help="store with transitions (and the model, unless --default)")
    ap.add_argument("--model-id", type=int, default=None, help="model id in the store (default: newest)")
    ap.add_argument("--default", action="store_true", help="evaluate the shipped default model")
    ap.add_argument("--model-file", help="evaluate the model saved in this file (torch.save bytes)")
    ap.add_argument("--per-step", type=int, default=60)
    ap.add_argument("--k", type=int, default=6)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--random-curves",
        type=int,
        default=None,
        help="random curves per transition (>= k) for a less noisy random baseline",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--steps", nargs="+", default=["0->1", "1->2", "2->3", "+2"])
    ap.add_argument(
        "--explained",
        action="store_true",
        help="only transitions that one high-level move explains (what the planner asks the model for)",
    )
    ap.add_argument(
        "--compare-default", action="store_true", help="also the shipped default model, same transitions"
    )
    ap.add_argument(
        "--tree-sets",
        nargs="+",
        default=None,
        help="take the steps from the planner trees of the runs towards these problem sets' goals",
    )
    ap.add_argument("--json", help="write the figures to this file")
    ap.add_argument("--oversample", type=int, default=None, help="override the model's sampling setting")
    ap.add_argument("--link-temperature", type=float, default=None, help="override the model's setting")
    ap.add_argument(
        "--side",
        choices=("held_out", "train", "all"),
        default="held_out",
        help="train: the model's own training transitions (a check of the pipeline)",
    )
    args = ap.parse_args()

    store = open_store(args.db)
    if args.model_file:
        from pathlib import Path

        from twisted.model.network import InverseModel

        model = InverseModel.from_bytes(Path(args.model_file).read_bytes())
    else:
        model = load_model(None if args.default else store, args.model_id)
    if args.oversample is not None:
        model.oversample = args.oversample
    if args.link_temperature is not None:
        model.link_temperature = args.link_temperature
    rng = np.random.default_rng(args.seed)
    if args.tree_sets:
        held = tree_steps(store, args.tree_sets, args.per_step, rng, args.steps, explained=args.explained)
    elif args.explained:
        from twisted.moves import explains

        # draw from every held-out transition, keep the explained ones, at most per_step of each step
        pool = held_out_transitions(store, model, 10**9, rng, steps=args.steps, side=args.side)
        pool = [t for t in pool if explains(t.p_from, t.p_to) is not None]
        held = []
        for step in args.steps:
            of_step = [t for t in pool if t.step == step]
            if len(of_step) > args.per_step:
                of_step = [of_step[i] for i in sorted(rng.choice(len(of_step), args.per_step, replace=False))]
            held += of_step
    else:
        held = held_out_transitions(store, model, args.per_step, rng, steps=args.steps, side=args.side)
    source = f"tree steps of {', '.join(args.tree_sets)}" if args.tree_sets else f"{args.side} transitions"
    meta = model.metadata
    print(
        f"model {model.model_id if model.model_id is not None else 'default'}: trained on "
        f"{meta.get('data_size')} transitions, val metrics {meta.get('metrics', {}).get('val_loss')}; "
        f"{len(held)} {source} from {args.db}; sampling: oversample {model.oversample}, "
        f"link temperature {model.link_temperature}"
    )
    t0 = time.perf_counter()
    shipped = None
    with SimPool(args.workers) as pool:
        results = success_at_k(model, held, pool, rng, k=args.k, random_curves=args.random_curves)
        if args.compare_default:
            default = load_model(None)
            shipped = success_at_k(default, held, pool, np.random.default_rng(args.seed + 1), args.k, 0)
    wall = time.perf_counter() - t0
    k = args.k
    print(
        f"{'step':6s} {'n':>5s} {'model@' + str(k):>9s} {'se':>6s} {'random@' + str(k):>10s} {'ratio':>6s}"
        f" {'random@' + str(k) + ' expected':>18s} {'ratio':>6s}"
        + (f" {'shipped@' + str(k):>10s}" if shipped is not None else "")
    )
    rows = []
    for step in args.steps:
        r = results.get(step)
        if r is None:
            print(f"{step:6s} {0:5d} {'-':>9s} {'-':>6s} {'-':>10s} {'-':>6s}")
            continue
        ratio = r.model_rate / r.random_rate if r.solved_random else float("nan")
        ratio_expected = r.model_rate / r.random_expected if r.random_expected > 0 else float("nan")
        shipped_rate = shipped[step].model_rate if shipped is not None else None
        se = math.sqrt(r.model_rate * (1.0 - r.model_rate) / r.n)  # binomial standard error of model@k
        print(
            f"{step:6s} {r.n:5d} {r.model_rate:9.3f} {se:6.3f} {r.random_rate:10.3f} {ratio:6.2f}"
            f" {r.random_expected:18.3f} {ratio_expected:6.2f}"
            + (f" {shipped_rate:10.3f}" if shipped_rate is not None else "")
        )
        rows.append(
            {
                "step": step,
                "n": r.n,
                "model": r.model_rate,
                "model_se": se,
                "random": r.random_rate,
                "random_expected": r.random_expected,
                "random_curves": r.random_curves,
                "solved_model": r.solved_model,
                "solved_random": r.solved_random,
                "shipped": shipped_rate,
            }
        )
    sims = sum((k + r.random_curves) * r.n for r in results.values())
    sims += sum(k * r.n for r in shipped.values()) if shipped is not None else 0
    print(
        f"{sims} simulations in {wall:.0f} s on {args.workers} workers; 'random@{k} expected' estimates each "
        f"transition's per-curve hit rate p from all its random curves: mean(1 - (1 - p)^{k}); 'se' is the "
        f"standard error of model@{k}, sqrt(p (1 - p) / n); the gap between two models' rates has a standard "
        "error of about sqrt(se1^2 + se2^2)"
    )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(
                {
                    "db": args.db,
                    "model_id": model.model_id,
                    "k": args.k,
                    "steps_from": source,
                    "rows": rows,
                    "metadata": {k: v for k, v in meta.items() if k != "parameters"},
                },
                fh,
                indent=2,
            )


if __name__ == "__main__":
    main()
