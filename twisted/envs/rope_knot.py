"""``RopeKnotEnv``: the rope as a goal-conditioned Gymnasium environment (one step = one curve).

* Episode: the straight rope (``RopeSim.reset()``) and a goal P-data state drawn from the goal pool
  (uniformly over the crossing counts in the pool, then uniformly within a count, so 1-, 2- and
  3-crossing goals are equally frequent whatever their numbers of states). ``reset(seed=...)``
  replays: the goal and, for the same actions, the whole trajectory (the simulator is deterministic).
* Action: ``Box(-1, 1, (4,))`` = (link, z_max, x, y) normalised. The link is the nearest of 0..N_LINKS-1
  to ``(a0 + 1) / 2 * (N_LINKS - 1)``; ``z_max = (a1 + 1) / 2 * 0.07`` m; ``(a2, a3) * 0.5`` m is the
  displacement in the rope's *canonical frame* (the inverse model's,
  :func:`twisted.model.encoding.preprocess`: centred, head->tail along +x), rotated back to the world and
  clipped to the curve ranges. The canonical frame makes the policy's job invariant to where the rope lies
  and how it is turned.
* Observation (Dict): ``observation`` = the inverse model's geometric features of the link points
  in the canonical frame (centred points, which segments cross with over/under and sign, where the
  crossing visits lie; 506 floats) then the configuration's 40 joint angles (qpos after the free
  joint); ``achieved_goal`` = ``encode_p_data(Top(q))``, ``desired_goal`` = ``encode_p_data(goal)``
  (199 floats each, the inverse model's encoder, which determines the state exactly).
* Reward: 0 when ``achieved_goal == desired_goal`` (the episode then terminates), else -1;
  :meth:`RopeKnotEnv.compute_reward` is vectorised for hindsight relabelling. Truncation after
  ``max_curves`` curves.
* A curve the simulator rejects (rope left the workspace, diverged, ...) or one that makes more than
  ``MAX_CROSSINGS`` (the rope's crossing limit, 6 by default) crossings is a *failed curve*: the
  previous state is restored, the step counts, reward -1, ``info["curve_failed"] = True`` with
  ``info["reason"]``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import numpy.typing as npt
from gymnasium import spaces

from twisted.model.encoding import (
    GEOMETRY_DIM,
    MAX_CROSSINGS,
    P_DATA_DIM,
    XY_HALF_M,
    Z_HIGH,
    Z_LOW,
    encode_p_data,
    preprocess,
)
from twisted.sim import N_LINKS, Curve, RopeSim
from twisted.topology import PData, PDataError

__all__ = [
    "ENV_ID",
    "GoalError",
    "JOINT_DIM",
    "OBSERVATION_DIM",
    "RopeKnotEnv",
    "action_to_curve",
    "curve_to_action",
    "env_spaces",
    "goal_pool",
    "observation_of",
]

ENV_ID = "twisted/RopeKnot-v0"
FREE_JOINT_QPOS = 7  # position and quaternion of the middle link; the joint angles follow
JOINT_DIM = 2 * (N_LINKS - 1)  # yaw and pitch of every joint
OBSERVATION_DIM = GEOMETRY_DIM + JOINT_DIM
DEFAULT_GOAL_CROSSINGS = (1, 2, 3)
DEFAULT_MAX_CURVES = 10
GOAL_MATCH_TOL = 1e-4  # encodings hold exact small fractions: equal states give equal vectors


class GoalError(ValueError):
    """Goals the environment cannot use (the message names the input and what is wrong)."""


# ---- the action and observation mappings, shared with the planner's policy sampler -----------------


def env_spaces() -> tuple[spaces.Dict, spaces.Box]:
    """The observation and action spaces of :class:`RopeKnotEnv` (the same for every goal source)."""
    goal_box = spaces.Box(-1.0, 1.0, shape=(P_DATA_DIM,), dtype=np.float32)
    observation = spaces.Dict(
        {
            "observation": spaces.Box(-np.inf, np.inf, shape=(OBSERVATION_DIM,), dtype=np.float32),
            "achieved_goal": goal_box,
            "desired_goal": goal_box,
        }
    )
    return observation, spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)


def _frame(points: npt.ArrayLike) -> tuple[npt.NDArray[np.float32], float, float]:
    """(geometric features (GEOMETRY_DIM,), cos, sin of the canonical frame) of link points (N_POINTS, 3)."""
    pre = preprocess(np.asarray(points, dtype=np.float64))
    return pre.features[0].numpy(), float(pre.cos[0]), float(pre.sin[0])


def observation_of(points: npt.ArrayLike, q: npt.ArrayLike) -> npt.NDArray[np.float32]:
    """The ``observation`` entry for link points (N_POINTS, 3) and simulator state ``q`` (RopeSim.state())."""
    features, _, _ = _frame(points)
    joints = np.asarray(q, dtype=np.float64)[FREE_JOINT_QPOS : FREE_JOINT_QPOS + JOINT_DIM]
    return np.concatenate([features, joints.astype(np.float32)]).astype(np.float32)


def action_to_curve(action: npt.ArrayLike, points: npt.ArrayLike) -> Curve:
    """The world curve of a normalised action (4,) for the rope whose link points are ``points``."""
    a = np.clip(np.asarray(action, dtype=np.float64).reshape(4), -1.0, 1.0)
    _, cos, sin = _frame(points)
    link = int(np.clip(np.rint((a[0] + 1.0) * 0.5 * (N_LINKS - 1)), 0, N_LINKS - 1))
    z_max_m = Z_LOW + (a[1] + 1.0) * 0.5 * (Z_HIGH - Z_LOW)
    cx, cy = a[2] * XY_HALF_M, a[3] * XY_HALF_M
    # canonical -> world is a rotation by +angle (encoding.target_to_curve does the same)
    return Curve(link, z_max_m, cos * cx - sin * cy, sin * cx + cos * cy).clipped()


def curve_to_action(curve: Curve, points: npt.ArrayLike) -> npt.NDArray[np.float32]:
    """Inverse of :func:`action_to_curve` (up to the link rounding and the clipping)."""
    _, cos, sin = _frame(points)
    cx = cos * curve.x_m + sin * curve.y_m
    cy = -sin * curve.x_m + cos * curve.y_m
    a = np.array(
        [
            2.0 * curve.link / (N_LINKS - 1) - 1.0,
            2.0 * (curve.z_max_m - Z_LOW) / (Z_HIGH - Z_LOW) - 1.0,
            cx / XY_HALF_M,
            cy / XY_HALF_M,
        ]
    )
    return np.clip(a, -1.0, 1.0).astype(np.float32)


# ---- goals -------------------------------------------------------------------------------------------


def _check_goals(states: Iterable[Any], what: str) -> list[PData]:
    from twisted.moves import parse_state

    out: list[PData] = []
    for i, value in enumerate(states):
        try:
            p = parse_state(value, f"{what} #{i}")
        except PDataError as exc:
            raise GoalError(str(exc)) from None
        if p.cross == 0:
            raise GoalError(f"{what} #{i} is [] (no crossing), which the straight rope already is")
        if p.cross > MAX_CROSSINGS:
            raise GoalError(
                f"{what} #{i} {p.key} has {p.cross} crossings; "
                f"the goal encoding holds at most {MAX_CROSSINGS}"
            )
        out.append(p)
    if not out:
        raise GoalError(f"{what}: no goal states")
    return out


def goal_pool(
    goals: Sequence[Any] | None = None,
    *,
    problem_set: str | None = None,
    db_url: str | None = None,
    knot: str | None = None,
    knot_crossings: int | None = None,
    goal_crossings: Sequence[int] = DEFAULT_GOAL_CROSSINGS,
) -> list[PData]:
    """The goal states of an environment, from exactly one source (GoalError otherwise).

    ``goals``: P-data (JSON text, lists or PData); ``problem_set`` (with ``db_url``): the goals of a
    stored problem set (``twisted problems``); ``knot``: the states that tie a named knot
    (:func:`twisted.goals.knot_goal`) with ``knot_crossings`` crossings (default: the knot's crossing
    number, as for ``twisted plan --knot``); none of
    them: every state with a crossing count in ``goal_crossings`` (enumerated by the moves).
    """
    given = [name for name, v in (("goals", goals), ("problem_set", problem_set), ("knot", knot)) if v]
    if len(given) > 1:
        raise GoalError(f"give one goal source, got {' and '.join(given)}")
    if goals is not None:
        if isinstance(goals, (str, PData)):
            goals = [goals]
        return _check_goals(goals, "goal")
    if problem_set is not None:
        if db_url is None:
            raise GoalError(f"problem set {problem_set!r}: give db_url, the database that holds it")
        from twisted.store import open_store
        from twisted.store.experiments import list_problem_sets, load_problem_set

        store = open_store(db_url)
        try:
            with store.session() as session:
                record = load_problem_set(session, problem_set)
                known = [s["name"] for s in list_problem_sets(session)] if record is None else []
        finally:
            store.close()
        if record is None:
            raise GoalError(
                f"there is no problem set {problem_set!r} in {db_url} (sets: {', '.join(known) or 'none'}); "
                "make one with `twisted problems`"
            )
        from twisted.goals import goal_from_spec

        # a knot goal of the set stands for every state that ties the knot
        states = [p for problem in record.problems for p in goal_from_spec(problem.goal_key).states]
        return _check_goals(states, f"problem set {problem_set!r} goal")
    if knot is not None:
        from twisted.goals import GoalError as KnotGoalError
        from twisted.goals import knot_goal

        try:
            knot_states = knot_goal(knot, knot_crossings).states
        except KnotGoalError as exc:
            raise GoalError(f"knot {knot!r}: {exc}") from None
        return _check_goals(knot_states, f"knot {knot!r} state")
    from twisted.moves import enumerate_states

    counts = sorted(set(int(c) for c in goal_crossings))
    if not counts or counts[0] < 1 or counts[-1] > 4:
        raise GoalError(f"goal_crossings must lie in 1..4 (enumerated states), got {list(goal_crossings)}")
    by_cross = enumerate_states(counts[-1])
    return [p for c in counts for p in by_cross[c]]


# ---- the environment --------------------------------------------------------------------------------


class RopeKnotEnv(gym.Env[dict[str, np.ndarray], np.ndarray]):
    """Tie a P-data goal from the straight rope, one curve per step (see the module docstring)."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        goals: Sequence[Any] | None = None,
        *,
        problem_set: str | None = None,
        db_url: str | None = None,
        knot: str | None = None,
        knot_crossings: int | None = None,
        goal_crossings: Sequence[int] = DEFAULT_GOAL_CROSSINGS,
        max_curves: int = DEFAULT_MAX_CURVES,
        friction_scale: float = 1.0,
    ) -> None:
        if max_curves < 1:
            raise ValueError(f"max_curves must be at least 1, got {max_curves}")
        self.goals = goal_pool(
            goals,
            problem_set=problem_set,
            db_url=db_url,
            knot=knot,
            knot_crossings=knot_crossings,
            goal_crossings=goal_crossings,
        )
        self._by_cross: dict[int, list[PData]] = {}
        for p in self.goals:
            self._by_cross.setdefault(p.cross, []).append(p)
        self._counts = sorted(self._by_cross)
        self.max_curves = int(max_curves)
        self.sim = RopeSim(friction_scale=friction_scale)
        self.observation_space, self.action_space = env_spaces()  # type: ignore[assignment]
        self.goal: PData = self.goals[0]
        self.p_data: PData = self.sim.p_data()
        self.curves = 0

    @property
    def friction_scale(self) -> float:
        return self.sim.friction_scale

    def _obs(self) -> dict[str, np.ndarray]:
        return {
            "observation": observation_of(self.sim.link_points(), self.sim.state()),
            "achieved_goal": encode_p_data(self.p_data),
            "desired_goal": encode_p_data(self.goal),
        }

    def _info(self) -> dict[str, Any]:
        return {
            "is_success": self.p_data == self.goal,
            "goal_cross": self.goal.cross,
            "cross": self.p_data.cross,
            "curves": self.curves,
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Straight rope and a new goal (``options={"goal": P-data}`` chooses it)."""
        super().reset(seed=seed)
        if options and options.get("goal") is not None:
            self.goal = _check_goals([options["goal"]], "options['goal']")[0]
        else:
            count = self._counts[int(self.np_random.integers(len(self._counts)))]
            pool = self._by_cross[count]
            self.goal = pool[int(self.np_random.integers(len(pool)))]
        self.sim.reset()
        self.p_data = self.sim.p_data()
        self.curves = 0
        return self._obs(), self._info()

    def step(self, action: npt.ArrayLike) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Apply one curve; a failed curve restores the previous configuration (see the module docstring)."""
        curve = action_to_curve(action, self.sim.link_points())
        before = self.sim.state()
        outcome = self.sim.apply(curve)
        reason = outcome.reason
        p_after = self.sim.p_data() if outcome.ok else None
        if p_after is not None and p_after.cross > MAX_CROSSINGS:
            reason, p_after = f"the curve made {p_after.cross} crossings (more than {MAX_CROSSINGS})", None
        if p_after is None:
            self.sim.set_state(before)
        else:
            self.p_data = p_after
        self.curves += 1
        obs = self._obs()
        info = self._info()
        info.update(curve=curve.to_array(), curve_failed=p_after is None, reason=reason, steps=outcome.steps)
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], info))
        terminated = reward == 0.0
        truncated = not terminated and self.curves >= self.max_curves
        return obs, reward, terminated, truncated, info

    def compute_reward(
        self, achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike, info: Any
    ) -> npt.NDArray[np.float32] | np.float32:
        """0 where the achieved state equals the desired one, else -1; any leading batch shape."""
        a = np.asarray(achieved_goal, dtype=np.float32)
        d = np.asarray(desired_goal, dtype=np.float32)
        reached = np.all(np.abs(a - d) <= GOAL_MATCH_TOL, axis=-1)
        return (reached.astype(np.float32) - 1.0).astype(np.float32)
