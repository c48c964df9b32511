"""Where plan steps lose their crossings (in the carry or in the settling), and could a step see it early?

    python bench/settle_loss.py --db sqlite:///tune.db --set tune-u5 --label L [--from 0 ... --from 4] \
        [--pairs 40] [--k 6] [--hold-s S] [--workers 2] [--seed 0]

A result enters the search tree only when its crossings stay between its parent's and the goal's
(``Twisted.keeps``, DESIGN 8); every other curve is simulated to the end of its settling all the same.
For ``--pairs`` (node, next state) pairs per crossing count drawn from the stored runs' plan steps
(``bench/step_moves.py``'s ``stored_pairs``; runs toward a state goal only), this simulates ``--k`` of
the planner's curves (``StepCurves`` with today's options) from the node's configuration with a watch
(``RopeSim.apply(curve, watch)``) that records the crossings of the rope's projection at the release
and after every settling window (it only looks: the outcomes are the simulator's own).

It prints per crossing count the share of curves that reached the step's next state, were kept, thrown
away (fewer crossings than the parent, or more than the goal) or rejected, and the share of the
simulator steps each took; then, for rules that give a curve up at the release or at a later window
(when its rope has fewer crossings than the parent, or any outside the kept range), the steps they
save and the curves they give up that would have been kept (the rule's errors).

``--hold-s S`` also simulates every curve with the gripper holding the link still for S seconds at the
end of the carry before it lets go (the bench's ``HoldingSim``; the planner's curves let go at once),
and prints the same first table for it: does a rope that settles while held keep its crossings?
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from typing import Any

import numpy as np
from r2_steps import planner_curves  # bench/ is this script's folder
from step_moves import add_run_selection, pool_map, step_groups

from twisted.model.registry import load_model
from twisted.model.sampler import ModelCurves
from twisted.planner.options import PlannerOptions
from twisted.planner.strategies import StepCurves
from twisted.planner.tree import Node
from twisted.sim import RopeSim
from twisted.store import open_store
from twisted.topology import parse_p_data, projected_crossings

# [(steps so far, crossings)] at the release and after each settling window; ok; the final state's key
# (None when rejected) and crossings (-1 when rejected); steps simulated
Trace = tuple[list[tuple[int, int]], bool, str | None, int, int]


class HoldingSim(RopeSim):
    """The simulator with the gripper holding the carried link still for ``hold_s`` seconds before it lets
    go (the penetration check runs while it holds; its steps count). A carry that was rejected is let go
    at once (its outcome is the rejection either way)."""

    def __init__(self, hold_s: float) -> None:
        super().__init__()
        self.hold_steps = round(hold_s / self.model.opt.timestep)
        self.held = 0
        self._carried = False  # whether the last carry ended valid: a rejected one is let go at once

    def _carry(self, link: int, path: Any) -> tuple[str | None, int]:
        reason, steps = super()._carry(link, path)
        self._carried = reason is None
        return reason, steps

    def release(self) -> None:
        self.held = 0
        if self._carried and self.data.eq_active.any():
            for _ in range(self.hold_steps):
                self.held += 1
                if self.step() is not None:
                    break
        super().release()


def goal_cross(goal_key: str) -> int | None:
    """The crossings of a state goal; None for a knot goal (its key is not P-data, and its states need not
    share one crossing count: its runs are left out)."""
    try:
        return parse_p_data(json.loads(goal_key)).cross
    except ValueError:
        return None


def crossings(points: Any) -> int:
    """The crossings of the rope's projection (``Top``'s count, without the P-data)."""
    return len(projected_crossings(points))


_SIMS: dict[float, RopeSim] = {}


def traced(job: tuple[Any, Any, float]) -> Trace:
    """Simulate one curve (holding the link ``hold_s`` at the end of the carry when above 0), recording the
    crossings at the release and at every settling window."""
    q, curve, hold_s = job
    if hold_s not in _SIMS:
        _SIMS[hold_s] = HoldingSim(hold_s) if hold_s > 0 else RopeSim()
    sim = _SIMS[hold_s]
    sim.set_state(q)
    trace: list[tuple[int, int]] = []

    def watch(points: Any, steps: int) -> None:
        trace.append((steps, crossings(points)))

    out = sim.apply(curve, watch)
    held = sim.held if isinstance(sim, HoldingSim) else 0
    if not out.ok:
        return trace, False, None, -1, out.steps + held
    p = sim.p_data()
    return trace, True, p.key, p.cross, out.steps + held


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap, required=True)
    ap.add_argument("--from", type=int, action="append", dest="levels", help="crossings of the steps' start")
    ap.add_argument("--pairs", type=int, default=40, help="pairs drawn per crossing count")
    ap.add_argument("--k", type=int, default=6, help="planner curves simulated per pair")
    ap.add_argument("--hold-s", type=float, default=0.0, help="also with the link held this long (s)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.pairs < 1 or args.k < 1 or args.hold_s < 0:
        ap.error("--pairs and --k must be at least 1, --hold-s at least 0")
    levels = args.levels or [0, 1, 2, 3, 4]
    rng = np.random.default_rng(args.seed)

    with open_store(args.db) as store:
        steps = step_groups(store, args.sets, args.labels, levels)
    groups: dict[int, list[tuple[Node, Any, Any, int]]] = defaultdict(list)
    for level, found in steps.items():
        groups[level] = [(n, nxt, m, c) for n, nxt, m, key in found if (c := goal_cross(key)) is not None]

    import torch

    torch.set_num_threads(1)  # the simulator workers own the cores
    planner = StepCurves(ModelCurves(load_model(None, None)), share=PlannerOptions().cross_move)
    jobs: list[tuple[Any, Any]] = []
    owner: list[tuple[int, int, str]] = []  # (parent crossings, goal crossings, next state's key)
    for level in levels:
        items = groups[level]
        for i in sorted(rng.choice(len(items), size=min(args.pairs, len(items)), replace=False)):
            node, nxt, move, goal = items[int(i)]
            curves = planner_curves(planner, node, nxt, move, args.k, rng)
            jobs += [(node.q, c) for c in curves]
            owner += [(level, goal, nxt.key)] * len(curves)
    drawn = {lv: (min(args.pairs, len(groups[lv])), len(groups[lv])) for lv in levels}
    print(f"{args.k} planner curves per pair, seed {args.seed}; the curves as the planner simulates them")
    results = pool_map(traced, [(q, c, 0.0) for q, c in jobs], args.workers)
    report(levels, owner, results, drawn, rules=True)
    if args.hold_s > 0:
        print(f"\nthe same curves with the link held {args.hold_s} s at the end of the carry")
        held = pool_map(traced, [(q, c, args.hold_s) for q, c in jobs], args.workers)
        report(levels, owner, held, drawn, rules=False)


# (name, the last window the rule looks at (0: the release), crossings under the parent's it takes; 0:
# any count outside the kept range)
RULES = (
    ("release, 1 fewer", 0, 1),
    ("release, 2 fewer", 0, 2),
    ("window 1, 1 fewer", 1, 1),
    ("window 3, 1 fewer", 3, 1),
    ("window 6, 1 fewer", 6, 1),
    ("release, out of range", 0, 0),
)


def gives_up(trace: list[tuple[int, int]], level: int, goal: int, upto: int, fewer: int) -> int | None:
    """The steps after which a rule gives the curve up, or None when it lets it settle."""
    for at, count in trace[: upto + 1]:
        if (count > goal or count < level) if fewer == 0 else count <= level - fewer:
            return at
    return None


def report(
    levels: list[int],
    owner: list[tuple[int, int, str]],
    results: list[Trace],
    drawn: dict[int, tuple[int, int]],
    rules: bool,
) -> None:
    """The markdown tables: where the curves and their steps went; what each rule saves and loses."""
    print(
        "| from | pairs (of) | curves | reached | kept | thrown away | rejected "
        "| steps kept / thrown / rejected |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    rule_rows = []
    for level in levels:
        rows = [(goal, nxt, r) for (lv, goal, nxt), r in zip(owner, results, strict=True) if lv == level]
        if not rows:
            continue
        fate = {"kept": [0, 0], "thrown": [0, 0], "rejected": [0, 0]}
        reached = 0
        saved = {rule: [0, 0, 0] for rule, _, _ in RULES}  # steps saved, curves given up, of them kept
        for goal, nxt, (trace, ok, key, final, steps) in rows:
            kept = ok and level <= final <= goal
            reached += key == nxt
            name = "rejected" if not ok else ("kept" if kept else "thrown")
            fate[name][0] += 1
            fate[name][1] += steps
            for rule, upto, fewer in RULES:
                at = gives_up(trace, level, goal, upto, fewer)
                if at is not None:
                    saved[rule][0] += steps - at
                    saved[rule][1] += 1
                    saved[rule][2] += int(kept)
        n, total = len(rows), sum(f[1] for f in fate.values())
        pairs, of = drawn[level]
        print(
            f"| {level} | {pairs} ({of}) | {n} | {reached} | "
            + " | ".join(f"{fate[k][0] / n:.1%}" for k in ("kept", "thrown", "rejected"))
            + " | "
            + " / ".join(f"{fate[k][1] / total:.1%}" for k in ("kept", "thrown", "rejected"))
            + f" ({total / n:.0f} a curve) |"
        )
        for rule, _, _ in RULES:
            steps_saved, given_up, lost = saved[rule]
            rule_rows.append(f"| {level} | {rule} | {steps_saved / total:.1%} | {given_up} of {n} | {lost} |")
    if rules:
        print()
        print("| from | give up at | steps saved | curves given up | of them kept |")
        print("| --- | --- | --- | --- | --- |")
        print("\n".join(rule_rows))


if __name__ == "__main__":
    main()
