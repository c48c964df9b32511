"""Which plan steps succeed: follow_plan steps per crossing level and kind of move, from eval runs.

    python bench/step_moves.py --db sqlite:///collect.db --set v26-4 --label z-now [--level 3] [--detail]
        [--by origin|free]

For every finished evaluation result it reads the plan run's ``pair`` statistics (per node and
requested next state: the steps tried and those that reached it, DESIGN 8) and the tree's nodes, and
names each request by the move that makes it (``twisted.moves.explains``, the move the plan named).
Steps are grouped by the crossings of the state they start from and by a class of move that means the
same in every state: R1 on an end segment or an inner one, Cross of a tip over the other end segment
or over an inner one, R2. ``--detail`` groups by the move itself instead (segment numbers are those of
the state the move starts from, so one move there can name different physical acts in two states).
``--by origin`` splits each group by where its node came from: ``arrived`` (its parent is in another
state: a step or an expansion that changed the state), ``same`` (a curve from a node in the same state
that changed only the configuration) or ``root``. ``--by free`` splits it by the node's free rope: the
links from each end to its first crossing, summed (``twisted.proposals.segment_bounds``), in the bins
of :data:`FREE_BINS`. Prints steps tried, steps that reached their state, the distinct (node, next
state) pairs, goals and runs per group; --json writes the figures.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from typing import Any

import numpy as np
from lib.steps import add_run_selection, move_class, stored_pairs

from twisted.proposals import segment_bounds
from twisted.store import open_store
from twisted.store.search_tree import SearchRunInfo, StoredNode
from twisted.topology import PData

# --by free: upper bounds (links) of the free-rope bins
FREE_BINS = (2.0, 4.0, 6.0, 10.0, float("inf"))


def free_rope(points: Any) -> float:
    """Links of rope from each end to its first crossing, summed (the whole rope without crossings)."""
    bounds = segment_bounds(points)
    if len(bounds) == 2:  # no crossing: one segment, head to tail
        return float(bounds[1] - bounds[0])
    return float(bounds[1] - bounds[0] + bounds[-1] - bounds[-2])


def split_name(by: str | None, node: StoredNode, parent: PData | None, free: float) -> str:
    """The ``--by`` part of a group's name for a step from ``node`` (whose parent is in ``parent`` and
    whose free rope is ``free``)."""
    if by == "origin":
        return "root" if parent is None else "same" if parent == node.p_data else "arrived"
    if by == "free":
        upper = next(b for b in FREE_BINS if free <= b)
        lower = max([0.0, *(b for b in FREE_BINS if b < upper)])
        return f"free {lower:g}-{upper:g}" if upper != float("inf") else f"free > {lower:g}"
    return ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap)
    ap.add_argument("--level", type=int, action="append", help="only steps from states of N crossings")
    ap.add_argument("--detail", action="store_true", help="group by the move itself, not its class")
    ap.add_argument(
        "--by", choices=("origin", "free"), help="split each group by the node's origin or its free rope"
    )
    ap.add_argument("--json", help="write the figures to this file")
    args = ap.parse_args()

    groups: dict[tuple[int, str], dict[str, Any]] = defaultdict(
        lambda: {"steps": 0.0, "reached": 0.0, "pairs": 0, "goals": set(), "runs": set()}
    )
    parents: dict[int, PData] = {}  # --by origin: the state of each node's parent in the run being read

    def note_parents(info: SearchRunInfo) -> None:
        nodes = {node.seq: node for node in info.nodes}
        parents.clear()
        parents.update({n.seq: nodes[n.parent_seq].p_data for n in info.nodes if n.parent_seq is not None})

    free_by_level: dict[int, list[float]] = defaultdict(list)  # --by free: each pair's node
    with open_store(args.db) as store:
        pairs = stored_pairs(store, args.sets, args.labels, note_parents if args.by == "origin" else None)
        for run_id, goal_key, node, _, move, tried, reached in pairs:
            level = node.p_data.cross
            if args.level and level not in args.level:
                continue
            if move is None:
                continue
            name = str(move) if args.detail else move_class(move, node.p_data)
            if args.by:
                free = 0.0
                if args.by == "free":
                    free = free_rope(node.points)
                    free_by_level[level].append(free)
                name = f"{name}, {split_name(args.by, node, parents.get(node.seq), free)}"
            g = groups[(level, name)]
            g["steps"] += tried
            g["reached"] += reached
            g["pairs"] += 1
            g["goals"].add(goal_key)
            g["runs"].add(run_id)

    print(f"{'from':>4} {'move':60} {'steps':>7} {'reached':>8} {'rate':>6}", end="")
    print(f" {'pairs':>6} {'goals':>5} {'runs':>5}")
    figures = []
    for (level, name), g in sorted(groups.items(), key=lambda item: (item[0][0], -item[1]["steps"])):
        rate = g["reached"] / g["steps"] if g["steps"] else 0.0
        print(
            f"{level:>4} {name:60} {int(g['steps']):>7,} {int(g['reached']):>8,} {rate:>6.1%} "
            f"{g['pairs']:>6,} {len(g['goals']):>5} {len(g['runs']):>5}"
        )
        figures.append(
            {
                "level": level,
                "move": name,
                "steps": g["steps"],
                "reached": g["reached"],
                "pairs": g["pairs"],
                "goals": len(g["goals"]),
                "runs": len(g["runs"]),
            }
        )
    if args.by == "free":
        print(
            "median free rope (links) of the pairs' nodes: "
            + ", ".join(f"{np.median(f):.1f} from {level}" for level, f in sorted(free_by_level.items()))
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(figures, f, indent=1)


if __name__ == "__main__":
    main()
