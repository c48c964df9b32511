"""The World protocol: the rope a plan is executed on, apart from the planner's model of it.

The planner plans in its own deterministic model (``twisted.sim.RopeSim`` with ``RopeParams()``). A world
is what the plan is carried out on: a perturbed simulator (:class:`twisted.world.SimWorld`) or, one day,
a robot. What crosses from the world to the planner is an :class:`Observation` (link points, and what the
world reports went wrong) and the pull test's verdict; nothing else (docs/DESIGN.md section 15.1).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from twisted.sim.simulator import Curve

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Observation:
    """What the world shows after an action: the N_POINTS link points as seen (metres, world frame), and
    ``fault``, the reason when the world could not carry the action out (the rope is then where it was)."""

    points: FloatArray
    fault: str | None = None


@dataclass(frozen=True)
class PullVerdict:
    """The world's pull test: ``knot`` names the knot of the taut rope (``knotoid`` when its closures
    differ, None when the pull could not be done: ``reason``). The rope stays as the pull left it, let go;
    ``moved`` is False when it lies as it did before the pull instead (it could not be pulled, or not come
    to rest after it)."""

    knot: str | None
    reason: str | None = None
    note: str | None = None  # how the knot was read when not by the usual pull (e.g. at less tension)
    moved: bool = True


@runtime_checkable
class World(Protocol):
    """The rope a plan is executed on (docs/DESIGN.md section 15.1)."""

    def reset(self, configuration: npt.ArrayLike | None = None) -> Observation:
        """Lay the rope out as the planner's configuration ``q`` says (None: straight) and observe it."""
        ...

    def execute(self, curve: Curve) -> Observation:
        """Carry out one curve action as well as the world can, let the rope rest, observe it."""
        ...

    def cinch(self) -> Observation:
        """Pull the rope tight by both ends, let go, let it rest, observe it (a plan's cinch step)."""
        ...

    def observe(self) -> Observation:
        """Look at the rope again (no action)."""
        ...

    def pull_test(self) -> PullVerdict:
        """Hold both ends, pull the rope taut and say which knot it is; the rope is let go afterwards."""
        ...

    def checkpoint(self) -> dict[str, Any]:
        """What :meth:`restore` needs to continue from here after the process stopped (JSON-able); it
        belongs to the world and is never handed to the planner."""
        ...

    def restore(self, checkpoint: dict[str, Any]) -> None:
        """Continue from a :meth:`checkpoint` (a robot: nothing to do, its rope is where it is)."""
        ...
