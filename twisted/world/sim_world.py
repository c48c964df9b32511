"""SimWorld: a MuJoCo rope whose physics are drawn per episode and whose actions and observations are noisy.

The world's rope is the planner's rope (docs/DESIGN.md section 2) with the sliding friction, the joint
stiffness and damping, the link mass and the link radius drawn from a :class:`~twisted.world.levels.Level`.
Its gripper takes a neighbour of the asked link with the level's probability and misses the carry target
and the lift height by Gaussian noise; its camera sees every link point with Gaussian noise. One seed
gives one world: the physics, the action noise and the observation noise each come from their own
generator spawned from ``SeedSequence(seed)``, so the same seed and the same actions give the same
observations (docs/DESIGN.md section 15.3).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from twisted.rope import N_LINKS
from twisted.sim.mjcf import RopeParams
from twisted.sim.simulator import DEEP_PENETRATION, Curve, RopeSim
from twisted.tighten import TAUT_LAG_M, cinch, tighten
from twisted.world.levels import Level
from twisted.world.protocol import FloatArray, Observation, PullVerdict

# The pull test's second try, when the world's simulator rejects the full pull for a strand pressed through
# another: this fraction of the gripper's lead (the tension). The ropes of all six overhand episodes at
# ``strong`` whose full pull was so rejected (friction x1.59-1.86) read their trefoil at half the lead,
# three at three quarters (docs/log/2026-12-07.md, session 9).
GENTLE_PULL = 0.5


@dataclass(frozen=True)
class WorldPhysics:
    """The physics one episode's world was drawn with: multipliers of the model's values, the radius in m."""

    friction: float
    stiffness: float
    damping: float
    mass: float
    radius_m: float

    def rope_params(self) -> RopeParams:
        base = RopeParams()
        return RopeParams(
            friction_scale=self.friction,
            joint_stiffness=base.joint_stiffness * self.stiffness,
            joint_damping=base.joint_damping * self.damping,
            link_radius_m=self.radius_m,
            # mass scales with the density; a thicker capsule is heavier as well, as a thicker rope is
            link_density_kg_m3=base.link_density_kg_m3 * self.mass,
        )

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def draw_physics(level: Level, rng: np.random.Generator) -> WorldPhysics:
    """Each quantity uniform in its range (a point range gives the value itself)."""
    names = ("friction", "stiffness", "damping", "mass", "radius_m")
    return WorldPhysics(**{name: float(rng.uniform(*getattr(level, name))) for name in names})


class SimWorld:
    """A perturbed MuJoCo rope behind the :class:`~twisted.world.protocol.World` protocol."""

    def __init__(self, level: Level, seed: int) -> None:
        self.level = level
        self.seed = int(seed)
        physics_seq, action_seq, observation_seq = np.random.SeedSequence(self.seed).spawn(3)
        self.physics = draw_physics(level, np.random.default_rng(physics_seq))
        self._actions = np.random.default_rng(action_seq)
        self._observations = np.random.default_rng(observation_seq)
        # the pull test's second gripper adds no degree of freedom: one simulator does curves and pulls
        self._sim = RopeSim(params=self.physics.rope_params(), tail_gripper=True)
        self._state = self._sim.state()
        self.sent: list[Curve] = []  # the curves the gripper really carried out (noise included)

    # ---- the protocol ---------------------------------------------------------------------------------

    def reset(self, configuration: npt.ArrayLike | None = None) -> Observation:
        sim = self._sim
        if configuration is None:
            sim.reset()  # this rope's straight layout (its own radius), as the model's reset() is the model's
        else:
            sim.set_state(configuration)
        reason = sim.invalid_reason()
        if reason is not None:
            raise ValueError(f"the world cannot lay the rope out as asked: {reason}")
        self._state = sim.state()
        return self.observe()

    def execute(self, curve: Curve) -> Observation:
        done = self._noisy(curve)
        self.sent.append(done)
        self._sim.set_state(self._state)
        outcome = self._sim.apply(done)
        if not outcome.ok:
            # the action is given up and the rope put back (a robot stops when the rope would leave its
            # table); the planner is told, and sees the rope where it was
            self._sim.set_state(self._state)
            return self.observe(fault=f"action not carried out: {outcome.reason}")
        self._state = self._sim.state()
        return self.observe()

    def cinch(self) -> Observation:
        done = cinch(self._sim, self._state)
        if done.state is None:
            self._sim.set_state(self._state)
            return self.observe(fault=f"cinch not carried out: {done.reason}")
        self._state = done.state
        self._sim.set_state(self._state)
        return self.observe()

    def observe(self, fault: str | None = None) -> Observation:
        self._sim.set_state(self._state)
        points = self._sim.link_points()
        sigma = self.level.observation_noise_m
        if sigma > 0:
            points = points + self._observations.normal(0.0, sigma, size=points.shape)
        return Observation(points, fault)

    def pull_test(self) -> PullVerdict:
        pulled, note = tighten(self._sim, self._state), None
        if not pulled.ok and (pulled.reason or "").startswith(DEEP_PENETRATION):
            # the world's simulator presses one strand through another before the rope resists as
            # much as the planner's does (a rope of high friction: docs/DESIGN.md 15.1); a robot that
            # feels the rope jam pulls less hard: again from the same rope, to GENTLE_PULL the tension
            note = f"pulled to {GENTLE_PULL:g} of the tension: at full tension {pulled.reason}"
            pulled = tighten(self._sim, self._state, taut_lag_m=GENTLE_PULL * TAUT_LAG_M)
        if not pulled.ok:
            self._sim.set_state(self._state)
            return PullVerdict(
                None, pulled.reason if note is None else f"{pulled.reason}; {note}", moved=False
            )
        # the rope stays as the pull left it: let go of both ends and let it come to rest
        self._sim.release()
        reason, _ = self._sim.settle()
        if reason is None:
            self._state = self._sim.state()
            return PullVerdict(pulled.knot_name, None, note)
        # read, but the pulled rope would not rest: it is put back as it lay (the knot read stands: a pull
        # by the ends does not change it)
        self._sim.set_state(self._state)
        unsettled = f"the pulled rope did not come to rest ({reason}): it lies as before"
        return PullVerdict(
            pulled.knot_name, None, unsettled if note is None else f"{note}; {unsettled}", moved=False
        )

    def checkpoint(self) -> dict[str, Any]:
        return {
            "state": self._state.tolist(),
            "actions_rng": self._actions.bit_generator.state,
            "observations_rng": self._observations.bit_generator.state,
        }

    def restore(self, checkpoint: dict[str, Any]) -> None:
        state = np.asarray(checkpoint["state"], dtype=np.float64)
        if state.shape != (self._sim.state_size,) or not np.all(np.isfinite(state)):
            raise ValueError(f"a world checkpoint holds a finite rope state of {self._sim.state_size} floats")
        self._state = state
        self._actions.bit_generator.state = checkpoint["actions_rng"]
        self._observations.bit_generator.state = checkpoint["observations_rng"]

    # ---- the world's own (never given to the planner) -------------------------------------------------

    def true_points(self) -> FloatArray:
        """The rope's link points without the camera's noise (for tests and pictures, not for planning)."""
        self._sim.set_state(self._state)
        return self._sim.link_points()

    def _noisy(self, curve: Curve) -> Curve:
        """The curve the gripper carries out: maybe a neighbour's link, the target and the lift off by noise.

        The draws are made whatever the level (zero noise draws zeros), so that one seed and one list of
        actions give one stream of noise at every level."""
        level, rng = self.level, self._actions
        off, side = rng.random() < level.grasp_off_by_one_p, rng.random() < 0.5
        dx, dy = rng.normal(0.0, 1.0, size=2) * level.carry_noise_m
        dz = float(rng.normal(0.0, 1.0)) * level.lift_noise_m
        link = curve.link
        if off:
            step = 1 if side else -1
            link = link + step if 0 <= link + step < N_LINKS else link - step
        return Curve(link, max(curve.z_max_m + dz, 0.0), curve.x_m + float(dx), curve.y_m + float(dy))
