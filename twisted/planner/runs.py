"""Searches from the store: start a run, resume one, choose between the two, replay a solved one.

:mod:`twisted.planner.search` is Algorithm 1 on its own; this module composes it with the store (the
run's tree and checkpoints, the plan cache as the high level), the straight rope or a stored start
configuration, and the curve sampler of a planner kind (:func:`curve_sampler`, which knows the model
registry and the SAC policies). :func:`choose_run` is the decision ``twisted plan`` makes between a
new run and a resumed one, with the checks that come with it. Every refusal raises
:class:`twisted.goals.PlanInputError` with a message that says which input is wrong.

Each search logs (``logging``, logger ``twisted.planner.runs``) its start, each checkpoint
(DEBUG) and how it ended.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from twisted.goals import Goal, PlanInputError, state_goal
from twisted.planner.parts import PullTest, SearchParts, default_parts
from twisted.planner.search import (
    Checkpoint,
    CurveSampler,
    Node,
    PlannerOptions,
    Pool,
    Search,
    SearchResult,
    SearchTree,
)
from twisted.planner.tree import CINCH
from twisted.runtime import StopRequested, StopSignals
from twisted.topology import PData

__all__ = [
    "ReplayResult",
    "ReplayStep",
    "RunChoice",
    "SearchProgress",
    "SearchRequest",
    "SearchResources",
    "SetupStopped",
    "check_request",
    "choose_run",
    "curve_sampler",
    "high_level",
    "model_info",
    "not_finite",
    "planner_options",
    "replay",
    "resume_search",
    "run_search",
    "search_parts",
    "start_search",
    "stored_options",
    "straight_rope",
    "tree_from_rows",
]

log = logging.getLogger(__name__)


def curve_sampler(
    store: Any, planner: str, model_id: int | None = None, torch_threads: int = 1
) -> tuple[CurveSampler | None, int | None]:
    """The curve sampler of a planner kind and the id of the model it uses (None: random curves).

    ``twisted`` samples the inverse model (``model_id``; default the newest in the store, else the shipped
    one); ``sac`` a trained SAC+HER policy (``twisted rl train``); the baselines need none. Raises
    :class:`PlanInputError` when the model is missing. ``torch_threads``: the simulator workers own the
    cores, and a second torch thread on a busy machine only slows sampling.
    """
    if planner not in ("twisted", "sac"):
        return None, None
    import torch

    torch.set_num_threads(torch_threads)
    if planner == "sac":
        try:
            from twisted.rl import load_policy_sampler
        except ImportError as exc:
            message = f"--planner sac needs the rl extra (pip install 'twisted-knots[rl]'): {exc}"
            raise PlanInputError(message) from None
        try:
            return load_policy_sampler(store, model_id)
        except LookupError as exc:
            raise PlanInputError(f"{exc} (train one with `twisted rl train`)") from None
    from twisted.model.registry import ModelError, load_model

    try:
        model = load_model(store, model_id)
    except ModelError as exc:
        raise PlanInputError(f"{exc} (or use --planner random-low, which needs no model)") from None
    broken = not_finite(model)
    if broken:
        which = "the shipped model" if model.model_id is None else f"model {model.model_id}"
        hint = "" if model_id is not None else " (the newest in the database)"
        raise PlanInputError(
            f"{which}{hint} cannot plan: {broken}; train a new one, or choose another with --model ID "
            "(see `twisted models`)"
        )
    from twisted.model.sampler import ModelCurves

    return ModelCurves(model), model.model_id


def not_finite(model: Any) -> str | None:
    """What makes an inverse model unable to plan (NaN or infinite weights or stored losses, a forward
    pass that is not finite: :meth:`InverseModel.unusable`), in words; None when it can."""
    return model.unusable()  # type: ignore[no-any-return]


def high_level(store: Any, goal: Goal, limit: int, both_ways: bool = False) -> Callable[[PData], list[Any]]:
    """``s -> plans(s, goal)``, shortest first, through the store's plan cache.

    For a goal of several states (a knot) the plans lead to any member (one BFS over all of them).
    ``both_ways``: plans with removing moves too (:func:`twisted.moves.plans_both_ways`).
    """
    from twisted.store.plans import cached_plans

    target = _plan_target(goal)

    def plans_from(start: PData) -> list[Any]:
        return list(cached_plans(store, start, target, limit, both_ways=both_ways))

    return plans_from


def _plan_target(goal: Goal) -> Goal | PData:
    """What the plan cache is asked for: the one state of a one-state goal, else the goal."""
    return goal.states[0] if len(goal.states) == 1 else goal


def straight_rope() -> tuple[np.ndarray, np.ndarray, PData]:
    """The default initial configuration: ``RopeSim.reset()`` (q, link points, Top(q))."""
    from twisted.sim import RopeSim

    sim = RopeSim()
    sim.reset()
    return sim.state(), sim.link_points(), sim.p_data()


def _root(q: np.ndarray, points: np.ndarray, p_data: PData) -> Node:
    return Node(index=0, parent=None, q=q, points=points, p_data=p_data, curve=None, iteration=0, sim_call=0)


def stored_options(parameters: Mapping[str, Any], run_id: int | None = None) -> PlannerOptions:
    """The options a run stored (:meth:`PlannerOptions.from_dict`), each checked by its declaration as
    the command line's value is (StoredValueError naming the field, :mod:`twisted.store.boundary`), with
    what a both-ways search stored (:data:`twisted.planner.both_ways.STORED`); PlanInputError when it used
    an option that was removed, so that it cannot be continued with other behaviour."""
    from twisted.planner.both_ways import STORED
    from twisted.planner.options import specs
    from twisted.store.boundary import check_declared

    row = "?" if run_id is None else run_id
    check_declared(parameters, (*specs(), *STORED), "runs", row, "parameters")
    try:
        return PlannerOptions.from_dict(parameters)
    except ValueError as exc:
        run = "the run" if run_id is None else f"run {run_id}"
        raise PlanInputError(f"{run} cannot be continued: {exc}; start a new run") from None


def search_parts(
    options: PlannerOptions,
    goal: Goal,
    sampler: CurveSampler | None,
    recorder: Any,
    parameters: Mapping[str, Any] | None = None,
    start: PData | None = None,
) -> SearchParts:
    """The parts of a search (:func:`twisted.planner.parts.default_parts`); with ``tighten`` the goal
    test is the pull test, each one stored with the run through ``recorder``; a run whose ``parameters``
    ask for it searches both ways from ``start`` (:func:`twisted.planner.both_ways.both_ways_parts`)."""
    from twisted.planner.both_ways import both_ways_parts

    goal_test = None
    if options.tighten:

        def record(node: Node, result: Any, ties: bool) -> None:
            recorder.record_tightening(node, result, goal, ties)

        goal_test = PullTest(goal, record)
    variant = both_ways_parts(parameters, goal, start) if parameters is not None and start is not None else {}
    return default_parts(options, goal, sampler, goal_test, **variant)


def planner_options(
    given: Mapping[str, Any], stored: Mapping[str, Any] | None = None, run_id: int | None = None
) -> PlannerOptions:
    """The options of a search from those asked for (a value of None: not given, the default).

    For a resumed run ``stored`` (run ``run_id``'s ``runs.parameters``) holds, and every option given must
    agree with it. Raises :class:`PlanInputError` naming the options that clash or are out of range.
    """
    asked = {name: value for name, value in given.items() if value is not None}
    if stored is not None:
        kept = stored_options(stored, run_id).to_dict()
        clash = [f"--{n.replace('_', '-')} {v} (run has {kept[n]})" for n, v in asked.items() if kept[n] != v]
        if clash:
            message = f"a resumed run keeps its own search options; drop or fix: {', '.join(clash)}"
            raise PlanInputError(message)
        return PlannerOptions.from_dict(kept)
    options = PlannerOptions(**asked)
    try:
        options.validate()
    except ValueError as exc:
        raise PlanInputError(str(exc)) from None
    return options


@dataclass(frozen=True)
class RunChoice:
    """What a plan command searches: the run to continue (``run_id``; None: a new run), with which
    options and which model (None: the default one)."""

    run_id: int | None
    options: PlannerOptions
    model_id: int | None


def check_request(
    given: Mapping[str, Any], *, resume: bool, start_config: int | None = None
) -> PlannerOptions | None:
    """What can be checked of a plan request without the store (PlanInputError when it is wrong): a
    new run's options (returned), or that a resumed run keeps its own start (None)."""
    if resume:
        if start_config is not None:
            raise PlanInputError("--start-config cannot change the start of a resumed run")
        return None
    return planner_options(given)


def choose_run(
    store: Any,
    goal: Goal | None,
    given: Mapping[str, Any],
    *,
    resume: bool,
    run_id: int | None = None,
    model_id: int | None = None,
    start_config: int | None = None,
) -> RunChoice:
    """A new run or one to continue, and its options and model.

    Without ``resume``: a new run with the options ``given`` (see :func:`planner_options`) and
    ``model_id``. With ``resume``: run ``run_id``, by default the newest unfinished one (for ``goal``
    when given); it must be a planner run for the same goal, neither solved nor still searched by a
    live process, and it keeps its own options, start and model (those given must agree). Raises
    :class:`PlanInputError` when the run cannot be continued.
    """
    options = check_request(given, resume=resume, start_config=start_config)
    if options is not None:
        return RunChoice(None, options, model_id)
    from twisted.store.search_tree import find_resumable_run, load_run

    if run_id is None:
        run_id = find_resumable_run(store, goal)
    if run_id is None:
        raise PlanInputError(
            "--resume: no unfinished planner run" + (f" for goal {goal.spec}" if goal is not None else "")
        )
    info = load_run(store, run_id, with_nodes=False)
    if info is None:
        raise PlanInputError(f"--resume {run_id}: there is no planner run {run_id} in this database")
    if goal is not None and info.goal.spec != goal.spec:
        raise PlanInputError(f"--resume {run_id}: that run's goal is {info.goal.spec}, not {goal.spec}")
    if info.outcome == "solved":
        raise PlanInputError(
            f"--resume {run_id}: run {run_id} already solved its goal (see `twisted replay {run_id}`)"
        )
    if info.holder is not None:
        raise PlanInputError(
            f"--resume {run_id}: run {run_id} is still being searched by {info.holder}; stop it first"
        )
    parameters = info.parameters
    if model_id is not None and parameters.get("model_id") not in (None, model_id):
        used = parameters.get("model_id")
        raise PlanInputError(f"--model {model_id}: run {run_id} was searched with model {used}")
    options = planner_options(given, stored=parameters, run_id=run_id)
    return RunChoice(run_id, options, parameters.get("model_id", model_id))


class _Logged:
    """A :class:`~twisted.planner.search.SearchRecorder` that logs each checkpoint and how the search
    ended, after the store has them."""

    def __init__(self, recorder: Any) -> None:
        self.recorder = recorder
        self.run_id: int = recorder.run_id

    def save(self, nodes: Sequence[Node], checkpoint: Checkpoint) -> None:
        self.recorder.save(nodes, checkpoint)
        log.debug(
            "run %d: checkpoint at iteration %d, %.1f s searched, %d simulator calls, %d new nodes",
            self.run_id, checkpoint.iteration, checkpoint.elapsed_s, checkpoint.sim_calls, len(nodes),
        )

    def finish(self, status: str, goal_node: Node | None, checkpoint: Checkpoint) -> None:
        self.recorder.finish(status, goal_node, checkpoint)
        if goal_node is not None:
            ended = f"reached the goal (state {goal_node.p_data.key}, node {goal_node.index})"
        else:
            ended = _ENDED.get(status, status)
        log.info(
            "run %d %s after %.1f s of search: %d simulator calls, %d iterations",
            self.run_id, ended, checkpoint.elapsed_s, checkpoint.sim_calls, checkpoint.iteration,
        )

    def record_tightening(self, node: Node, result: Any, goal: Goal, ties_goal: bool) -> None:
        self.recorder.record_tightening(node, result, goal, ties_goal)


_ENDED = {
    "timeout": "ran out of time",
    "interrupted": "was interrupted (checkpoint saved)",
    "stopped": "stopped at its iteration limit",
}


def _log_start(what: str, run_id: int, goal: Goal, options: PlannerOptions, model_id: Any) -> None:
    log.info(
        "run %d: %s for goal %s: planner %s, heuristic %s, model %s, seed %d, k %d, p_expand %g%s",
        run_id, what, goal.spec, options.planner, options.heuristic,
        _model_name(options.planner, model_id), options.seed, options.k, options.p_expand,
        ", with pull test" if options.tighten else "",
    )


def _model_name(planner: str, model_id: Any) -> str:
    if model_id is not None:
        return str(model_id)
    return "shipped" if planner == "twisted" else "none"


def start_search(
    store: Any,
    goal: Goal | PData,
    options: PlannerOptions,
    pool: Pool,
    sampler: CurveSampler | None = None,
    start_configuration_id: int | None = None,
    stop: StopSignals | None = None,
    progress: Callable[[Search], None] | None = None,
    extra_parameters: dict[str, Any] | None = None,
    from_run: int | None = None,
    removal_curves: str | None = None,
) -> Search:
    """A new run (``runs.kind = 'plan'``) for ``goal`` from the straight rope, a stored configuration
    or the end configuration of stored run ``from_run``.

    ``extra_parameters`` are stored with the options in ``runs.parameters`` (e.g. the model id). The
    search also removes crossings (:mod:`twisted.planner.both_ways`, its removing steps' curves from
    ``removal_curves``) when it starts from a run's end (``twisted untie``, ``plan --from-run``) or
    when adding moves alone cannot reach the goal from the start.
    """
    from twisted.planner.both_ways import (
        DEFAULT_REMOVAL_CURVES,
        accepted_configuration,
        both_ways_needed,
        run_end,
    )
    from twisted.store.search_tree import SearchRun

    options.validate()
    goal = goal if isinstance(goal, Goal) else state_goal(goal)
    if from_run is not None:
        from twisted.topology import top

        end = run_end(store, from_run)
        root = _root(end.q, end.points, top(end.points))
    elif start_configuration_id is None:
        root = _root(*straight_rope())
    else:
        from sqlalchemy.exc import NoResultFound

        from twisted.store.queries import load_configuration
        from twisted.topology import top

        with store.session() as session:
            try:
                config = load_configuration(session, start_configuration_id)
            except NoResultFound:
                message = f"configuration {start_configuration_id} is not in this database"
                raise PlanInputError(message) from None
            q, points = config.q_array(), config.points_array()
        accepted_configuration(q, points, "configurations", start_configuration_id)
        root = _root(q, points, top(points))
    if root.p_data in goal:
        raise PlanInputError(f"the initial configuration is already in the goal state {root.p_data.key}")
    tree = SearchTree()
    tree.add(root)
    rng = np.random.default_rng(options.seed)
    first = Checkpoint(0, 0.0, 0, dict(rng.bit_generator.state), {"state": {}, "plan": {}})
    parameters = {**options.to_dict(), **(extra_parameters or {})}
    both_ways = from_run is not None or both_ways_needed(root.p_data, goal)
    if both_ways:
        removal_curves = removal_curves or DEFAULT_REMOVAL_CURVES
        parameters.update(both_ways=True, removal_curves=removal_curves, from_run=from_run)
    recorder = _Logged(SearchRun.create(store, goal, parameters, root, first, start_configuration_id))
    start = "straight rope" if start_configuration_id is None else f"configuration {start_configuration_id}"
    start = start if from_run is None else f"end of run {from_run}"
    _log_start(f"new search from the {start}", recorder.run_id, goal, options, parameters.get("model_id"))
    return Search(
        goal,
        tree,
        options,
        pool,
        high_level(store, goal, options.plan_limit, both_ways),
        parts=search_parts(options, goal, sampler, recorder, parameters, root.p_data),
        recorder=recorder,
        run_id=recorder.run_id,
        stop=stop,
        progress=progress,
    )


def tree_from_rows(rows: Sequence[Any]) -> SearchTree:
    """Rebuild ``T`` from stored nodes (``twisted.store.search_tree.StoredNode``, in ``seq`` order)."""
    from twisted.sim import Curve

    tree = SearchTree()
    for row in rows:
        curve: Any = None if row.curve is None else Curve(*row.curve)
        if getattr(row, "action", "curve") == "cinch":
            curve = CINCH
        node = Node(
            index=row.seq,
            parent=row.parent_seq,
            q=row.q,
            points=row.points,
            p_data=row.p_data,
            curve=curve,
            iteration=row.iteration,
            sim_call=row.sim_call,
            created_s=row.created_s,
            db_id=row.id,
        )
        tree.add(node)
    return tree


def resume_search(
    store: Any,
    run_id: int,
    pool: Pool,
    sampler: CurveSampler | None = None,
    stop: StopSignals | None = None,
    progress: Callable[[Search], None] | None = None,
) -> Search:
    """Continue a stopped run from its checkpoint: same run id, tree reloaded, elapsed time carried over."""
    from twisted.store.plans import check_cached_plans
    from twisted.store.search_tree import (
        RunBusyError,
        SearchRun,
        discard_after_checkpoint,
        load_run,
        take_lease,
    )

    # the whole run is read and checked (parameters, checkpoint, every node) before the lease: a run
    # the boundary refuses stays exactly as it is stored
    info = load_run(store, run_id)
    if info is None:
        raise PlanInputError(f"run {run_id} is not a planner run in this database")
    if info.checkpoint is None:
        raise PlanInputError(f"run {run_id} has no checkpoint to resume from")
    options = stored_options(info.parameters, run_id)  # before the lease: a refused run stays as it is
    check_cached_plans(store, run_id, _plan_target(info.goal), bool(info.parameters.get("both_ways")))
    try:
        take_lease(store, run_id)  # from here on this process is the run's one writer
    except (LookupError, RunBusyError) as exc:
        raise PlanInputError(str(exc)) from None
    discard_after_checkpoint(store, run_id)  # only after a write outside SearchRun; normally none
    info = load_run(store, run_id)
    assert info is not None and info.checkpoint is not None
    tree = tree_from_rows(info.nodes)
    checkpoint = Checkpoint(
        iteration=info.checkpoint.iteration,
        elapsed_s=info.checkpoint.elapsed_s,
        sim_calls=info.checkpoint.sim_calls,
        rng_state=info.checkpoint.rng_state,
        stats=info.checkpoint.stats,
    )
    node_ids = {node.index: node.db_id for node in tree.nodes if node.db_id is not None}
    recorder = _Logged(SearchRun(store, run_id, node_ids))
    resumed = f"resumed at iteration {checkpoint.iteration} ({checkpoint.elapsed_s:.1f} s searched)"
    _log_start(resumed, run_id, info.goal, options, info.parameters.get("model_id"))
    both_ways = bool(info.parameters.get("both_ways"))
    return Search(
        info.goal,
        tree,
        options,
        pool,
        high_level(store, info.goal, options.plan_limit, both_ways),
        parts=search_parts(options, info.goal, sampler, recorder, info.parameters, tree.nodes[0].p_data),
        recorder=recorder,
        checkpoint=checkpoint,
        run_id=run_id,
        stop=stop,
        progress=progress,
    )


@dataclass
class ReplayStep:
    curve: Any
    recorded: PData
    replayed: PData | None  # None: the simulator rejected the result
    reason: str | None = None

    @property
    def matches(self) -> bool:
        return self.replayed == self.recorded


@dataclass
class ReplayResult:
    run_id: int
    goal: Goal
    steps: list[ReplayStep]
    # with tighten=True: the pull test of the replayed final rope (None when it was not run)
    tightened: Any = None
    tighten: bool = False  # the pull test was asked for

    def to_dict(self) -> dict[str, Any]:
        """The replay as JSON-ready data (what ``twisted replay --json`` prints)."""
        from twisted.planner.tree import curve_row

        steps = [
            {
                **curve_row(step.curve),
                "recorded": step.recorded.to_list(),
                "replayed": None if step.replayed is None else step.replayed.to_list(),
                "reason": step.reason,
            }
            for step in self.steps
        ]
        out: dict[str, Any] = {"run_id": self.run_id, "goal": self.goal.spec}
        out.update(reached_goal=self.reached_goal, steps=steps)
        if self.tighten:
            out["goal_knot_types"] = sorted(self.goal.knot_types)
            out["tightened"] = None if self.tightened is None else self.tightened.to_dict()
            out["ties_goal"] = self.ties_goal
        return out

    @property
    def reached_goal(self) -> bool:
        return bool(self.steps) and self.steps[-1].replayed in self.goal

    @property
    def ties_goal(self) -> bool:
        """The replayed rope reached the goal and, pulled tight, ties the goal's knot."""
        t = self.tightened
        return self.reached_goal and t is not None and t.ok and self.goal.tightened_ties(t.knot_name)


def replay(store: Any, run_id: int, friction_scale: float = 1.0, tighten: bool = False) -> ReplayResult:
    """Re-simulate a solved run's plan from its initial configuration, in this process.

    ``tighten``: then pull the final rope tight (:mod:`twisted.tighten`) and store the pull test with
    the run (table ``tightenings``).
    """
    from twisted.planner.both_ways import accepted_configuration
    from twisted.sim import Curve, RopeSim
    from twisted.sim.pool import simulate
    from twisted.store.search_tree import NoPlanError, solved_run

    try:
        info, path = solved_run(store, run_id)
    except NoPlanError as exc:
        raise PlanInputError(f"{exc}: nothing to replay") from None
    from twisted.tighten import cinch, tightening_sim

    # a path with a cinch needs the second gripper; the states are the same vectors either way
    cinched = any(node.action == "cinch" for node in path)
    sim = tightening_sim(friction_scale) if cinched else RopeSim(friction_scale)
    start = path[0]
    accepted_configuration(start.q, start.points, "search_nodes", start.id)  # the simulator takes it
    state = start.q
    steps = []
    final_p_data = None
    for node in path[1:]:
        if node.action == "cinch":
            pulled = cinch(sim, state)
            steps.append(ReplayStep(CINCH, node.p_data, pulled.p_data, pulled.reason))
            if pulled.state is None:
                break
            state, final_p_data = pulled.state, pulled.p_data
            continue
        assert node.curve is not None
        curve = Curve(*node.curve)
        result = simulate(sim, state, curve)
        steps.append(ReplayStep(curve, node.p_data, result.p_data if result.ok else None, result.reason))
        if result.state is None:
            break
        state, final_p_data = result.state, result.p_data
    out = ReplayResult(run_id, info.goal, steps, tighten=tighten)
    if tighten and final_p_data is not None:
        from twisted.store.knots import record_tightening
        from twisted.tighten import tighten as pull
        from twisted.tighten import tightening_sim

        out.tightened = pull(tightening_sim(friction_scale), state)
        goal = info.goal
        with store.session(write=True) as session:
            record_tightening(
                session, out.tightened, final_p_data, run_id=run_id, node_seq=path[-1].seq,
                goal_knot=goal.knot_label,
                ties_goal=out.ties_goal,
            )
    return out


# --- one call runs a search ----------------------------------------------------------------------------


@dataclass(frozen=True)
class SearchRequest:
    """What one search is asked for, as given (nothing checked, nothing opened): the goal (``goal``: P-data
    JSON or a ``knot:`` spec; or ``knot`` with ``crossings``), a new run's start (the straight rope,
    ``start_config`` or where solved run ``from_run`` ended) or the run to continue (``resume``, ``run_id``;
    None: the newest unfinished one), the planner options given (``options``: name -> value, None: the
    default), the model, the workers and the budget. ``parameters`` are stored with a new run beside its
    options and model id (an evaluation's id, an improve generation's tags). ``timed_setup``: the set-up
    counts toward ``timeout_s`` and stops at a stop signal (``twisted plan``); False: the search time
    alone is timed (an evaluation's and improve's results measure the search)."""

    goal: str | None = None
    knot: str | None = None
    crossings: int | None = None
    options: Mapping[str, Any] = field(default_factory=dict)
    resume: bool = False
    run_id: int | None = None
    start_config: int | None = None
    from_run: int | None = None
    removal_curves: str | None = None
    model_id: int | None = None
    workers: int = 2
    friction_scale: float = 1.0
    timeout_s: float | None = None
    max_iterations: int | None = None
    checkpoint_every_s: float = 2.0
    parameters: Mapping[str, Any] = field(default_factory=dict)
    timed_setup: bool = True

    def check(self) -> None:
        """Raise :class:`PlanInputError` on what is wrong without the store (the goal itself is checked by
        :func:`run_search`: a knot's states can take a minute to enumerate)."""
        from twisted.planner.both_ways import check_start

        if self.run_id is not None and not self.resume:
            hint = f"`twisted plan --resume {self.run_id}`"
            raise PlanInputError(f"a run id is only taken with --resume: {hint}")
        if self.goal is None and self.knot is None and self.crossings is None and not self.resume:
            raise PlanInputError(
                'a goal is required: --goal P-DATA (e.g. \'[[1,"O",2,"+"],[2,"U",1,"+"]]\') or --knot '
                "NAME (e.g. overhand); or continue a stopped run with --resume [RUN_ID]"
            )
        check_request(self.options, resume=self.resume, start_config=self.start_config)
        check_start(self.resume, self.start_config, self.from_run, self.removal_curves)

    def needs_stored(self) -> str | None:
        """The input that names something stored (a run, a model, a configuration), if any: a database
        that does not exist yet is then refused instead of created."""
        if self.resume:
            return "--resume" + ("" if self.run_id is None else f" {self.run_id}")
        for flag, value in (
            ("--model", self.model_id),
            ("--start-config", self.start_config),
            ("--from-run", self.from_run),
        ):
            if value is not None:
                return f"{flag} {value}"
        return None


class SearchProgress:
    """What :func:`run_search` reports as it goes (override what you show); here nothing is shown and the
    search is kept as ``search`` (a bench reads its tree)."""

    search: Search | None = None

    def phase(self, what: str, spent_s: float) -> None:
        """A step of the set-up begins (``what``: "checking the goal", "loading the model", ...)."""

    def started(self, search: Search) -> None:
        """The search is built (its run id known), about to run."""
        self.search = search

    def iteration(self, search: Search) -> None:
        """An iteration ended."""


class SetupStopped(Exception):
    """A stop signal or the deadline ended the set-up: nothing was searched (a resumed run is unchanged)."""

    def __init__(self, phase: str, spent_s: float, timed_out: bool) -> None:
        super().__init__(f"stopped during the set-up ({phase}, after {spent_s:.1f} s)")
        self.phase, self.spent_s, self.timed_out = phase, spent_s, timed_out


class SearchResources:
    """What :func:`run_search` starts for a search (the simulator workers, the curve sampler with its
    model), kept open for the next search of a caller that runs many in a row (the world's replans,
    :mod:`twisted.experiments.episodes`): given to ``run_search(..., resources=)``, they are made on first
    use and reused while the workers and the friction, resp. the planner kind and model asked for, are the
    same. ``close()`` (or the end of a ``with`` block) stops the workers."""

    def __init__(self) -> None:
        import contextlib

        self._stack = contextlib.ExitStack()
        self._pools: dict[tuple[int, float], Pool] = {}
        self._samplers: dict[tuple[str, int | None], tuple[CurveSampler | None, int | None]] = {}

    def pool(self, workers: int, friction_scale: float) -> Pool:
        """``workers`` simulator workers of the rope at ``friction_scale``, started once."""
        from twisted.sim.pool import SimPool

        key = (workers, friction_scale)
        if key not in self._pools:
            self._pools[key] = self._stack.enter_context(SimPool(workers, friction_scale))
        return self._pools[key]

    def sampler(
        self, store: Any, planner: str, model_id: int | None
    ) -> tuple[CurveSampler | None, int | None]:
        """:func:`curve_sampler` of ``planner`` and ``model_id``, loaded once."""
        key = (planner, model_id)
        if key not in self._samplers:
            self._samplers[key] = curve_sampler(store, planner, model_id)
        return self._samplers[key]

    def close(self) -> None:
        self._stack.close()
        self._pools.clear()
        self._samplers.clear()

    def __enter__(self) -> SearchResources:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


StoreOpener = Callable[..., Any]


def model_info(sampler: Any) -> dict[str, Any]:
    """The inverse model a search samples from (``model_id`` None: the shipped default) and its training
    samples per source; nothing for a planner without one."""
    model = getattr(sampler, "model", None)
    if model is None or not hasattr(model, "metadata"):
        return {}
    sources = model.metadata.get("data_sources") or {"collect": model.metadata.get("data_size")}
    return {"model_id": model.model_id, "model_samples": sources}


def run_search(
    store: Any,
    request: SearchRequest,
    stop: StopSignals | None = None,
    progress: SearchProgress | None = None,
    resources: SearchResources | None = None,
) -> SearchResult:
    """Run the search ``request`` asks for, from the set-up to the stored end; every caller's one call
    (``twisted plan``, ``twisted untie``, an evaluation's tasks, ``twisted improve``, the benches, the
    world's replans). ``resources``: workers and model kept from an earlier search (else started here
    and stopped at the end).

    The set-up: check the request, make the goal (a knot's states: read from the store when it kept
    them, else enumerated and kept), choose a new run or the run to continue (:func:`choose_run`: a run
    to continue is read and checked there, once, before anything is written), load the model, start
    ``request.workers`` simulators. Then the search runs to its goal, ``timeout_s``,
    ``max_iterations`` or a stop signal (``stop``), and a search that dies of an exception is marked
    failed with the reason. ``store``: an open store, or a function ``opener(create=...)`` that opens
    it, called with ``create=False`` for an existing store only (None when there is none: the kept
    knot states are read from it before the goal is checked) and with ``create=True`` once the goal is
    good, so that a bad goal creates no database. Raises :class:`PlanInputError` on a bad input and
    :class:`SetupStopped` when the set-up was stopped (``request.timed_setup``).
    """
    import contextlib
    import time

    from twisted.sim.pool import SimPool

    request.check()
    stop = stop if stop is not None else StopSignals()
    progress = progress if progress is not None else SearchProgress()
    started = time.perf_counter()
    phase = ["checking the goal"]

    def step(what: str) -> None:
        phase[0] = what
        progress.phase(what, time.perf_counter() - started)

    with contextlib.ExitStack() as started_here:
        timed = stop.setup(request.timeout_s) if request.timed_setup else contextlib.nullcontext()
        try:
            with timed:
                opened, goal, choice, sampler, model_id = _set_up(store, request, stop, step, resources)
                step(f"starting {request.workers} simulator worker{'s' if request.workers > 1 else ''}")
                if resources is not None:
                    pool = resources.pool(request.workers, request.friction_scale)
                else:
                    pool = started_here.enter_context(SimPool(request.workers, request.friction_scale))
        except StopRequested:
            spent_s = time.perf_counter() - started
            raise SetupStopped(phase[0], spent_s, stop.signum is None and stop.timed_out) from None
        search = _begin(opened, request, goal, choice, sampler, model_id, pool, stop)
        setup_s = time.perf_counter() - started
        if request.timed_setup:
            search.add_setup_time(setup_s)
        search.checkpoint_every_s = request.checkpoint_every_s
        search.progress = progress.iteration
        progress.started(search)
        try:
            result = search.run(timeout_s=request.timeout_s, max_iterations=request.max_iterations)
        except Exception as exc:  # a run that dies is marked failed with the reason, not left running
            from twisted.store.search_tree import mark_failed

            mark_failed(opened, search.run_id, f"{type(exc).__name__}: {exc}")
            raise
    return dataclasses.replace(result, setup_s=setup_s, model=model_info(sampler))


def _set_up(
    store: Any,
    request: SearchRequest,
    stop: StopSignals,
    step: Callable[[str], None],
    resources: SearchResources | None = None,
) -> tuple[Any, Goal | None, RunChoice, CurveSampler | None, int | None]:
    """The goal, the open store, the run chosen and the model of :func:`run_search`. Enumerating a knot's
    states stops at once at a signal or the deadline; the checks in between (database, run, model)
    finish first, so that a bad input is reported as such."""
    from twisted.planner.both_ways import make_any_goal
    from twisted.store.knots import keep_states_by_type

    goal = None
    kept = _kept_crossings(request)
    if request.goal is not None or request.knot is not None or request.crossings is not None:
        step("making the knot's states" if request.knot is not None else "checking the goal")
        if kept is not None:
            _load_kept_states(store, kept)
        other_start = request.from_run is not None or request.start_config is not None
        try:
            goal = make_any_goal(request.goal, request.knot, request.crossings, other_start=other_start)
        except PlanInputError as exc:
            raise PlanInputError(f"{'--knot' if request.knot is not None else '--goal'}: {exc}") from None
    step("opening the database")
    with stop.deferred():
        opened = store(create=True) if callable(store) else store
        if kept is not None and goal is not None:  # made in this process (or read): kept for the next search
            keep_states_by_type(opened, kept)
        choice = choose_run(
            opened,
            goal,
            request.options,
            resume=request.resume,
            run_id=request.run_id,
            model_id=request.model_id,
            start_config=request.start_config,
        )
        step("loading the model")
        try:
            load = resources.sampler if resources is not None else curve_sampler
            sampler, used_model_id = load(opened, choice.options.planner, choice.model_id)
        except PlanInputError as exc:
            given = f"--model {request.model_id}: " if request.model_id is not None else ""
            raise PlanInputError(f"{given}{exc}") from None
    return opened, goal, choice, sampler, used_model_id


def _kept_crossings(request: SearchRequest) -> int | None:
    """The crossing count whose knot state sets the goal enumerates and a store keeps (a 5-crossing knot:
    a minute), or None."""
    from twisted.goals import KNOT_PREFIX
    from twisted.store.knots import kept_crossings

    if request.knot is not None:
        return kept_crossings(request.knot, request.crossings)
    if request.goal is not None and request.goal.startswith(KNOT_PREFIX):
        name, _, count = request.goal[len(KNOT_PREFIX) :].partition("@")
        return kept_crossings(name, int(count) if count.isdigit() else None)
    return None


def _load_kept_states(store: Any, crossings: int) -> None:
    """Read the knot state sets of ``crossings`` an existing store kept (nothing is created before the
    goal is checked: a new store gets them once the run's store is open)."""
    from twisted.store.knots import load_states_by_type

    if not callable(store):
        load_states_by_type(store, crossings)
        return
    existing = store(create=False)
    if existing is not None:
        with existing:
            load_states_by_type(existing, crossings)


def _begin(
    store: Any,
    request: SearchRequest,
    goal: Goal | None,
    choice: RunChoice,
    sampler: CurveSampler | None,
    model_id: int | None,
    pool: Pool,
    stop: StopSignals,
) -> Search:
    """The search of :func:`run_search`: run ``choice.run_id`` continued (its lease taken) or a new run."""
    if choice.run_id is not None:
        return resume_search(store, choice.run_id, pool, sampler, stop=stop)
    assert goal is not None
    return start_search(
        store,
        goal,
        choice.options,
        pool,
        sampler,
        start_configuration_id=request.start_config,
        stop=stop,
        extra_parameters={"model_id": model_id, **request.parameters},
        from_run=request.from_run,
        removal_curves=request.removal_curves,
    )
