"""RopeSim: the MuJoCo rope, its state, its link points and one curve action ``f(q, c) -> q'``.

A curve ``c = (link, z_max, x, y)`` (docs/DESIGN.md section 3): weld the gripper to ``link``, carry it
along a straight line to ``(x, y)`` away from where it lies, with minimum-jerk timing and a height
arc on top, release it a little above the table (or as soon as it lands on another strand), and
step until the rope has settled. The result depends only on ``state()`` and the curve: every
action starts from ``mj_resetData`` and the restored state, so solver warm starts or a previous
grasp never leak into the next action, in this process or another.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np
import numpy.typing as npt

from twisted.rope import N_LINKS, N_POINTS
from twisted.sim.mjcf import (
    LINK_RADIUS_M,
    TAIL_GRIPPER,
    TAIL_WELD,
    RopeParams,
    joint_names,
    link_name,
    rope_xml,
    weld_name,
)
from twisted.topology import PData, top

FloatArray = npt.NDArray[np.float64]

# Action ranges (reference): link 0..N_LINKS-1 (0..20 on the default rope), z_max 0..0.07 m,
# (x, y) displacement -0.5..0.5 m.
CURVE_LOW = np.array([0.0, 0.0, -0.5, -0.5])
CURVE_HIGH = np.array([N_LINKS - 1, 0.07, 0.5, 0.5])

# Gripper path. z_max = 0 still lifts by MIN_LIFT_M: a link dragged at table height scrapes the
# table with full friction and is pressed into it by the weld, so the smallest curve lifts the
# link just clear of the table (half a radius) and still pushes any strand it meets. The lift is
# z_max + MIN_LIFT_M, which keeps distinct z_max values distinct for the inverse model.
MIN_LIFT_M = 0.005
GRIPPER_SPEED_M_S = 0.3  # mean speed along the path; the minimum-jerk peak is 1.875x this
MIN_MOVE_S = 0.2
RELEASE_HEIGHT_M = LINK_RADIUS_M + 0.003  # centre height at the end of the path, just above the table

# Settling: every link slower than SETTLE_SPEED_M_S over two consecutive windows, with a cap.
SETTLE_WINDOW_S = 0.05
SETTLE_SPEED_M_S = 0.01
SETTLE_CAP_S = 3.0

# Validity of a configuration: anything else is rejected, never silently kept.
WORKSPACE_RADIUS_M = 1.2
MAX_HEIGHT_M = 0.3
MIN_HEIGHT_M = -LINK_RADIUS_M / 2  # a centreline point this far under the table surface: through it
MAX_PENETRATION_M = LINK_RADIUS_M

# 5 ms rather than 2 ms: measured on 300 random curves from reached configurations, 0.032 s cpu
# per action against 0.064 s, with the same rejections (none from the physics), crossings settled
# with a ~2-radius vertical gap and the same random-curve crossing statistics.
DEFAULT_TIMESTEP_S = 0.005

# An observer of a curve's settling (RopeSim.apply): called with the link points and the steps so far.
Watch = Callable[[FloatArray, int], None]

_INSTABILITY_WARNINGS = [
    int(mujoco.mjtWarning.mjWARN_BADQACC),
    int(mujoco.mjtWarning.mjWARN_BADQVEL),
    int(mujoco.mjtWarning.mjWARN_BADQPOS),
]


@dataclass(frozen=True, slots=True)
class Curve:
    """One curve action: grasp ``link``, lift by ``z_max_m``, move it by ``(x_m, y_m)``, release.

    ``x_m``/``y_m`` are a displacement relative to the grasped link's current position; the
    link's peak lift is ``z_max_m + MIN_LIFT_M`` (so z_max = 0 still clears the table). Values
    outside ``CURVE_LOW..CURVE_HIGH`` are allowed (a sampled curve may stray); the simulator rejects
    a result that leaves the workspace. A negative ``z_max_m`` counts as 0.
    """

    link: int
    z_max_m: float
    x_m: float
    y_m: float

    def __post_init__(self) -> None:
        if isinstance(self.link, bool) or not isinstance(self.link, (int, np.integer)):
            raise ValueError(f"curve link must be an integer 0..{N_LINKS - 1}, got {self.link!r}")
        if not 0 <= self.link < N_LINKS:
            raise ValueError(f"curve link must be in 0..{N_LINKS - 1}, got {self.link}")
        values = (self.z_max_m, self.x_m, self.y_m)
        if not all(math.isfinite(float(v)) for v in values):
            raise ValueError(f"curve (z_max_m, x_m, y_m) must be finite, got {values}")
        object.__setattr__(self, "link", int(self.link))
        for name, v in zip(("z_max_m", "x_m", "y_m"), values, strict=True):
            object.__setattr__(self, name, float(v))

    def to_array(self) -> FloatArray:
        """``[link, z_max_m, x_m, y_m]`` as float64."""
        return np.array([self.link, self.z_max_m, self.x_m, self.y_m], dtype=np.float64)

    @classmethod
    def from_array(cls, a: npt.ArrayLike) -> Curve:
        """Inverse of :meth:`to_array`; the link is rounded to the nearest integer."""
        v = np.asarray(a, dtype=np.float64).reshape(-1)
        if v.shape != (4,):
            raise ValueError(f"a curve array has 4 entries [link, z_max_m, x_m, y_m], got shape {v.shape}")
        return cls(int(round(v[0])), float(v[1]), float(v[2]), float(v[3]))

    def clipped(self) -> Curve:
        """The curve with z_max, x and y clipped to ``CURVE_LOW..CURVE_HIGH``."""
        lo, hi = CURVE_LOW, CURVE_HIGH
        return Curve(
            self.link,
            float(np.clip(self.z_max_m, lo[1], hi[1])),
            float(np.clip(self.x_m, lo[2], hi[2])),
            float(np.clip(self.y_m, lo[3], hi[3])),
        )


def sample_curve(rng: np.random.Generator) -> Curve:
    """A uniform random curve: link in 0..N_LINKS-1, z_max in [0, 0.07] m, x, y in [-0.5, 0.5] m."""
    link = int(rng.integers(0, N_LINKS))
    z, x, y = rng.uniform(CURVE_LOW[1:], CURVE_HIGH[1:])
    return Curve(link, float(z), float(x), float(y))


@dataclass(frozen=True, slots=True)
class CurveOutcome:
    """Result of :meth:`RopeSim.apply`: ``ok=False`` comes with the reason; ``steps`` simulated, of them
    ``settle_steps`` after the release."""

    ok: bool
    reason: str | None
    steps: int
    settle_steps: int = 0


def minimum_jerk(tau: FloatArray) -> FloatArray:
    """Minimum-jerk progress 0 -> 1 at normalised time ``tau`` in [0, 1]; at rest at both ends."""
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)


class RopeSim:
    """The rope on the table with a mocap gripper; one MuJoCo model built once per instance."""

    def __init__(
        self,
        friction_scale: float = 1.0,
        timestep_s: float = DEFAULT_TIMESTEP_S,
        tail_gripper: bool = False,
        params: RopeParams | None = None,
    ) -> None:
        """``params``, when given, is the whole physics (a world apart from the planner's model,
        :mod:`twisted.world`) and ``friction_scale`` / ``timestep_s`` are then not taken."""
        if not (math.isfinite(friction_scale) and friction_scale > 0):
            raise ValueError(f"friction_scale must be a positive number, got {friction_scale!r}")
        self.params = params or RopeParams(timestep_s=timestep_s, friction_scale=friction_scale)
        self.tail_gripper = tail_gripper  # the second gripper of the pull test (docs/DESIGN.md section 2.2)
        self.model = mujoco.MjModel.from_xml_string(rope_xml(self.params, tail_gripper=tail_gripper))
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._link_body = np.array([m.body(link_name(i)).id for i in range(N_LINKS)])
        self._link_geom = np.array([m.geom(link_name(i)).id for i in range(N_LINKS)])
        self._weld = np.array([m.equality(weld_name(i)).id for i in range(N_LINKS)])
        # centreline point i (1..N_LINKS-1) is the anchor of the joint between links i-1 and i
        self._pitch = np.array([m.joint(joint_names(i)[1]).id for i in range(N_LINKS - 1)])
        self._gripper = m.body("gripper").mocapid[0]
        self._tail_gripper = int(m.body(TAIL_GRIPPER).mocapid[0]) if tail_gripper else -1
        self._tail_weld = int(m.equality(TAIL_WELD).id) if tail_gripper else -1
        # the rope tips lie opposite the first/last joint anchor in the end links' frames
        self._head_offset = -m.jnt_pos[self._pitch[0]].copy()
        self._tail_offset = -m.jnt_pos[self._pitch[-1]].copy()
        # link index of each geom (-1 for the table) to find which strand the grasped link touches
        self._geom_link = np.full(m.ngeom, -1)
        self._geom_link[self._link_geom] = np.arange(N_LINKS)
        self._window_steps = max(1, round(SETTLE_WINDOW_S / m.opt.timestep))
        # the speed under which the rope counts as at rest (an attribute so that a bench can vary it)
        self.settle_speed_m_s = SETTLE_SPEED_M_S
        self._settle_cap_steps = round(SETTLE_CAP_S / m.opt.timestep)
        self.reset()

    # ---- state ---------------------------------------------------------------------------------

    @property
    def friction_scale(self) -> float:
        return self.params.friction_scale

    @property
    def state_size(self) -> int:
        return self.model.nq + self.model.nv

    @property
    def window_steps(self) -> int:
        """Time steps in one settle window (``SETTLE_WINDOW_S``): how often long loops check validity."""
        return self._window_steps

    def reset(self) -> None:
        """The straight rope along x, centred at the origin, resting on the table."""
        mujoco.mj_resetData(self.model, self.data)
        mujoco.mj_forward(self.model, self.data)

    def state(self) -> FloatArray:
        """The configuration ``q``: qpos (47) then qvel (46), float64; restores exactly."""
        return np.concatenate([self.data.qpos, self.data.qvel]).astype(np.float64)

    def set_state(self, state: npt.ArrayLike) -> None:
        """Restore a configuration from :meth:`state` (any process, any RopeSim of this model)."""
        q = np.asarray(state, dtype=np.float64)
        if q.shape != (self.state_size,):
            raise ValueError(
                f"a rope state has {self.state_size} floats (qpos then qvel), got shape {q.shape}"
            )
        m, d = self.model, self.data
        # Everything else (warm start, contacts, equality switches, mocap, time) back to defaults,
        # so that what happens next depends on q alone.
        mujoco.mj_resetData(m, d)
        d.qpos[:] = q[: m.nq]
        d.qvel[:] = q[m.nq :]
        mujoco.mj_forward(m, d)

    # ---- named quantities -----------------------------------------------------------------------

    def link_points(self) -> FloatArray:
        """The N_POINTS centreline points: link-0 tip (head), the N_LINKS - 1 joints, the last link's tip."""
        d = self.data
        head, tail = self._link_body[0], self._link_body[-1]
        pts = np.empty((N_POINTS, 3))
        pts[0] = d.xpos[head] + d.xmat[head].reshape(3, 3) @ self._head_offset
        pts[1:-1] = d.xanchor[self._pitch]
        pts[-1] = d.xpos[tail] + d.xmat[tail].reshape(3, 3) @ self._tail_offset
        return pts

    def link_positions(self) -> FloatArray:
        """The N_LINKS link centres, shape (N_LINKS, 3)."""
        return self.data.xpos[self._link_body].copy()

    def p_data(self) -> PData:
        """``Top(q)``: the P-data of the current configuration."""
        return top(self.link_points())

    def invalid_reason(self, workspace_radius_m: float = WORKSPACE_RADIUS_M) -> str | None:
        """Why the current configuration is not acceptable, or None when it is.

        ``workspace_radius_m``: how far from the origin the rope may be (the pull test, which moves both
        ends apart wherever the rope lies, allows more than the curves do)."""
        d = self.data
        if not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
            return "simulation diverged (NaN or infinity in the state)"
        # mj_step resets the data on a bad acceleration and carries on from qpos0: never keep that
        unstable = [w for w in _INSTABILITY_WARNINGS if d.warning[w].number > 0]
        if unstable:
            names = ", ".join(mujoco.mjtWarning(w).name for w in unstable)
            return f"simulation diverged (MuJoCo warned {names} and reset the rope)"
        pts = self.link_points()
        far = float(np.max(np.linalg.norm(pts, axis=1)))
        if far > workspace_radius_m:
            return f"rope left the workspace ({far:.2f} m from the origin > {workspace_radius_m} m)"
        z_min, z_top = float(pts[:, 2].min()), float(pts[:, 2].max())
        if z_min < MIN_HEIGHT_M:
            return f"rope went below the table (centreline at z = {z_min:.4f} m)"
        if z_top > MAX_HEIGHT_M:
            return f"rope flew up (centreline at z = {z_top:.2f} m > {MAX_HEIGHT_M} m)"
        if d.ncon and float(d.contact.dist.min()) < -MAX_PENETRATION_M:
            return f"deep penetration ({-float(d.contact.dist.min()):.4f} m > {MAX_PENETRATION_M} m)"
        return None

    # ---- the curve action -------------------------------------------------------------------------

    def gripper_path(self, curve: Curve, min_duration_s: float = 0.0) -> FloatArray:
        """The gripper positions, one per time step, for ``curve`` from the current configuration.

        A straight horizontal line to the target with minimum-jerk timing, plus a height arc
        ``lift * sin(pi s)`` over the line from the link's height down to the release height. The
        carry lasts at least ``min_duration_s`` (a bench that also turns the gripper slows it down).
        """
        start = self.data.xpos[self._link_body[curve.link]].copy()
        dxy = np.array([curve.x_m, curve.y_m])
        lift = max(curve.z_max_m, 0.0) + MIN_LIFT_M
        duration = max(MIN_MOVE_S, min_duration_s, (float(np.hypot(*dxy)) + 2.0 * lift) / GRIPPER_SPEED_M_S)
        n = max(1, math.ceil(duration / self.model.opt.timestep))
        s = minimum_jerk(np.arange(1, n + 1) / n)
        path = np.empty((n, 3))
        path[:, :2] = start[:2] + s[:, None] * dxy
        path[:, 2] = start[2] + (RELEASE_HEIGHT_M - start[2]) * s + lift * np.sin(np.pi * s)
        return path

    def grasp(self, link: int) -> None:
        """Put the gripper exactly on ``link`` and weld it there (its weld relpose is the identity)."""
        d, body = self.data, self._link_body[link]
        d.mocap_pos[self._gripper] = d.xpos[body]
        d.mocap_quat[self._gripper] = d.xquat[body]
        d.eq_active[self._weld] = 0
        d.eq_active[self._weld[link]] = 1

    def release(self) -> None:
        """Open the gripper (and the tail gripper, if any): no link is welded any more."""
        self.data.eq_active[:] = 0

    # ---- both ends held (the pull test, docs/DESIGN.md section 9.5) ---------------------------------

    def grasp_ends(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Weld the head link to the gripper and the tail link to the tail gripper, each where it lies.

        Needs ``RopeSim(tail_gripper=True)``. Returns the end links' poses (copies), which are now the
        grippers' poses: ``head_pos, head_quat, tail_pos, tail_quat``.
        """
        if not self.tail_gripper:
            raise ValueError("grasp_ends needs a simulator with a tail gripper (RopeSim(tail_gripper=True))")
        d = self.data
        head_body, tail_body = self._link_body[0], self._link_body[N_LINKS - 1]
        d.eq_active[:] = 0
        head_pos, tail_pos = d.xpos[head_body].copy(), d.xpos[tail_body].copy()
        head_quat, tail_quat = d.xquat[head_body].copy(), d.xquat[tail_body].copy()
        self.set_end_grippers(head_pos, tail_pos, head_quat, tail_quat)
        d.eq_active[self._weld[0]] = 1
        d.eq_active[self._tail_weld] = 1
        return head_pos, head_quat, tail_pos, tail_quat

    def set_end_grippers(
        self,
        head_pos: npt.ArrayLike,
        tail_pos: npt.ArrayLike,
        head_quat: npt.ArrayLike | None = None,
        tail_quat: npt.ArrayLike | None = None,
    ) -> None:
        """Move the head and tail grippers (positions, and orientations when given) for the next step."""
        d = self.data
        d.mocap_pos[self._gripper] = head_pos
        d.mocap_pos[self._tail_gripper] = tail_pos
        if head_quat is not None:
            d.mocap_quat[self._gripper] = head_quat
        if tail_quat is not None:
            d.mocap_quat[self._tail_gripper] = tail_quat

    def end_gripper_positions(self) -> tuple[FloatArray, FloatArray]:
        """Where the head and tail grippers are (copies)."""
        d = self.data
        return d.mocap_pos[self._gripper].copy(), d.mocap_pos[self._tail_gripper].copy()

    def end_lag_m(self) -> float:
        """How far an end gripper leads its link, the larger of the two: the welds stretch under tension."""
        d = self.data
        head_body, tail_body = self._link_body[0], self._link_body[N_LINKS - 1]
        return max(
            float(np.linalg.norm(d.mocap_pos[self._gripper] - d.xpos[head_body])),
            float(np.linalg.norm(d.mocap_pos[self._tail_gripper] - d.xpos[tail_body])),
        )

    def apply(self, curve: Curve, watch: Watch | None = None) -> CurveOutcome:
        """Simulate one curve from the current state; deterministic given ``state()`` and ``curve``.

        ``watch``, when given, is called with the link points at the release and after every settling
        window (``SETTLE_WINDOW_S``) and the steps simulated so far; it only looks (``bench/settle_loss.py``
        records where a result loses its crossings).
        On ``ok=False`` the rope is left in an invalid configuration: restore a state before reuse.
        """
        self.set_state(self.state())  # resets everything but q: the result depends on q alone
        reason = self.invalid_reason()
        if reason is not None:
            return CurveOutcome(False, f"invalid start state: {reason}", 0)
        path = self.gripper_path(curve)
        reach = float(np.hypot(*path[-1, :2]))
        if reach > WORKSPACE_RADIUS_M:
            # the grasped link would end there: the rope leaves for sure, so do not simulate it
            return CurveOutcome(False, f"curve target is outside the workspace ({reach:.2f} m out)", 0)
        self.grasp(curve.link)
        reason, carry_steps = self._carry(curve.link, path)
        self.release()
        if reason is not None:
            return CurveOutcome(False, reason, carry_steps)
        if watch is not None:
            watch(self.link_points(), carry_steps)
        reason, settle_steps = self._settle(watch, carry_steps)
        steps = carry_steps + settle_steps
        if reason is not None:
            return CurveOutcome(False, reason, steps, settle_steps)
        self.forward()  # kinematics of the final state for link_points()
        reason = self.invalid_reason()
        return CurveOutcome(reason is None, reason, steps, settle_steps)

    def _carry(self, link: int, path: FloatArray) -> tuple[str | None, int]:
        """Move the gripper along ``path``, one point per step; (reason to stop or None, steps).

        Stops early, to release there, when the grasped link comes down onto another strand: the
        link is let go on top of it rather than pressed through it into the table.
        """
        d = self.data
        grasped_geom = self._link_geom[link]
        landing_from = len(path) // 2  # only the descending half of the arc may land
        window = self._window_steps
        steps = 0
        for k, target in enumerate(path):
            d.mocap_pos[self._gripper] = target
            steps += 1
            if (reason := self.step()) is not None:
                return reason, steps
            if steps % window == 0 and (reason := self.invalid_reason()) is not None:
                return reason, steps
            if k >= landing_from and self._lands_on_strand(grasped_geom, link):
                break
        return None, steps

    def _settle(self, watch: Watch | None = None, before: int = 0) -> tuple[str | None, int]:
        """Step until every link is slower than SETTLE_SPEED over two consecutive windows (``watch``: see
        :meth:`apply`; ``before``: the steps of the carry, which it is told with the settling's)."""
        window = self._window_steps
        window_s = window * self.model.opt.timestep
        last = self.link_positions()
        quiet, steps, moved = 0, 0, 0.0
        while steps < self._settle_cap_steps:
            for _ in range(window):
                steps += 1
                if (reason := self.step()) is not None:
                    return reason, steps
            if (reason := self.invalid_reason()) is not None:
                return reason, steps
            if watch is not None:
                watch(self.link_points(), before + steps)
            now = self.link_positions()
            moved = float(np.max(np.linalg.norm(now - last, axis=1)))
            last = now
            quiet = quiet + 1 if moved < self.settle_speed_m_s * window_s else 0
            if quiet >= 2:
                return None, steps
        speed = moved / window_s
        return f"rope did not settle within {SETTLE_CAP_S} s (a link still moves at {speed:.3f} m/s)", steps

    def settle(self) -> tuple[str | None, int]:
        """Let the rope come to rest as a curve's end does (no link held): (reason it was rejected or
        None, steps); afterwards the kinematics are current and the configuration valid when None."""
        reason, steps = self._settle()
        if reason is None:
            self.forward()
            reason = self.invalid_reason()
        return reason, steps

    def forward(self) -> None:
        """Recompute the kinematics of the current state (after :meth:`step`, before reading points)."""
        mujoco.mj_forward(self.model, self.data)

    def step(self) -> str | None:
        """One time step; the reason to stop when two geoms sink deeper than a radius into each other.

        Checked at every step because a strand moving at the gripper's speed could pass through
        another one between two window checks, changing the topology unphysically.
        """
        d = self.data
        mujoco.mj_step(self.model, d)
        if d.ncon and (depth := -float(d.contact.dist[: d.ncon].min())) > MAX_PENETRATION_M:
            return f"deep penetration ({depth:.4f} m > {MAX_PENETRATION_M} m)"
        return None

    def _lands_on_strand(self, grasped_geom: int, link: int) -> bool:
        """True when the grasped link rests on (not beside) a link that is not its neighbour."""
        d = self.data
        if d.ncon == 0:
            return False
        geom = d.contact.geom[: d.ncon]
        rows = np.flatnonzero((geom[:, 0] == grasped_geom) | (geom[:, 1] == grasped_geom))
        if rows.size == 0:
            return False
        pair = geom[rows]
        other_link = self._geom_link[np.where(pair[:, 0] == grasped_geom, pair[:, 1], pair[:, 0])]
        strand = (other_link >= 0) & (np.abs(other_link - link) >= 2)
        vertical = np.abs(d.contact.frame[rows, 2]) > 0.7  # contact normal mostly along z: on top
        return bool(np.any(strand & vertical))
