"""From observed link points back to the planner: P-data and a configuration ``q`` of the planner's model.

P-data is ``Top`` of the points (docs/DESIGN.md section 4.2). The configuration is a fit of the model's
chain to the points (docs/DESIGN.md section 15.4): link ``i`` runs from point ``i`` to point ``i + 1``, so
its direction is known; the middle link carries the free joint (its centre is the mid-point of its two
points) and every other link hangs off its neighbour towards the middle by a yaw about the parent's z
and then a pitch about the new y (the order of the hinges in the MJCF, 2.1). Each hinge pair is read
from the child's direction in the parent's frame; of the two pairs that give a direction bent past 90
degrees, the one within the joint limits. The roll of the middle link about its own axis is not seen in
the points; the fit takes the roll nearest a configuration the rope is expected to be near (``like``: the
model's outcome of the last action), else the roll whose hinge angles bend the chain least (the least
elastic energy). Points lower than the model's link radius (less 2 mm) are raised to it (they lie on the
table). Joint angles are clipped to the model's limits, the velocity is zero (a rope at rest), and the
fit's residual is the RMS distance between the observed points and the points of the fitted
configuration (:func:`rms_distance`).

That first fit places each link from its own two points and the links before it, so the camera's noise
adds up along the chain (about 1 cm RMS at the ``moderate`` level's 2 mm), enough to press one strand
through another where they cross. It is then refined by damped least squares (Levenberg-Marquardt) over
the middle link's pose and every hinge angle, towards the observed points: about 2-3 mm RMS at
``moderate``, 20 ms (docs/DESIGN.md section 15.4).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np
import numpy.typing as npt

from twisted.rope import N_LINKS, N_POINTS
from twisted.sim.mjcf import MIDDLE_LINK, RopeParams, joint_names
from twisted.sim.simulator import RopeSim
from twisted.topology import PData, top

FloatArray = npt.NDArray[np.float64]

ROLL_GRID = 36  # roll candidates of the middle link, 10 degrees apart
HEIGHT_STRETCHES = (
    1.0,
    1.5,
    2.0,
    3.0,
)  # tried in turn when a fit is pressed through a strand (rest_configuration)
REFINE_ITERATIONS = 20  # Levenberg-Marquardt steps of the refinement (each: one finite-difference Jacobian)
REFINE_DONE_M2 = 1e-16  # a sum of squared misses under this is an exact fit: nothing to refine
TABLE_GIVE_M = 0.002  # how far under one radius a resting rope's centreline may be seen before it is raised


@dataclass(frozen=True)
class Fit:
    """A configuration of the planner's model fitted to observed points."""

    q: FloatArray  # qpos then qvel (zero), docs/DESIGN.md section 2.3
    points: FloatArray  # the link points of ``q``
    residual_m: float  # RMS distance of ``points`` from the observed points


def observed_p_data(points: npt.ArrayLike) -> PData:
    """``Top`` of observed link points (the one P-data reader, topology.top)."""
    return top(np.asarray(points, dtype=np.float64))


def rms_distance(points: FloatArray, other: FloatArray) -> float:
    """The RMS distance (m) between two ropes' link points, point by point."""
    return float(np.sqrt(np.mean(np.sum((points - other) ** 2, axis=1))))


def _rz(a: float) -> FloatArray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a: float) -> FloatArray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _hinges(parent: FloatArray, direction: FloatArray, limit: float) -> tuple[float, float, FloatArray]:
    """Yaw and pitch turning ``parent``'s x axis onto ``direction``, and the child frame.

    Two hinge pairs give one direction: (yaw, pitch) with the pitch within +-90 degrees, and (yaw + 180,
    180 - pitch), whose child frame is the first's rolled half a turn. With the model's limits beyond 90
    degrees (a curl bends a joint that far) both can be within them; the pair within the limits is taken,
    of two the one bending less (the smaller sum of squares), and an angle beyond its limit is clipped."""
    u = parent.T @ direction
    yaw = math.atan2(u[1], u[0])
    pitch = math.atan2(-u[2], math.hypot(u[0], u[1]))
    other_yaw = yaw - math.pi if yaw > 0.0 else yaw + math.pi
    other_pitch = (math.pi if pitch >= 0.0 else -math.pi) - pitch

    def cost(a: float, b: float) -> tuple[float, float]:
        beyond = max(abs(a) - limit, 0.0) + max(abs(b) - limit, 0.0)
        return beyond, a * a + b * b

    if cost(other_yaw, other_pitch) < cost(yaw, pitch):
        yaw, pitch = other_yaw, other_pitch
    yaw = float(np.clip(yaw, -limit, limit))
    pitch = float(np.clip(pitch, -limit, limit))
    return yaw, pitch, parent @ _rz(yaw) @ _ry(pitch)


def _root_frame(direction: FloatArray, roll: float) -> FloatArray:
    x = direction
    y = np.cross([0.0, 0.0, 1.0], x)
    if np.linalg.norm(y) < 1e-9:  # a vertical middle link: any horizontal y will do
        y = np.array([0.0, 1.0, 0.0])
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    frame = np.column_stack([x, y, z])
    c, s = math.cos(roll), math.sin(roll)
    return frame @ np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


class ChainFit:
    """Fits the planner's chain to link points; holds one model simulator for the forward kinematics."""

    def __init__(self, params: RopeParams | None = None) -> None:
        self.sim = RopeSim(params=params or RopeParams())
        m = self.sim.model
        # the qpos addresses of each joint's (yaw, pitch)
        self._adr = [[int(m.jnt_qposadr[m.joint(n).id]) for n in joint_names(i)] for i in range(N_LINKS - 1)]
        self._limit = math.radians(self.sim.params.joint_limit_deg)
        self._hinge_adr = np.array(sorted(a for pair in self._adr for a in pair))

    def _qpos(self, points: FloatArray, roll: float) -> tuple[FloatArray, float]:
        """qpos for one roll of the middle link, and its bending energy (sum of squared hinge angles)."""
        d = np.diff(points, axis=0)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        qpos = np.zeros(self.sim.model.nq)
        root = _root_frame(d[MIDDLE_LINK], roll)
        qpos[:3] = 0.5 * (points[MIDDLE_LINK] + points[MIDDLE_LINK + 1])
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, root.reshape(-1))
        qpos[3:7] = quat
        energy = 0.0
        # the head half hangs off the middle by joint i (links i, i+1), the tail half by joint i-1
        halves = ((range(MIDDLE_LINK - 1, -1, -1), 0), (range(MIDDLE_LINK + 1, N_LINKS), -1))
        for order, joint_shift in halves:
            frame = root
            for link in order:
                yaw, pitch, frame = _hinges(frame, d[link], self._limit)
                a_yaw, a_pitch = self._adr[link + joint_shift]
                qpos[a_yaw], qpos[a_pitch] = yaw, pitch
                energy += yaw * yaw + pitch * pitch
        return qpos, energy

    def _points_of(self, qpos: FloatArray) -> FloatArray:
        """The link points of ``qpos`` (forward kinematics only)."""
        self.sim.data.qpos[:] = qpos
        mujoco.mj_kinematics(self.sim.model, self.sim.data)
        return self.sim.link_points()

    def _moved(self, qpos: FloatArray, x: FloatArray) -> FloatArray:
        """``qpos`` moved by ``x``: the middle link's centre by x[0:3], its orientation by the rotation
        vector x[3:6] (in its own frame), the hinge angles by x[6:] (clipped to the joint limits)."""
        q = qpos.copy()
        q[:3] += x[:3]
        angle = float(np.linalg.norm(x[3:6]))
        if angle > 0.0:
            turn, turned = np.empty(4), np.empty(4)
            mujoco.mju_axisAngle2Quat(turn, x[3:6] / angle, angle)
            mujoco.mju_mulQuat(turned, q[3:7], turn)
            q[3:7] = turned / np.linalg.norm(turned)
        q[self._hinge_adr] = np.clip(q[self._hinge_adr] + x[6:], -self._limit, self._limit)
        return q

    def _refine(self, qpos: FloatArray, target: FloatArray) -> FloatArray:
        """Levenberg-Marquardt on the squared distances of ``qpos``'s link points from ``target``: a step
        is kept only when it lowers them, so an exact fit stays exact."""
        n = 6 + self._hinge_adr.size
        miss = (self._points_of(qpos) - target).ravel()
        cost, damping, h = float(miss @ miss), 1e-3, 1e-6
        for _ in range(REFINE_ITERATIONS):
            if cost < REFINE_DONE_M2:
                break
            jac = np.empty((miss.size, n))
            for k in range(n):
                x = np.zeros(n)
                x[k] = h
                jac[:, k] = ((self._points_of(self._moved(qpos, x)) - target).ravel() - miss) / h
            normal, gradient = jac.T @ jac, jac.T @ miss
            while damping < 1e6:
                step = -np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-9), gradient)
                trial = self._moved(qpos, np.asarray(step, dtype=np.float64))
                trial_miss = (self._points_of(trial) - target).ravel()
                if float(trial_miss @ trial_miss) < cost:
                    qpos, miss, cost = trial, trial_miss, float(trial_miss @ trial_miss)
                    damping = max(damping / 3.0, 1e-7)
                    break
                damping *= 10.0
            else:
                break
        return qpos

    def _roll_score(self, like: npt.ArrayLike | None) -> Callable[[FloatArray, float], float]:
        """What a roll of the middle link is chosen by: the bending energy, or (``like`` given) the
        squared distance of the hinge angles and the middle link's orientation from ``like``'s."""
        if like is None:
            return lambda qpos, energy: energy
        q = np.asarray(like, dtype=np.float64)
        if q.shape != (self.sim.state_size,) or not np.all(np.isfinite(q)):
            raise ValueError(f"an expected configuration holds {self.sim.state_size} finite values")
        if not 0.5 < float(np.linalg.norm(q[3:7])) < 2.0:
            raise ValueError("an expected configuration's middle link has no orientation (quaternion)")
        hinges, quat = q[self._hinge_adr], q[3:7] / np.linalg.norm(q[3:7])

        def distance(qpos: FloatArray, energy: float) -> float:
            # the hinge angles' squared distance, and the middle link's turn from ``like``'s (the one
            # that tells rolls apart where the hinges cannot: a straight rope)
            turn = 2.0 * math.acos(min(abs(float(qpos[3:7] @ quat)) / float(np.linalg.norm(qpos[3:7])), 1.0))
            return float(np.sum((qpos[self._hinge_adr] - hinges) ** 2)) + turn * turn

        return distance

    def fit(self, points: npt.ArrayLike, like: npt.ArrayLike | None = None) -> Fit:
        """The configuration whose link points come closest to ``points`` (N_POINTS x 3, metres).

        The points do not show how the chain is rolled about itself (the middle link's roll, which the
        hinge angles then follow). Without ``like`` the roll is the one that bends the chain least; with
        ``like``, a configuration the rope is expected to be near (the model's prediction of the last
        action's outcome), it is the roll whose hinge angles lie closest to ``like``'s: the twist a curve
        leaves in the rope is then carried from one observation to the next (docs/DESIGN.md 15.4)."""
        p = np.asarray(points, dtype=np.float64)
        if p.shape != (N_POINTS, 3) or not np.all(np.isfinite(p)):
            raise ValueError(f"observed points must be {N_POINTS} x 3 finite values, got shape {p.shape}")
        if np.min(np.linalg.norm(np.diff(p, axis=0), axis=1)) < 1e-9:
            raise ValueError("observed points: two neighbouring link points coincide")
        score = self._roll_score(like)
        observed = p
        # a point lower than the model's resting height lies on the table: the model's rope rests with
        # its centreline one radius up (less a contact's sub-millimetre give), and a chain fitted lower
        # would be pressed into the table
        p = p.copy()
        p[:, 2] = np.maximum(p[:, 2], self.sim.params.link_radius_m - TABLE_GIVE_M)
        rolls = np.linspace(-math.pi, math.pi, ROLL_GRID, endpoint=False)
        best = int(np.argmin([score(*self._qpos(p, float(r))) for r in rolls]))
        # refine around the best grid roll (golden-section on the score)
        lo, hi = rolls[best] - math.pi / ROLL_GRID, rolls[best] + math.pi / ROLL_GRID
        for _ in range(30):
            a, b = hi - 0.618 * (hi - lo), lo + 0.618 * (hi - lo)
            if score(*self._qpos(p, a)) < score(*self._qpos(p, b)):
                hi = b
            else:
                lo = a
        qpos = self._refine(self._qpos(p, 0.5 * (lo + hi))[0], p)
        q = np.concatenate([qpos, np.zeros(self.sim.model.nv)])
        self.sim.set_state(q)
        fitted = self.sim.link_points()
        return Fit(q, fitted, rms_distance(fitted, observed))

    def rest_configuration(
        self, points: npt.ArrayLike, like: npt.ArrayLike | None = None
    ) -> tuple[Fit, tuple[FloatArray, FloatArray, PData] | None]:
        """The fit of ``points`` and its configuration at rest in the model (:meth:`at_rest`).

        A chain fitted through noisy points can press one strand more than a radius into another where
        they cross, which the model rejects; then the heights above the resting height are stretched
        (x1.5, x2, x3: which strand is over stays over) and fitted again, and the model lets the rope
        fall back when it rests. The fit returned is that of the points as observed."""
        p = np.asarray(points, dtype=np.float64)
        first = self.fit(p, like)
        floor = self.sim.params.link_radius_m
        for stretch in HEIGHT_STRETCHES:
            fit = first
            if stretch != 1.0:
                stretched = p.copy()
                stretched[:, 2] = floor + np.maximum(p[:, 2] - floor, 0.0) * stretch
                fit = self.fit(stretched, like)
            rest = self.at_rest(fit)
            if rest is not None:
                return first, rest
        return first, None

    def at_rest(self, fit: Fit) -> tuple[FloatArray, FloatArray, PData] | None:
        """The fitted configuration let come to rest in the planner's model (the noise of the points may
        press a link into the table or another strand): its ``q``, points and P-data, or None when the
        model rejects it."""
        self.sim.set_state(fit.q)
        reason, _ = self.sim.settle()
        if reason is not None:
            return None
        return self.sim.state(), self.sim.link_points(), self.sim.p_data()
