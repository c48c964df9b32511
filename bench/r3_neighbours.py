"""Would R3 moves give the last step more places to start from? R3 on P-data, checked, and counted on
stored search trees.

    python bench/r3_neighbours.py --db sqlite:///tune.db [--set tune-u5] [--label L] [--check 4]

The high level's moves add or remove crossings (R1, R2, Cross; DESIGN 5.2). R3 keeps the count: a strand
slides across the crossing of two others, through a triangular face whose three sides are one strand
over both others, one under both and one between; on the P-data the two visits of each side swap. Here
it is defined on P-data only (the planner has no R3), and ``--check N`` first tests it on every state up
to N crossings: each R3 state is planar, is in the enumeration, and has the start among its own R3s.

Over the finished evaluation runs toward ``--set`` under ``--label`` (all when not given), per run: the
goal's R3 neighbours and those the tree holds; the goal's sub-states one crossing short (where a plan's
last step starts), those the tree holds, their R3 neighbours that are no sub-state and those the tree
holds (the extra starts an R3 step would give); then, over all trees, the kept results that changed
their parent's state without changing its crossings, and how many of them were an R3 of it.
"""

from __future__ import annotations

import argparse
from collections import Counter
from functools import cache

from step_moves import add_run_selection, finished_runs  # bench/ is this script's folder

from twisted.diagram import diagram
from twisted.moves import enumerate_states, sub_states
from twisted.store import open_store
from twisted.store.search import load_run
from twisted.topology import PData, PDataError, Visit


@cache  # asked again for the same states: each R3's inverse, every child's parent
def r3_states(p: PData) -> tuple[PData, ...]:
    """The states one R3 move from ``p`` (none when ``p`` cannot be drawn)."""
    try:
        d = diagram(p)
    except PDataError:
        return ()
    last, v = 2 * p.cross, p.visits
    out = []
    for face in d.faces:
        segments = [side.segment for side in face.sides]
        if len(face.sides) != 3 or len(set(segments)) != 3 or not all(0 < k < last for k in segments):
            continue  # a triangle of three inner segments
        ends = {q for k in segments for q in (k, k + 1)}
        if len(ends) != 6 or len({min(q, v[q - 1].partner) for q in ends}) != 3:
            continue  # three sides that meet in three distinct crossings
        marks = sorted(v[k - 1].over + v[k].over for k in segments)
        if marks[0] != "OO" or marks[-1] != "UU" or marks[1] not in ("OU", "UO"):
            continue  # one strand over both others, one under both: the middle one slides
        swap = {q: q for q in range(1, last + 1)}
        for k in segments:
            swap[k], swap[k + 1] = k + 1, k
        moved = sorted(
            (Visit(swap[x.position], x.over, swap[x.partner], x.sign) for x in v), key=lambda x: x.position
        )
        out.append(PData(tuple(moved)))
    return tuple(out)


def check(max_cross: int) -> None:
    every = enumerate_states(max_cross)
    for cross in range(1, max_cross + 1):
        known = set(every[cross])
        moves = with_r3 = 0
        for p in every[cross]:
            near = r3_states(p)
            for q in near:
                diagram(q)  # raises when the state cannot be drawn
                if q not in known or p not in r3_states(q):
                    raise AssertionError(f"R3 of {p.key} gave {q.key}: not enumerated, or not undone by R3")
            moves += len(near)
            with_r3 += bool(near)
        print(
            f"{cross} crossings: {len(known):,} states, {with_r3:,} with an R3, {moves:,} R3 moves, checked"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap)
    ap.add_argument("--check", type=int, default=4, help="check R3 on every state up to this many crossings")
    args = ap.parse_args()
    if not 0 <= args.check <= 4:
        ap.error("--check must lie in [0, 4]")
    check(args.check)

    changed: Counter[int] = Counter()
    r3: Counter[int] = Counter()
    with open_store(args.db) as store:
        run_ids = [run_id for run_id, _ in finished_runs(store, args.sets, args.labels)]
        print("| run | outcome | goal's R3 (held) | sub-states one short (held) | their other R3 (held) |")
        print("| --- | --- | --- | --- | --- |")
        for run_id in run_ids:
            info = load_run(store, run_id)
            if info is None:
                continue
            goal = info.goal.representative
            short = {p for p in sub_states(goal) if p.cross == goal.cross - 1}
            extra = set().union(*(r3_states(p) for p in short)) - short
            near = set(r3_states(goal))
            held = {node.p_data for node in info.nodes}
            print(
                f"| {run_id} | {info.outcome} | {len(near)} ({len(near & held)}) | {len(short)} "
                f"({len(short & held)}) | {len(extra)} ({len(extra & held)}) |"
            )
            nodes = {node.seq: node for node in info.nodes}
            for node in info.nodes:
                parent = nodes.get(node.parent_seq) if node.parent_seq is not None else None
                if parent is None or node.p_data == parent.p_data or node.p_data.cross != parent.p_data.cross:
                    continue
                changed[parent.p_data.cross] += 1
                r3[parent.p_data.cross] += node.p_data in r3_states(parent.p_data)
    print("\nkept results in another state of as many crossings as their parent, and of those an R3 of it:")
    for cross in sorted(changed):
        print(f"  from {cross}: {changed[cross]:,}, R3 {r3[cross]:,}")


if __name__ == "__main__":
    main()
