"""Does turning the grasped link make curls, and smaller ones, where the planner's curves make few?

    python bench/twist_curl.py --db sqlite:///tune.db --set tune-u5 --label L [--from 1 --from 2 --from 3 \
        --from 4] [--pairs 40] [--k 6] [--straight 300] [--workers 2] [--seed 0]

A curve (DESIGN 3) carries the grasped link without turning it. A person makes a small curl by turning the
wrist: the rope beside the hand swings round and crosses itself next to it. This bench adds that turn to
the carry (here only, in :class:`TwistSim`: it was not built into the simulator): the gripper's yaw turns by
``twist`` radians over the carry with the same minimum-jerk progress as its position, and the carry lasts
at least ``|twist| / TWIST_RATE_RAD_S``. A twist curve for an R1 move (:func:`twist_curve`) grasps a whole
link inside the curl's segment, lifts it by 0-7 cm, moves it by at most 10 cm and turns it by 1.5-2.5 pi,
counter-clockwise (seen from above) for a curl of sign ``-`` and clockwise for ``+`` (part 1 prints how
many one-crossing results from the straight rope have that sign).

1. From the straight rope, ``--straight`` twist curves on uniform links 1-19 and turns of either sign, and
   as many of the planner's curves for the R1 steps of the straight rope (one of its 4 curls, uniform):
   how many made one crossing, and the loop of those curls (links between its two visits).
2. For ``--pairs`` (node, next state) pairs per crossing count, drawn from the R1 steps (adding moves)
   that the stored runs asked for on an inner segment (``bench/step_moves.py``'s ``stored_pairs``),
   ``--k`` of the planner's curves (``StepCurves`` with today's options: the inverse model) and ``--k``
   twist curves from the node's configuration: the curves that reached the next state, the pairs with
   at least one, and where the others went (fewer crossings, the node's own state, another state,
   rejected by the simulator).
"""

from __future__ import annotations

import argparse
import math
from collections import Counter, defaultdict

import numpy as np
import numpy.typing as npt
from bottleneck import curl_segments  # bench/ is this script's folder
from r2_steps import outcome, planner_curves, print_proposer_table
from step_moves import add_run_selection, segment_link, step_groups

from twisted.model.registry import load_model
from twisted.model.sampler import ModelCurves
from twisted.moves import successors
from twisted.planner.options import PlannerOptions
from twisted.planner.strategies import StepCurves
from twisted.planner.tree import Node
from twisted.proposals import segment_bounds
from twisted.rope import N_LINKS
from twisted.sim import Curve, RopeSim
from twisted.sim.pool import SimPool
from twisted.sim.rope import CurveOutcome, minimum_jerk
from twisted.store import open_store
from twisted.topology import PData

TWIST_RATE_RAD_S = 3.0  # the slowest carry turns the link no faster than this
TWIST_TURNS = (1.5, 2.5)  # half-turns (pi) of a twist curve
TWIST_LIFT_M = (0.0, 0.07)
TWIST_SHIFT_M = 0.1  # the largest move of the grasped link during a twist


class TwistSim(RopeSim):
    """:class:`RopeSim` whose carry can also turn the grasped link about the vertical."""

    def apply_twist(self, curve: Curve, twist: float) -> CurveOutcome:
        """:meth:`RopeSim.apply` of ``curve`` with the gripper's yaw turned by ``twist`` radians over the
        carry (positive: counter-clockwise seen from above); the same checks, settling and result, but
        the link is carried to the end of its path (no early release on top of a strand)."""
        self.set_state(self.state())
        reason = self.invalid_reason()
        if reason is not None:
            return CurveOutcome(False, f"invalid start state: {reason}", 0)
        path = self.gripper_path(curve, min_duration_s=abs(twist) / TWIST_RATE_RAD_S)
        s = minimum_jerk(np.arange(1, len(path) + 1) / len(path))
        self.grasp(curve.link)
        d = self.data
        w0, x0, y0, z0 = d.mocap_quat[self._gripper].copy()
        steps = 0
        for k, target in enumerate(path):
            half = 0.5 * twist * s[k]
            c, z = math.cos(half), math.sin(half)  # (c, 0, 0, z) * q0: a turn about the world z axis
            d.mocap_pos[self._gripper] = target
            d.mocap_quat[self._gripper] = (c * w0 - z * z0, c * x0 - z * y0, c * y0 + z * x0, c * z0 + z * w0)
            steps += 1
            if (reason := self.step()) is not None:
                self.release()
                return CurveOutcome(False, reason, steps)
        self.release()
        reason, settle_steps = self._settle()
        if reason is not None:
            return CurveOutcome(False, reason, steps + settle_steps, settle_steps)
        self.forward()
        reason = self.invalid_reason()
        return CurveOutcome(reason is None, reason, steps + settle_steps, settle_steps)


def twist_curve(rng: np.random.Generator, link: int, sign: str) -> tuple[Curve, float]:
    """A twist curve on ``link`` (and its turn, radians) for a curl of ``sign``: a random lift and shift."""
    turn = float(rng.uniform(*TWIST_TURNS)) * math.pi * (1.0 if sign == "-" else -1.0)
    shift, angle = rng.uniform(0.0, TWIST_SHIFT_M), rng.uniform(0.0, 2 * math.pi)
    lift = float(rng.uniform(*TWIST_LIFT_M))
    return Curve(link, lift, float(shift * math.cos(angle)), float(shift * math.sin(angle))), turn


def curl_loop(points: npt.ArrayLike, p: PData) -> float | None:
    """The loop of a one-crossing curl (links between its two visits), None when ``p`` is not one."""
    if p.cross != 1 or not curl_segments(p):
        return None
    bounds = segment_bounds(points)
    return float(bounds[2] - bounds[1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap, required=True)
    ap.add_argument("--from", type=int, action="append", dest="levels", help="crossings of the steps' start")
    ap.add_argument("--pairs", type=int, default=40, help="pairs drawn per crossing count")
    ap.add_argument("--k", type=int, default=6, help="curves simulated per pair and proposer")
    ap.add_argument("--straight", type=int, default=300, help="curves of each kind from the straight rope")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.pairs < 1 or args.k < 1 or args.straight < 0:
        ap.error("--pairs and --k must be at least 1, --straight at least 0")
    levels = args.levels or [1, 2, 3, 4]
    rng = np.random.default_rng(args.seed)
    sim = TwistSim()

    import torch

    torch.set_num_threads(1)  # the simulator workers own the cores
    options = PlannerOptions()
    planner = StepCurves(ModelCurves(load_model(None, None)), share=options.cross_move)

    # 1. from the straight rope
    sim.reset()
    root = Node(0, None, sim.state(), sim.link_points(), sim.p_data(), None, 0, 0)
    curls = [(s.state, s.move) for s in successors(root.p_data) if s.move.kind == "R1"]
    loops: dict[str, list[float]] = defaultdict(list)
    made: Counter[tuple[str, int]] = Counter()
    signed = 0  # one-crossing twists whose crossing has the sign the turn was for
    for _ in range(args.straight):
        sim.reset()
        link = int(rng.integers(1, N_LINKS - 1))
        sign = "-" if rng.random() < 0.5 else "+"
        curve, turn = twist_curve(rng, link, sign)
        if sim.apply_twist(curve, turn).ok:
            p = sim.p_data()
            made[("twist", p.cross)] += 1
            if p.cross == 1:
                signed += p.crossings()[0][2] == (1 if sign == "+" else -1)
            if (loop := curl_loop(sim.link_points(), p)) is not None:
                loops["twist"].append(loop)
    jobs = []
    for _ in range(args.straight):
        curl, first = curls[int(rng.integers(len(curls)))]
        jobs.append((root.q, planner.propose(root, curl, first, 1, rng)[0][0]))
    with SimPool(args.workers) as pool:
        for result in pool.run(jobs):
            if result.ok and result.p_data is not None and result.points is not None:
                made[("planner", result.p_data.cross)] += 1
                if (loop := curl_loop(result.points, result.p_data)) is not None:
                    loops["planner"].append(loop)
    print(f"From the straight rope: {args.straight} curves of each kind, seed {args.seed}")
    print("| curves | valid | 1 crossing | 2 or more | loop of a 1-crossing curl, median (quartiles) |")
    print("| --- | --- | --- | --- | --- |")
    for name in ("planner", "twist"):
        valid = sum(n for (who, _), n in made.items() if who == name)
        more = sum(n for (who, c), n in made.items() if who == name and c >= 2)
        q = np.percentile(loops[name], [50, 25, 75]) if loops[name] else [math.nan] * 3
        print(f"| {name} | {valid} | {made[(name, 1)]} | {more} | {q[0]:.1f} ({q[1]:.1f}-{q[2]:.1f}) links |")
    print(f"one-crossing twists with the sign they were turned for: {signed} of {made[('twist', 1)]}")

    # 2. the R1 steps of stored searches
    with open_store(args.db) as store:
        groups = step_groups(  # curls on inner segments
            store,
            args.sets,
            args.labels,
            levels,
            lambda move, p: move.kind == "R1" and 0 < move.segment < 2 * p.cross,
        )
    rows: dict[tuple[int, str], Counter[str]] = defaultdict(Counter)
    hit_pairs: dict[tuple[int, str], set[int]] = defaultdict(set)
    jobs, owner = [], []
    for level in levels:
        items = groups[level]
        for i in sorted(rng.choice(len(items), size=min(args.pairs, len(items)), replace=False)):
            node, nxt, move, _ = items[int(i)]
            jobs += [(node.q, c) for c in planner_curves(planner, node, nxt, move, args.k, rng)]
            owner += [(level, int(i), node.p_data, nxt)] * args.k
            assert move.sign is not None  # an R1 move names its curl's sign
            for _ in range(args.k):
                curve, turn = twist_curve(rng, segment_link(rng, node.points, move.segment), move.sign)
                sim.set_state(node.q)
                twisted = sim.apply_twist(curve, turn)
                what = outcome(twisted.ok, sim.p_data() if twisted.ok else None, node.p_data, nxt)
                rows[(level, "twist")][what] += 1
                if what == "reached":
                    hit_pairs[(level, "twist")].add(int(i))
    with SimPool(args.workers) as pool:
        for (level, pair, start, nxt), result in zip(owner, pool.run(jobs), strict=True):
            what = outcome(result.ok, result.p_data, start, nxt)
            rows[(level, "planner")][what] += 1
            if what == "reached":
                hit_pairs[(level, "planner")].add(pair)
    print(f"\nR1 steps on an inner segment: {args.k} curves per pair and proposer, seed {args.seed}")
    drawn = {level: (min(args.pairs, len(groups[level])), len(groups[level])) for level in levels}
    print_proposer_table(drawn, ("planner", "twist"), rows, hit_pairs)


if __name__ == "__main__":
    main()
