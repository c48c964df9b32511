"""Is the simulated rope symmetric under a mirror (y -> -y) and under walking it backwards?

    python bench/mirror_paths.py --db sqlite:///tune.db --set tune-u5 --label L [--paths 30] [--curves 200]
        [--from 3] [--seed 0]

The inverse model's augmentations (``twisted.model.augment``) use two symmetries of the rope: the mirror
y -> -y (a curve ``(link, z, x, y)`` becomes ``(link, z, x, -y)``; every crossing sign flips) and the
reverse, the same physical rope with its links numbered from the other end (``(20 - link, z, x, y)``;
positions walk backwards), and both; ``mirror_state`` / ``reverse_state`` map a simulator state. If the
simulator were exactly symmetric, a mapped curve sequence from the mapped straight rope would pass through
the mapped states (the mirror maps the straight rope, along x, to itself), and a search that reached the
mirror image of its goal would have the goal too, by replaying its path mirrored (DESIGN 4.4).

1. ``--curves`` uniform random curves from the straight rope, each simulated as drawn and mapped from the
   mapped straight rope: how far the mapped result's link points lie from the mapped points of the result
   (median and largest, m), and in how many the mapped state is the state of the mapped curve.
2. ``--paths`` nodes of ``--from`` or more crossings drawn from the stored runs' trees (curve edges only):
   their paths from the root replayed mapped, from the mapped straight rope; a path holds when every step
   reaches the mapped state of its node. Prints the paths that held, and where the others first left.
"""

from __future__ import annotations

import argparse
from collections import Counter

import numpy as np
from step_moves import add_run_selection, finished_runs  # bench/ is this script's folder

from twisted.model.augment import (
    MIRROR,
    REVERSE,
    apply_variant_p_data,
    mirror_curve,
    mirror_points,
    mirror_state,
    reverse_curve,
    reverse_points,
    reverse_state,
)
from twisted.sim import Curve, RopeSim, sample_curve
from twisted.store import open_store
from twisted.store.search import load_run
from twisted.topology import PData

MAPS = {"mirror": MIRROR, "reverse": REVERSE, "both": MIRROR | REVERSE}  # augment's variant bits


def map_curve(curve: Curve, variant: int) -> Curve:
    """The curve that does to the mapped rope what ``curve`` does to the rope."""
    a = curve.to_array()
    a = mirror_curve(a) if variant & MIRROR else a
    return Curve.from_array(reverse_curve(a) if variant & REVERSE else a)


def map_points(points: np.ndarray, variant: int) -> np.ndarray:
    points = mirror_points(points) if variant & MIRROR else points
    return reverse_points(points) if variant & REVERSE else points


def map_state(sim: RopeSim, state: np.ndarray, variant: int) -> np.ndarray:
    state = mirror_state(sim, state) if variant & MIRROR else state
    return reverse_state(sim, state) if variant & REVERSE else state


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
    starts = {kind: map_state(sim, root, variant) for kind, variant in MAPS.items()}

    apart: dict[str, list[float]] = {kind: [] for kind in MAPS}
    same: Counter[str] = Counter()
    valid = 0
    for _ in range(args.curves):
        curve = sample_curve(rng)
        sim.set_state(root)
        if not sim.apply(curve).ok:
            continue
        points, p = sim.link_points(), sim.p_data()
        for kind, variant in MAPS.items():
            sim.set_state(starts[kind])
            if sim.apply(map_curve(curve, variant)).ok:
                apart[kind].append(float(np.abs(sim.link_points() - map_points(points, variant)).max()))
                same[kind] += sim.p_data() == apply_variant_p_data(p, variant)
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
        for kind, variant in MAPS.items():
            sim.set_state(starts[kind])
            for step, (curve, p) in enumerate(paths[int(i)]):
                ok = sim.apply(map_curve(curve, variant)).ok
                if not ok or sim.p_data() != apply_variant_p_data(p, variant):
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
