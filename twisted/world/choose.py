"""Choosing the curve to send to a world: of the model's curves that reach the next state, the one that
reaches it in most imagined ropes.

docs/DESIGN.md section 15.6. One curve of the model from one configuration reaches its planned state in a
world about half the time (docs/log/2026-12-06.md): the world's rope is a fit, not the model's, and the
simulator's outcome of a curve changes with a ten-micrometre change of the start in about one curve of
five. :class:`EnsembleChooser` asks the inverse model for ``k`` curves toward the next state from the
fitted configuration, keeps those that reach it in the model, and tries each of them in ``ensemble``
ropes whose physics are drawn from the ranges of a level (``imagine``), with that level's gripper noise;
the curve sent is the one that reached the next state in most of them (the first such on a tie).

The ropes are the planner's imagination: their physics come from the ranges of a named level and the
chooser's own seed, never from the world's draw (the planner does not see the world). The draws of a
choice are seeded by ``(seed, key)``, ``key`` being the episode's action count, so that an episode
replays from its seeds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from twisted.moves import explains
from twisted.sim.simulator import Curve, RopeSim
from twisted.topology import PData
from twisted.world.levels import Level
from twisted.world.protocol import FloatArray
from twisted.world.sim_world import draw_physics, noisy_curve


class Sampler(Protocol):
    """Curves toward a next state from a rope (the planner's ``CurveSampler``; the inverse model)."""

    def sample(
        self, node: Any, next_state: PData, move: Any, n: int, rng: np.random.Generator
    ) -> list[Any]: ...


@dataclass(frozen=True)
class Rope:
    """A configuration of the planner's model as the sampler takes it: ``q``, link ``points``, ``p_data``."""

    q: FloatArray
    points: FloatArray
    p_data: PData


@dataclass(frozen=True)
class Choice:
    """The curve to send, the model's outcome of it (its configuration and points: what the world's rope
    is then expected to be near), how many imagined ropes it reached the next state in, and the count of
    curves that reached it in the model."""

    curve: Curve
    q: FloatArray
    points: FloatArray
    score: int
    reaching: int


class EnsembleChooser:
    """See the module's docstring. ``rounds``: draws of ``k`` curves while none reaches in the model."""

    def __init__(
        self, sampler: Sampler, imagine: Level, k: int, ensemble: int, seed: int, rounds: int = 2
    ) -> None:
        if k < 1 or ensemble < 1 or rounds < 1:
            raise ValueError(f"a chooser needs k, ensemble and rounds >= 1, got {k}, {ensemble}, {rounds}")
        self.sampler, self.imagine, self.k, self.ensemble = sampler, imagine, k, ensemble
        self.seed, self.rounds = int(seed), rounds
        self._model = RopeSim()
        physics = [draw_physics(imagine, np.random.default_rng([self.seed, 0, r])) for r in range(ensemble)]
        self._ropes = [RopeSim(params=p.rope_params()) for p in physics]

    def choose(self, rope: Rope, target: PData, key: int) -> Choice | None:
        """The curve from ``rope`` toward ``target``; None when no curve of ``rounds`` x ``k`` reaches it
        in the model. The model is told the move to ``target`` where one move leads there (a plan's step
        can also turn a state into another of as many crossings: then no move is given)."""
        move = explains(rope.p_data, target)
        rng = np.random.default_rng([self.seed, 1, key])
        reaching: list[tuple[Curve, FloatArray, FloatArray]] = []
        for _ in range(self.rounds):
            for curve in self.sampler.sample(rope, target, move, self.k, rng):
                self._model.set_state(rope.q)
                if self._model.apply(curve).ok and self._model.p_data() == target:
                    reaching.append((curve, self._model.state(), self._model.link_points()))
            if reaching:
                break
        if not reaching:
            return None
        scores = [self._score(rope.q, curve, target, key, j) for j, (curve, _, _) in enumerate(reaching)]
        best = int(np.argmax(scores))
        curve, q, points = reaching[best]
        return Choice(curve, q, points, scores[best], len(reaching))

    def _score(self, q: FloatArray, curve: Curve, target: PData, key: int, j: int) -> int:
        """In how many imagined ropes ``curve`` from ``q`` (with the imagined gripper's noise) ends in
        ``target``."""
        hits = 0
        for r, sim in enumerate(self._ropes):
            done = noisy_curve(curve, self.imagine, np.random.default_rng([self.seed, 2, key, j, r]))
            sim.set_state(q)
            hits += bool(sim.apply(done).ok and sim.p_data() == target)
        return hits
