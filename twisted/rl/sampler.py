"""The planner's hook: curves from a stored SAC+HER policy in place of the inverse model.

``load_policy_sampler(store, model_id)`` returns ``(SacCurves, checkpoint_id)``; ``SacCurves.sample``
has the signature of ``twisted.model.sampler.ModelCurves.sample``. The observation is the environment's
(:func:`twisted.envs.observation_of` of the node's points and q), the achieved goal the node's P-data,
the desired goal the plan's next state, as during training.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from twisted.model.registry import ModelError
from twisted.sim import Curve
from twisted.store.db import Store
from twisted.store.models import by_id_or_newest
from twisted.store.rl import RlCheckpoint, RlRun
from twisted.topology import PData

__all__ = ["PolicyError", "SacCurves", "load_policy", "load_policy_sampler"]


class PolicyError(ModelError):
    """No usable SAC policy (the message says what to do)."""


class SacCurves:
    """Curves from a SAC policy for the rope at ``node`` and the goal ``next_state``.

    The first curve is the policy's deterministic action (the mean, squashed); the others are
    samples of its squashed Gaussian, drawn with a torch generator seeded from ``rng``.
    """

    name = "sac"

    def __init__(self, model: Any, checkpoint_id: int | None = None) -> None:
        self.model = model
        self.checkpoint_id = checkpoint_id
        self.model.policy.set_training_mode(False)

    def actions(
        self, points: np.ndarray, q: np.ndarray, p_data: PData, goal: PData, n: int, rng: np.random.Generator
    ) -> np.ndarray:
        """(n, 4) normalised actions: row 0 the deterministic one, the rest sampled."""
        import torch

        from twisted.envs import observation_of
        from twisted.model.encoding import encode_p_data

        obs = {
            "observation": observation_of(points, q)[None],
            "achieved_goal": encode_p_data(p_data)[None],
            "desired_goal": encode_p_data(goal)[None],
        }
        policy = self.model.policy
        obs_t, _ = policy.obs_to_tensor(obs)
        generator = torch.Generator().manual_seed(int(rng.integers(0, 2**63 - 1)))
        with torch.no_grad():
            mean, log_std, _ = policy.actor.get_action_dist_params(obs_t)
            eps = torch.randn(n, mean.shape[1], generator=generator)
            eps[0] = 0.0
            actions = torch.tanh(mean + log_std.exp() * eps)
        return actions.numpy().astype(np.float64)

    def sample(
        self, node: Any, next_state: PData, move: Any | None, n: int, rng: np.random.Generator
    ) -> list[Curve]:
        """``n`` curves for ``node`` (with ``.points``, ``.q``, ``.p_data``) towards ``next_state``."""
        from twisted.envs import action_to_curve

        if n < 1:
            return []
        actions = self.actions(node.points, node.q, node.p_data, next_state, n, rng)
        return [action_to_curve(a, node.points) for a in actions]


def load_policy(store: Store, model_id: int | None = None) -> tuple[Any, int]:
    """The SB3 SAC model of checkpoint ``model_id`` (None: the newest stored) and its id."""
    try:
        from twisted.rl.sac import inference_model, require_rl

        require_rl()
    except ImportError as exc:
        raise PolicyError(
            f"the sac planner needs the rl extra ({exc.name} is missing): pip install 'twisted-knots[rl]'"
        ) from exc
    with store.session() as session:
        row = by_id_or_newest(
            session, RlCheckpoint, model_id, what="SAC policy", see="twisted rl list", error=PolicyError
        )
        if row is None:
            raise PolicyError("the database holds no SAC policy: train one with `twisted rl train`")
        blob, checkpoint_id = row.policy, row.id
        run = session.get(RlRun, row.rl_run_id)
        parameters = dict(run.parameters or {}) if run is not None else {}
    try:
        # tensors and plain data only, into a model built from the run's settings (docs/security.md)
        model = inference_model(blob, parameters, f"SAC policy {checkpoint_id}")
    except ValueError as exc:
        raise PolicyError(str(exc)) from None
    return model, checkpoint_id


def load_policy_sampler(store: Store, model_id: int | None = None) -> tuple[SacCurves, int]:
    """``(sampler, checkpoint id)`` for ``twisted plan --planner sac``; PolicyError (a ModelError) if none."""
    model, checkpoint_id = load_policy(store, model_id)
    return SacCurves(model, checkpoint_id), checkpoint_id
