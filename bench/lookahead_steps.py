"""Does aiming the tip's landing for the plan's next move make the next step more often?

    python bench/lookahead_steps.py --db sqlite:///tune.db --set tune-u5 --label L [--from 3] [--pairs 60] \
        [--k 6] [--then-k 3] [--draws 16] [--workers 2] [--seed 0]

A plan step toward a Cross move of the tip over segment b ("O") puts the tip down somewhere past b; where
decides whether the next step, another Cross of the same end, can be made by a straight carry
(``twisted.proposals.cross_fit``, ``cross_reach``). A look-ahead curve (:func:`lookahead_curve`) draws the
landing with that in view; it lives here only (it was tried in the planner's scripted Cross curve and not
kept: docs/log/2026-12-05.md). The bench takes the (node, next state) pairs of stored runs whose node has
``--from`` crossings, whose step is such an "O" Cross and whose next state is one move (an adding Cross of
the same end) from the run's goal: the penultimate step. For each pair it simulates ``--k`` scripted curves
without the look-ahead and ``--k`` with it (``--draws`` landings each), and from every result in the next
state ``--then-k`` scripted curves for the last move. Printed per proposer: the curves that reached the next
state, those whose result has a fitting point for the last move (``cross_fit`` > 0) and a reach under 0.5,
the last-move curves tried from them and those that reached the goal, and the pairs with a goal reached.
"""

from __future__ import annotations

import argparse
import json
import math
from collections import Counter
from typing import Any

import numpy as np
import numpy.typing as npt
from step_moves import add_run_selection, step_groups  # bench/ is this script's folder

from twisted.moves import explains
from twisted.proposals import (  # the scripted Cross curve's parts (private: this bench varies them)
    CROSS_BEYOND_M,
    _aim_weights,
    _approach,
    _cross_aim,
    _cross_curve,
    cross_fit,
    cross_move_curve,
    cross_reach,
    segment_bounds,
    segment_points,
)
from twisted.rope import LINK_SPACING_M
from twisted.sim import Curve
from twisted.sim.pool import SimPool
from twisted.store import open_store
from twisted.topology import parse_p_data

PROPOSERS = ("plain", "lookahead")
LOOKAHEAD_FLOOR = 0.02  # the landing score where no point of the next move's segment fits


def landing_scores(
    pts: npt.NDArray[np.float64],
    bounds: npt.NDArray[np.float64],
    aim: Any,
    then: Any,
    c: npt.NDArray[np.int64],
    beyond: npt.NDArray[np.float64],
) -> npt.NDArray[np.float64]:
    """How well a tip carried over point ``c`` of b (``aim``) and put down ``beyond`` past it lies for
    ``then``, the plan's next move (a Cross of the same end, in the next state's segments): ``exp(-2 d /
    beyond)``, ``d`` the distance from the landing point to the nearest point of ``then``'s crossed segment
    that a straight approach crosses with its sign (``beyond`` is about the free piece the tip will have),
    and :data:`LOOKAHEAD_FLOOR` where none does; 1 where that segment is the piece the carry moves. The
    next state's segments are this rope's with the new crossing's two visits added: on b at the aimed point
    and on the end piece ``beyond`` from the tip."""
    scores = np.ones(len(c))
    end_piece = beyond / LINK_SPACING_M
    for i in range(len(c)):
        s_tip = end_piece[i] if aim.head else float(len(pts) - 1) - end_piece[i]
        nb = np.sort(np.concatenate([bounds, [s_tip, aim.s[c[i]]]]))
        moving = 1 if aim.head else len(nb) - 3  # between the new crossing and the old first one
        b = then.other_segment
        if b is None or b == moving or not 0 <= b < len(nb) - 1:
            continue
        _, _, at, along = segment_points(pts, nb, b)
        landing = aim.at[c[i], :2] + beyond[i] * aim.towards[c[i]]
        _, dist, fits = _approach(landing, aim.head, at, along, str(then.over), str(then.sign))
        scores[i] = math.exp(-2.0 * float(dist[fits].min()) / beyond[i]) if fits.any() else LOOKAHEAD_FLOOR
    return scores


def lookahead_curve(rng: np.random.Generator, points: Any, move: Any, then: Any, draws: int) -> Curve:
    """The scripted Cross curve of ``move`` (an "O" carry of the tip) with its landing drawn for ``then``:
    ``draws`` (aimed point, distance past b) pairs drawn as ``cross_move_curve`` draws one, one of them
    kept in proportion to :func:`landing_scores`."""
    pts = np.asarray(points, dtype=np.float64)
    bounds = segment_bounds(pts)
    aim = _cross_aim(pts, move, bounds)
    cs = rng.choice(len(aim.s), size=draws, p=_aim_weights(aim))
    beyonds = rng.uniform(*CROSS_BEYOND_M, size=draws)
    scores = landing_scores(pts, bounds, aim, then, cs, beyonds)
    pick = int(rng.choice(draws, p=scores / scores.sum()))
    return _cross_curve(rng, pts, move, aim, int(cs[pick]), float(beyonds[pick]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap, required=True)
    ap.add_argument("--from", type=int, default=3, dest="level", help="crossings of the pairs' nodes")
    ap.add_argument("--pairs", type=int, default=60, help="pairs drawn (all when fewer)")
    ap.add_argument("--k", type=int, default=6, help="curves simulated per pair and proposer")
    ap.add_argument("--then-k", type=int, default=3, help="scripted curves for the last move per result")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--draws", type=int, default=16, help="landings drawn per look-ahead curve")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.pairs < 1 or args.k < 1 or args.then_k < 1 or args.workers < 1:
        ap.error("--pairs, --k, --then-k and --workers must be at least 1")
    if args.draws < 1:
        ap.error("--draws must be at least 1")
    rng = np.random.default_rng(args.seed)

    def over_cross(move: Any, _: Any) -> bool:
        return bool(move.kind == "Cross" and move.over == "O")

    with open_store(args.db) as store:
        over = step_groups(store, args.sets, args.labels, [args.level], over_cross)
    items: list[tuple[Any, Any, Any, Any, Any]] = []
    for node, nxt, move, goal_key in over[args.level]:
        goal = parse_p_data(json.loads(goal_key))
        then = explains(nxt, goal)
        if then is None or then.remove or then.kind != "Cross":
            continue
        if (then.segment == 0) != (move.segment == 0):
            continue
        items.append((node, nxt, move, then, goal))
    picked = sorted(rng.choice(len(items), size=min(args.pairs, len(items)), replace=False)) if items else []
    print(
        f"{len(items)} pairs from {args.level} crossings with an O Cross step before a last Cross of the "
        f"same end; {len(picked)} drawn, {args.k} curves per proposer, {args.then_k} for the last move, "
        f"{args.draws} landings drawn per look-ahead curve, seed {args.seed}"
    )

    counts: dict[str, Counter[str]] = {name: Counter() for name in PROPOSERS}
    goal_pairs: dict[str, set[int]] = {name: set() for name in PROPOSERS}
    jobs, owner = [], []
    for i in picked:
        node, nxt, move, then, _ = items[int(i)]
        for name in PROPOSERS:
            if name == "lookahead":
                curves = [lookahead_curve(rng, node.points, move, then, args.draws) for _ in range(args.k)]
            else:
                curves = [cross_move_curve(rng, node.points, move) for _ in range(args.k)]
            jobs += [(node.q, curve) for curve in curves]
            owner += [(name, int(i))] * args.k
    with SimPool(args.workers) as pool:
        results = pool.run(jobs)
        last_jobs, last_owner = [], []
        for (name, i), result in zip(owner, results, strict=True):
            node, nxt, move, then, _ = items[i]
            counts[name]["curves"] += 1
            if not result.ok or result.p_data != nxt or result.points is None or result.state is None:
                continue
            counts[name]["reached"] += 1
            counts[name]["fit"] += cross_fit(result.points, then) > 0
            counts[name]["reach<0.5"] += cross_reach(result.points, then) < 0.5
            last_jobs += [
                (result.state, cross_move_curve(rng, result.points, then)) for _ in range(args.then_k)
            ]
            last_owner += [(name, i)] * args.then_k
        for (name, i), result in zip(last_owner, pool.run(last_jobs), strict=True):
            counts[name]["last tried"] += 1
            if result.ok and result.p_data == items[i][4]:
                counts[name]["last reached"] += 1
                goal_pairs[name].add(i)
    print(
        "| proposer | curves | reached the next state | lie with a fit | reach < 0.5 | last curves | goal | "
        "pairs |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name in PROPOSERS:
        c = counts[name]
        print(
            f"| {name} | {c['curves']} | {c['reached']} | {c['fit']} | {c['reach<0.5']} | "
            f"{c['last tried']} | {c['last reached']} | {len(goal_pairs[name])} |"
        )


if __name__ == "__main__":
    main()
