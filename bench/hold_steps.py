"""Would a second gripper that holds the knot in place make the Cross steps that stored searches failed?

    python bench/hold_steps.py --db sqlite:///tune.db --set tune-u5 --label L --from 4 \
        [--pairs 25] [--curves 4] [--seed 0]

From 3-4 crossings most scripted Cross carries leave the rope with fewer crossings than it had: the carried
tip, or the lifted strand, pulls rope out of the knot (log, 2026-12-05). This asks whether holding one
link still would keep the knot: a second mocap gripper (made here, not part of the planner's simulator)
is welded to one link where it lies for the whole carry and let go with the grasp, before the rope
settles. For ``--pairs`` (node, next state) pairs drawn uniformly from the stored runs' Cross steps from
``--from`` crossings (``bench/step_moves.py``'s ``stored_pairs``), it draws ``--curves`` scripted Cross
curves (``twisted.proposals.cross_move_curve``) and simulates each with no hold and with each link held
that is not the grasped link or its neighbour. Prints, per over / under: the results with no hold and
with all holds (reached the next state, fewer crossings, the node's own state, another state, rejected
by the simulator), the curves that some hold made reach, and the reached share per held link.
"""

from __future__ import annotations

import argparse
from collections import Counter, defaultdict

import mujoco
import numpy as np
from step_moves import add_run_selection, stored_pairs  # bench/ is this script's folder

from twisted.proposals import cross_move_curve
from twisted.rope import N_LINKS
from twisted.sim import RopeSim
from twisted.sim.mjcf import link_name, rope_xml
from twisted.store import open_store
from twisted.topology import PData

OUTCOMES = ("reached", "fewer", "same", "other", "rejected")


class HoldingSim(RopeSim):
    """The rope simulator with a second gripper (``holder``) and an inactive weld of it to every link;
    ``hold_link`` (-1: none) is welded where it lies whenever a curve grasps its link."""

    def __init__(self) -> None:
        super().__init__()
        solref = " ".join(f"{v:g}" for v in self.params.weld_solref)  # as stiff as the grasp
        welds = "".join(
            f'<weld name="hold_{i}" body1="holder" body2="{link_name(i)}" active="false" '
            f'relpose="0 0 0 1 0 0 0" solref="{solref}"/>'
            for i in range(N_LINKS)
        )
        xml = rope_xml(self.params)
        # the holder comes last, so every id the simulator cached (bodies, geoms, joints, welds) stays
        xml = xml.replace("</worldbody>", '<body name="holder" mocap="true" pos="0 0 0.6"/></worldbody>', 1)
        xml = xml.replace("</equality>", welds + "</equality>", 1)
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        assert self.model.body(link_name(0)).id == self._link_body[0]
        self._holder = self.model.body("holder").mocapid[0]
        self._holds = np.array([self.model.equality(f"hold_{i}").id for i in range(N_LINKS)])
        self.hold_link = -1
        self.reset()

    def grasp(self, link: int) -> None:
        super().grasp(link)
        d = self.data
        d.eq_active[self._holds] = 0
        if self.hold_link >= 0:
            body = self._link_body[self.hold_link]
            d.mocap_pos[self._holder] = d.xpos[body]
            d.mocap_quat[self._holder] = d.xquat[body]
            d.eq_active[self._holds[self.hold_link]] = 1


def outcome(sim: RopeSim, ok: bool, start: PData, next_state: PData) -> str:
    if not ok:
        return "rejected"
    reached = sim.p_data()
    if reached == next_state:
        return "reached"
    return "fewer" if reached.cross < start.cross else "same" if reached == start else "other"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap)
    ap.add_argument("--from", type=int, dest="cross", required=True, help="steps from states of N crossings")
    ap.add_argument("--pairs", type=int, default=25)
    ap.add_argument("--curves", type=int, default=4, help="scripted curves per pair")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    with open_store(args.db) as store:
        pairs = [
            (node, next_state, move)
            for _, _, node, next_state, move, _, _ in stored_pairs(store, args.sets, args.labels)
            if move is not None
            and move.kind == "Cross"
            and not move.remove
            and node.p_data.cross == args.cross
        ]
    picks = sorted(rng.choice(len(pairs), size=min(args.pairs, len(pairs)), replace=False)) if pairs else []
    print(
        f"{len(pairs)} Cross pairs from {args.cross} crossings, {len(picks)} drawn, {args.curves} curves each"
    )
    sim = HoldingSim()
    free: dict[str, Counter[str]] = defaultdict(Counter)
    held: dict[str, Counter[str]] = defaultdict(Counter)
    per_link: dict[str, Counter[int]] = defaultdict(Counter)
    tried_link: dict[str, Counter[int]] = defaultdict(Counter)
    rescued: Counter[str] = Counter()
    for i in picks:
        node, next_state, move = pairs[int(i)]
        over = str(move.over)
        for _ in range(args.curves):
            curve = cross_move_curve(rng, node.points, move)
            any_hold = False
            for hold in [-1] + [h for h in range(N_LINKS) if abs(h - curve.link) >= 2]:
                sim.hold_link = hold
                sim.set_state(node.q)
                result = outcome(sim, sim.apply(curve).ok, node.p_data, next_state)
                if hold < 0:
                    free[over][result] += 1
                    continue
                held[over][result] += 1
                tried_link[over][hold] += 1
                if result == "reached":
                    per_link[over][hold] += 1
                    any_hold = True
            rescued[over] += any_hold
    for over in sorted(free):
        n = sum(free[over].values())
        print(f"\n{over}: {n} curves")
        print("  no hold:   " + "  ".join(f"{k} {free[over][k]}" for k in OUTCOMES))
        print("  all holds: " + "  ".join(f"{k} {held[over][k]}" for k in OUTCOMES))
        print(f"  curves that some held link made reach: {rescued[over]} of {n}")
        shares = [f"{h}:{per_link[over][h]}/{tried_link[over][h]}" for h in sorted(tried_link[over])]
        print("  reached per held link: " + " ".join(shares))


if __name__ == "__main__":
    main()
