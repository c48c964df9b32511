"""Which Cross steps can a straight carry make? The stored searches' Cross steps by the node's sign fit.

    python bench/cross_fit.py --db sqlite:///tune.db --set tune-u5 [--label L ...] [--reach]

A Cross move lays the tip of an end segment over or under segment b with a given sign; which sign a
straight carry of the tip makes depends on the side of b the tip starts from. ``twisted.proposals.
cross_fit`` is the share of the points of b that a straight approach from the tip crosses with the
move's sign (the points the scripted Cross curve aims at). This reads every (node, requested next state)
pair of the stored runs (``bench/step_moves.py``'s ``stored_pairs``) whose step one adding Cross move
explains, and prints, per crossing count and fit class (none: 0, some, all: 1), the pairs, the steps
tried and those that reached their state.

``--reach`` splits them instead by over / under and by ``twisted.proposals.cross_reach``: how far the tip
is from the nearest fitting point of b, in lengths of the end's free piece (tip to first crossing);
none: no point fits (the fit class none).
"""

from __future__ import annotations

import argparse
from collections import defaultdict

from step_moves import add_run_selection, stored_pairs  # bench/ is this script's folder

from twisted.proposals import cross_fit, cross_reach
from twisted.store import open_store

# upper edges of the --reach classes (lengths of the free piece)
REACH_BINS = (0.5, 1.0, 1.5, float("inf"))


def reach_class(reach: float) -> str:
    if reach == float("inf"):
        return "none"
    upper = next(b for b in REACH_BINS if reach < b)
    return f"<{upper:g}" if upper < float("inf") else f">={REACH_BINS[-2]:g}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap)
    ap.add_argument("--reach", action="store_true", help="split by over / under and the tip's reach instead")
    args = ap.parse_args()
    store = open_store(args.db)
    table: dict[tuple[int, str], list[float]] = defaultdict(lambda: [0, 0.0, 0.0])
    for _, _, node, _, move, tried, reached in stored_pairs(store, args.sets, args.labels):
        if move is None or move.kind != "Cross" or move.remove:
            continue
        if args.reach:
            key = f"{move.over} {reach_class(cross_reach(node.points, move))}"
        else:
            fit = cross_fit(node.points, move)
            key = "none" if fit == 0 else "all" if fit == 1 else "some"
        row = table[(node.p_data.cross, key)]
        row[0] += 1
        row[1] += tried
        row[2] += reached
    head = "reach" if args.reach else "fit"
    print(f"{'from':>4s} {head:>8s} {'pairs':>6s} {'steps':>6s} {'reached':>8s} {'rate':>6s}")
    for (cross, key), (pairs, tried, reached) in sorted(table.items()):
        print(f"{cross:4d} {key:>8s} {pairs:6d} {tried:6.0f} {reached:8.0f} {reached / max(tried, 1):6.1%}")


if __name__ == "__main__":
    main()
