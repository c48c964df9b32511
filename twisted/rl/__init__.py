"""The SAC+HER baseline: training into the store (:mod:`twisted.rl.sac`) and the planner's sampler.

Stable-Baselines3 is imported only when a policy is trained or loaded (the ``rl`` extra).
"""

from twisted.rl.sac import RlProgress, SacConfig, SacOutcome, make_env, require_rl, train_sac
from twisted.rl.sampler import PolicyError, SacCurves, load_policy, load_policy_sampler

__all__ = [
    "PolicyError",
    "RlProgress",
    "SacConfig",
    "SacCurves",
    "SacOutcome",
    "load_policy",
    "load_policy_sampler",
    "make_env",
    "require_rl",
    "train_sac",
]
