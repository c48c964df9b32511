"""Do scripted R2 curves make the R2 steps of stored searches more often than the planner's own curves?

    python bench/r2_steps.py --db sqlite:///tune.db --set tune-u5 --label L [--from 1 --from 2 --from 3] \
        [--pairs 60] [--k 6] [--workers 2] [--seed 0]

An R2 step pushes a bight of one segment across another and adds two crossings at once; from three
crossings it makes a five-crossing goal in one step, where the other plans need a step from four (log,
2026-12-05). The planner draws an R2 step's curves from the inverse model. For ``--pairs`` (node, next
state) pairs per crossing count drawn from the stored runs' R2 steps (``bench/step_moves.py``'s
``stored_pairs``: every step the searches asked for), this simulates ``--k`` curves of the planner's
(``StepCurves`` with today's options) and ``--k`` scripted ones (``r2_move_curve`` below) from
the node's configuration, and prints per crossing count the curves that reached the next state, the
pairs with at least one such curve, and where the other curves went (fewer crossings, the node's own
state, another state, rejected by the simulator), and the other states by the crossings they added.
The scripted curve is defined here; in the planner (two of an R2 step's three curves) it solved fewer
tuning goals, and it was not kept.
"""

from __future__ import annotations

import argparse
from collections import Counter, defaultdict
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
from step_moves import add_run_selection, step_groups  # bench/ is this script's folder

from twisted.model.registry import load_model
from twisted.model.sampler import ModelCurves
from twisted.planner.options import PlannerOptions
from twisted.planner.strategies import StepCurves
from twisted.planner.tree import Node
from twisted.proposals import CROSS_BEYOND_M, CROSS_LIFT_M, segment_bounds, segment_points
from twisted.sim import CURVE_HIGH, CURVE_LOW, Curve
from twisted.sim.pool import SimPool
from twisted.store import open_store
from twisted.topology import PData, cross2

OUTCOMES = ("reached", "fewer", "same", "other", "rejected")
PLANNER_K = PlannerOptions().k  # the curves of one of the planner's steps (its default K)


# -- the scripted R2 curve (here only: it was not kept in the planner, log 2026-12-05) -----------------------

# How sharply nearer pairs of points are preferred (m), and the least rope between the two points when
# both lie on one segment (in links).
R2_REACH_M = 0.1
R2_SAME_SEGMENT_GAP = 2.0
R2_SQUARE_POWER = 2.0


class R2Move(Protocol):
    """What :func:`r2_move_curve` reads of a ``twisted.moves.Move`` of kind ``R2`` (read-only, as a frozen
    ``Move`` has them)."""

    @property
    def segment(self) -> int: ...
    @property
    def side(self) -> str | None: ...
    @property
    def other_segment(self) -> int | None: ...
    @property
    def other_side(self) -> str | None: ...
    @property
    def over(self) -> str | None: ...


def _segment_points(
    pts: npt.NDArray[np.float64], bounds: npt.NDArray[np.float64], segment: int, n: int = 30
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """``n`` points along a P-data segment, clear of its crossings: rope parameters, links, points (x, y)
    and the rope's walking direction there (unit, x, y)."""
    s, link_of, at, along = segment_points(pts, bounds, segment, n)
    along = along[:, :2] / np.maximum(np.hypot(along[:, 0], along[:, 1]), 1e-9)[:, None]
    return s, link_of, at[:, :2], along


def r2_move_curve(rng: np.random.Generator, points: npt.ArrayLike, move: R2Move) -> Curve:
    """A curve aimed at making ``move`` (an ``R2``) from the rope with these N_POINTS link points.

    The move pushes the piece E of segment a (leaving it on its side ``side``) across the piece F of
    segment b (met from its side ``other_side``), E over F for ``over`` "O". The script looks at pairs of
    points, one on each segment, such that the straight line from E's point to F's point leaves a on
    that side and meets b from that side, nearer pairs more often (any pair where none does), and carries
    a bight across: for "O" E's link, lifted past F's point; for "U" F's link, lifted past E's point.
    Geometry only, like ``twisted.proposals.cross_move_curve``; the simulator says what it made."""
    if move.other_segment is None or move.over not in ("O", "U") or move.side not in ("L", "R"):
        raise ValueError(f"not an R2 move: {move}")
    pts = np.asarray(points, dtype=np.float64)
    bounds = segment_bounds(pts)
    a, b = move.segment, move.other_segment
    if not (0 <= a < len(bounds) - 1 and 0 <= b < len(bounds) - 1):
        raise ValueError(f"{move} does not fit a rope with {len(bounds) // 2 - 1} crossings")
    s_e, link_e, at_e, along_e = _segment_points(pts, bounds, a)
    s_f, link_f, at_f, along_f = _segment_points(pts, bounds, b)
    d = at_f[None, :, :] - at_e[:, None, :]  # (E point, F point)
    dist = np.hypot(d[..., 0], d[..., 1]) + 1e-9
    u = d / dist[..., None]
    leaves = np.sign(cross2(along_e[:, None, :], u)) == (1 if move.side == "L" else -1)
    meets = np.sign(cross2(along_f[None, :, :], -d)) == (1 if move.other_side == "L" else -1)
    fits = leaves & meets
    if a == b:  # E is the earlier piece of the segment, and some rope lies between the two
        fits &= (s_f[None, :] - s_e[:, None]) >= R2_SAME_SEGMENT_GAP
    # a bight carried square to both strands crosses F twice near F's point, rather than sliding along
    square = np.abs(cross2(along_e[:, None, :], u) * cross2(along_f[None, :, :], u)) ** R2_SQUARE_POWER
    allowed = fits if fits.any() else np.ones_like(fits)
    weights = np.exp(-dist / R2_REACH_M) * square * allowed
    if not weights.sum() > 0:  # every allowed pair far away, or carried along a strand
        weights = allowed.astype(np.float64)
    flat = weights.ravel() / weights.sum()
    i, j = np.unravel_index(int(rng.choice(flat.size, p=flat)), weights.shape)
    beyond = rng.uniform(*CROSS_BEYOND_M)
    lift = rng.uniform(*CROSS_LIFT_M)
    if move.over == "O":
        link = int(link_e[i])
        target = at_f[j] + beyond * u[i, j]
    else:
        link = int(link_f[j])
        target = at_e[i] - beyond * u[i, j]
    centre = 0.5 * (pts[link, :2] + pts[link + 1, :2])
    x, y = np.clip(target - centre, CURVE_LOW[2:], CURVE_HIGH[2:])
    return Curve(link, float(lift), float(x), float(y))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap, required=True)
    ap.add_argument("--from", type=int, action="append", dest="levels", help="crossings of the steps' start")
    ap.add_argument("--pairs", type=int, default=60, help="pairs drawn per crossing count")
    ap.add_argument("--k", type=int, default=6, help="curves simulated per pair and proposer")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.pairs < 1 or args.k < 1:
        ap.error("--pairs and --k must be at least 1")
    levels = args.levels or [1, 2, 3]
    rng = np.random.default_rng(args.seed)

    with open_store(args.db) as store:
        groups = step_groups(store, args.sets, args.labels, levels, lambda move, _: move.kind == "R2")

    import torch

    torch.set_num_threads(1)  # the simulator workers own the cores
    options = PlannerOptions()
    planner = StepCurves(ModelCurves(load_model(None, None)), share=options.cross_move)
    jobs: list[tuple[Any, Any]] = []
    owner: list[tuple[int, str, int, Any, Any]] = []
    for level in levels:
        items = groups[level]
        for i in sorted(rng.choice(len(items), size=min(args.pairs, len(items)), replace=False)):
            node, nxt, move, _ = items[int(i)]
            own = planner_curves(planner, node, nxt, move, args.k, rng)
            scripted = [r2_move_curve(rng, node.points, move) for _ in range(args.k)]
            for name, curves in (("planner", own), ("scripted", scripted)):
                jobs += [(node.q, c) for c in curves]
                owner += [(level, name, int(i), node.p_data, nxt)] * len(curves)
    rows: dict[tuple[int, str], Counter[str]] = defaultdict(Counter)
    delta: dict[tuple[int, str], Counter[int]] = defaultdict(Counter)
    hit_pairs: dict[tuple[int, str], set[int]] = defaultdict(set)
    with SimPool(args.workers) as pool:
        for (level, name, pair, start, nxt), result in zip(owner, pool.run(jobs), strict=True):
            what = outcome(result.ok, result.p_data, start, nxt)
            if what == "reached":
                hit_pairs[(level, name)].add(pair)
            elif what == "other" and result.p_data is not None:
                delta[(level, name)][result.p_data.cross - start.cross] += 1
            rows[(level, name)][what] += 1
    for key in sorted(delta):
        print("other states by crossings added", key, dict(sorted(delta[key].items())))
    print(f"R2 steps: {args.k} curves per pair and proposer, seed {args.seed}")
    drawn = {level: (min(args.pairs, len(groups[level])), len(groups[level])) for level in levels}
    print_proposer_table(drawn, ("planner", "scripted"), rows, hit_pairs)


def planner_curves(
    planner: StepCurves, node: Node, nxt: Any, move: Any, k: int, rng: np.random.Generator
) -> list[Any]:
    """``k`` curves the planner proposes for the step (as many of its K-curve steps as it takes)."""
    own: list[Any] = []
    while len(own) < k:
        own += planner.propose(node, nxt, move, PLANNER_K, rng)[0]
    return own[:k]


def outcome(ok: bool, p: PData | None, start: PData, nxt: PData) -> str:
    """Where one curve of a step from ``start`` toward ``nxt`` went (one of :data:`OUTCOMES`)."""
    if not ok or p is None:
        return "rejected"
    if p == nxt:
        return "reached"
    if p.cross < start.cross:
        return "fewer"
    return "same" if p == start else "other"


def print_proposer_table(
    drawn: dict[int, tuple[int, int]],
    names: tuple[str, ...],
    rows: dict[tuple[int, str], Counter[str]],
    hit_pairs: dict[tuple[int, str], set[int]],
) -> None:
    """The markdown table of the curves of each proposer by crossings of the steps' start: ``drawn`` maps
    a crossing count to (pairs drawn, pairs there were); ``rows`` counts the :data:`OUTCOMES` and
    ``hit_pairs`` holds the pairs with a curve that reached, both per (crossings, proposer)."""
    print(
        "| from | pairs (of) | proposer | curves reached | pairs reached | " + " | ".join(OUTCOMES[1:]) + " |"
    )
    print("| --- | --- | --- | --- | --- | " + " | ".join("---" for _ in OUTCOMES[1:]) + " |")
    for level, (n_pairs, of) in drawn.items():
        for name in names:
            row = rows[(level, name)]
            n = sum(row.values())
            if not n:
                continue
            print(
                f"| {level} | {n_pairs} ({of}) | {name} | {row['reached']} / {n} "
                f"({row['reached'] / n:.1%}) | {len(hit_pairs[(level, name)])} | "
                + " | ".join(str(row[k]) for k in OUTCOMES[1:])
                + " |"
            )


if __name__ == "__main__":
    main()
