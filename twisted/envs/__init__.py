"""Gymnasium environments of the rope; importing this package registers ``twisted/RopeKnot-v0``.

Needs ``gymnasium`` (the ``rl`` extra: ``pip install 'twisted-knots[rl]'``); Stable-Baselines3 is
not needed to make or step the environment.
"""

from __future__ import annotations

try:
    import gymnasium
except ImportError as exc:  # pragma: no cover - depends on the installation
    raise ImportError(
        "twisted.envs needs gymnasium: install the rl extra (pip install 'twisted-knots[rl]')"
    ) from exc

from twisted.envs.rope_knot import (
    ENV_ID,
    GoalError,
    RopeKnotEnv,
    action_to_curve,
    curve_to_action,
    goal_pool,
    observation_of,
)

__all__ = [
    "ENV_ID",
    "GoalError",
    "RopeKnotEnv",
    "action_to_curve",
    "curve_to_action",
    "goal_pool",
    "observation_of",
]

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="twisted.envs.rope_knot:RopeKnotEnv")
