"""TWISTED (Algorithm 1 of the paper) and its baselines: the search itself.

The search keeps a tree ``T`` of reached configurations (each with its topological state ``Top(q)``)
and a set of high-level plans ``P`` from every reached state to the goal. Each iteration:

    s = select_topological_state()          # rnd | crs (weight 1 + Cross(s), opt. * r(s)) | ucb (bandit)
    plan = select_plan(s)                   # uniform (or ucb) over the plans from s
    q = select_configuration(s)             # a node of T in state s (retry weight)
    found = follow_plan(q, plan)            # K curves per step, continue from the first that hits
    if not found and rng.random() < p:      # completeness: random curves from a random node
        random_expand()

until the goal state appears in ``T`` or the time runs out. The answer is the path of curves from
the root of ``T`` to the goal node. Where this differs from the paper (DESIGN 8): the node choice
weights a node by how often it was already asked for the plan's next state (the retry weight; the
paper's choice is uniform); only when asked for (``state_prior > 0``), ``r(s)`` is how the plan
steps started from ``s`` fared against those of its crossing level (the paper's crs has 1); with
``r1_room > 0`` (default 8) states, plans and nodes are weighted by the rope they leave for a
plan's R1 curl; with ``cross_move > 0`` (default 0.67) a step toward a Cross move takes that share
of its K curves from a scripted curve (:func:`twisted.proposals.cross_move_curve`) instead of the
inverse model; and RandomExpand follows a failed iteration with p = 0.01 (the paper's 0.05).

Baselines (``planner``): ``twisted`` samples curves from the inverse model; ``random-low`` follows
the same high-level plans with uniformly random curves (the paper's "low+high level");
``low-level-only`` applies random curves to random nodes of ``T`` with no topological guidance
beyond the goal test; ``sac`` follows the high-level plans like ``twisted`` with a SAC+HER policy
(``twisted rl train``) in place of the inverse model, as in the paper's comparison.

The goal is a set of states (:class:`twisted.goals.Goal`): one P-data state, or every state that ties
a named knot; the search succeeds on reaching any member.

Everything random goes through one ``numpy.random.Generator``; simulation results come back in
the order the curves were sampled (``SimPool`` preserves order), so a run replays from its seed
for any number of workers. The search is persisted through a :class:`SearchRecorder` at iteration
boundaries only: a checkpoint (iteration, elapsed time, RNG state, selection statistics) and the
tree nodes created up to that boundary are written in one transaction, so a resumed run continues
exactly where the checkpoint left it and never writes a node twice.

This module knows nothing of the store or the model registry: what a search composes (a curve
sampler, a worker pool, the high level, a recorder) comes in through the protocols below;
:mod:`twisted.planner.session` builds searches from the store.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from twisted.goals import Goal, state_goal
from twisted.runtime import StopRequested, StopSignals
from twisted.topology import PData

__all__ = [
    "CALL_SOURCES",
    "HEURISTICS",
    "PLANNERS",
    "Checkpoint",
    "CurveSampler",
    "Node",
    "PlannerOptions",
    "Pool",
    "RandomCurves",
    "SearchRecorder",
    "SearchResult",
    "SearchTree",
    "Twisted",
    "pair_key",
]

PLANNERS = ("twisted", "random-low", "low-level-only", "sac")
HEURISTICS = ("rnd", "crs", "ucb")
# Tables of the search's statistics (kept in every checkpoint): [times selected, summed reward] per
# state and per (state, plan) index; [steps tried, steps achieved] per move kind in follow_plan;
# [simulator calls, results kept in T] per source of curves (CALL_SOURCES); [tries, hits] per
# (node index, requested next state) pair of follow_plan (read by the retry weight); [steps tried,
# steps achieved] per state a follow_plan step started from (read by the state prior); [curves, curves
# that reached the plan's next state] per proposer of a Cross step's curves ("cross_move", "sampler")
STATS_TABLES = ("state", "plan", "move", "calls", "pair", "step", "cross")
CALL_SOURCES = ("follow_plan", "random_expand", "low_level_only")
# what a run stored before an option existed ran with (PlannerOptions.from_dict)
OPTIONS_BEFORE = {"retry_weight": 1.0, "state_prior": 0.0, "cross_move": 0.0, "r1_room": 0.0}
# the least node weight r1_room gives (a curl on a segment of a link or less almost never works)
R1_ROOM_FLOOR = 0.02
# links of the rope: twisted.sim.N_LINKS, repeated so that importing the planner does not load MuJoCo
# (tests/test_cross_move.py checks that they agree)
N_LINKS = 21


def pair_key(node_index: int, next_state_key: str) -> str:
    """The key of a (node, requested next state) pair in the ``pair`` statistics table; the state
    is given by its ``PData.key`` so that a caller asking for many nodes serialises it once."""
    return f"{node_index}|{next_state_key}"


@dataclass(frozen=True)
class PlannerOptions:
    """Algorithm options; the defaults are the paper's values except ``k``, ``p_expand``,
    ``k_expand``, ``retry_weight``, ``cross_move`` and ``r1_room``, which measured searches set
    (DESIGN 8)."""

    planner: str = "twisted"
    heuristic: str = "crs"
    k: int = 3  # curves sampled per plan step (K; the paper's 6 is --k 6)
    p_expand: float = 0.01  # probability of RandomExpand after a failed iteration (p; the paper's 0.05)
    k_expand: int = 25  # random curves per RandomExpand (k; the paper's 100 is --k-expand 100)
    plan_limit: int = 100  # high-level plans kept per reached state
    seed: int = 0
    ucb_c: float = 0.7  # exploration weight of the ucb heuristic (rewards lie in [0, 1])
    # weight of a node already asked n times for the plan's next state: retry_weight**n (1: uniform,
    # the paper's choice)
    retry_weight: float = 0.1
    # opt-in: the crs state choice learns from the plan steps tried, weight (1 + Cross(s)) * r(s), r(s)
    # the step success of s against its crossing level, shrunk by this many tries' worth of the level's
    # rate (0, the default: the paper's crs, r = 1; 50 saved calls on one 4-crossing set and cost
    # calls on another, DESIGN 8)
    state_prior: float = 0.0
    # share of the K curves of a plan step toward a Cross move that come from the scripted Cross move
    # curve (twisted.proposals) instead of the inverse model; planner "twisted" only (DESIGN 8)
    cross_move: float = 0.67
    # an R1 curl needs rope to curl: a node whose segment for the plan's R1 step is shorter than this
    # many links gets node weight (length / r1_room)**2 (at least R1_ROOM_FLOOR), and a plan that starts
    # with a curl, and a state (crs), the weight of the best node for it; 0: off (DESIGN 8)
    r1_room: float = 8.0
    # success means "reached a goal state and the pull test ties the goal's knot" (twisted.tighten)
    tighten: bool = False

    def validate(self) -> None:
        """Raise ValueError naming the option that is out of range."""
        if self.planner not in PLANNERS:
            raise ValueError(f"planner must be one of {', '.join(PLANNERS)}, got {self.planner!r}")
        if self.heuristic not in HEURISTICS:
            raise ValueError(f"heuristic must be one of {', '.join(HEURISTICS)}, got {self.heuristic!r}")
        if self.k < 1:
            raise ValueError(f"k (curves per step) must be at least 1, got {self.k}")
        if not 0.0 <= self.p_expand <= 1.0:
            raise ValueError(f"p_expand must lie in [0, 1], got {self.p_expand}")
        if self.k_expand < 1:
            raise ValueError(f"k_expand must be at least 1, got {self.k_expand}")
        if self.plan_limit < 1:
            raise ValueError(f"plan_limit must be at least 1, got {self.plan_limit}")
        if not 0.0 < self.retry_weight <= 1.0:
            raise ValueError(f"retry_weight must lie in (0, 1], got {self.retry_weight}")
        if not (0.0 <= self.state_prior and math.isfinite(self.state_prior)):
            raise ValueError(f"state_prior must be a finite number of tries >= 0, got {self.state_prior}")
        if not 0.0 <= self.cross_move <= 1.0:
            raise ValueError(f"cross_move must lie in [0, 1], got {self.cross_move}")
        if not 0.0 <= self.r1_room <= N_LINKS:
            raise ValueError(f"r1_room must be a number of links in [0, {N_LINKS}], got {self.r1_room}")

    def to_dict(self) -> dict[str, Any]:
        return {
            "planner": self.planner,
            "heuristic": self.heuristic,
            "k": self.k,
            "p_expand": self.p_expand,
            "k_expand": self.k_expand,
            "plan_limit": self.plan_limit,
            "seed": self.seed,
            "ucb_c": self.ucb_c,
            "retry_weight": self.retry_weight,
            "state_prior": self.state_prior,
            "cross_move": self.cross_move,
            "r1_room": self.r1_room,
            "tighten": self.tighten,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PlannerOptions:
        """The options a run stored; a run stored before ``retry_weight``, ``state_prior`` or
        ``cross_move`` existed chose its nodes uniformly, its states by the paper's crs and all its
        curves from its sampler; one stored before ``r1_room`` chose nodes without it."""
        known = {k: v for k, v in data.items() if k in cls.__dataclass_fields__}
        return cls(**{**OPTIONS_BEFORE, **known})


# --- the tree T -------------------------------------------------------------------------------------


@dataclass(eq=False, slots=True)
class Node:
    """A vertex of ``T``: a reached configuration ``q``, its state ``Top(q)``, the curve that made it."""

    index: int  # creation order in the run (0 = root)
    parent: int | None
    q: np.ndarray  # opaque simulator state (RopeSim.state())
    points: np.ndarray  # (22, 3) link points, head first
    p_data: PData
    curve: Any | None  # twisted.sim.Curve; None for the root
    iteration: int  # iteration that created it (0 = root)
    sim_call: int  # number of the simulator call that produced it (0 = root)
    created_s: float = 0.0  # elapsed search time when it was created
    db_id: int | None = None  # row id once written to the store


class SearchTree:
    """``T``: the nodes in creation order, indexed by topological state."""

    def __init__(self) -> None:
        self.nodes: list[Node] = []
        self.by_state: dict[str, list[int]] = {}
        self.states: dict[str, PData] = {}  # insertion order = order of first reach

    def __len__(self) -> int:
        return len(self.nodes)

    def add(self, node: Node) -> Node:
        if node.index != len(self.nodes):
            raise ValueError(f"node index {node.index} breaks creation order (expected {len(self.nodes)})")
        self.nodes.append(node)
        key = node.p_data.key
        if key not in self.states:
            self.states[key] = node.p_data
            self.by_state[key] = []
        self.by_state[key].append(node.index)
        return node

    def truncate(self, size: int) -> None:
        """Forget the nodes created after the first ``size`` (an iteration that was not finished)."""
        while len(self.nodes) > size:
            node = self.nodes.pop()
            key = node.p_data.key
            self.by_state[key].pop()
            if not self.by_state[key]:
                del self.by_state[key]
                del self.states[key]

    def path(self, index: int) -> list[Node]:
        """The nodes from the root to node ``index``."""
        out = []
        cursor: int | None = index
        while cursor is not None:
            node = self.nodes[cursor]
            out.append(node)
            cursor = node.parent
        return out[::-1]


# --- what the search composes -------------------------------------------------------------------------


class CurveSampler(Protocol):
    """Proposes curves that should move the rope of ``node`` to ``next_state``."""

    name: str

    def sample(
        self, node: Node, next_state: PData, move: Any | None, n: int, rng: np.random.Generator
    ) -> list[Any]: ...


class RandomCurves:
    """Uniformly random curves over the action ranges (the baselines, and RandomExpand)."""

    name = "random"

    def sample(
        self, node: Node, next_state: PData | None, move: Any | None, n: int, rng: np.random.Generator
    ) -> list[Any]:
        from twisted.sim import sample_curve

        return [sample_curve(rng) for _ in range(n)]


class Pool(Protocol):
    def run(self, jobs: Sequence[tuple[np.ndarray, Any]]) -> list[Any]: ...


@dataclass
class Checkpoint:
    """The consistent cut of a search at an iteration boundary."""

    iteration: int
    elapsed_s: float
    sim_calls: int
    rng_state: dict[str, Any]
    stats: dict[str, Any]


class SearchRecorder(Protocol):
    """Persists nodes and checkpoints (implemented by :class:`twisted.store.search.SearchRun`)."""

    def save(self, nodes: Sequence[Node], checkpoint: Checkpoint) -> None:
        """Write ``nodes`` (assigning ``db_id``) and ``checkpoint`` in one transaction."""

    def finish(self, status: str, goal_node: Node | None, checkpoint: Checkpoint) -> None:
        """Mark the run ``solved`` / ``timeout`` / ``interrupted`` / ``stopped``."""


@dataclass
class SearchResult:
    """What a search returns; ``path`` runs from the root to the goal node (empty when not solved)."""

    run_id: int | None
    status: str  # solved | timeout | interrupted | stopped (iteration cap)
    elapsed_s: float
    sim_calls: int
    iterations: int
    nodes: int
    states: int
    path: list[Node] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)  # the checkpoint's tables (STATS_TABLES)

    @property
    def solved(self) -> bool:
        return self.status == "solved"

    def calls_by_source(self) -> dict[str, int]:
        """Simulator calls per source of curves (CALL_SOURCES); they add up to ``sim_calls`` unless the
        run was resumed from a checkpoint written before these counts were kept."""
        return {source: int(entry[0]) for source, entry in self.stats.get("calls", {}).items()}

    def steps_by_move(self) -> dict[str, tuple[int, int]]:
        """(follow_plan steps tried, steps that reached the plan's next state) per move kind."""
        return {kind: (int(entry[0]), int(entry[1])) for kind, entry in self.stats.get("move", {}).items()}


class _Stop(Exception):
    """Unwinds an unfinished iteration (time out or a stop signal): it is discarded, not half-saved."""

    def __init__(self, status: str) -> None:
        super().__init__(status)
        self.status = status


# --- Algorithm 1 ----------------------------------------------------------------------------------------


class Twisted:
    """One search for ``goal`` (Algorithm 1), resumable from a :class:`Checkpoint`."""

    def __init__(
        self,
        goal: Goal | PData,
        tree: SearchTree,
        options: PlannerOptions,
        pool: Pool,
        high_level: Callable[[PData], list[Any]],
        sampler: CurveSampler | None = None,
        recorder: SearchRecorder | None = None,
        checkpoint: Checkpoint | None = None,
        run_id: int | None = None,
        stop: StopSignals | None = None,
        checkpoint_every_s: float = 2.0,
        progress: Callable[[Twisted], None] | None = None,
    ) -> None:
        options.validate()
        if len(tree) == 0:
            raise ValueError("the tree needs its root (the initial configuration)")
        self.goal = goal if isinstance(goal, Goal) else state_goal(goal)
        self.tree = tree
        self.options = options
        self.pool = pool
        self.high_level = high_level
        self.random_curves = RandomCurves()
        self.sampler: CurveSampler = sampler if sampler is not None else self.random_curves
        self.recorder = recorder
        self.run_id = run_id
        self.stop = stop if stop is not None else StopSignals()
        self.checkpoint_every_s = checkpoint_every_s
        self.progress = progress

        self.rng = np.random.default_rng(options.seed)
        self.iteration = 0
        self.elapsed_before_s = 0.0
        self.sim_calls = 0
        self.stats: dict[str, dict[str, list[float]]] = {table: {} for table in STATS_TABLES}
        if checkpoint is not None:
            self.rng.bit_generator.state = checkpoint.rng_state
            self.iteration = checkpoint.iteration
            self.elapsed_before_s = checkpoint.elapsed_s
            self.sim_calls = checkpoint.sim_calls
            # a checkpoint written before a table existed starts it empty
            self.stats = {table: dict(checkpoint.stats.get(table, {})) for table in STATS_TABLES}

        # P: the high-level plans from every reached state (recomputed from the plan cache on resume)
        self.plans: dict[str, list[Any]] = {}
        self.goal_node: Node | None = None
        for p_data in tree.states.values():
            self._reached(p_data)
        self.pull_tests = 0
        self._tighten_sim: Any = None
        # a resumed run: the first node in a goal state (that passes the pull test with --tighten)
        reached = sorted(i for key in self.goal.keys for i in tree.by_state.get(key, ()))
        for index in reached:
            if self._accepts(tree.nodes[index], record=False):
                self.goal_node = tree.nodes[index]
                break

        self._bounds: dict[int, Any] = {}  # node index -> segment_bounds of its points (r1_room)
        # state -> (its nodes weighed, best room per R1 segment, plan_rooms)
        self._plan_rooms: dict[str, tuple[int, dict[int, float], list[float]]] = {}
        self._saved = len(tree)  # nodes already in the store
        self._t0: float | None = None  # set while run() is searching
        self._last_save = time.perf_counter()
        self._deadline_s: float | None = None
        self._boundary = self._checkpoint()

    # -- bookkeeping ------------------------------------------------------------------------------------

    @property
    def elapsed_s(self) -> float:
        """Search time so far, over every run() and resumed process."""
        running_s = 0.0 if self._t0 is None else time.perf_counter() - self._t0
        return self.elapsed_before_s + running_s

    def add_setup_time(self, seconds: float) -> None:
        """Count ``seconds`` of set-up (loading, starting workers) as time spent on this run.

        It then counts toward the timeout and is stored with the run's search time, like a resumed
        run's earlier time.
        """
        self.elapsed_before_s += seconds
        self._boundary.elapsed_s = self.elapsed_s

    def _checkpoint(self) -> Checkpoint:
        return Checkpoint(
            iteration=self.iteration,
            elapsed_s=self.elapsed_s,
            sim_calls=self.sim_calls,
            rng_state=dict(self.rng.bit_generator.state),
            stats={table: {k: list(v) for k, v in entries.items()} for table, entries in self.stats.items()},
        )

    def _save(self, upto: int, checkpoint: Checkpoint) -> None:
        if self.recorder is not None:
            self.recorder.save(self.tree.nodes[self._saved : upto], checkpoint)
        self._saved = upto
        self._last_save = time.perf_counter()

    def _check_stop(self, deadline_s: float | None) -> None:
        if self.stop():
            raise _Stop("interrupted")
        if deadline_s is not None and self.elapsed_s >= deadline_s:
            raise _Stop("timeout")

    @property
    def candidate_states(self) -> list[str]:
        """Reached states with at least one plan to the goal, in order of first reach."""
        return [key for key, plans in self.plans.items() if plans]

    # -- the main loop ----------------------------------------------------------------------------------

    def run(self, timeout_s: float | None = None, max_iterations: int | None = None) -> SearchResult:
        """Search until the goal is in ``T``, ``timeout_s`` of total search time, or ``max_iterations``."""
        self._t0 = time.perf_counter()
        self._last_save = self._t0
        self._deadline_s = timeout_s
        status = "solved" if self.goal_node is not None else ""
        committed = len(self.tree)
        while not status:
            if max_iterations is not None and self.iteration >= max_iterations:
                status = "stopped"
                break
            try:
                self._check_stop(timeout_s)
                self.iteration += 1
                if self.options.planner == "low-level-only":
                    self.low_level_only_step()
                else:
                    self.twisted_iteration()
            except _Stop as stop:
                # discard the unfinished iteration: the store keeps the last boundary, so resuming
                # replays it from the same RNG state and writes its nodes exactly once
                status = stop.status
                break
            committed = len(self.tree)
            self._boundary = self._checkpoint()
            if self.goal_node is not None:
                status = "solved"
            elif time.perf_counter() - self._last_save >= self.checkpoint_every_s:
                self._save(committed, self._boundary)
            if self.progress is not None:
                self.progress(self)
        self._boundary.elapsed_s = self.elapsed_s  # the discarded part still counts toward the timeout
        self.elapsed_before_s, self._t0 = self._boundary.elapsed_s, None
        if status != "solved":
            self._rollback(committed)
        self._save(committed, self._boundary)
        if self.recorder is not None:
            self.recorder.finish(status, self.goal_node, self._boundary)
        return SearchResult(
            run_id=self.run_id,
            status=status,
            elapsed_s=self._boundary.elapsed_s,
            sim_calls=self._boundary.sim_calls,
            iterations=self._boundary.iteration,
            nodes=committed,
            states=len({self.tree.nodes[i].p_data.key for i in range(committed)}),
            path=self.tree.path(self.goal_node.index) if self.goal_node is not None else [],
            stats=self._boundary.stats,
        )

    def _rollback(self, committed: int) -> None:
        """Back to the last iteration boundary, exactly what a resume from the store would load."""
        self.tree.truncate(committed)
        for key in [key for key in self.plans if key not in self.tree.states]:
            del self.plans[key]
        for index in [index for index in self._bounds if index >= committed]:
            del self._bounds[index]
        self._plan_rooms.clear()
        self.rng.bit_generator.state = self._boundary.rng_state
        self.iteration = self._boundary.iteration
        self.sim_calls = self._boundary.sim_calls
        self.stats = {table: {k: list(v) for k, v in e.items()} for table, e in self._boundary.stats.items()}

    def twisted_iteration(self) -> None:
        """Lines 5-12 of Algorithm 1."""
        s = self.select_topological_state()
        if s is None:
            # no reached state has a plan to the goal: only random curves can make progress
            self.random_expand()
            return
        plan_index, plan = self.select_plan(s)
        node = self.select_configuration(s, plan.states[1], plan.moves[0])
        steps_done = self.follow_plan(node, plan)
        self.learn(s, plan_index, steps_done / len(plan.moves))
        if self.goal_node is None and self.rng.random() < self.options.p_expand:
            self.random_expand()

    # -- SelectTopologicalState / SelectPlan / SelectConfiguration -------------------------------------

    def select_topological_state(self) -> str | None:
        """A reached state with a plan: rnd uniform, crs weight 1 + Cross(s) (with ``r1_room``, times
        its best plan's room, :meth:`plan_rooms`), ucb upper confidence bound."""
        candidates = self.candidate_states
        if not candidates:
            return None
        if self.options.heuristic == "rnd":
            return candidates[int(self.rng.integers(len(candidates)))]
        if self.options.heuristic == "crs":
            weights = np.array([1.0 + self.tree.states[key].cross for key in candidates])
            if self.options.state_prior > 0.0:
                weights = weights * self.step_ratios(candidates)
            if self.options.r1_room > 0.0:
                weights = weights * np.array([max(self.plan_rooms(key)) for key in candidates])
            return candidates[int(self.rng.choice(len(candidates), p=weights / weights.sum()))]
        return self._ucb_state(candidates)

    def step_ratios(self, candidates: list[str]) -> np.ndarray:
        """``r(s)`` of the crs weight: how the plan steps started from ``s`` fare against those of its
        crossing level, ``((h_s + n0 m) / (t_s + n0)) / m``.

        ``t_s`` steps tried from ``s``, ``h_s`` achieved; ``m = (H + 1) / (T + 2)`` the rate of every
        step from a state with as many crossings; ``n0 = state_prior``. An untried state has r = 1;
        a state whose steps keep failing sinks as ``n0 / (t_s + n0)`` (and its level's share of the
        choices with it, toward the levels that reach new states); one that beats its level rises.
        """
        steps = self.stats["step"]
        level: dict[int, list[float]] = {}
        for key, (tried, hit) in steps.items():
            entry = level.setdefault(self.tree.states[key].cross, [0.0, 0.0])
            entry[0] += tried
            entry[1] += hit
        n0 = self.options.state_prior
        ratios = []
        for key in candidates:
            tried, hit = steps.get(key, (0.0, 0.0))
            level_tried, level_hit = level.get(self.tree.states[key].cross, (0.0, 0.0))
            m = (level_hit + 1.0) / (level_tried + 2.0)
            ratios.append((hit + n0 * m) / ((tried + n0) * m))
        return np.array(ratios)

    def _ucb_state(self, candidates: list[str]) -> str:
        # Each state starts with one pseudo-observation worth (1 + Cross(s)) / (1 + Cross(goal)), so an
        # untried state is preferred by depth as in crs instead of forcing a round over every state.
        stats = self.stats["state"]
        total = sum(stats.get(key, [0.0, 0.0])[0] for key in candidates)
        best, best_score = candidates[0], -math.inf
        for key in candidates:
            n, reward = stats.get(key, [0.0, 0.0])
            prior = (1.0 + self.tree.states[key].cross) / (1.0 + self.goal.cross)
            bonus = self.options.ucb_c * math.sqrt(math.log(1.0 + total) / (n + 1.0))
            score = (reward + prior) / (n + 1.0) + bonus
            if score > best_score:
                best, best_score = key, score
        return best

    def select_plan(self, s: str) -> tuple[int, Any]:
        """A high-level plan from ``s``: uniform (rnd, crs; with ``r1_room``, weighted by
        :meth:`plan_rooms`) or upper confidence bound (ucb)."""
        plans = self.plans[s]
        if self.options.heuristic != "ucb":
            rooms = self.plan_rooms(s) if self.options.r1_room > 0.0 else [1.0]
            if min(rooms) == max(rooms):
                index = int(self.rng.integers(len(plans)))
            else:
                index = int(self.rng.choice(len(plans), p=np.array(rooms) / sum(rooms)))
            return index, plans[index]
        n_state = self.stats["state"].get(s, [0.0, 0.0])[0]
        best, best_score = 0, -math.inf
        for index in range(len(plans)):
            n, reward = self.stats["plan"].get(f"{s}|{index}", [0.0, 0.0])
            if n == 0:
                return index, plans[index]  # each plan of a selected state is tried once first
            score = reward / n + self.options.ucb_c * math.sqrt(math.log(1.0 + n_state) / n)
            if score > best_score:
                best, best_score = index, score
        return best, plans[best]

    def select_configuration(self, s: str, next_state: PData, move: Any = None) -> Node:
        """A node of ``T`` in state ``s`` to ask for ``next_state``: weight ``retry_weight ** n`` for a
        node already asked for it ``n`` times; with ``r1_room`` and an R1 ``move``, times the node's
        room for the curl (:meth:`r1_room_weight`).

        A plan step succeeds or fails by its (node, next state) pair far more than by the curves
        drawn (DESIGN 8), so among the configurations of one state the untried ones go first. While
        every weight is equal the draw is uniform and takes the random number the paper's choice
        takes, so ``retry_weight = 1`` replays it exactly.
        """
        indices = self.tree.by_state[s]
        pairs, key = self.stats["pair"], next_state.key
        weights = [self.options.retry_weight ** pairs.get(pair_key(i, key), [0.0])[0] for i in indices]
        if self.options.r1_room > 0.0 and move is not None and move.kind == "R1":
            nodes = self.tree.nodes
            weights = [
                w * self.r1_room_weight(nodes[i], move.segment) for w, i in zip(weights, indices, strict=True)
            ]
        if min(weights) == max(weights):
            return self.tree.nodes[indices[int(self.rng.integers(len(indices)))]]
        p = np.array(weights) / sum(weights)
        return self.tree.nodes[indices[int(self.rng.choice(len(indices), p=p))]]

    def r1_room_weight(self, node: Node, segment: int) -> float:
        """How much rope ``node`` has on ``segment`` for a curl, as a node weight:
        ``(length / r1_room) ** 2`` in links, between ``R1_ROOM_FLOOR`` and 1 (DESIGN 8)."""
        bounds = self._bounds.get(node.index)
        if bounds is None:
            from twisted.proposals import segment_bounds

            bounds = self._bounds[node.index] = segment_bounds(node.points)
        length = float(bounds[segment + 1] - bounds[segment])
        return max(R1_ROOM_FLOOR, min(1.0, length / self.options.r1_room) ** 2)

    def plan_rooms(self, s: str) -> list[float]:
        """Per plan of ``s``: 1, or for a plan that starts with an R1 curl the most room any node of
        ``s`` has for it (:meth:`r1_room_weight`). The best room per segment is kept per state and
        only the nodes ``s`` gained since the last call are weighed (the cache is dropped on rollback)."""
        indices = self.tree.by_state[s]
        cached = self._plan_rooms.get(s)
        if cached is not None and cached[0] == len(indices):
            return cached[2]
        seen, best = (cached[0], cached[1]) if cached is not None else (0, {})
        nodes, new = self.tree.nodes, indices[seen:]
        for segment in best:
            best[segment] = max(best[segment], *(self.r1_room_weight(nodes[i], segment) for i in new))
        rooms = []
        for plan in self.plans[s]:
            move = plan.moves[0]
            if move.kind != "R1":
                rooms.append(1.0)
                continue
            if move.segment not in best:
                best[move.segment] = max(self.r1_room_weight(nodes[i], move.segment) for i in indices)
            rooms.append(best[move.segment])
        self._plan_rooms[s] = (len(indices), best, rooms)
        return rooms

    def learn(self, s: str, plan_index: int, reward: float) -> None:
        """Record how far a followed plan got (the ucb heuristic learns from it; all keep it for analysis)."""
        self._count("state", s, 1, reward)
        self._count("plan", f"{s}|{plan_index}", 1, reward)

    # -- FollowPlan / RandomExpand -------------------------------------------------------------------

    def follow_plan(self, node: Node, plan: Any) -> int:
        """Follow ``plan`` from ``node``; returns the number of plan steps achieved (goal: all)."""
        current = node
        for step, (next_state, move) in enumerate(zip(plan.states[1:], plan.moves, strict=True)):
            if step:
                self._check_stop(self._deadline_s)
            curves, scripted = self.step_curves(current, next_state, move)
            children = self.simulate(current, curves, "follow_plan")
            reached = [c is not None and c.p_data == next_state for c in children]
            hit = next((c for c, ok in zip(children, reached, strict=True) if ok), None)
            if move is not None and move.kind == "Cross":
                self._count("cross", "cross_move", scripted, sum(reached[:scripted]))
                self._count("cross", "sampler", len(curves) - scripted, sum(reached[scripted:]))
            self._count("move", str(move.kind), 1, hit is not None)
            self._count("pair", pair_key(current.index, next_state.key), 1, hit is not None)
            self._count("step", current.p_data.key, 1, hit is not None)
            if self.goal_node is not None:
                return len(plan.moves)
            if hit is None:
                return step
            current = hit
        return len(plan.moves)

    def step_curves(self, node: Node, next_state: PData, move: Any) -> tuple[list[Any], int]:
        """The K curves of a plan step, and how many of them (the first) are scripted Cross move curves.

        With ``cross_move`` > 0 a step toward a Cross move (planner ``twisted``) takes
        ``round(cross_move * K)`` curves from :func:`twisted.proposals.cross_move_curve` and the rest
        from the sampler; every other step takes all K from the sampler.
        """
        k = self.options.k
        scripted = 0
        if self.options.planner == "twisted" and move is not None and move.kind == "Cross":
            scripted = min(k, int(round(self.options.cross_move * k)))
        curves: list[Any] = []
        if scripted:
            from twisted.proposals import cross_move_curve

            curves = [cross_move_curve(self.rng, node.points, move) for _ in range(scripted)]
        if scripted < k:
            curves += self.sampler.sample(node, next_state, move, k - scripted, self.rng)
        return curves, scripted

    def random_expand(self) -> None:
        """k random curves from a uniformly chosen node of ``T`` (the completeness guarantee)."""
        node = self.tree.nodes[int(self.rng.integers(len(self.tree)))]
        curves = self.random_curves.sample(node, None, None, self.options.k_expand, self.rng)
        # simulated in chunks so that a stop signal or the deadline is noticed within a second or two
        chunk = 24
        for start in range(0, len(curves), chunk):
            if start:
                self._check_stop(self._deadline_s)
            self.simulate(node, curves[start : start + chunk], "random_expand")
            if self.goal_node is not None:
                return

    def low_level_only_step(self) -> None:
        """Baseline: K random curves from a uniformly chosen node of ``T``; only the goal test guides it."""
        node = self.tree.nodes[int(self.rng.integers(len(self.tree)))]
        curves = self.random_curves.sample(node, None, None, self.options.k, self.rng)
        self.simulate(node, curves, "low_level_only")

    # -- simulation and growing T -----------------------------------------------------------------------

    def simulate(self, parent: Node, curves: list[Any], source: str) -> list[Node | None]:
        """Apply ``curves`` to ``parent`` in the worker pool; add the kept results to ``T`` in curve order.

        ``source`` (one of CALL_SOURCES) is what the calls and kept results are counted under.
        """
        try:
            with self.stop.interruptible():
                results = self.pool.run([(parent.q, curve) for curve in curves])
        except StopRequested:
            raise _Stop("interrupted") from None
        first_call = self.sim_calls + 1
        self.sim_calls += len(curves)
        pairs = enumerate(zip(curves, results, strict=True))
        children = [self.add_to_tree(parent, curve, result, first_call + i) for i, (curve, result) in pairs]
        self._count("calls", source, len(curves), sum(child is not None for child in children))
        return children

    def _count(self, table: str, key: str, first: float, second: float) -> None:
        entry = self.stats[table].setdefault(key, [0.0, 0.0])
        entry[0] += first
        entry[1] += second

    def add_to_tree(self, parent: Node, curve: Any, result: Any, sim_call: int) -> Node | None:
        """Keep ``result`` when Cross does not drop (the paper's rule) and can still lead to the goal.

        A state with more crossings than the goal is dropped as well: every curve kept after it has
        at least as many crossings, so nothing below it can be the goal.
        """
        if not result.ok:
            return None
        p_data: PData = result.p_data
        if p_data.cross < parent.p_data.cross or p_data.cross > self.goal.cross:
            return None
        node = self.tree.add(
            Node(
                index=len(self.tree),
                parent=parent.index,
                q=result.state,
                points=result.points,
                p_data=p_data,
                curve=curve,
                iteration=self.iteration,
                sim_call=sim_call,
                created_s=self.elapsed_s,
            )
        )
        if p_data.key not in self.plans:
            self._reached(p_data)
        if self.goal_node is None and p_data in self.goal and self._accepts(node):
            self.goal_node = node
        return node

    def _accepts(self, node: Node, record: bool = True) -> bool:
        """Whether a node in a goal state ends the search: always, or with ``tighten`` when the rope pulled
        tight ties the goal's knot (the pull test is deterministic; a resume re-runs it unrecorded)."""
        if not self.options.tighten:
            return True
        from twisted.tighten import tighten, tightening_sim

        if self._tighten_sim is None:
            self._tighten_sim = tightening_sim()
        result = tighten(self._tighten_sim, node.q)
        ties = result.ok and self.goal.tightened_ties(result.knot_name)
        self.pull_tests += 1
        if record and self.recorder is not None and hasattr(self.recorder, "record_tightening"):
            self.recorder.record_tightening(node, result, self.goal, ties)
        return ties

    def _reached(self, p_data: PData) -> None:
        """A state reached for the first time: run the high level from it (through the plan cache)."""
        if self.options.planner == "low-level-only" or p_data.cross >= self.goal.cross:
            self.plans[p_data.key] = []
            return
        self.plans[p_data.key] = list(self.high_level(p_data))[: self.options.plan_limit]
