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

``--simulate N`` then asks whether the steps with no fitting point can be made by one curve at all: for
``N`` pairs of each (crossings, over / under, fit class none or some) of the table (drawn with ``--seed``),
8 scripted Cross curves (``twisted.proposals.cross_move_curve``) and 8 curves near the move without the
sign rule (:func:`near_curve`: for "U" a link inside b carried to a point in a uniform direction and at a
uniform distance up to 10 cm from the tip, for "O" the tip's link or the next carried likewise up to 12 cm
from a uniformly drawn point of b) are simulated from the node's configuration (``--workers``
processes): the curves and the pairs that reached the requested state.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from typing import Any

import numpy as np
from step_moves import add_run_selection, segment_link, stored_pairs  # bench/ is this script's folder

from twisted.proposals import (
    CROSS_TIP_LINK_P,
    cross_fit,
    cross_move_curve,
    cross_reach,
    segment_bounds,
    segment_points,
)
from twisted.rope import N_LINKS
from twisted.sim import CURVE_HIGH, CURVE_LOW, Curve
from twisted.sim.pool import SimPool
from twisted.store import open_store

# upper edges of the --reach classes (lengths of the free piece)
REACH_BINS = (0.5, 1.0, 1.5, float("inf"))


def reach_class(reach: float) -> str:
    if reach == float("inf"):
        return "none"
    upper = next(b for b in REACH_BINS if reach < b)
    return f"<{upper:g}" if upper < float("inf") else f">={REACH_BINS[-2]:g}"


def near_curve(rng: np.random.Generator, points: Any, move: Any) -> Curve:
    """A curve near ``move`` (a Cross) that ignores which side makes its sign (see ``--simulate``)."""
    pts = np.asarray(points, dtype=np.float64)
    bounds = segment_bounds(pts)
    head = move.segment == 0
    angle, lift = rng.uniform(0.0, 2.0 * np.pi), rng.uniform(0.03, 0.07)
    if move.over == "U":
        link = segment_link(rng, pts, move.other_segment, bounds)
        target = (pts[0] if head else pts[-1])[:2] + rng.uniform(0.0, 0.10) * np.array(
            [np.cos(angle), np.sin(angle)]
        )
    else:
        end = 0 if head else N_LINKS - 1
        link = end if rng.random() < CROSS_TIP_LINK_P else end + (1 if head else -1)
        _, _, at, _ = segment_points(pts, bounds, move.other_segment)
        target = at[int(rng.integers(len(at))), :2] + rng.uniform(0.0, 0.12) * np.array(
            [np.cos(angle), np.sin(angle)]
        )
    x, y = np.clip(target - 0.5 * (pts[link, :2] + pts[link + 1, :2]), CURVE_LOW[2:], CURVE_HIGH[2:])
    return Curve(link, float(lift), float(x), float(y))


def simulate(pairs: dict[tuple[int, str, str], list[Any]], n: int, workers: int, seed: int) -> None:
    """The ``--simulate`` table over the (node, next state, move) ``pairs`` of each group."""
    rng = np.random.default_rng(seed)
    jobs, owner = [], []
    for group in sorted(pairs):
        items = pairs[group]
        for i in sorted(rng.choice(len(items), size=min(n, len(items)), replace=False)):
            node, nxt, move = items[int(i)]
            for name in ("scripted", "near"):
                for _ in range(8):
                    curve = (
                        cross_move_curve(rng, node.points, move)
                        if name == "scripted"
                        else near_curve(rng, node.points, move)
                    )
                    jobs.append((node.q, curve))
                    owner.append((group, name, int(i), nxt))
    hits: dict[tuple[Any, str], list[int]] = defaultdict(lambda: [0, 0])
    hit_pairs: dict[tuple[Any, str], set[int]] = defaultdict(set)
    with SimPool(workers) as pool:
        for (group, name, i, nxt), result in zip(owner, pool.run(jobs), strict=True):
            hits[(group, name)][0] += 1
            if result.ok and result.p_data == nxt:
                hits[(group, name)][1] += 1
                hit_pairs[(group, name)].add(i)
    print(f"\none curve per try, 8 of each kind per pair, seed {seed}")
    print("| from | over | fit | pairs (of) | scripted: reached | pairs | near: reached | pairs |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for group in sorted(pairs):
        drawn = min(n, len(pairs[group]))
        cells = []
        for name in ("scripted", "near"):
            tried, reached = hits[(group, name)]
            cells += [f"{reached} / {tried}", str(len(hit_pairs[(group, name)]))]
        print(
            f"| {group[0]} | {group[1]} | {group[2]} | {drawn} ({len(pairs[group])}) | "
            + " | ".join(cells)
            + " |"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap)
    ap.add_argument("--reach", action="store_true", help="split by over / under and the tip's reach instead")
    ap.add_argument("--simulate", type=int, default=0, metavar="N", help="simulate N pairs per group (above)")
    ap.add_argument("--workers", type=int, default=2, help="simulator processes for --simulate")
    ap.add_argument("--seed", type=int, default=0, help="the draw of --simulate")
    args = ap.parse_args()
    if args.simulate < 0 or args.workers < 1:
        ap.error("--simulate must be at least 0 and --workers at least 1")
    store = open_store(args.db)
    table: dict[tuple[int, str], list[float]] = defaultdict(lambda: [0, 0.0, 0.0])
    groups: dict[tuple[int, str, str], list[Any]] = defaultdict(list)  # --simulate's pairs
    seen = set()
    for run_id, _, node, nxt, move, tried, reached in stored_pairs(store, args.sets, args.labels):
        if move is None or move.kind != "Cross" or move.remove:
            continue
        fit = cross_fit(node.points, move)
        if args.reach:
            key = f"{move.over} {reach_class(cross_reach(node.points, move))}"
        else:
            key = "none" if fit == 0 else "all" if fit == 1 else "some"
        if args.simulate and fit < 1 and (run_id, node.seq, nxt.key) not in seen:
            seen.add((run_id, node.seq, nxt.key))
            groups[(node.p_data.cross, str(move.over), "none" if fit == 0 else "some")].append(
                (node, nxt, move)
            )
        row = table[(node.p_data.cross, key)]
        row[0] += 1
        row[1] += tried
        row[2] += reached
    head = "reach" if args.reach else "fit"
    print(f"{'from':>4s} {head:>8s} {'pairs':>6s} {'steps':>6s} {'reached':>8s} {'rate':>6s}")
    for (cross, key), (n_pairs, tried, reached) in sorted(table.items()):
        print(f"{cross:4d} {key:>8s} {n_pairs:6d} {tried:6.0f} {reached:8.0f} {reached / max(tried, 1):6.1%}")
    if args.simulate:
        simulate(groups, args.simulate, args.workers, args.seed)


if __name__ == "__main__":
    main()
