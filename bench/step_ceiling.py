"""Can the plan steps that stored searches failed be made at all? Many more of the planner's curves for each.

    python bench/step_ceiling.py --db sqlite:///tune.db --set tune-u5 --label cur --from 4 \
        [--pairs 20] [--steps 20] [--workers 2] [--seed 0] [--model-id N] [--json out.json]
    python bench/step_ceiling.py --db ... --set ... --label ... --from 4 --pairs 100 --save-pairs p.npz
    python bench/step_ceiling.py --pairs-file p.npz --steps 40 --workers 16     # on another machine

A search asks a node of its tree for the next state of a plan and draws K = 3 curves for it (a step,
DESIGN 8); its ``pair`` statistics keep, per (node, requested next state), the steps tried and those
that reached it. This draws ``--pairs`` pairs the stored runs tried from states of ``--from`` crossings
and never reached, uniformly, and as many they did reach, and gives each ``--steps`` more steps of the
planner's own curves (``StepCurves`` with the default options: a Cross step 2 scripted curves and 1 from
the model, any other step 3 from the model; the model of ``--model-id``, default the shipped one),
simulated from the node's configuration.

If a failed pair is reached by a few more steps, the search gave up on it too soon, or never came back;
if it is not reached by many, the configuration does not allow the move (as far as these curves go), and
the search has to pick another node or plan. Prints, per class of move (``bench/step_moves.py``'s
classes): pairs, the steps they had been tried, and the pairs reached within 1, 2, 5 and all new steps,
with the share of curves that reached, scripted and model apart.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from typing import Any

import numpy as np
from lib.steps import choose, move_class, pairs_from, step_curves

from twisted.moves import explains
from twisted.planner.options import PlannerOptions
from twisted.planner.tree import Node
from twisted.sim.pool import SimPool
from twisted.topology import parse_p_data

WITHIN = (1, 2, 5)


def save_pairs(path: str, chosen: list[dict[str, Any]], cross: int) -> None:
    """The chosen pairs as plain arrays and JSON text (no pickles): a file another machine runs."""
    np.savez_compressed(
        path,
        q=np.stack([p["node"].q for p in chosen]),
        points=np.stack([p["node"].points for p in chosen]),
        meta=np.array(
            json.dumps(
                {
                    "cross": cross,
                    "pairs": [
                        {
                            "run": p["run"],
                            "seq": p["node"].seq,
                            "from": p["node"].p_data.key,
                            "next": p["next"].key,
                            "tried": p["tried"],
                            "reached": p["reached"],
                            "group": p["group"],
                        }
                        for p in chosen
                    ],
                }
            )
        ),
    )


def load_pairs(path: str) -> tuple[list[dict[str, Any]], int]:
    with np.load(path, allow_pickle=False) as f:
        meta = json.loads(str(f["meta"]))
        q, points = f["q"], f["points"]
    out = []
    for i, p in enumerate(meta["pairs"]):
        start, nxt = parse_p_data(p["from"]), parse_p_data(p["next"])
        move = explains(start, nxt)
        node = Node(int(p["seq"]), None, q[i], points[i], start, None, 0, 0)
        out.append(dict(p, node=node, next=nxt, move=move))
    return out, int(meta["cross"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--db", help="store with the eval runs (and --model-id's model)")
    ap.add_argument("--set", action="append", dest="sets", default=[], help="problem set (repeatable)")
    ap.add_argument("--label", action="append", dest="labels", default=[], help="eval label (repeatable)")
    ap.add_argument("--from", type=int, dest="cross", help="crossings of the steps' start")
    ap.add_argument("--pairs", type=int, default=20, help="failed pairs drawn (and as many reached ones)")
    ap.add_argument("--save-pairs", help="write the drawn pairs to this .npz and stop (run them elsewhere)")
    ap.add_argument("--pairs-file", help="run the pairs of this .npz (from --save-pairs) instead of drawing")
    ap.add_argument("--steps", type=int, default=20, help="new steps of K curves per pair")
    ap.add_argument("--model-id", type=int, default=None, help="model in --db (default: the shipped one)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", help="write the figures to this file")
    args = ap.parse_args()
    if args.pairs < 1 or args.steps < 1:
        ap.error("--pairs and --steps must be at least 1")
    if args.pairs_file is None and not (args.db and args.sets and args.labels and args.cross is not None):
        ap.error("give --db, --set, --label and --from (or --pairs-file)")
    if args.model_id is not None and args.db is None:
        ap.error("--model-id needs --db")

    rng = np.random.default_rng(args.seed)
    if args.pairs_file:
        chosen, cross = load_pairs(args.pairs_file)
        print(f"{len(chosen)} pairs from {cross} crossings read from {args.pairs_file}")
    else:
        cross = args.cross
        pairs = pairs_from(args.db, args.sets, args.labels, cross)
        chosen = choose(pairs, args.pairs, rng)
        print(
            f"{len(pairs)} pairs tried from {cross} crossings in {', '.join(args.sets)} "
            f"({', '.join(args.labels)}): {sum(p['reached'] == 0 for p in pairs)} never reached; "
            f"{len(chosen)} drawn"
        )
        if args.save_pairs:
            save_pairs(args.save_pairs, chosen, cross)
            print(f"wrote {args.save_pairs}")
            return

    options, model_id = PlannerOptions(), args.model_id
    curves_of = step_curves(args.db, model_id)
    first: list[int | None] = [None] * len(chosen)
    counts = [[0, 0, 0, 0] for _ in chosen]  # scripted curves, their hits, model curves, their hits
    with SimPool(args.workers) as pool:
        for step in range(args.steps):  # one round: a step for every pair, simulated together
            batch, owner = [], []
            for i, pair in enumerate(chosen):
                curves, scripted = curves_of.propose(pair["node"], pair["next"], pair["move"], options.k, rng)
                batch += [(pair["node"].q, c) for c in curves]
                owner += [(i, j < scripted) for j in range(len(curves))]
            for (i, is_scripted), result in zip(owner, pool.run(batch), strict=True):
                hit = bool(result.ok and result.p_data == chosen[i]["next"])
                counts[i][0 if is_scripted else 2] += 1
                counts[i][1 if is_scripted else 3] += hit
                if hit and first[i] is None:
                    first[i] = step + 1
    rows: dict[tuple[str, str], dict[str, Any]] = defaultdict(
        lambda: {"pairs": 0, "tried": [], "first": [], "counts": [0, 0, 0, 0]}
    )
    for i, pair in enumerate(chosen):
        row = rows[(pair["group"], move_class(pair["move"], pair["node"].p_data))]
        row["pairs"] += 1
        row["tried"].append(pair["tried"])
        row["first"].append(first[i])
        row["counts"] = [a + b for a, b in zip(row["counts"], counts[i], strict=True)]
    which = f"model {model_id}" if model_id is not None else "the shipped model"
    print(f"{which}; K = {options.k}, scripted share {options.cross_move}; {args.steps} new steps per pair")
    print(
        "| pairs | move | n | steps tried before (median) | "
        + " | ".join(f"reached within {w}" for w in WITHIN)
        + f" | within {args.steps} | scripted curves hit | model curves hit |"
    )
    print("| --- | --- | --- | --- |" + " --- |" * (len(WITHIN) + 3))
    figures = []
    for (group, cls), row in sorted(rows.items()):
        firsts = [f for f in row["first"] if f is not None]
        within = [sum(f <= w for f in firsts) for w in WITHIN]
        c = row["counts"]
        rates = [f"{h} / {n}" + (f" ({h / n:.1%})" if n else "") for n, h in ((c[0], c[1]), (c[2], c[3]))]
        print(
            f"| {group} | {cls} | {row['pairs']} | {float(np.median(row['tried'])):.0f} | "
            + " | ".join(str(w) for w in within)
            + f" | {len(firsts)} | {rates[0]} | {rates[1]} |"
        )
        figures.append({"group": group, "move": cls, **row, "within": dict(zip(WITHIN, within, strict=True))})
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(
                {"args": vars(args), "model_id": model_id, "cross": cross, "rows": figures}, fh, indent=1
            )


if __name__ == "__main__":
    main()
