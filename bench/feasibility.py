"""How well the feasibility model ranks the plan steps of stored searches it never trained on.

    python bench/feasibility.py --db sqlite:///final.db --sets final-u4 final-u5 [--model-file F]

Reads the pair statistics (per node and requested next state: plan steps tried and reached) of the
stored runs toward the sets' goals (``twisted.model.feasibility.pair_samples``), scores every pair with
the model (default the shipped ``twisted/data/default_feasibility.pt``) and prints per move kind and
crossing count of the start state: pairs, steps tried and reached, the rate, the AUC (the probability
that a reaching step scores above a failing one), and the rate among the steps of the best-scored 10 %
and 25 % of the steps and of the worse half. A search that drew its steps from the top decile would
reach its states that many times as often.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from twisted.model.feasibility import (
    Feasibility,
    auc,
    geometry_features,
    load_default_feasibility,
    pair_samples,
)
from twisted.store import open_store


def rate_of_best(score: np.ndarray, tried: np.ndarray, reached: np.ndarray, share: float) -> float:
    """The rate of the steps of the best-scored pairs that hold ``share`` of the steps."""
    order = np.argsort(-score, kind="stable")
    steps, hits = np.cumsum(tried[order]), np.cumsum(reached[order])
    k = int(np.searchsorted(steps, share * steps[-1]))
    return float(hits[k] / steps[k])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--db", required=True)
    ap.add_argument("--sets", nargs="+", required=True, help="runs toward these stored sets' goals")
    ap.add_argument("--model-file", help="a model written by `twisted train-feasibility` (default: shipped)")
    ap.add_argument("--json", help="write the figures to this file")
    args = ap.parse_args()
    model = Feasibility.from_bytes(Path(args.model_file).read_bytes()) if args.model_file else None
    model = model or load_default_feasibility()
    samples = pair_samples(open_store(args.db, readonly=True), only_sets=args.sets)
    if not len(samples):
        raise SystemExit(f"no stored search toward {', '.join(args.sets)} has pair statistics")
    x = torch.cat([geometry_features(samples.points), samples.steps], dim=1)
    model.net.eval()
    with torch.no_grad():
        score = torch.sigmoid(model.net(x)).numpy()
    groups = np.array(samples.group)
    rows = []
    print("| start | pairs | steps | reached | rate | AUC | rate, best 10 % | best 25 % | worse half |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for g in sorted(set(groups.tolist()), key=lambda g: (int(g.split("|")[1]), g)):
        m = groups == g
        t, r = samples.tried[m], samples.reached[m]
        if t.sum() < 50:
            continue
        area = auc(score[m], t, r)
        row = {
            "group": g,
            "pairs": int(m.sum()),
            "tried": int(t.sum()),
            "reached": int(r.sum()),
            "rate": float(r.sum() / t.sum()),
            "auc": area,
            "best10": rate_of_best(score[m], t, r, 0.1) if r.sum() else 0.0,
            "best25": rate_of_best(score[m], t, r, 0.25) if r.sum() else 0.0,
        }
        order = np.argsort(-score[m], kind="stable")
        steps, hits = np.cumsum(t[order]), np.cumsum(r[order])
        half = int(np.searchsorted(steps, 0.5 * steps[-1]))
        row["worse_half"] = float((hits[-1] - hits[half]) / max(steps[-1] - steps[half], 1.0))
        rows.append(row)
        kind, cross = g.split("|")
        shown = "-" if area is None else f"{area:.3f}"
        print(
            f"| {kind} from {cross} | {row['pairs']:,} | {row['tried']:,} | {row['reached']:,} | "
            f"{row['rate']:.4f} | {shown} | {row['best10']:.4f} | {row['best25']:.4f} | "
            f"{row['worse_half']:.4f} |"
        )
    if args.json:
        Path(args.json).write_text(json.dumps({"sets": args.sets, "groups": rows}, indent=1))


if __name__ == "__main__":
    main()
