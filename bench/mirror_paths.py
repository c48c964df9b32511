"""Is the simulated rope symmetric under a mirror (y -> -y) and under walking it backwards?

    python bench/mirror_paths.py --db sqlite:///tune.db --set tune-u5 --label L [--paths 30] [--curves 200]
        [--from 3] [--seed 0]

The straight rope (``RopeSim.reset``) lies along x, centred on the origin, so two maps take it to itself:
the mirror y -> -y (a curve ``(link, z, x, y)`` becomes ``(link, z, x, -y)``; every crossing sign flips,
``PData.mirror``) and the half turn about z with the links numbered from the other end (``(20 - link, z,
-x, -y)``; positions walk backwards, ``PData.reverse``), and both. If the simulator were exactly
symmetric, a mapped curve sequence from the straight rope would pass through the mapped states, and a
search that reached the mirror image of its goal would have the goal too, by replaying its path mirrored
(DESIGN 2, 4.4; the inverse model's augmentations use both maps).

1. ``--curves`` uniform random curves from the straight rope, each simulated as drawn and mapped: how
   far the mapped result's link points lie from the mapped points of the result (median and largest, m),
   and in how many the mapped state is the state of the mapped curve.
2. ``--paths`` nodes of ``--from`` or more crossings drawn from the stored runs' trees (curve edges only):
   their paths from the root replayed mapped, from the straight rope; a path holds when every step
   reaches the mapped state of its node. Prints the paths that held, and where the others first left.
"""

from __future__ import annotations

import argparse
from collections import Counter

import numpy as np
from step_moves import add_run_selection, finished_runs  # bench/ is this script's folder

from twisted.rope import N_LINKS
from twisted.sim import Curve, RopeSim, sample_curve
from twisted.store import open_store
from twisted.store.search import load_run
from twisted.topology import PData

MAPS = ("mirror", "reverse", "both")


def map_curve(curve: Curve, kind: str) -> Curve:
    """The curve that does to the mapped rope what ``curve`` does to the rope."""
    if kind == "mirror":
        return Curve(curve.link, curve.z_max_m, curve.x_m, -curve.y_m)
    if kind == "reverse":
        return Curve(N_LINKS - 1 - curve.link, curve.z_max_m, -curve.x_m, -curve.y_m)
    return Curve(N_LINKS - 1 - curve.link, curve.z_max_m, -curve.x_m, curve.y_m)


def map_state(p: PData, kind: str) -> PData:
    return p.mirror() if kind == "mirror" else p.reverse() if kind == "reverse" else p.mirror().reverse()


def map_points(points: np.ndarray, kind: str) -> np.ndarray:
    if kind == "mirror":
        return points * [1.0, -1.0, 1.0]
    if kind == "reverse":
        return points[::-1] * [-1.0, -1.0, 1.0]
    return points[::-1] * [-1.0, 1.0, 1.0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap, required=True)
    ap.add_argument("--paths", type=int, default=30, help="stored paths replayed per map")
    ap.add_argument("--curves", type=int, default=200, help="random curves from the straight rope")
    ap.add_argument("--from", type=int, default=3, dest="level", help="least crossings of a path's end")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.paths < 0 or args.curves < 0:
        ap.error("--paths and --curves must not be negative")
    rng = np.random.default_rng(args.seed)
    sim = RopeSim()
    sim.reset()
    root = sim.state()
    straight = sim.link_points()
    off = {kind: float(np.abs(map_points(straight, kind) - straight).max()) for kind in MAPS}
    print("the straight rope mapped lies on itself to " + ", ".join(f"{k} {v:.1e} m" for k, v in off.items()))

    apart: dict[str, list[float]] = {kind: [] for kind in MAPS}
    same: Counter[str] = Counter()
    valid = 0
    for _ in range(args.curves):
        curve = sample_curve(rng)
        sim.set_state(root)
        if not sim.apply(curve).ok:
            continue
        points, p = sim.link_points(), sim.p_data()
        for kind in MAPS:
            sim.set_state(root)
            if sim.apply(map_curve(curve, kind)).ok:
                apart[kind].append(float(np.abs(sim.link_points() - map_points(points, kind)).max()))
                same[kind] += sim.p_data() == map_state(p, kind)
        valid += 1
    print(f"\n{valid} valid random curves from the straight rope, seed {args.seed}")
    print("| map | mapped state reached | points apart, median | largest |")
    print("| --- | --- | --- | --- |")
    for kind in MAPS:
        gap = np.array(apart[kind]) if apart[kind] else np.array([np.nan])
        print(f"| {kind} | {same[kind]} / {valid} | {np.median(gap):.1e} m | {gap.max():.1e} m |")

    paths: list[list[tuple[Curve, PData]]] = []
    with open_store(args.db) as store:
        for run_id, _ in finished_runs(store, args.sets, args.labels):
            info = load_run(store, run_id)
            if info is None:
                continue
            nodes = {n.seq: n for n in info.nodes}
            for n in info.nodes:
                if n.p_data.cross < args.level:
                    continue
                path, m = [], n
                while m.parent_seq is not None and m.curve is not None and m.action == "curve":
                    path.append((Curve(*m.curve), m.p_data))
                    m = nodes[m.parent_seq]
                if m.parent_seq is None:  # a path of curves all the way from the root
                    paths.append(path[::-1])
    held: Counter[str] = Counter()
    left: dict[str, Counter[int]] = {kind: Counter() for kind in MAPS}
    picked = rng.choice(len(paths), size=min(args.paths, len(paths)), replace=False) if paths else []
    for i in picked:
        for kind in MAPS:
            sim.set_state(root)
            for step, (curve, p) in enumerate(paths[int(i)]):
                if not sim.apply(map_curve(curve, kind)).ok or sim.p_data() != map_state(p, kind):
                    left[kind][step + 1] += 1
                    break
            else:
                held[kind] += 1
    lengths = [len(paths[int(i)]) for i in picked]
    print(
        f"\n{len(picked)} stored paths to nodes of {args.level}+ crossings (of {len(paths)}), "
        f"median {np.median(lengths) if lengths else 0:.0f} curves, seed {args.seed}"
    )
    print("| map | paths that held | first step that left, median |")
    print("| --- | --- | --- |")
    for kind in MAPS:
        steps = sorted(left[kind].elements())
        print(f"| {kind} | {held[kind]} / {len(picked)} | {np.median(steps) if steps else '-'} |")


if __name__ == "__main__":
    main()
