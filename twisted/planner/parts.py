"""The parts Algorithm 1 is built from: how it selects a state, a plan and a node, where the curves of a
plan step come from, and when a reached node ends the search.

:class:`twisted.planner.search.Search` runs the loop and keeps the tree and the statistics; each
decision in it is one of the small classes here, handed in as a :class:`SearchParts` bundle (the way a
Monte Carlo tree search takes its evaluator and child-selection function):

- state selection (``StateSelection``): :class:`UniformStates` (rnd), :class:`CrossingStates` (crs,
  weight ``1 + Cross(s)``), :class:`UcbStates` (ucb, a bandit rewarded by the plan steps achieved);
- plan selection (``PlanSelection``): :class:`UniformPlans` (rnd, crs), :class:`UcbPlans` (ucb);
- node selection (``NodeSelection``): :class:`RetryWeightedNodes` (a node already asked for the plan's
  next state weighs ``retry_weight ** n``; 1 is the paper's uniform choice);
- :class:`R1Room`: the room a node's segment leaves for an R1 curl, shared by the three selections
  above when ``r1_room > 0`` (DESIGN 8);
- curve proposers (``CurveSampler``): the inverse model (``twisted.model.sampler.ModelCurves``), a SAC
  policy (``twisted.rl``), :class:`RandomCurves`, :class:`ScriptedCross` (``twisted.proposals``);
  :class:`StepCurves` draws a plan step's K curves from them;
- goal tests (``GoalTest``): :class:`StateMatch` (a goal state reached) and :class:`PullTest` (and the
  rope pulled tight ties the goal's knot, ``twisted.tighten``);
- growth (``Growth``): which results enter ``T`` and which reached states get high-level plans:
  :class:`AddingMoves` (Algorithm 1: Cross never drops), :class:`BothWays` (removing moves too, the
  search of ``twisted untie``; :mod:`twisted.planner.both_ways`);
- the iteration (``Iteration``): :class:`PlanGuided` (Algorithm 1's lines 5-12) or :class:`LowLevelOnly`
  (the baseline: random curves from random nodes, no high level);
- :class:`SummandCinch`: toward a composite knot (granny, square), a node whose rope ties one of the
  summands is pulled tight and let go once (``twisted.tighten.cinch``); steps start from the tight
  ropes (cinched, or made from a cinched one) where a state has any, and the crs choice weighs such a
  state more (``cinch``, DESIGN 8).

:func:`default_parts` builds the parts that :class:`~twisted.planner.options.PlannerOptions` name
(the pull test excepted: :mod:`twisted.planner.runs` adds it with the run's recorder). Every random
choice takes the search's one ``numpy.random.Generator``; the parts that keep state (:class:`R1Room`, a
cache, and :class:`SummandCinch`, the nodes it cinched) forget what an unfinished iteration added
(:meth:`SearchParts.forget`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from twisted.goals import Goal
from twisted.planner.options import PlannerOptions
from twisted.planner.tree import Node, SearchTree, is_cinched, pair_key
from twisted.topology import PData

__all__ = [
    "R1_ROOM_FLOOR",
    "AddingMoves",
    "BlindCurves",
    "BothWays",
    "CrossingStates",
    "CurveSampler",
    "GoalTest",
    "Growth",
    "Iteration",
    "LowLevelOnly",
    "NodeSelection",
    "SearchParts",
    "PlanGuided",
    "PlanSelection",
    "PullTest",
    "R1Room",
    "RandomCurves",
    "RetryWeightedNodes",
    "ScriptedCross",
    "SearchView",
    "StateMatch",
    "StateSelection",
    "StepCurves",
    "SummandCinch",
    "UcbPlans",
    "UcbStates",
    "UniformPlans",
    "UniformStates",
    "default_parts",
]

# the least node weight r1_room gives (a curl on a segment of a link or less almost never works)
R1_ROOM_FLOOR = 0.02


class SearchView(Protocol):
    """What the parts read of a search (:class:`~twisted.planner.search.Search`): the tree, the plans
    from every reached state, the statistics tables and the goal."""

    tree: SearchTree
    plans: dict[str, list[Any]]
    stats: dict[str, dict[str, list[float]]]
    goal: Goal


def _draw(weights: list[float] | np.ndarray, rng: np.random.Generator) -> int:
    """An index drawn with ``weights``; while all are equal the uniform draw, which takes the random
    number a uniform choice takes (so a weight that changes nothing replays the uniform choice)."""
    if min(weights) == max(weights):
        return int(rng.integers(len(weights)))
    return int(rng.choice(len(weights), p=np.array(weights) / sum(weights)))


# --- the room for an R1 curl --------------------------------------------------------------------------


class R1Room:
    """How much rope a node has on a segment for an R1 curl: ``(length / links) ** 2`` in links, between
    :data:`R1_ROOM_FLOOR` and 1 (DESIGN 8). Segment bounds are cached per node, the best room per
    segment per state."""

    def __init__(self, links: float) -> None:
        if not links > 0.0:
            raise ValueError(f"R1Room needs a positive number of links, got {links}")
        self.links = links
        self._bounds: dict[int, Any] = {}  # node index -> segment_bounds of its points
        # state -> (its nodes weighed, best room per R1 segment, plan_rooms)
        self._plan_rooms: dict[str, tuple[int, dict[int, float], list[float]]] = {}

    def node_weight(self, node: Node, segment: int) -> float:
        bounds = self._bounds.get(node.index)
        if bounds is None:
            from twisted.proposals import segment_bounds

            bounds = self._bounds[node.index] = segment_bounds(node.points)
        length = float(bounds[segment + 1] - bounds[segment])
        return max(R1_ROOM_FLOOR, min(1.0, length / self.links) ** 2)

    def plan_rooms(self, search: SearchView, s: str) -> list[float]:
        """Per plan of ``s``: 1, or for a plan that starts with an R1 curl the most room any node of
        ``s`` has for it. Only the nodes ``s`` gained since the last call are weighed."""
        indices = search.tree.by_state[s]
        cached = self._plan_rooms.get(s)
        if cached is not None and cached[0] == len(indices):
            return cached[2]
        seen, best = (cached[0], cached[1]) if cached is not None else (0, {})
        nodes, new = search.tree.nodes, indices[seen:]
        for segment in best:
            best[segment] = max(best[segment], *(self.node_weight(nodes[i], segment) for i in new))
        rooms = []
        for plan in search.plans[s]:
            move = plan.moves[0]
            if move.kind != "R1" or move.remove:
                rooms.append(1.0)
                continue
            if move.segment not in best:
                best[move.segment] = max(self.node_weight(nodes[i], move.segment) for i in indices)
            rooms.append(best[move.segment])
        self._plan_rooms[s] = (len(indices), best, rooms)
        return rooms

    def forget(self, committed: int) -> None:
        """Drop what was cached about the nodes from ``committed`` on (an iteration rolled back)."""
        for index in [index for index in self._bounds if index >= committed]:
            del self._bounds[index]
        self._plan_rooms.clear()


# --- SelectTopologicalState ----------------------------------------------------------------------------


class StateSelection(Protocol):
    def select(self, search: SearchView, candidates: list[str], rng: np.random.Generator) -> str:
        """One of ``candidates`` (reached states with a plan, in order of first reach)."""
        ...


class UniformStates:
    """rnd: every candidate state alike."""

    def select(self, search: SearchView, candidates: list[str], rng: np.random.Generator) -> str:
        return candidates[int(rng.integers(len(candidates)))]


class CrossingStates:
    """crs: weight ``1 + Cross(s)``; with an :class:`R1Room`, times the room of the best plan of ``s``;
    with a :class:`SummandCinch`, times its weight of ``s`` (a state holding a tight rope weighs more)."""

    def __init__(self, room: R1Room | None = None, cinch: SummandCinch | None = None) -> None:
        self.room = room
        self.cinch = cinch

    def select(self, search: SearchView, candidates: list[str], rng: np.random.Generator) -> str:
        weights = np.array([1.0 + search.tree.states[key].cross for key in candidates])
        if self.room is not None:
            room = self.room
            weights = weights * np.array([max(room.plan_rooms(search, key)) for key in candidates])
        if self.cinch is not None:
            cinch = self.cinch
            weights = weights * np.array([cinch.state_weight(search, key) for key in candidates])
        return candidates[int(rng.choice(len(candidates), p=weights / weights.sum()))]


class UcbStates:
    """ucb: upper confidence bound over the states, rewarded by the share of plan steps achieved
    (``stats["state"]``). Each state starts with one pseudo-observation worth
    ``(1 + Cross(s)) / (1 + Cross(goal))``, so an untried state is preferred by depth as in crs instead
    of forcing a round over every state."""

    def __init__(self, c: float) -> None:
        self.c = c

    def select(self, search: SearchView, candidates: list[str], rng: np.random.Generator) -> str:
        stats = search.stats["state"]
        total = sum(stats.get(key, [0.0, 0.0])[0] for key in candidates)
        best, best_score = candidates[0], -math.inf
        for key in candidates:
            n, reward = stats.get(key, [0.0, 0.0])
            prior = (1.0 + search.tree.states[key].cross) / (1.0 + search.goal.cross)
            bonus = self.c * math.sqrt(math.log(1.0 + total) / (n + 1.0))
            score = (reward + prior) / (n + 1.0) + bonus
            if score > best_score:
                best, best_score = key, score
        return best


# --- SelectPlan ------------------------------------------------------------------------------------------


class PlanSelection(Protocol):
    def select(self, search: SearchView, s: str, rng: np.random.Generator) -> int:
        """The index of a plan of ``search.plans[s]``."""
        ...


class UniformPlans:
    """rnd, crs: every plan alike; with an :class:`R1Room`, a plan that starts with a curl weighs the
    room of the best node of ``s`` for it."""

    def __init__(self, room: R1Room | None = None) -> None:
        self.room = room

    def select(self, search: SearchView, s: str, rng: np.random.Generator) -> int:
        rooms = self.room.plan_rooms(search, s) if self.room is not None else [1.0]
        if min(rooms) == max(rooms):
            return int(rng.integers(len(search.plans[s])))
        return _draw(rooms, rng)


class UcbPlans:
    """ucb: each plan of the state once, then the upper confidence bound (``stats["plan"]``)."""

    def __init__(self, c: float) -> None:
        self.c = c

    def select(self, search: SearchView, s: str, rng: np.random.Generator) -> int:
        n_state = search.stats["state"].get(s, [0.0, 0.0])[0]
        best, best_score = 0, -math.inf
        for index in range(len(search.plans[s])):
            n, reward = search.stats["plan"].get(f"{s}|{index}", [0.0, 0.0])
            if n == 0:
                return index
            score = reward / n + self.c * math.sqrt(math.log(1.0 + n_state) / n)
            if score > best_score:
                best, best_score = index, score
        return best


# --- SelectConfiguration ------------------------------------------------------------------------------


class NodeSelection(Protocol):
    def select(
        self, search: SearchView, s: str, next_state: PData, move: Any, rng: np.random.Generator
    ) -> Node:
        """A node of ``T`` in state ``s`` to ask for ``next_state`` (by ``move``)."""
        ...


class RetryWeightedNodes:
    """Weight ``retry_weight ** n`` for a node already asked ``n`` times for ``next_state`` (the ``pair``
    statistics); with an :class:`R1Room` and an R1 ``move``, times the node's room for the curl.

    A plan step succeeds or fails by its (node, next state) pair far more than by the curves drawn
    (DESIGN 8), so the untried configurations of a state go first. While every weight is equal the
    draw is uniform and takes the random number the paper's choice takes: ``retry_weight = 1``
    replays the paper's choice.
    """

    def __init__(
        self, retry_weight: float, room: R1Room | None = None, cinch: SummandCinch | None = None
    ) -> None:
        if not 0.0 < retry_weight <= 1.0:
            raise ValueError(f"retry_weight must lie in (0, 1], got {retry_weight}")
        self.retry_weight = retry_weight
        self.room = room
        self.cinch = cinch

    def select(
        self, search: SearchView, s: str, next_state: PData, move: Any, rng: np.random.Generator
    ) -> Node:
        indices = search.tree.by_state[s]
        if self.cinch is not None:
            indices = self.cinch.candidates(search, s, indices)
        pairs, key = search.stats["pair"], next_state.key
        weights = [self.retry_weight ** pairs.get(pair_key(i, key), [0.0])[0] for i in indices]
        if self.room is not None and move is not None and move.kind == "R1" and not move.remove:
            nodes, room = search.tree.nodes, self.room
            weights = [
                w * room.node_weight(nodes[i], move.segment) for w, i in zip(weights, indices, strict=True)
            ]
        return search.tree.nodes[indices[_draw(weights, rng)]]


# --- curve proposers ------------------------------------------------------------------------------------


class CurveSampler(Protocol):
    """Proposes curves that should move the rope of ``node`` to ``next_state`` (by ``move``)."""

    name: str

    def sample(
        self, node: Node, next_state: PData, move: Any | None, n: int, rng: np.random.Generator
    ) -> list[Any]: ...


class BlindCurves(Protocol):
    """Proposes curves with no next state in view (RandomExpand, the low-level-only baseline)."""

    name: str

    def sample(
        self, node: Node, next_state: PData | None, move: Any | None, n: int, rng: np.random.Generator
    ) -> list[Any]: ...


class RandomCurves:
    """Uniformly random curves over the action ranges (the baselines, and RandomExpand)."""

    name = "random"

    def sample(
        self, node: Node, next_state: PData | None, move: Any | None, n: int, rng: np.random.Generator
    ) -> list[Any]:
        from twisted.sim import sample_curve

        return [sample_curve(rng) for _ in range(n)]


class ScriptedCross:
    """The scripted Cross move curve (:func:`twisted.proposals.cross_move_curve`): the tip, or the
    crossed segment, lifted across with the move's sign. Only for Cross moves."""

    name = "cross_move"
    kind = "Cross"

    def sample(
        self, node: Node, next_state: PData, move: Any | None, n: int, rng: np.random.Generator
    ) -> list[Any]:
        from twisted.proposals import cross_move_curve

        if move is None or move.kind != self.kind:
            raise ValueError(f"the scripted Cross curve makes Cross moves, not {move}")
        return [cross_move_curve(rng, node.points, move) for _ in range(n)]


class ScriptedMove(Protocol):
    """A curve proposer for one kind of move (:class:`ScriptedCross`)."""

    name: str
    kind: str

    def sample(
        self, node: Node, next_state: PData, move: Any | None, n: int, rng: np.random.Generator
    ) -> list[Any]: ...


class StepCurves:
    """The K curves of a plan step: for a step toward the move ``script`` makes (default
    :class:`ScriptedCross`), ``round(share * K)`` scripted curves first, then the rest from ``sampler``;
    every other step all K from ``sampler``.

    :meth:`propose` returns the curves, scripted first, and how many are scripted; the search counts
    the curves and hits of each proposer of a step toward the script's move (the ``cross`` statistics).
    A removing move (``move.remove``) is never scripted; its K curves come from ``removal`` when given
    (a both-ways search's ``--removal-curves random``), else from ``sampler``.
    """

    def __init__(
        self,
        sampler: CurveSampler,
        script: ScriptedMove | None = None,
        share: float = 0.0,
        removal: BlindCurves | None = None,
    ) -> None:
        if not 0.0 <= share <= 1.0:
            raise ValueError(f"the scripted share must lie in [0, 1], got {share}")
        self.sampler, self.share, self.removal = sampler, share, removal
        self.script: ScriptedMove = script if script is not None else ScriptedCross()

    def propose(
        self, node: Node, next_state: PData, move: Any, k: int, rng: np.random.Generator
    ) -> tuple[list[Any], int]:
        if move is not None and move.remove and self.removal is not None:
            return self.removal.sample(node, None, None, k, rng), 0
        scripted = 0
        if move is not None and move.kind == self.script.kind and not move.remove:
            scripted = min(k, int(round(self.share * k)))
        curves = self.script.sample(node, next_state, move, scripted, rng) if scripted else []
        if scripted < k:
            curves += self.sampler.sample(node, next_state, move, k - scripted, rng)
        return curves, scripted


# --- the goal test ------------------------------------------------------------------------------------------


class GoalTest(Protocol):
    """Whether a node ends the search; ``tests`` counts the costly checks run (pull tests)."""

    tests: int

    def accepts(self, node: Node, *, record: bool = True) -> bool:
        """``record``: store what the check found (False while a resumed run re-reads its tree)."""
        ...


class StateMatch:
    """The paper's goal test: the node's P-data is a goal state."""

    tests = 0

    def __init__(self, goal: Goal) -> None:
        self.goal = goal

    def accepts(self, node: Node, *, record: bool = True) -> bool:
        return node.p_data in self.goal


class PullTest:
    """A goal state reached, and the rope pulled tight (:func:`twisted.tighten.tighten`) ties the goal's
    knot. The pull test is deterministic; ``record(node, result, ties)`` stores each one."""

    def __init__(self, goal: Goal, record: Callable[[Node, Any, bool], None] | None = None) -> None:
        self.goal = goal
        self.record = record
        self.tests = 0
        self._sim: Any = None

    def accepts(self, node: Node, *, record: bool = True) -> bool:
        if node.p_data not in self.goal:
            return False
        from twisted.tighten import tighten, tightening_sim

        if self._sim is None:
            self._sim = tightening_sim()
        result = tighten(self._sim, node.q)
        ties = result.ok and self.goal.tightened_ties(result.knot_name)
        self.tests += 1
        if record and self.record is not None:
            self.record(node, result, ties)
        return ties


# --- cinching the first knot of a composite --------------------------------------------------------------

# A state that ties a summand starts its steps from its tight nodes (cinched, or made from a cinched one)
# until it has had this many steps per tight node; then also from its loose nodes not cinched yet (the
# one chosen is cinched).
CINCH_STEPS = 30
# cinches of a state's nodes that did not give a node in that state (the knot came undone, the rope
# was rejected, the pull changed the diagram) before the state's nodes are no longer cinched
CINCH_FAILURES = 3
# crs weight of a state that holds a tight node, against 1 for a state reached only by loose ropes
TIGHT_WEIGHT = 10.0


class SummandCinch:
    """Toward a composite knot goal (granny ``3_1+#3_1+``, square ``3_1+#3_1-``): a node whose rope ties one
    of the summands (both closures, at its crossing number) is pulled tight and let go once
    (:func:`twisted.tighten.cinch`) before a plan step starts from it (the node chosen, or one a step
    reached on the way). The cinched node and every node made from it are *tight*: a state's steps
    start from its tight nodes when it has any, and the crs choice weighs a state holding one
    ``TIGHT_WEIGHT`` times.

    A loose overhand spreads its loops over the rope where the second one must be made; pulled tight it
    is compact and leaves the rest free. Started from the cinched rope of an overhand, searches for a granny
    took a fraction of the calls they took from the same overhand loose (docs/goals.md, "Cinching the
    first overhand"). Deterministic: the cinch draws no random number.
    """

    def __init__(self, goal: Goal) -> None:
        # knot goals only: a state goal asks for one diagram, and cinching on the way there is unmeasured
        # (a bare P-data goal, as a part is sometimes made with, has none either)
        self.summands: frozenset[str] = getattr(goal, "summands", frozenset())
        # a summand's crossing number ("3_1+" -> 3): a state with more crossings that ties it has one the
        # pull would take out, so only states of exactly these counts are cinched
        from twisted.knots import crossing_number

        self._crossings = frozenset(crossing_number(name) for name in self.summands)
        self._ties: dict[str, bool] = {}
        # loose node index -> the node its cinch made (None: the cinch gave no node in its state)
        self.tried: dict[int, int | None] = {}
        self._tight: list[bool] = []  # per node index: cinched, or made from a tight node
        self._keys: list[str] = []  # per node index: its state
        self._tight_in: dict[str, int] = {}  # tight nodes per state
        self._sim: Any = None

    def ties_summand(self, p_data: PData) -> bool:
        """Whether a rope in ``p_data`` ties one of the goal's summands (both closures) with as many
        crossings as that summand's crossing number."""
        found = self._ties.get(p_data.key)
        if found is None:
            from twisted.knots import identify

            found = p_data.cross in self._crossings and identify(p_data).name in self.summands
            self._ties[p_data.key] = found
        return found

    def restore(self, tree: SearchTree) -> None:
        """Learn the cinches of a tree reloaded from the store (a cinch that gave no node is tried again:
        it gives no node again)."""
        for node in tree.nodes:
            if is_cinched(node) and node.parent is not None:
                self.tried[node.parent] = node.index

    def _sync(self, tree: SearchTree) -> None:
        """Mark the nodes added since the last call tight or loose (a parent comes before its child)."""
        for node in tree.nodes[len(self._tight) :]:
            tight = is_cinched(node) or (node.parent is not None and self._tight[node.parent])
            self._tight.append(tight)
            self._keys.append(node.p_data.key)
            if tight:
                self._tight_in[node.p_data.key] = self._tight_in.get(node.p_data.key, 0) + 1

    def is_tight(self, tree: SearchTree, index: int) -> bool:
        """Whether node ``index`` is cinched or made from a cinched node."""
        self._sync(tree)
        return self._tight[index]

    def state_weight(self, search: SearchView, s: str) -> float:
        """``TIGHT_WEIGHT`` for a state holding a tight node, else 1 (a factor of the crs weight)."""
        self._sync(search.tree)
        return TIGHT_WEIGHT if self._tight_in.get(s) else 1.0

    def candidates(self, search: SearchView, s: str, indices: list[int]) -> list[int]:
        """The nodes of state ``s`` a step may start from: its tight nodes when it has any. In a state that
        ties a summand, only while it has had fewer than ``CINCH_STEPS`` steps per tight node; then also
        its loose nodes not cinched yet (the one chosen is cinched), never one that was."""
        self._sync(search.tree)
        tight = [i for i in indices if self._tight[i]]
        if not self.ties_summand(search.tree.states[s]):
            return tight or indices
        steps = search.stats["step"].get(s, [0.0])[0]
        if tight and steps < CINCH_STEPS * len(tight):
            return tight
        loose = [i for i in indices if not self._tight[i] and self.tried.get(i) is None]
        return tight + loose or indices

    def wants(self, tree: SearchTree, node: Node) -> bool:
        """Whether ``node`` is to be cinched now: a loose node tying a summand, not cinched before, in a
        state whose cinches have failed fewer than ``CINCH_FAILURES`` times."""
        if self.is_tight(tree, node.index) or node.index in self.tried or not self.ties_summand(node.p_data):
            return False
        key = node.p_data.key
        failed = sum(
            1
            for loose, made in self.tried.items()
            if tree.nodes[loose].p_data.key == key and (made is None or tree.nodes[made].p_data.key != key)
        )
        return failed < CINCH_FAILURES

    def cinch(self, node: Node) -> Any:
        """Pull ``node``'s rope tight and let it go (:class:`twisted.tighten.Cinched`)."""
        from twisted.tighten import cinch, tightening_sim

        if self._sim is None:
            self._sim = tightening_sim()
        return cinch(self._sim, node.q)

    def forget(self, committed: int) -> None:
        for loose in [i for i, made in self.tried.items() if i >= committed or (made or 0) >= committed]:
            del self.tried[loose]
        # the tree is already cut back: the marks of the nodes it dropped go with them
        while len(self._tight) > committed:
            key = self._keys.pop()
            if self._tight.pop():
                self._tight_in[key] -= 1


# --- what enters T, and where the high level is asked ---------------------------------------------------


class Growth(Protocol):
    """Which simulated results enter ``T`` and from which reached states the high level is asked for plans."""

    def keeps(self, parent: PData, p_data: PData) -> bool:
        """Whether a result in ``p_data``, made from a node in ``parent``, enters ``T``."""
        ...

    def wants_plans(self, p_data: PData) -> bool:
        """Whether plans to the goal are asked for from ``p_data`` (reached for the first time)."""
        ...


class AddingMoves:
    """Algorithm 1: a result enters ``T`` when Cross does not drop and stays within the goal's (nothing
    below a state with more crossings than the goal can be the goal); adding moves only lead to the goal
    from states with fewer crossings, so only those get plans."""

    def __init__(self, goal: Goal) -> None:
        self.goal = goal

    def keeps(self, parent: PData, p_data: PData) -> bool:
        return parent.cross <= p_data.cross <= self.goal.cross

    def wants_plans(self, p_data: PData) -> bool:
        return p_data.cross < self.goal.cross


class BothWays:
    """A search with removing moves too (``twisted untie``, ``plan --from-run``;
    :mod:`twisted.planner.both_ways`): a result enters ``T`` whenever it has no more crossings than the start
    or the goal, whichever has more (every state on a both-ways plan does), and every state not in the
    goal gets plans. The high level given must plan both ways
    (:func:`twisted.planner.runs.high_level` with ``both_ways=True``)."""

    def __init__(self, goal: Goal, start: PData) -> None:
        self.goal = goal
        self.cross_cap = max(start.cross, goal.cross)

    def keeps(self, parent: PData, p_data: PData) -> bool:
        return p_data.cross <= self.cross_cap

    def wants_plans(self, p_data: PData) -> bool:
        return p_data not in self.goal


# --- one iteration -----------------------------------------------------------------------------------------


class Iteration(Protocol):
    """What one iteration of the search does; ``plans``: whether it follows high-level plans (without, no
    reached state is given any)."""

    plans: bool

    def iterate(self, search: Any) -> None:
        """One iteration of ``search`` (a :class:`~twisted.planner.search.Search`)."""
        ...


class PlanGuided:
    """Lines 5-12 of Algorithm 1: a state, a plan from it and a node in it (the selection parts), follow
    the plan, and after a failed plan RandomExpand with probability ``p_expand``. While no reached state
    has a plan, only RandomExpand."""

    plans = True

    def iterate(self, search: Any) -> None:
        s = search.select_topological_state()
        if s is None:  # no reached state has a plan to the goal: only random curves can make progress
            search.random_expand()
            return
        plan_index, plan = search.select_plan(s)
        node = search.select_configuration(s, plan.states[1], plan.moves[0])
        steps_done = search.follow_plan(node, plan)
        search.learn(s, plan_index, steps_done / len(plan.moves))
        if search.goal_node is None and search.rng.random() < search.options.p_expand:
            search.random_expand()


class LowLevelOnly:
    """The low-level-only baseline: K random curves (``parts.expand_curves``) from a uniformly chosen node
    of ``T``; only the goal test guides it (no high level)."""

    plans = False

    def iterate(self, search: Any) -> None:
        node = search.tree.nodes[int(search.rng.integers(len(search.tree)))]
        curves = search.parts.expand_curves.sample(node, None, None, search.options.k, search.rng)
        search.simulate(node, curves, "low_level_only")


# --- the bundle -----------------------------------------------------------------------------------------


@dataclass
class SearchParts:
    """What one search is built from (see the module's docstring)."""

    states: StateSelection
    plans: PlanSelection
    nodes: NodeSelection
    step_curves: StepCurves
    expand_curves: BlindCurves  # RandomExpand's curves (and the low-level-only baseline's)
    goal_test: GoalTest
    growth: Growth
    iteration: Iteration
    room: R1Room | None = None  # the cache the selections share, forgotten on rollback
    cinch: SummandCinch | None = None  # toward a composite knot with options.cinch

    def forget(self, committed: int) -> None:
        """An unfinished iteration was rolled back to ``committed`` nodes: drop what it cached."""
        if self.room is not None:
            self.room.forget(committed)
        if self.cinch is not None:
            self.cinch.forget(committed)


def default_parts(
    options: PlannerOptions,
    goal: Goal,
    sampler: CurveSampler | None = None,
    goal_test: GoalTest | None = None,
    growth: Growth | None = None,
    removal: BlindCurves | None = None,
) -> SearchParts:
    """The parts ``options`` name: heuristic -> state and plan selection, ``retry_weight`` and ``r1_room``
    -> node selection (and the room the crs and plan choices weigh), ``cross_move`` -> the scripted share
    of a Cross step (planner twisted), planner ``low-level-only`` -> :class:`LowLevelOnly` iterations
    (else :class:`PlanGuided`); ``sampler`` (None: random curves) proposes the other curves.
    ``goal_test`` defaults to :class:`StateMatch`; with ``options.tighten`` it must be given (a
    :class:`PullTest`, as :mod:`twisted.planner.runs` makes it). ``growth`` defaults to
    :class:`AddingMoves`; ``removal``: the proposer of a removing step's curves (None: ``sampler``)."""
    if goal_test is None:
        if options.tighten:
            raise ValueError("tighten: the search needs a PullTest goal test (see twisted.planner.runs)")
        goal_test = StateMatch(goal)
    room = R1Room(options.r1_room) if options.r1_room > 0.0 else None
    cinch = SummandCinch(goal) if options.cinch else None
    if cinch is not None and not cinch.summands:
        cinch = None  # a prime knot or a state: nothing to cinch on the way
    states: StateSelection
    plans: PlanSelection
    if options.heuristic == "ucb":
        states, plans = UcbStates(options.ucb_c), UcbPlans(options.ucb_c)
    elif options.heuristic == "rnd":
        states, plans = UniformStates(), UniformPlans(room)
    else:
        states, plans = CrossingStates(room, cinch), UniformPlans(room)
    random_curves = RandomCurves()
    share = options.cross_move if options.planner == "twisted" else 0.0
    return SearchParts(
        states=states,
        plans=plans,
        nodes=RetryWeightedNodes(options.retry_weight, room, cinch),
        step_curves=StepCurves(
            sampler if sampler is not None else random_curves, ScriptedCross(), share, removal
        ),
        expand_curves=random_curves,
        goal_test=goal_test,
        growth=growth if growth is not None else AddingMoves(goal),
        iteration=LowLevelOnly() if options.planner == "low-level-only" else PlanGuided(),
        room=room,
        cinch=cinch,
    )
