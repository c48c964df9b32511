"""The pull test: hold both rope ends, lift them a little, pull them apart until the rope is taut.

A knot we name must survive being pulled tight (docs/DESIGN.md section 9.5). The test re-simulates from a
stored configuration:

1. *grasp*: the head link is welded to the usual gripper and the tail link to a second mocap gripper
   (:data:`twisted.sim.mjcf.TAIL_GRIPPER`), each exactly where the link lies (:meth:`RopeSim.grasp_ends`);
2. *lift and align*: both grippers rise by :data:`LIFT_M` while turning the end links (yaw only) to
   point along the pull direction, the line from the head tip to the tail tip on the table;
3. *pull*: the grippers move apart along that line at :data:`PULL_SPEED_M_S` each, slowly enough that
   the penetration check of every step (:meth:`RopeSim.step`, deeper than a radius is an error, never
   a silent pass-through) holds, until the rope resists: a gripper leads its link by more than
   :data:`TAUT_LAG_M` (the weld stretches only under tension);
4. *hold*: the grippers stop and the taut rope settles for :data:`HOLD_S`; then its link points give the
   P-data and :func:`twisted.knots.identify` the knot. The ends are now far apart and outside the knot,
   so both closures agree unless something is wrong (the result says so).

Deterministic given the state: it starts from ``set_state`` like every curve.

The same pull, followed by letting go of both ends and letting the rope settle, is the planner's
*cinch* (:func:`cinch`, docs/DESIGN.md section 8): an overhand tied on the way to a granny or a square
is pulled tight so that the rest of the rope is free for the second one. The module sits beside
``twisted.knots`` in the layers (docs/DESIGN.md section 1): it drives the simulator through ``RopeSim``'s
public methods and names the knot, so ``twisted.sim`` stays physics only.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from twisted.knots import RopeKnot, identify
from twisted.rope import ROPE_LENGTH_M
from twisted.sim.mjcf import LINK_RADIUS_M
from twisted.sim.simulator import WORKSPACE_RADIUS_M, RopeSim, minimum_jerk
from twisted.topology import PData, PDataError, top

FloatArray = npt.NDArray[np.float64]

LIFT_M = 0.5 * LINK_RADIUS_M  # "a little": the end centres clear the table, not the strands on it
LIFT_S = 0.5
PULL_SPEED_M_S = 0.05  # each gripper, in metres a second (1.25 link spacings on the default 0.04 m rope)
TAUT_LAG_M = 1.5 * LINK_RADIUS_M
HOLD_S = 0.5
# The ends cannot be further apart than the rope is long: a pull that gets there never met the knot.
MAX_SEPARATION_M = ROPE_LENGTH_M + 0.05
# The curves' workspace (1.2 m) bounds where a rope may be taken; pulling a rope that lies near its edge
# carries an end further out, which is no physical fault: the pull test allows a rope length more.
PULL_WORKSPACE_RADIUS_M = WORKSPACE_RADIUS_M + ROPE_LENGTH_M


@dataclass(frozen=True, slots=True)
class Tightened:
    """Outcome of a pull test. ``ok=False`` comes with the reason (the simulation was rejected)."""

    ok: bool
    reason: str | None
    p_data: PData | None
    knot: RopeKnot | None
    points: FloatArray | None
    end_distance_m: float | None
    sim_seconds: float
    wall_seconds: float

    @property
    def knot_name(self) -> str | None:
        """The knot of the tightened rope (``"knotoid"`` when its closures still differ), None if not ok."""
        return None if self.knot is None else self.knot.name

    def to_dict(self) -> dict[str, Any]:
        """The pull test as JSON-ready data (``replay --tighten --json``)."""
        return {
            "ok": self.ok,
            "reason": self.reason,
            "p_data": None if self.p_data is None else self.p_data.to_list(),
            "knot": None if self.knot is None else self.knot.to_dict(),
            "knot_type": self.knot_name,
            "end_distance_m": self.end_distance_m,
            "sim_seconds": self.sim_seconds,
            "wall_seconds": self.wall_seconds,
        }


@dataclass(frozen=True, slots=True)
class Cinched:
    """Outcome of :func:`cinch`: the rope pulled tight, let go and settled. ``ok=False`` comes with the
    reason (the pull or the settling was rejected); otherwise the configuration and what it ties."""

    ok: bool
    reason: str | None
    state: FloatArray | None  # RopeSim.state() of the settled rope
    points: FloatArray | None
    p_data: PData | None
    sim_seconds: float


def tightening_sim(friction_scale: float = 1.0) -> RopeSim:
    """A simulator with the second (tail) gripper the pull test needs; states are interchangeable."""
    return RopeSim(friction_scale, tail_gripper=True)


def _yaw_quat(yaw: float) -> FloatArray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def _nlerp(a: FloatArray, b: FloatArray, s: float) -> FloatArray:
    if float(np.dot(a, b)) < 0:
        b = -b
    q = (1 - s) * a + s * b
    return q / np.linalg.norm(q)


def tighten(sim: RopeSim, state: npt.ArrayLike, taut_lag_m: float = TAUT_LAG_M) -> Tightened:
    """Pull the rope in ``state`` tight on ``sim`` (made by :func:`tightening_sim`) and read its knot.

    ``taut_lag_m``: how far a gripper leads its link when the pull stops (the tension it pulls to); a
    world whose rope the full pull presses through itself pulls again at less (docs/DESIGN.md 15.1)."""
    started = time.perf_counter()
    if not sim.tail_gripper:
        raise ValueError("the pull test needs a simulator with a tail gripper (tightening_sim())")
    dt = float(sim.model.opt.timestep)
    steps = 0

    def result(reason: str | None) -> Tightened:
        wall = time.perf_counter() - started
        if reason is not None:
            return Tightened(False, reason, None, None, None, None, steps * dt, wall)
        sim.forward()
        points = sim.link_points()
        try:
            p = top(points)
            knot = identify(p)
        except PDataError as exc:
            reason = f"tightened rope has no P-data: {exc}"
            return Tightened(False, reason, None, None, None, None, steps * dt, wall)
        distance = float(np.linalg.norm(points[-1, :2] - points[0, :2]))
        return Tightened(True, None, p, knot, points, distance, steps * dt, time.perf_counter() - started)

    def step() -> str | None:
        nonlocal steps
        steps += 1
        return sim.step()

    sim.set_state(state)
    if (reason := sim.invalid_reason()) is not None:
        return result(f"invalid start state: {reason}")
    # 1. grasp both ends where they lie
    head_pos, head_quat, tail_pos, tail_quat = sim.grasp_ends()
    tips = sim.link_points()[[0, -1], :2]
    direction = tips[1] - tips[0]
    if float(np.linalg.norm(direction)) < 2 * LINK_RADIUS_M:  # ends on top of each other: pull along x
        direction = np.array([1.0, 0.0])
    direction = direction / np.linalg.norm(direction)
    target_quat = _yaw_quat(math.atan2(direction[1], direction[0]))  # links' x axis (head -> tail) along it
    window = sim.window_steps
    # 2. lift and align
    n_lift = max(1, math.ceil(LIFT_S / dt))
    for k in range(1, n_lift + 1):
        s = float(minimum_jerk(np.array(k / n_lift)))
        sim.set_end_grippers(
            head_pos + [0.0, 0.0, LIFT_M * s],
            tail_pos + [0.0, 0.0, LIFT_M * s],
            _nlerp(head_quat, target_quat, s),
            _nlerp(tail_quat, target_quat, s),
        )
        if (reason := step()) is not None:
            return result(reason)
    # 3. pull apart along the line until a weld stretches (the rope resists)
    move = np.array([direction[0], direction[1], 0.0]) * PULL_SPEED_M_S * dt
    head, tail = sim.end_gripper_positions()
    while True:
        for _ in range(window):
            head -= move
            tail += move
            sim.set_end_grippers(head, tail)
            if (reason := step()) is not None:
                return result(reason)
        if (reason := sim.invalid_reason(PULL_WORKSPACE_RADIUS_M)) is not None:
            return result(reason)
        if sim.end_lag_m() > taut_lag_m:
            break
        if float(np.linalg.norm(tail - head)) > MAX_SEPARATION_M:
            return result("the ends came further apart than the rope is long, without tension")
    # 4. hold the taut rope still, then read it
    for _ in range(max(1, math.ceil(HOLD_S / dt))):
        if (reason := step()) is not None:
            return result(reason)
    if (reason := sim.invalid_reason(PULL_WORKSPACE_RADIUS_M)) is not None:
        return result(reason)
    return result(None)


def cinch(sim: RopeSim, state: npt.ArrayLike) -> Cinched:
    """Pull the rope in ``state`` tight (:func:`tighten`), let go of both ends and let it settle.

    The knot stays as the pull left it, compact and with its loops closed, and the ends lie free (the
    ends of seven overhands lay 0.08-0.45 m apart loose and 0.41-0.55 m cinched on the 0.84 m rope,
    bench/cinch_start.py). Deterministic given ``state``.
    """
    pulled = tighten(sim, state)
    if not pulled.ok:
        return Cinched(False, pulled.reason, None, None, None, pulled.sim_seconds)
    sim.release()
    reason, steps = sim.settle()
    sim_seconds = pulled.sim_seconds + steps * float(sim.model.opt.timestep)
    if reason is not None:
        return Cinched(False, f"after the pull: {reason}", None, None, None, sim_seconds)
    try:
        p_data = sim.p_data()
    except PDataError as exc:
        return Cinched(False, f"cinched rope has no P-data: {exc}", None, None, None, sim_seconds)
    return Cinched(True, None, sim.state(), sim.link_points(), p_data, sim_seconds)
