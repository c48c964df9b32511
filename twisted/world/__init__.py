"""Worlds apart from the planner's model: where plans are executed, observed and judged (docs/DESIGN.md
section 15).

``World`` is the protocol (``reset``, ``execute``, ``cinch``, ``observe``, ``pull_test``, ``checkpoint``,
``restore``); ``SimWorld`` a MuJoCo rope with physics drawn from a perturbation ``Level`` and noisy
actions and observations; ``ChainFit`` turns observed link points back into a configuration of the
planner's model.
"""

from twisted.world.fit import ChainFit, Fit, observed_p_data, rms_distance
from twisted.world.levels import LEVELS, Level, LevelError, check_level, parse_level
from twisted.world.protocol import Observation, PullVerdict, World
from twisted.world.sim_world import SimWorld, WorldPhysics, draw_physics

__all__ = [
    "LEVELS",
    "ChainFit",
    "Fit",
    "Level",
    "LevelError",
    "Observation",
    "PullVerdict",
    "SimWorld",
    "World",
    "WorldPhysics",
    "check_level",
    "draw_physics",
    "observed_p_data",
    "parse_level",
    "rms_distance",
]
