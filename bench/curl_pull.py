"""Can one pull make a curl on a stored search's rope tighter, and free rope for the next move?

    python bench/curl_pull.py --db sqlite:///tune.db --set tune-u5 --label L [--from 3 --from 4]
        [--per-run 5] [--seed 0]

The goals the searches fail have curls, and at the loop sizes the searches make a goal with three curls
needs more than the 21 links (docs/goals.md, "Finding the bottleneck"). A curl made loose stays loose
unless something pulls it shut. This asks whether the planner's own action can: from up to ``--per-run``
tree nodes a run (drawn uniformly, with ``--seed``) of ``--from`` crossings that have a curl on an inner
segment, it picks one such curl and pulls on the rope beside it, away from the loop along the rope: the
grasped link is the first (``k = 1``) or the second (``k = 2``) whole link past the curl's crossing on
the head side (``before``) or the tail side (``after``), carried ``d`` = 2, 4 or 7 cm in the direction
its link points away from the loop, at the smallest lift (a plain :class:`twisted.sim.Curve`, simulated
by :class:`twisted.sim.RopeSim`). Prints, per crossings, side, k and d: the pulls, those that left the
node's state as it was, those of these that shortened the loop by half a link or more, and the median
change of the loop (links) and of the free rope (``step_moves.free_rope``: links from each end to its first
crossing, summed).
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from typing import Any

import numpy as np
from bottleneck import curl_segments  # bench/ is this script's folder
from step_moves import add_run_selection, finished_runs, free_rope

from twisted.proposals import segment_bounds
from twisted.rope import N_LINKS
from twisted.sim import Curve, RopeSim
from twisted.store import open_store
from twisted.store.search import load_run
from twisted.topology import PData

SIDES = ("before", "after")
LINKS_PAST = (1, 2)
PULLS_M = (0.02, 0.04, 0.07)


def inner_curls(p: PData) -> list[int]:
    """The inner segments (not the two end segments) that are a curl's loop."""
    return sorted(s for s in curl_segments(p) if 0 < s < 2 * p.cross)


def pull(points: Any, bounds: Any, segment: int, side: str, k: int, d: float) -> Curve | None:
    """The pull on link ``k`` past curl ``segment``'s crossing on ``side``, ``d`` metres away from the loop
    along its link; None when that link is off the rope."""
    if side == "after":
        link = int(np.ceil(bounds[segment + 1])) + k - 1
        if link > N_LINKS - 1:
            return None
        direction = points[link + 1] - points[link]
    else:
        link = int(np.floor(bounds[segment])) - k
        if link < 0:
            return None
        direction = points[link] - points[link + 1]
    xy = direction[:2] / max(float(np.linalg.norm(direction[:2])), 1e-9)
    return Curve(link, 0.0, float(xy[0] * d), float(xy[1] * d))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap, required=True)
    ap.add_argument("--from", type=int, action="append", dest="levels", help="crossings of the nodes")
    ap.add_argument("--per-run", type=int, default=5, help="nodes drawn per run and crossing count")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.per_run < 1:
        ap.error("--per-run must be at least 1")
    levels = sorted(set(args.levels or [3, 4]))
    rng = np.random.default_rng(args.seed)
    sim = RopeSim()
    rows: dict[tuple[int, str, int, float], dict[str, Any]] = defaultdict(
        lambda: {"pulls": 0, "same": 0, "shorter": 0, "loop": [], "free": []}
    )
    with open_store(args.db) as store:
        for run_id, _ in finished_runs(store, args.sets, args.labels):
            info = load_run(store, run_id)
            if info is None:
                continue
            for level in levels:
                candidates = []
                for node in info.nodes:
                    if node.p_data.cross != level or not inner_curls(node.p_data):
                        continue
                    bounds = segment_bounds(node.points)
                    if len(bounds) == 2 * level + 2:  # a tie in the projection: the bounds do not match
                        candidates.append((node, bounds))
                if not candidates:
                    continue
                picks = rng.choice(len(candidates), size=min(args.per_run, len(candidates)), replace=False)
                for i in sorted(int(i) for i in picks):
                    node, bounds = candidates[i]
                    segment = int(rng.choice(inner_curls(node.p_data)))
                    loop = bounds[segment + 1] - bounds[segment]
                    for side in SIDES:
                        for k in LINKS_PAST:
                            for d in PULLS_M:
                                curve = pull(node.points, bounds, segment, side, k, d)
                                if curve is None:
                                    continue
                                row = rows[(level, side, k, d)]
                                row["pulls"] += 1
                                sim.set_state(node.q)
                                if not sim.apply(curve).ok or sim.p_data() != node.p_data:
                                    continue
                                points = sim.link_points()
                                after = segment_bounds(points)
                                row["same"] += 1
                                change = after[segment + 1] - after[segment] - loop
                                row["shorter"] += change <= -0.5
                                row["loop"].append(change)
                                row["free"].append(free_rope(points) - free_rope(node.points))

    def median(values: list[float]) -> str:
        return f"{np.median(values):+.2f}" if values else "-"

    print(f"pulls beside an inner curl, up to {args.per_run} nodes a run, seed {args.seed} (changes: median)")
    print("| from | side | k | d (m) | pulls | same state | loop 0.5+ shorter | loop change | free change |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for (level, side, k, d), row in sorted(rows.items()):
        print(
            f"| {level} | {side} | {k} | {d:g} | {row['pulls']} | {row['same']} | {row['shorter']} | "
            f"{median(row['loop'])} | {median(row['free'])} |"
        )


if __name__ == "__main__":
    main()
