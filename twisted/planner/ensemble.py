"""Robust steps: a plan step's curve is kept only when it reaches the next state in ropes the model is not.

docs/DESIGN.md section 15.5. A plan made in one deterministic rope chooses, for each step, the first curve
the model carries into the next state; about half of those land somewhere else in a rope whose friction,
stiffness or mass differ by tens of percent, or under a gripper that misses by half a centimetre
(``bench/robust_steps.py``). :class:`Ensemble` holds ``size`` ropes whose physics are drawn once from a
perturbation level (the same ranges a world draws from, :mod:`twisted.world.levels`) and tries a curve in
each, with the gripper's noise of the level drawn afresh for each try; the search keeps a curve's result
only when every rope reaches the plan's next state (:meth:`twisted.planner.search.Search.follow_plan`).

The ropes are the planner's own imagination, drawn from the search's seed: the planner never sees the
world it acts in. The noise of a try is drawn from ``(seed, rope, call)``, ``call`` being the search's
number of the curve's simulator call, so a resumed search tries a curve with the noise the uninterrupted
one would have used.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from twisted.sim.simulator import Curve, RopeSim
from twisted.topology import PData
from twisted.world.levels import LEVELS
from twisted.world.sim_world import draw_physics, noisy_curve


class Ensemble:
    """``size`` ropes drawn from the level ``level_name`` with ``seed``; see the module's docstring."""

    def __init__(self, size: int, level_name: str, seed: int) -> None:
        if size < 1:
            raise ValueError(f"an ensemble needs at least one rope, got {size}")
        if level_name not in LEVELS:
            raise ValueError(f"unknown perturbation level {level_name!r}: {', '.join(LEVELS)}")
        self.level = LEVELS[level_name]
        self.seed = int(seed)
        self.physics = [
            draw_physics(self.level, np.random.default_rng([self.seed, rope, 0])) for rope in range(size)
        ]
        self._sims: list[RopeSim] | None = None  # built on the first try (a few MJCF compilations)

    @property
    def size(self) -> int:
        return len(self.physics)

    def tries(self, q: npt.ArrayLike, curve: Curve, target: PData, call: int) -> tuple[bool, int]:
        """Whether ``curve`` from configuration ``q`` reaches ``target`` in every rope, and how many
        simulator calls it took (it stops at the first rope that misses)."""
        if self._sims is None:
            self._sims = [RopeSim(params=physics.rope_params()) for physics in self.physics]
        for rope, sim in enumerate(self._sims):
            done = noisy_curve(curve, self.level, np.random.default_rng([self.seed, rope, int(call) + 1]))
            sim.set_state(q)
            outcome = sim.apply(done)
            if not outcome.ok or sim.p_data() != target:
                return False, rope + 1
        return True, len(self._sims)
