"""The planner's hook: curves from the learned inverse model.

:class:`ModelCurves` is what ``twisted plan --planner twisted`` samples, as
:class:`twisted.rl.sampler.SacCurves` is for ``--planner sac``. It fits the planner's ``CurveSampler``
protocol structurally, so this layer never imports the planner: a node is anything with the rope's
link points, its state ``q`` and its P-data.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from twisted.topology import PData

if TYPE_CHECKING:
    from twisted.model.network import InverseModel

__all__ = ["ModelCurves", "RopeNode"]


class RopeNode(Protocol):
    """The rope a curve starts from (the planner's ``Node`` is one)."""

    points: np.ndarray  # (N_POINTS, 3) link points, head first
    q: np.ndarray  # the simulator state
    p_data: PData


class ModelCurves:
    """Curves from the learned inverse model, conditioned on the rope's points, the next state and
    the plan's move to it."""

    name = "model"

    def __init__(self, model: InverseModel) -> None:
        self.model = model

    def sample(
        self, node: RopeNode, next_state: PData, move: Any | None, n: int, rng: np.random.Generator
    ) -> list[Any]:
        return list(self.model.sample(node.points, node.q, next_state, n, rng, p_data=node.p_data, move=move))
