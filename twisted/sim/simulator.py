"""RopeSim: the MuJoCo rope, its state, its link points and one curve action ``f(q, c) -> q'``.

A curve ``c = (link, z_max, x, y)`` (docs/DESIGN.md section 3): weld the gripper to ``link``, carry it
along a straight line to ``(x, y)`` away from where it lies, with minimum-jerk timing and a height
arc on top, release it a little above the table (or as soon as it lands on another strand), and
step until the rope has settled. The result depends only on ``state()`` and the curve: every
action starts from ``mj_resetData`` and the restored state, so solver warm starts or a previous
grasp never leak into the next action, in this process or another.

A curve may name a second hand (:class:`Pin`, docs/DESIGN.md section 3.6): a second gripper holds one
link where it lies (or after placing it, or while carrying it) until the active link is let go.
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
    PIN_GRIPPER,
    TAIL_GRIPPER,
    TAIL_WELD,
    RopeParams,
    joint_names,
    link_name,
    pin_weld_name,
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

# A pinned link (two-hand curve) dragged farther than this from the second hand is a rejection: the carry
# pulled the rope between the two hands taut, which a gripper would not hold.
PIN_SLIP_M = LINK_RADIUS_M / 2
# a hand that carries its link leads it by a few mm at speed anyway (the weld is a stiff spring)
MOVING_PIN_SLIP_M = 2 * LINK_RADIUS_M

# Settling: every link slower than SETTLE_SPEED_M_S over two consecutive windows, with a cap.
SETTLE_WINDOW_S = 0.05
SETTLE_SPEED_M_S = 0.01
SETTLE_CAP_S = 3.0

# Validity of a configuration: anything else is rejected, never silently kept.
WORKSPACE_RADIUS_M = 1.2
MAX_HEIGHT_M = 0.3
# Both in link radii of the rope simulated (``RopeParams.link_radius_m``: a world's rope may be thicker
# or thinner than the planner's): a centreline point this far under the table surface is through it,
# and two geoms sunk this deep into each other have passed through
MIN_HEIGHT_RADII = -0.5
MAX_PENETRATION_RADII = 1.0
# how a rejection for one strand pressed more than MAX_PENETRATION_RADII into another begins
DEEP_PENETRATION = "deep penetration"

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


def _check_link(what: str, link: object) -> int:
    """``link`` as an int in 0..N_LINKS-1, else a ValueError that names ``what``."""
    if isinstance(link, bool) or not isinstance(link, (int, np.integer)):
        raise ValueError(f"{what} must be an integer 0..{N_LINKS - 1}, got {link!r}")
    if not 0 <= link < N_LINKS:
        raise ValueError(f"{what} must be in 0..{N_LINKS - 1}, got {link}")
    return int(link)


PIN_MODES = ("hold", "place", "carry")


@dataclass(frozen=True, slots=True)
class Pin:
    """The second hand of a two-hand curve (docs/DESIGN.md section 3.6): it grasps ``link`` and

    - ``"hold"``: holds it where it lies (position and orientation, not lifted) from before the active
      carry until the active link is let go;
    - ``"place"``: first carries it by ``(x_m, y_m)`` with a lift of ``z_max_m + MIN_LIFT_M``, turning it by
      ``turn_rad`` about the vertical (the active gripper waits), lets the rope come to rest with it held,
      then holds it there through the active carry (pick, place, hold);
    - ``"carry"``: carries it so, at the same time as the active link (both paths last as long as the
      longer would alone), and lets go with it.

    ``around`` (-1, 0, +1) bends the active link's path: 0 is the straight carry of section 3.2; +1 (-1)
    carries it counter-clockwise (clockwise) about where the pinned link is when the active carry starts,
    to the same target, the link turned with the angle it sweeps. Then both hands let go and the rope
    settles as after a one-hand curve.
    """

    link: int
    mode: str = "hold"
    z_max_m: float = 0.0
    x_m: float = 0.0
    y_m: float = 0.0
    turn_rad: float = 0.0
    around: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "link", _check_link("the pinned link", self.link))
        if self.mode not in PIN_MODES:
            raise ValueError(f"pin mode must be one of {', '.join(PIN_MODES)}, got {self.mode!r}")
        values = (self.z_max_m, self.x_m, self.y_m, self.turn_rad)
        if not all(math.isfinite(float(v)) for v in values):
            raise ValueError(f"pin (z_max_m, x_m, y_m, turn_rad) must be finite, got {values}")
        for name, v in zip(("z_max_m", "x_m", "y_m", "turn_rad"), values, strict=True):
            object.__setattr__(self, name, float(v))
        if self.mode == "hold" and any(values):
            raise ValueError(
                f"a held pin does not move: z_max_m, x_m, y_m and turn_rad are for modes place and carry, "
                f"got {values}"
            )
        if self.around not in (-1, 0, 1) or isinstance(self.around, bool):
            raise ValueError(f"pin around must be -1, 0 or +1, got {self.around!r}")


@dataclass(frozen=True, slots=True)
class Curve:
    """One curve action: grasp ``link``, lift by ``z_max_m``, move it by ``(x_m, y_m)``, release.

    ``x_m``/``y_m`` are a displacement relative to the grasped link's current position; the
    link's peak lift is ``z_max_m + MIN_LIFT_M`` (so z_max = 0 still clears the table). Values
    outside ``CURVE_LOW..CURVE_HIGH`` are allowed (a sampled curve may stray); the simulator rejects
    a result that leaves the workspace. A negative ``z_max_m`` counts as 0. ``pin``, when given, is the
    second hand (:class:`Pin`); it must hold another link than ``link``.
    """

    link: int
    z_max_m: float
    x_m: float
    y_m: float
    pin: Pin | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "link", _check_link("curve link", self.link))
        values = (self.z_max_m, self.x_m, self.y_m)
        if not all(math.isfinite(float(v)) for v in values):
            raise ValueError(f"curve (z_max_m, x_m, y_m) must be finite, got {values}")
        for name, v in zip(("z_max_m", "x_m", "y_m"), values, strict=True):
            object.__setattr__(self, name, float(v))
        if self.pin is not None:
            if not isinstance(self.pin, Pin):
                raise ValueError(f"a curve's pin must be a Pin, got {self.pin!r}")
            if self.pin.link == self.link:
                raise ValueError(
                    f"the pinned link {self.pin.link} is the curve's active link: the second hand must "
                    f"hold another link"
                )

    def to_array(self) -> FloatArray:
        """``[link, z_max_m, x_m, y_m]`` as float64 (a one-hand curve: a two-hand one has no such array)."""
        if self.pin is not None:
            raise ValueError("a two-hand curve (with a pin) has no 4-number array")
        return np.array([self.link, self.z_max_m, self.x_m, self.y_m], dtype=np.float64)

    @classmethod
    def from_array(cls, a: npt.ArrayLike) -> Curve:
        """Inverse of :meth:`to_array`; the link is rounded to the nearest integer."""
        v = np.asarray(a, dtype=np.float64).reshape(-1)
        if v.shape != (4,):
            raise ValueError(f"a curve array has 4 entries [link, z_max_m, x_m, y_m], got shape {v.shape}")
        return cls(int(round(v[0])), float(v[1]), float(v[2]), float(v[3]))

    def clipped(self) -> Curve:
        """The curve with z_max, x and y clipped to ``CURVE_LOW..CURVE_HIGH`` (the pin kept as it is)."""
        lo, hi = CURVE_LOW, CURVE_HIGH
        return Curve(
            self.link,
            float(np.clip(self.z_max_m, lo[1], hi[1])),
            float(np.clip(self.x_m, lo[2], hi[2])),
            float(np.clip(self.y_m, lo[3], hi[3])),
            self.pin,
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


def _turned(quat: npt.ArrayLike, yaw: FloatArray) -> FloatArray:
    """The orientation ``quat`` (w, x, y, z) turned about the world's vertical by each angle of ``yaw``."""
    w0, x0, y0, z0 = np.asarray(quat, dtype=np.float64)
    c, s = np.cos(0.5 * yaw), np.sin(0.5 * yaw)
    return np.stack([c * w0 - s * z0, c * x0 - s * y0, c * y0 + s * x0, c * z0 + s * w0], axis=1)


def _pad(a: FloatArray, n: int) -> FloatArray:
    """``a`` (one row per step) held at its last row up to ``n`` rows."""
    return a if len(a) >= n else np.concatenate([a, np.repeat(a[-1:], n - len(a), axis=0)])


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
        self._pin_gripper = int(m.body(PIN_GRIPPER).mocapid[0])
        self._pin_weld = np.array([m.equality(pin_weld_name(i)).id for i in range(N_LINKS)])
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
        self.min_height_m = MIN_HEIGHT_RADII * self.params.link_radius_m
        self.max_penetration_m = MAX_PENETRATION_RADII * self.params.link_radius_m
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
        if z_min < self.min_height_m:
            return f"rope went below the table (centreline at z = {z_min:.4f} m)"
        if z_top > MAX_HEIGHT_M:
            return f"rope flew up (centreline at z = {z_top:.2f} m > {MAX_HEIGHT_M} m)"
        if d.ncon and (depth := -float(d.contact.dist[: d.ncon].min())) > self.max_penetration_m:
            return f"{DEEP_PENETRATION} ({depth:.4f} m > {self.max_penetration_m:.4g} m)"
        return None

    # ---- the curve action -------------------------------------------------------------------------

    def gripper_path(self, curve: Curve, min_duration_s: float = 0.0) -> FloatArray:
        """The gripper positions, one per time step, for ``curve`` from the current configuration.

        A straight horizontal line to the target with minimum-jerk timing, plus a height arc
        ``lift * sin(pi s)`` over the line from the link's height down to the release height. The
        carry lasts at least ``min_duration_s`` (a bench that also turns the gripper slows it down).
        """
        return self._line_path(curve.link, curve.z_max_m, curve.x_m, curve.y_m, min_duration_s)[0]

    def _line_path(
        self, link: int, z_max_m: float, x_m: float, y_m: float, min_duration_s: float = 0.0
    ) -> tuple[FloatArray, FloatArray]:
        """The straight carry of :meth:`gripper_path` for ``link`` and its progress ``s`` per step."""
        start = self.data.xpos[self._link_body[link]].copy()
        dxy = np.array([x_m, y_m])
        lift = max(z_max_m, 0.0) + MIN_LIFT_M
        duration = max(MIN_MOVE_S, min_duration_s, (float(np.hypot(*dxy)) + 2.0 * lift) / GRIPPER_SPEED_M_S)
        s = self._progress(duration)
        path = np.empty((len(s), 3))
        path[:, :2] = start[:2] + s[:, None] * dxy
        path[:, 2] = start[2] + (RELEASE_HEIGHT_M - start[2]) * s + lift * np.sin(np.pi * s)
        return path, s

    def _progress(self, duration_s: float) -> FloatArray:
        """Minimum-jerk progress, one value per time step of a carry lasting ``duration_s``."""
        n = max(1, math.ceil(duration_s / self.model.opt.timestep))
        return minimum_jerk(np.arange(1, n + 1) / n)

    @staticmethod
    def _line_duration(z_max_m: float, x_m: float, y_m: float) -> float:
        return (float(np.hypot(x_m, y_m)) + 2.0 * (max(z_max_m, 0.0) + MIN_LIFT_M)) / GRIPPER_SPEED_M_S

    def _around_path(
        self, curve: Curve, pivot: FloatArray, around: int, min_duration_s: float = 0.0
    ) -> tuple[FloatArray, FloatArray]:
        """The active carry of a pin with ``around`` = +1 / -1: from the link's centre to the same target as
        :meth:`gripper_path`, counter-clockwise / clockwise about ``pivot`` (x, y), the radius changing
        evenly with the angle, the same height arc; positions and the angle swept so far, per step."""
        start = self.data.xpos[self._link_body[curve.link]].copy()
        v0 = start[:2] - pivot
        v1 = v0 + np.array([curve.x_m, curve.y_m])
        r0, r1 = float(np.hypot(*v0)), float(np.hypot(*v1))
        a0 = math.atan2(v0[1], v0[0])
        sweep = (math.atan2(v1[1], v1[0]) - a0) % (2.0 * math.pi)  # counter-clockwise, in [0, 2 pi)
        if around < 0 and sweep > 0.0:
            sweep -= 2.0 * math.pi
        lift = max(curve.z_max_m, 0.0) + MIN_LIFT_M
        length = abs(sweep) * 0.5 * (r0 + r1) + abs(r1 - r0)
        duration = max(MIN_MOVE_S, min_duration_s, (length + 2.0 * lift) / GRIPPER_SPEED_M_S)
        s = self._progress(duration)
        angle, radius = a0 + s * sweep, r0 + s * (r1 - r0)
        path = np.empty((len(s), 3))
        path[:, 0] = pivot[0] + radius * np.cos(angle)
        path[:, 1] = pivot[1] + radius * np.sin(angle)
        path[:, 2] = start[2] + (RELEASE_HEIGHT_M - start[2]) * s + lift * np.sin(np.pi * s)
        return path, s * sweep

    def grasp(self, link: int) -> None:
        """Put the gripper exactly on ``link`` and weld it there (its weld relpose is the identity)."""
        self._weld_to(self._gripper, self._weld, link)

    def _weld_to(self, mocap: int, welds: npt.NDArray[np.int64], link: int) -> None:
        """Put mocap body ``mocap`` on ``link`` and switch on its weld there (of its ``welds``), only that."""
        d, body = self.data, self._link_body[link]
        d.mocap_pos[mocap] = d.xpos[body]
        d.mocap_quat[mocap] = d.xquat[body]
        d.eq_active[welds] = 0
        d.eq_active[welds[link]] = 1

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
        pin, placed = curve.pin, 0
        if pin is not None:
            pin_end = self._line_path(pin.link, pin.z_max_m, pin.x_m, pin.y_m)[0]
            if (reason := self._outside(pin_end)) is not None:
                return CurveOutcome(False, f"pin {reason}", 0)
            self.grasp_pin(pin.link)
            if pin.mode == "place":
                reason, placed = self._place(pin)
                if reason is not None:
                    self.release()
                    return CurveOutcome(False, f"placing the pinned link: {reason}", placed)
        path, quats, other = (self.gripper_path(curve), None, None)
        if pin is not None:
            path, quats, other = self._hand_paths(curve)
        if (reason := self._outside(path)) is not None:
            # the grasped link would end there: the rope leaves for sure, so do not simulate it
            self.release()
            return CurveOutcome(False, f"curve {reason}", placed)
        self.grasp(curve.link)
        reason, carry_steps = self._carry(curve.link, path, quats=quats, other=other)
        carry_steps += placed
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

    def _outside(self, path: FloatArray) -> str | None:
        """Why a carry along ``path`` is not simulated (its end beyond the workspace), or None."""
        reach = float(np.hypot(*path[-1, :2]))
        return f"target is outside the workspace ({reach:.2f} m out)" if reach > WORKSPACE_RADIUS_M else None

    def grasp_pin(self, link: int) -> None:
        """Put the second hand exactly on ``link`` and weld it there (position and orientation held)."""
        self._weld_to(self._pin_gripper, self._pin_weld, link)

    def pinned_link(self) -> int | None:
        """The link the second hand holds now, or None."""
        held = np.flatnonzero(self.data.eq_active[self._pin_weld])
        return int(held[0]) if held.size else None

    def _pin_slip(self, link: int, moving: bool) -> str | None:
        """Why the second hand lost ``link``: it lags the hand by more than :data:`PIN_SLIP_M` (a
        ``moving`` hand: :data:`MOVING_PIN_SLIP_M`); else None."""
        d = self.data
        lag = float(np.linalg.norm(d.mocap_pos[self._pin_gripper] - d.xpos[self._link_body[link]]))
        limit = MOVING_PIN_SLIP_M if moving else PIN_SLIP_M
        if lag > limit:
            return (
                f"the rope between the hands was pulled taut (pinned link {link} dragged {lag * 1000:.0f} mm "
                f"from the second hand > {limit * 1000:.0f} mm)"
            )
        return None

    def _place(self, pin: Pin) -> tuple[str | None, int]:
        """Pick, place, hold: carry the pinned link (already grasped by the second hand) by the pin's
        displacement, then let the rope come to rest with it held; (reason to stop or None, steps)."""
        path, s = self._line_path(pin.link, pin.z_max_m, pin.x_m, pin.y_m)
        quats = _turned(self.data.mocap_quat[self._pin_gripper], pin.turn_rad * s)
        reason, steps = self._carry(pin.link, path, mocap=self._pin_gripper, quats=quats)
        if reason is not None:
            return reason, steps
        reason, settled = self._settle()
        self.forward()  # the active carry starts from the current kinematics
        return reason, steps + settled

    def _hand_paths(
        self, curve: Curve
    ) -> tuple[FloatArray, FloatArray | None, tuple[int, FloatArray, FloatArray] | None]:
        """The active gripper's path and orientations (None: kept) for a two-hand curve, and for a pin in
        mode carry the second hand's (mocap id, path, orientations), both as long."""
        pin = curve.pin
        assert pin is not None
        alone = self._line_duration(pin.z_max_m, pin.x_m, pin.y_m) if pin.mode == "carry" else 0.0
        quats = None
        if pin.around:
            pivot = self.data.xpos[self._link_body[pin.link], :2].copy()
            path, swept = self._around_path(curve, pivot, pin.around, alone)
            quats = _turned(self.data.xquat[self._link_body[curve.link]], swept)
        else:
            path = self._line_path(curve.link, curve.z_max_m, curve.x_m, curve.y_m, alone)[0]
        if pin.mode != "carry":
            return path, quats, None
        duration = len(path) * self.model.opt.timestep
        pin_path, s = self._line_path(pin.link, pin.z_max_m, pin.x_m, pin.y_m, duration)
        pin_quats = _turned(self.data.xquat[self._link_body[pin.link]], pin.turn_rad * s)
        n = max(len(path), len(pin_path))  # the same duration up to a step of rounding: hold the last point
        path, pin_path, pin_quats = (_pad(a, n) for a in (path, pin_path, pin_quats))
        return path, None if quats is None else _pad(quats, n), (self._pin_gripper, pin_path, pin_quats)

    def _carry(
        self,
        link: int,
        path: FloatArray,
        mocap: int | None = None,
        quats: FloatArray | None = None,
        other: tuple[int, FloatArray, FloatArray] | None = None,
    ) -> tuple[str | None, int]:
        """Move the gripper (``mocap``, default the active one) along ``path``, one point per step, turned
        to ``quats`` when given, and ``other``'s gripper (mocap id, path, orientations) with it; (reason to
        stop or None, steps).

        Stops early, to release there, when the grasped link comes down onto another strand: the
        link is let go on top of it rather than pressed through it into the table.
        """
        d = self.data
        mocap = self._gripper if mocap is None else mocap
        grasped_geom = self._link_geom[link]
        landing_from = len(path) // 2  # only the descending half of the arc may land
        window = self._window_steps
        steps = 0
        pinned = self.pinned_link()
        pin_moves = mocap == self._pin_gripper or other is not None
        for k, target in enumerate(path):
            d.mocap_pos[mocap] = target
            if quats is not None:
                d.mocap_quat[mocap] = quats[k]
            if other is not None:
                d.mocap_pos[other[0]] = other[1][k]
                d.mocap_quat[other[0]] = other[2][k]
            steps += 1
            if (reason := self.step()) is not None:
                return reason, steps
            if pinned is not None and (reason := self._pin_slip(pinned, pin_moves)) is not None:
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
        if d.ncon and (depth := -float(d.contact.dist[: d.ncon].min())) > self.max_penetration_m:
            return f"{DEEP_PENETRATION} ({depth:.4f} m > {self.max_penetration_m:.4g} m)"
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
