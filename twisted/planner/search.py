"""TWISTED (Algorithm 1 of the paper) and its baselines: the search loop.

The search keeps a tree ``T`` of reached configurations (each with its topological state ``Top(q)``)
and a set of high-level plans ``P`` from every reached state to the goal. Each iteration:

    s = select_topological_state()          # parts.states: rnd | crs | ucb
    plan = select_plan(s)                   # parts.plans: uniform (or ucb) over the plans from s
    q = select_configuration(s)             # parts.nodes: a node of T in state s (retry weight)
    found = follow_plan(q, plan)            # parts.step_curves: K curves per step, continue from a hit
    if not found and rng.random() < p:      # completeness: parts.expand_curves from a random node
        random_expand()

until a node passes the goal test (``parts.goal_test``: a goal state, or a goal state whose rope
passes the pull test) or the time runs out. The answer is the path of curves from the root of ``T``
to that node. Each decision is a part (:mod:`twisted.planner.parts`), the iteration itself
(``parts.iteration``) and which results enter ``T`` (``parts.growth``) included; :class:`Search`
keeps the tree, the plans, the statistics the parts read and the checkpoints. Where the parts differ
from the paper: DESIGN 8.

Baselines (``planner``) are parts too: ``twisted`` samples curves from the inverse model;
``random-low`` follows the same high-level plans with uniformly random curves (the paper's "low+high
level"); ``low-level-only`` (:class:`~twisted.planner.parts.LowLevelOnly`) applies random curves
to random nodes of ``T`` with no topological guidance beyond the goal test; ``sac`` follows the
high-level plans like ``twisted`` with a SAC+HER policy (``twisted rl train``) in place of the inverse
model, as in the paper's comparison. A search both ways (``twisted untie``) is the growth
:class:`~twisted.planner.parts.BothWays` with a high level that plans removing moves too.

The goal is a set of states (:class:`twisted.goals.Goal`): one P-data state, or every state that ties
a named knot.

Everything random goes through one ``numpy.random.Generator``; simulation results come back in
the order the curves were sampled (``SimPool`` preserves order), so a run replays from its seed
for any number of workers. The search is persisted through a :class:`SearchRecorder` at iteration
boundaries only: a checkpoint (iteration, elapsed time, RNG state, selection statistics) and the
tree nodes created up to that boundary are written in one transaction, so a resumed run continues
exactly where the checkpoint left it and never writes a node twice.

This module knows nothing of the store, the model registry, the simulator or the pull test: what a
search composes (its parts, a worker pool, the high level, a recorder) comes in through the
protocols below; :mod:`twisted.planner.runs` builds searches from the store.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from twisted.goals import Goal, state_goal
from twisted.planner.options import HEURISTICS, N_LINKS, OPTIONS_BEFORE, PLANNERS, PlannerOptions
from twisted.planner.parts import BlindCurves, CurveSampler, RandomCurves, SearchParts, default_parts
from twisted.planner.tree import CINCH, Node, SearchTree, curve_row, pair_key
from twisted.runtime import StopRequested, StopSignals
from twisted.topology import PData

__all__ = [
    "CALL_SOURCES",
    "HEURISTICS",
    "N_LINKS",
    "OPTIONS_BEFORE",
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
    "Search",
    "pair_key",
]

# Tables of the search's statistics (kept in every checkpoint): [times selected, summed reward] per
# state and per (state, plan) index; [steps tried, steps achieved] per move kind in follow_plan;
# [simulator calls, results kept in T] per source of curves (CALL_SOURCES); [tries, hits] per
# (node index, requested next state) pair of follow_plan (read by the retry weight); [steps tried,
# steps achieved] per state a follow_plan step started from (for analysis); [curves, curves
# that reached the plan's next state] per proposer of a Cross step's curves ("cross_move", "sampler")
STATS_TABLES = ("state", "plan", "move", "calls", "pair", "step", "cross")
CALL_SOURCES = ("follow_plan", "random_expand", "low_level_only", "cinch")


# --- what the search composes -------------------------------------------------------------------------


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
    """Persists nodes and checkpoints (implemented by :class:`twisted.store.search_tree.SearchRun`)."""

    def save(self, nodes: Sequence[Node], checkpoint: Checkpoint) -> None:
        """Write ``nodes`` (assigning ``db_id``) and ``checkpoint`` in one transaction."""
        ...

    def finish(self, status: str, goal_node: Node | None, checkpoint: Checkpoint) -> None:
        """Mark the run ``solved`` / ``timeout`` / ``interrupted`` / ``stopped``."""
        ...


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
    goal: Goal | None = None
    tighten: bool = False  # the goal test was the pull test
    pull_tests: int = 0
    setup_s: float = 0.0  # set-up before the search (twisted.planner.runs.run_search), in elapsed_s
    model: dict[str, Any] = field(default_factory=dict)  # the inverse model sampled (model_id, model_samples)

    @property
    def solved(self) -> bool:
        return self.status == "solved"

    def plan(self) -> list[dict[str, Any]]:
        """The low-level plan as rows: step number, action and curve, crossings and state after it."""
        return [
            {"step": i, **curve_row(node.curve), "cross": node.p_data.cross, "state": node.p_data.to_list()}
            for i, node in enumerate(self.path[1:], start=1)
        ]

    def to_dict(self) -> dict[str, Any]:
        """The result as JSON-ready data (what ``twisted plan --json`` prints)."""
        goal = self.goal
        return {
            "run_id": self.run_id,
            "goal": None if goal is None else goal.spec,
            "knot": None if goal is None else goal.knot,
            "goal_states": [] if goal is None else [p.to_list() for p in goal.states],
            "reached_state": self.path[-1].p_data.to_list() if self.path else None,
            "outcome": self.status,
            "solved": self.solved,
            "search_time_s": round(self.elapsed_s, 3),
            "setup_s": round(self.setup_s, 3),
            "sim_calls": self.sim_calls,
            "sim_calls_by_source": self.calls_by_source(),
            "plan_steps_by_move": {
                kind: {"tried": tried, "reached": reached}
                for kind, (tried, reached) in self.steps_by_move().items()
            },
            "iterations": self.iterations,
            "nodes": self.nodes,
            "states": self.states,
            "plan": self.plan(),
            "tighten": self.tighten,
            "pull_tests": self.pull_tests,
            **self.model,
        }

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


class Search:
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
        progress: Callable[[Search], None] | None = None,
        parts: SearchParts | None = None,
    ) -> None:
        """``parts``: what the search's decisions are (default: those ``options`` name, with ``sampler``
        proposing the curves; :func:`twisted.planner.parts.default_parts`)."""
        options.validate()
        if len(tree) == 0:
            raise ValueError("the tree needs its root (the initial configuration)")
        self.goal = goal if isinstance(goal, Goal) else state_goal(goal)
        self.tree = tree
        self.options = options
        self.pool = pool
        self.high_level = high_level
        self.parts = parts if parts is not None else default_parts(options, self.goal, sampler)
        self.sampler: CurveSampler = self.parts.step_curves.sampler
        self.random_curves: BlindCurves = self.parts.expand_curves
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

        if self.parts.cinch is not None:
            self.parts.cinch.restore(tree)
        # P: the high-level plans from every reached state (recomputed from the plan cache on resume)
        self.plans: dict[str, list[Any]] = {}
        self.goal_node: Node | None = None
        for p_data in tree.states.values():
            self._reached(p_data)
        # a resumed run: the first node in a goal state that passes the goal test (re-run, not recorded)
        reached = sorted(i for key in self.goal.keys for i in tree.by_state.get(key, ()))
        for index in reached:
            if self.parts.goal_test.accepts(tree.nodes[index], record=False):
                self.goal_node = tree.nodes[index]
                break

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
    def pull_tests(self) -> int:
        """Pull tests run by the goal test (0 without ``tighten``)."""
        return self.parts.goal_test.tests

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
                self.parts.iteration.iterate(self)
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
            goal=self.goal,
            tighten=self.options.tighten,
            pull_tests=self.pull_tests,
        )

    def _rollback(self, committed: int) -> None:
        """Back to the last iteration boundary, exactly what a resume from the store would load."""
        self.tree.truncate(committed)
        for key in [key for key in self.plans if key not in self.tree.states]:
            del self.plans[key]
        self.parts.forget(committed)
        self.rng.bit_generator.state = self._boundary.rng_state
        self.iteration = self._boundary.iteration
        self.sim_calls = self._boundary.sim_calls
        self.stats = {table: {k: list(v) for k, v in e.items()} for table, e in self._boundary.stats.items()}

    # -- SelectTopologicalState / SelectPlan / SelectConfiguration: the parts decide ---------------------

    def select_topological_state(self) -> str | None:
        """A reached state with a plan (``parts.states``); None when there is none."""
        candidates = self.candidate_states
        if not candidates:
            return None
        return self.parts.states.select(self, candidates, self.rng)

    def select_plan(self, s: str) -> tuple[int, Any]:
        """A high-level plan from ``s`` and its index (``parts.plans``)."""
        index = self.parts.plans.select(self, s, self.rng)
        return index, self.plans[s][index]

    def select_configuration(self, s: str, next_state: PData, move: Any = None) -> Node:
        """A node of ``T`` in state ``s`` to ask for ``next_state`` by ``move`` (``parts.nodes``)."""
        return self.parts.nodes.select(self, s, next_state, move, self.rng)

    def learn(self, s: str, plan_index: int, reward: float) -> None:
        """Record how far a followed plan got (the ucb heuristic learns from it; all keep it for analysis)."""
        self._count("state", s, 1, reward)
        self._count("plan", f"{s}|{plan_index}", 1, reward)

    def cinched(self, node: Node) -> Node:
        """The node a plan step starts from instead of ``node``: toward a composite knot, a loose node tying
        a summand is cinched first (``parts.cinch``, :class:`~twisted.planner.parts.SummandCinch`),
        and the cinched node takes its place when it is in the same state (else the step starts from
        ``node``). A loose node cinched before is never chosen again (``SummandCinch.candidates``)."""
        part = self.parts.cinch
        if part is None or not part.wants(self.tree, node):
            return node
        try:
            with self.stop.interruptible():
                result = part.cinch(node)
        except StopRequested:
            raise _Stop("interrupted") from None
        self.sim_calls += 1
        child = self.add_to_tree(node, CINCH, result, self.sim_calls)
        part.tried[node.index] = None if child is None else child.index
        self._count("calls", "cinch", 1, child is not None)
        return child if child is not None and child.p_data == node.p_data else node

    # -- FollowPlan / RandomExpand -------------------------------------------------------------------

    def follow_plan(self, node: Node, plan: Any) -> int:
        """Follow ``plan`` from ``node``; returns the number of plan steps achieved (goal: all)."""
        current = node
        for step, (next_state, move) in enumerate(zip(plan.states[1:], plan.moves, strict=True)):
            if step:
                self._check_stop(self._deadline_s)
            current = self.cinched(current)
            if self.goal_node is not None:
                return len(plan.moves)
            curves, scripted = self.step_curves(current, next_state, move)
            children = self.simulate(current, curves, "follow_plan")
            reached = [c is not None and c.p_data == next_state for c in children]
            hit = next((c for c, ok in zip(children, reached, strict=True) if ok), None)
            script = self.parts.step_curves.script
            if move is not None and move.kind == script.kind and not move.remove:  # each proposer's hits
                self._count("cross", script.name, scripted, sum(reached[:scripted]))
                self._count("cross", "sampler", len(curves) - scripted, sum(reached[scripted:]))
            self._count("move", f"{move.kind}^-1" if move.remove else str(move.kind), 1, hit is not None)
            self._count("pair", pair_key(current.index, next_state.key), 1, hit is not None)
            self._count("step", current.p_data.key, 1, hit is not None)
            if self.goal_node is not None:
                return len(plan.moves)
            if hit is None:
                return step
            current = hit
        return len(plan.moves)

    def step_curves(self, node: Node, next_state: PData, move: Any) -> tuple[list[Any], int]:
        """The K curves of a plan step and how many of them (the first) are scripted
        (``parts.step_curves``)."""
        return self.parts.step_curves.propose(node, next_state, move, self.options.k, self.rng)

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
        """Keep ``result`` when the growth part takes it (``parts.growth``; Algorithm 1: Cross does not
        drop and stays within the goal's)."""
        if not result.ok:
            return None
        p_data: PData = result.p_data
        if not self.parts.growth.keeps(parent.p_data, p_data):
            return None
        if not self.options.same_state and curve is not CINCH and p_data == parent.p_data:
            return None  # --no-same-state: only moves enter T (a cinch keeps its state by design)
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
        if self.goal_node is None and self.parts.goal_test.accepts(node):
            self.goal_node = node
        return node

    def _reached(self, p_data: PData) -> None:
        """A state reached for the first time: run the high level from it (through the plan cache) when
        the iteration follows plans and the growth wants them from there (``parts.growth``)."""
        if not self.parts.iteration.plans or not self.parts.growth.wants_plans(p_data):
            self.plans[p_data.key] = []
            return
        self.plans[p_data.key] = list(self.high_level(p_data))[: self.options.plan_limit]
