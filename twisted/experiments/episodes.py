"""Episodes: a plan made in the planner's model, executed in a world, observed and (closed loop) replanned.

docs/DESIGN.md section 15. Open loop sends the plan's curves to the world one after another and pulls the
rope at the end. Closed loop, after every action, reads the observation's P-data and compares it and its
points with the plan's next node; when the state is another, the points lie further than ``drift_m`` (RMS)
from the plan's, or the world reports a fault, it plans again in the planner's model from a configuration
fitted to the observed points (:class:`ModelPlanner`), and it pulls the rope as soon as the observed state
is one of the goal's. A rope seen in a dead end for the goal (no adding move leads from its state to a goal
state) is first pulled straight by both ends, and the replan starts from the straight rope. The episode
ends when the world's rope passes the pull test for the goal's knot, or when the budget (``timeout_s`` of
wall time, planning included, and ``max_actions``) is spent. A rope the world could not pull (its last
pull test has a reason instead of a knot) ends ``unpulled``.

The planner sees only observations: :class:`ModelPlanner.replan` takes link points, nothing of the world.
Every step is stored (:mod:`twisted.store.episodes`) with the world's checkpoint, so that an episode
stopped by Ctrl-C continues from its last stored observation (:func:`resume_state`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from twisted.goals import Goal, PlanInputError
from twisted.runtime import StopSignals
from twisted.topology import PData, PDataError, parse_p_data, top

if TYPE_CHECKING:
    from twisted.world.protocol import PullVerdict

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

# A plan made for a rope whose points lie more than this (RMS) from the observed ones is another rope's
# plan: the next curve's displacement still applies, but the inverse model chose it for other geometry.
# Three link spacings' worth of RMS is well outside the camera's noise at every level (<= 5 mm) and inside
# what one curve moves a rope (docs/DESIGN.md section 15.4).
DEFAULT_DRIFT_M = 0.05
DEFAULT_MAX_ACTIONS = 30
# A rope that keeps failing the pull test while it looks tied (the pull itself fails) is not pulled forever.
MAX_PULLS = 3
# What a replan says when the observed rope, fitted and at rest in the model, is already in the goal (the
# camera's noise can add a crossing to Top of the raw points that the rope at rest does not have): pull it.
FIT_IN_GOAL = "the fit is in the goal"
# What a replan says when its fit is pressed through a strand at every height stretch. When the observed
# rope cannot be made a configuration of the model (that, or points no chain fits: ``Replan.unfitted``),
# the episode looks again, up to MAX_LOOKS times in a row, before it ends ``lost`` (DESIGN 15.4).
FIT_REJECTED = "the model rejects the fit"
MAX_LOOKS = 3
# What the world's pull reads on a rope with no knot.
UNKNOT = "0_1"


@dataclass(frozen=True)
class PlanStep:
    """One node of a low-level plan: the action that leads to it (a curve as ``(link, z, x, y)``, None for
    a cinch), and the state, link points and configuration the model says it ends in."""

    curve: tuple[int, float, float, float] | None
    p_data: PData
    points: FloatArray
    q: FloatArray


@dataclass(frozen=True)
class Plan:
    """A solved planner run's plan: the root's configuration, then the steps (root excluded)."""

    run_id: int
    root_q: FloatArray
    steps: tuple[PlanStep, ...]


def plan_of_run(store: Any, run_id: int) -> Plan:
    """The plan of a solved planner run (PlanInputError when there is none)."""
    from twisted.store.search_tree import NoPlanError, solved_run

    try:
        _, path = solved_run(store, run_id)
    except NoPlanError as exc:
        raise PlanInputError(str(exc)) from None
    steps = tuple(
        PlanStep(None if node.action == "cinch" else node.curve, node.p_data, node.points, node.q)
        for node in path[1:]
    )
    return Plan(run_id, path[0].q, steps)


@dataclass
class Replan:
    """What one replan gave: its planner run (None when the observation could not be made a configuration
    of the model: ``reason``), the plan when solved, seconds, the fit's residual."""

    run_id: int | None
    plan: Plan | None
    planning_s: float
    fit_residual_m: float | None
    reason: str | None = None
    unfitted: bool = False  # the observation could not be made a configuration (the episode looks again)


class ModelPlanner:
    """Plans in the planner's model from observed link points (what the world shows, nothing else).

    Each search is the library's :func:`twisted.planner.run_search` (one :class:`SearchRequest`: the goal,
    the start, the options with the replan's seed); the simulator workers and the model are started once
    for all of them (:class:`twisted.planner.SearchResources`), until :meth:`close`."""

    def __init__(
        self,
        store: Any,
        goal: Goal,
        options: Any,
        model_id: int | None,
        workers: int = 1,
        episode_run_id: int | None = None,
        stop: StopSignals | None = None,
    ) -> None:
        from twisted.planner import SearchResources

        self.store, self.goal, self.options, self.model_id = store, goal, options, model_id
        self.workers, self.episode_run_id, self.stop = workers, episode_run_id, stop
        self._resources = SearchResources()
        self._fit: Any = None
        # a composite knot goal's first stage (None: the goal has none) and the summands that end it
        self.first_stage = first_summand_goal(goal)
        self.summands = goal.summands if self.first_stage is not None else frozenset()

    def close(self) -> None:
        self._resources.close()

    def ties_summand(self, p_data: PData | None) -> bool:
        """Whether a rope in ``p_data`` ties one of a staged goal's summands (both closures, whatever its
        crossings); False for a goal with no stages."""
        return _ties_any(self.summands, p_data)

    def goal_for(self, p_data: PData | None, staged: bool) -> Goal:
        """The goal a search from a rope in ``p_data`` aims at: with ``staged``, toward a composite knot,
        the first summand's goal while the rope ties none of the summands (:func:`first_summand_goal`),
        else the goal itself (the search cinches the summand tied: DESIGN 8)."""
        if not staged or self.first_stage is None or p_data is None or self.ties_summand(p_data):
            return self.goal
        return self.first_stage

    def search(
        self,
        start_configuration_id: int | None,
        seed: int,
        timeout_s: float,
        goal: Goal | None = None,
        cinched: bool = False,
    ) -> tuple[int, bool]:
        """One search of ``goal`` (None: the episode's) from a stored configuration (None: the straight
        rope); (run id, solved). ``cinched``: the rope it starts from was pulled tight in the world since it
        tied a summand, so the search cinches nothing (its plan would start with a second pull of a tight
        knot, which the world now and then cannot carry out: DESIGN 15.4)."""
        from twisted.planner import SearchRequest, run_search

        options = {**self.options.to_dict(), "seed": seed}
        if cinched:
            options["cinch"] = False
        request = SearchRequest(
            goal=(goal or self.goal).spec,
            options=options,
            start_config=start_configuration_id,
            model_id=self.model_id,
            workers=self.workers,
            timeout_s=timeout_s,
            parameters={"episode": self.episode_run_id},
            timed_setup=False,  # the replan's wall time (planning_s) counts it; a signal stops the search
        )
        result = run_search(self.store, request, self.stop, resources=self._resources)
        assert result.run_id is not None  # a started search has its run
        return int(result.run_id), bool(result.solved)

    def replan(
        self,
        points: FloatArray,
        seed: int,
        timeout_s: float,
        like: FloatArray | None = None,
        staged: bool = False,
        cinched: bool = False,
    ) -> Replan:
        """Fit the model's chain to observed ``points`` (near ``like``, the model's expectation of them,
        when given), let it rest in the model, store it as a configuration and search from there (for
        :meth:`goal_for` the fit at rest; ``cinched``: see :meth:`search`)."""
        from twisted.store.queries import add_configuration
        from twisted.world import ChainFit

        started = time.perf_counter()
        if self._fit is None:
            self._fit = ChainFit()
        try:
            fit, rest = self._fit.rest_configuration(points, like)
        except ValueError as exc:
            return Replan(None, None, time.perf_counter() - started, None, f"no fit: {exc}", unfitted=True)
        if rest is None:
            return Replan(
                None, None, time.perf_counter() - started, fit.residual_m, FIT_REJECTED, unfitted=True
            )
        q, fitted_points, p_data = rest
        if ties_goal(self.goal, p_data):
            # the fit ties the goal: nothing to plan (the episode pulls the rope)
            return Replan(None, None, time.perf_counter() - started, fit.residual_m, FIT_IN_GOAL)
        with self.store.session(write=True) as session:
            configuration = add_configuration(
                session, run_id=self.episode_run_id, p_data=p_data, q=q, points=fitted_points
            )
            configuration_id = int(configuration.id)
        remaining = max(timeout_s - (time.perf_counter() - started), 1.0)
        try:
            goal = self.goal_for(p_data, staged)
            run_id, solved = self.search(
                configuration_id, seed, remaining, goal, cinched and goal is self.goal
            )
        except PlanInputError as exc:
            return Replan(None, None, time.perf_counter() - started, fit.residual_m, str(exc))
        plan = plan_of_run(self.store, run_id) if solved else None
        return Replan(run_id, plan, time.perf_counter() - started, fit.residual_m)


@dataclass
class EpisodeSettings:
    closed_loop: bool
    timeout_s: float
    max_actions: int = DEFAULT_MAX_ACTIONS
    drift_m: float = DEFAULT_DRIFT_M
    # closed loop: a rope in a dead end for the goal is pulled straight before the replan (DESIGN 15.4)
    straighten: bool = True
    # closed loop, a composite knot goal: replans aim at the first summand until the rope ties one
    stages: bool = True


@dataclass
class EpisodeState:
    """Where an episode stands: what it last saw, the plan it follows and its counters."""

    points: FloatArray
    plan: Plan | None
    position: int  # index into plan.steps of the next action
    actions: int = 0
    replans: int = 0
    planning_s: float = 0.0
    elapsed_s: float = 0.0
    replan_runs: list[int] = field(default_factory=list)
    pulls: int = 0
    looks: int = 0  # observations taken again in a row because the last one could not be fitted
    fit_in_goal: bool = False  # the last replan found the observation's fit in the goal: pull next
    straightens: int = 0  # the rope pulled straight because it was in a dead end for the goal
    # False once a straightening pull read a knot (a staged goal: other than a summand), or could not be done
    may_straighten: bool = True
    # staged (a composite goal): the rope was pulled tight since it last tied no summand (DESIGN 15.4)
    cinched: bool = False
    # the last step pulled the rope straight: it is planned from as it lies, even if still in a dead end
    # (a rope pulled straight with a crossing left in it, a twist or an end lying across, is not pulled again)
    just_straightened: bool = False
    # the model's configuration of what the world's rope should now be (the last action's outcome in the
    # model); each observation is fitted near it (twisted.world.fit.ChainFit.fit). None: not known
    expected_q: FloatArray | None = None


@dataclass
class EpisodeResult:
    run_id: int
    outcome: str
    actions: int
    replans: int
    planning_s: float
    elapsed_s: float
    final_knot: str | None
    replan_runs: list[int]
    straightens: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {
            "episode": self.run_id,
            "outcome": self.outcome,
            "tied": self.outcome == "tied",
            "actions": self.actions,
            "replans": self.replans,
            "planning_s": round(self.planning_s, 3),
            "elapsed_s": round(self.elapsed_s, 3),
            "final_knot": self.final_knot,
            "replan_runs": self.replan_runs,
            "straightens": self.straightens,
        }


def _observed(points: FloatArray) -> PData | None:
    try:
        return top(points)
    except PDataError:
        return None


def ties_goal(goal: Goal, p_data: PData) -> bool:
    """Whether a rope in ``p_data`` is worth pulling for ``goal``: a goal state, or (a knot goal) a state
    whose both closures are a knot the goal names, whatever its crossings. Pulling such a rope by its ends
    cannot change what it ties (docs/DESIGN.md section 9.2), so the pull test decides there and then; in a
    world apart from the model a curve now and then overshoots the plan's next state into one with more
    crossings that still ties the knot (3 of 15 overhand episodes tied at ``moderate`` were pulled so)."""
    if p_data in goal:
        return True
    if goal.knot is None:
        return False
    from twisted.knots import identify

    return goal.tightened_ties(identify(p_data).name)


def first_summand_goal(goal: Goal) -> Goal | None:
    """The goal of a composite knot goal's first stage (docs/DESIGN.md section 15.4): the summand of
    fewest crossings, in every chirality the goal's types hold it (granny and square: the overhand, either
    chirality; granny+: 3_1+; 3_1#4_1: the overhand, either chirality). None for a prime knot or a state
    goal."""
    from twisted.goals import knot_goal
    from twisted.knots import crossing_number, resolve_knot

    types = goal.knot_types if goal.knot is not None else frozenset()
    if not types or not all("#" in t for t in types):
        return None
    firsts: set[str] = set()
    for t in types:
        parts = t.split("#")
        least = min(crossing_number(part) for part in parts)
        firsts.update(part for part in parts if crossing_number(part) == least)
    bases = {part.rstrip("+-") for part in firsts}
    if len(bases) == 1 and resolve_knot(next(iter(bases))) == firsts:
        name = bases.pop()
    elif len(firsts) == 1:
        name = firsts.pop()
    else:  # summands of different knots with no one name for them: no stages
        return None
    return knot_goal(name)


def summands_of(goal: Goal) -> frozenset[str]:
    """The summands of a goal tied in stages (:func:`first_summand_goal`); empty for any other goal."""
    return goal.summands if first_summand_goal(goal) is not None else frozenset()


def _ties_any(summands: frozenset[str], p_data: PData | None) -> bool:
    if not summands or p_data is None:
        return False
    from twisted.knots import identify

    return identify(p_data).name in summands


def _drift(points: FloatArray, step: PlanStep) -> float:
    from twisted.world import rms_distance

    return rms_distance(points, step.points)


class Episode:
    """Runs one episode of ``world`` toward ``goal``, storing every step (see the module's docstring)."""

    def __init__(
        self,
        store: Any,
        run_id: int,
        world: Any,
        goal: Goal,
        planner: ModelPlanner,
        settings: EpisodeSettings,
        stop: Callable[[], bool] = lambda: False,
        progress: Callable[[str], None] | None = None,
    ) -> None:
        self.store, self.run_id, self.world, self.goal = store, run_id, world, goal
        self.planner, self.settings, self.stop = planner, settings, stop
        self.progress = progress or (lambda line: None)
        self._clock = 0.0
        self._started = time.perf_counter()

    # ---- bookkeeping ----------------------------------------------------------------------------------

    def _elapsed(self, state: EpisodeState) -> float:
        return state.elapsed_s + (time.perf_counter() - self._started)

    def _record(self, state: EpisodeState, kind: str, **values: Any) -> None:
        from twisted.store.episodes import StepRecord, add_step

        elapsed = self._elapsed(state)
        if "plan_run_id" not in values and state.plan is not None:
            values.update(plan_run_id=state.plan.run_id, plan_step=state.position)
        step = StepRecord(kind=kind, elapsed_s=elapsed, **values)
        counters = {
            "actions": state.actions,
            "replans": state.replans,
            "planning_s": state.planning_s,
            "elapsed_s": elapsed,
        }
        add_step(self.store, self.run_id, step, counters)

    def _observation(self, points: FloatArray) -> dict[str, Any]:
        observed = _observed(points)
        return {"points": points, "observed_key": None if observed is None else observed.key}

    # ---- the episode ----------------------------------------------------------------------------------

    def begin(self, plan: Plan) -> EpisodeState:
        """Lay the world's rope out as the plan's root and observe it (the episode's first step)."""
        seen = self.world.reset(plan.root_q)
        state = EpisodeState(seen.points, plan, 0, expected_q=plan.root_q)
        self._record(
            state, "reset", **self._observation(seen.points), world_checkpoint=self.world.checkpoint()
        )
        return state

    def run(self, state: EpisodeState) -> EpisodeResult:
        """Act, observe and (closed loop) replan until tied, out of budget or stopped; stores the outcome."""
        from twisted.store.episodes import finish_episode

        self._started = time.perf_counter()
        outcome, knot = self._loop(state)
        finish_episode(self.store, self.run_id, outcome, knot, self._elapsed(state))
        elapsed = self._elapsed(state)
        return EpisodeResult(
            self.run_id,
            outcome,
            state.actions,
            state.replans,
            state.planning_s,
            elapsed,
            knot,
            state.replan_runs,
            state.straightens,
        )

    def _loop(self, state: EpisodeState) -> tuple[str, str | None]:
        s = self.settings
        knot: str | None = None
        while True:
            if self.stop():
                return "interrupted", knot
            remaining = s.timeout_s - self._elapsed(state)
            if remaining <= 0:
                return "out_of_budget", knot
            observed = _observed(state.points)
            plan_done = state.plan is None or state.position >= len(state.plan.steps)
            in_goal = state.fit_in_goal or (observed is not None and ties_goal(self.goal, observed))
            if in_goal if s.closed_loop else plan_done:
                state.fit_in_goal = False
                verdict = self._pull(state)
                state.pulls += 1
                knot = verdict.knot
                if self.goal.tightened_ties(knot):
                    return "tied", knot
                if not s.closed_loop or state.pulls >= MAX_PULLS:
                    # a pull the world could not carry out says nothing of the knot: not "not tied"
                    return ("unpulled" if knot is None and verdict.reason else "not_tied"), knot
                state.plan = None
                continue
            if plan_done or state.plan is None:
                if self._staged() and not state.cinched and self.planner.ties_summand(observed):
                    self._cinch(state)
                    continue
                if self._dead_end(state, observed):
                    straightened = self._straighten(state)
                    if self.goal.knot is not None and self.goal.tightened_ties(straightened):
                        return "tied", straightened  # the pull read the knot (a state goal needs the state)
                    continue
                replanned = self._replan(state, remaining)
                if replanned is not None:
                    return replanned, knot
                continue
            if state.actions >= s.max_actions:
                return "out_of_budget", knot
            self._act(state)

    def _pull(self, state: EpisodeState, kind: str = "pull_test") -> PullVerdict:
        """The world's pull by both ends, then the rope observed as the pull left it; both stored as a step
        of ``kind``: the goal's pull test, or a rope pulled straight (``straighten``)."""
        verdict = self.world.pull_test()
        seen = self.world.observe()
        state.points = seen.points
        self.progress(
            f"{kind.replace('_', ' ')}: {verdict.knot or verdict.reason}"
            + (f" ({verdict.note})" if verdict.note else "")
        )
        self._record(
            state,
            kind,
            **self._observation(seen.points),
            knot=verdict.knot,
            fault=verdict.reason or verdict.note,  # a note: how the knot was read (at less tension)
            world_checkpoint=self.world.checkpoint(),
        )
        return verdict

    def _staged(self) -> bool:
        """Whether this episode ties its goal in stages (closed loop, ``stages``, a composite knot)."""
        return self.settings.closed_loop and self.settings.stages and self.planner.first_stage is not None

    def _cinch(self, state: EpisodeState) -> None:
        """A staged goal's rope that ties a summand is pulled tight and let go (the world's cinch, as a
        plan's cinch step) before the replan for the whole knot starts from it (DESIGN 15.4)."""
        seen = self.world.cinch()
        state.actions += 1
        state.just_straightened = False
        state.points = seen.points
        state.expected_q = None  # a rope the model did not make: the fit takes the least bent roll
        observed = _observed(seen.points)
        state.cinched = self.planner.ties_summand(observed)
        self.progress(
            f"action {state.actions}: cinch the first summand -> {observed.key if observed else '?'}"
            + ("" if state.cinched else " (no summand left)")
        )
        self._record(
            state,
            "cinch",
            **self._observation(seen.points),
            fault=seen.fault,
            world_checkpoint=self.world.checkpoint(),
            plan_run_id=None,
            plan_step=None,
        )

    def _dead_end(self, state: EpisodeState, observed: PData | None) -> bool:
        """Whether the observed rope (``observed``: its P-data) has crossings from which adding crossings
        never reaches a state of the goal its replan would aim at (more than the goal's, or one no goal
        state has; :meth:`ModelPlanner.goal_for`), so that a replan would have to remove them in a rope the
        world has bent: then it is pulled straight first (closed loop, ``straighten``)."""
        from twisted.planner.both_ways import both_ways_needed

        wanted = self.settings.closed_loop and self.settings.straighten
        if not wanted or not state.may_straighten or state.just_straightened:
            return False
        if observed is None or observed.cross == 0:
            return False
        return both_ways_needed(observed, self.planner.goal_for(observed, self._staged()))

    def _straighten(self, state: EpisodeState) -> str | None:
        """Pull the world's rope straight by both ends (the pull test's act: DESIGN 15.4) and observe it;
        the knot the pull read (None: the world could not pull, and the rope is as it was)."""
        verdict = self._pull(state, "straighten")
        state.straightens += 1
        state.just_straightened = True
        if verdict.moved:  # pulled: the model made no rope like it; the fit takes the least bent roll
            state.expected_q = None  # (a rope the pull left as it lay keeps the expectation)
        # a rope that pulls to a knot stays knotted, and one the world cannot pull stays as it is; a staged
        # goal's rope that pulls to a summand is the rope its second stage starts from: pulled tight
        summand = self._staged() and verdict.knot in self.planner.summands
        state.may_straighten = verdict.knot == UNKNOT or summand
        state.cinched = summand
        return verdict.knot

    def _replan(self, state: EpisodeState, remaining_s: float) -> str | None:
        """Plan again from what was last seen; an outcome when the episode cannot go on, else None."""
        seed = int(getattr(self.planner.options, "seed", 0)) + state.replans + 1
        staged = self._staged()
        replanned = self.planner.replan(
            state.points, seed, remaining_s, state.expected_q, staged, cinched=staged and state.cinched
        )
        state.replans += 1
        state.planning_s += replanned.planning_s
        if replanned.run_id is not None:
            state.replan_runs.append(replanned.run_id)
        state.plan, state.position = replanned.plan, 0
        if replanned.plan is not None:
            state.expected_q = replanned.plan.root_q  # the fit at rest the plan starts from
        self.progress(
            f"replan {state.replans}: run {replanned.run_id}, "
            f"{'solved' if replanned.plan else replanned.reason or 'not solved'} "
            f"in {replanned.planning_s:.1f} s"
        )
        self._record(
            state,
            "replan",
            replan_run_id=replanned.run_id,
            planning_s=replanned.planning_s,
            fit_residual_m=replanned.fit_residual_m,
            fault=replanned.reason,
            plan_run_id=None if replanned.plan is None else replanned.plan.run_id,
            plan_step=0,
        )
        state.fit_in_goal = replanned.reason == FIT_IN_GOAL
        if replanned.run_id is None and not state.fit_in_goal:
            if not replanned.unfitted or state.looks >= MAX_LOOKS:
                return "lost"
            self._look_again(state)
            return None
        state.looks = 0
        return None

    def _look_again(self, state: EpisodeState) -> None:
        """Observe the rope again, no action: a camera frame the model cannot fit is not the rope's last
        word (the next one has other noise; docs/DESIGN.md section 15.4)."""
        seen = self.world.observe()
        state.looks += 1
        state.points = seen.points
        self.progress(f"look again ({state.looks} of {MAX_LOOKS}): the last observation could not be fitted")
        self._record(
            state, "observe", **self._observation(seen.points), world_checkpoint=self.world.checkpoint()
        )

    def _act(self, state: EpisodeState) -> None:
        from twisted.sim import Curve

        assert state.plan is not None
        step = state.plan.steps[state.position]
        seen = self.world.cinch() if step.curve is None else self.world.execute(Curve(*step.curve))
        state.actions += 1
        state.position += 1
        state.just_straightened = False
        state.expected_q = step.q
        state.points = seen.points
        drift = _drift(seen.points, step)
        observed = _observed(seen.points)
        tied = self.planner.ties_summand(observed)
        state.cinched = tied and (step.curve is None or state.cinched)
        off_plan = seen.fault is not None or observed != step.p_data or drift > self.settings.drift_m
        if off_plan and self.settings.closed_loop:
            state.plan = None
        self.progress(
            f"action {state.actions}: {'cinch' if step.curve is None else 'curve'} -> "
            f"{observed.key if observed else '?'} (plan {step.p_data.key}, drift {drift:.3f} m)"
            + (" off plan" if off_plan else "")
        )
        self._record(
            state,
            "curve" if step.curve is not None else "cinch",
            curve=step.curve,
            **self._observation(seen.points),
            expected_key=step.p_data.key,
            drift_m=drift,
            fault=seen.fault,
            world_checkpoint=self.world.checkpoint(),
            **({"plan_run_id": None, "plan_step": None} if state.plan is None else {}),
        )


def run_episode(
    store: Any,
    plan: Plan,
    goal: Goal,
    planner: ModelPlanner,
    level: Any,
    seed: int,
    settings: EpisodeSettings,
    progress: Callable[[str], None] | None = None,
) -> EpisodeResult:
    """A new episode: the world drawn at ``level`` from ``seed`` (:class:`twisted.world.SimWorld`), its row
    stored, the rope laid out as ``plan``'s root, then :meth:`Episode.run`."""
    from twisted.store.episodes import create_episode
    from twisted.world import SimWorld

    world = SimWorld(level, seed)
    parameters = {
        "drift_m": settings.drift_m,
        "straighten": settings.straighten,
        "stages": settings.stages,
        "same_state": planner.options.same_state,  # the plan's and the replans' search option (DESIGN 8)
        "workers": planner.workers,
        "level": level.to_dict(),
    }
    run_id = create_episode(
        store,
        parameters,
        plan_run_id=plan.run_id,
        goal_knot=goal.knot_label or goal.spec,
        level=level.name,
        level_ranges=level.to_dict(),
        world_seed=seed,
        physics=world.physics.to_dict(),
        closed_loop=settings.closed_loop,
        timeout_s=settings.timeout_s,
        max_actions=settings.max_actions,
    )
    planner.episode_run_id = run_id
    stop = planner.stop or (lambda: False)
    episode = Episode(store, run_id, world, goal, planner, settings, stop, progress)
    return episode.run(episode.begin(plan))


def _trailing_looks(steps: Sequence[Any]) -> int:
    """How many observations in a row the episode last took again: ``observe`` steps since the last step
    that was neither one nor a replan that could not fit (a replan with a planner run had its fit)."""
    looks = 0
    for step in reversed(steps):
        if step.kind == "observe":
            looks += 1
        elif step.kind != "replan" or step.replan_run_id is not None:
            break
    return looks


def _straightened_last(steps: Sequence[Any]) -> bool:
    """Whether the rope was pulled straight after the episode's last action (no action since)."""
    moved = [s.kind for s in steps if s.kind in ("curve", "cinch", "straighten")]
    return bool(moved) and moved[-1] == "straighten"


def summand_cinched(steps: Sequence[Any], summands: frozenset[str]) -> bool:
    """Whether a staged episode's rope was pulled tight (a cinch, or a pull that read a summand) since it
    last was seen tying no summand (:attr:`EpisodeState.cinched`)."""
    cinched = False
    for step in steps if summands else ():
        if step.observed_key is None:
            continue
        tied = _ties_any(summands, parse_p_data(step.observed_key))
        if step.kind == "cinch" or (step.kind == "straighten" and step.knot in summands):
            cinched = tied
        else:
            cinched = cinched and tied
    return cinched


def resume_state(
    store: Any, steps: Sequence[Any], goal: Goal | None = None
) -> tuple[EpisodeState, dict[str, Any]]:
    """Where a stopped episode stood after its last stored step, and the world's checkpoint to restore.

    The observation is the last one stored; the plan the last step named (None: the next thing is a
    replan); ``goal``, the episode's, tells whether its rope holds a cinched summand (a staged goal).
    Raises PlanInputError when the steps hold no observation with a world checkpoint."""
    seen = [s for s in steps if s.points is not None and s.world_checkpoint is not None]
    if not seen:
        raise PlanInputError("the episode stored no observation to resume from")
    last_seen = seen[-1]
    last = steps[-1]
    summands = frozenset() if goal is None else summands_of(goal)
    plan = None
    position = 0
    if last.plan_run_id is not None:
        plan = plan_of_run(store, int(last.plan_run_id))
        position = int(last.plan_step or 0)
        if not 0 <= position <= len(plan.steps):
            raise PlanInputError(
                f"the episode's last step names step {position} of a plan of {len(plan.steps)}"
            )
    state = EpisodeState(
        points=last_seen.points,
        plan=plan,
        position=position,
        actions=sum(1 for s in steps if s.kind in ("curve", "cinch")),
        replans=sum(1 for s in steps if s.kind == "replan"),
        planning_s=float(sum(s.planning_s or 0.0 for s in steps)),
        elapsed_s=float(last.elapsed_s),
        replan_runs=[int(s.replan_run_id) for s in steps if s.replan_run_id is not None],
        pulls=sum(1 for s in steps if s.kind == "pull_test"),
        straightens=sum(1 for s in steps if s.kind == "straighten"),
        may_straighten=all(s.knot == UNKNOT or s.knot in summands for s in steps if s.kind == "straighten"),
        cinched=summand_cinched(steps, summands),
        just_straightened=_straightened_last(steps),
        fit_in_goal=last.kind == "replan" and last.fault == FIT_IN_GOAL,
        looks=_trailing_looks(steps),
    )
    if plan is not None:  # the model's expectation of the rope: the node the plan last reached
        state.expected_q = plan.steps[position - 1].q if position else plan.root_q
    return state, dict(last_seen.world_checkpoint)
