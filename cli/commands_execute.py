"""`twisted execute` and `twisted tie`: plans carried out in a world apart from the planner's model.

`execute RUN_ID --world LEVEL --seed S` sends a solved run's plan to a world drawn at LEVEL from seed S
(open loop, or `--closed-loop`: observe after every action and replan from the observation when the rope
left the plan); `tie --knot K --world LEVEL` plans in the model from the straight rope first. Every episode
is stored (tables `episodes`, `episode_steps`; docs/DESIGN.md section 15).

Exit codes: 0 the world's rope passed the pull test for the goal's knot; 2 bad input (an unknown or
senseless level, a run without a plan, an episode that cannot be resumed: nothing written); 3 not tied
(the pull test failed, or the budget ran out); 130 / 143 interrupted after storing the last observation
(continue with `twisted execute --resume EPISODE`).
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any, TypeVar

import typer

from cli.app import EXIT_NOT_REACHED, EXIT_OK, app, check_workers, console, err_console, fail, open_db
from cli.options import json_option, print_json

F = TypeVar("F", bound=Callable[..., Any])


def _level(text: str) -> Any:
    from twisted.world import LevelError, parse_level

    try:
        return parse_level(text)
    except LevelError as exc:
        fail(f"--world {text}: {exc}")


def _check_budget(timeout_s: float, max_actions: int, drift_m: float, workers: int) -> None:
    check_workers(workers)
    if not 0.0 < drift_m <= 1.0:
        fail(f"--drift {drift_m:g}: give a distance in metres in (0, 1]")
    if timeout_s <= 0:
        fail(f"--timeout {timeout_s:g}: give a positive number of seconds")
    if max_actions < 1:
        fail(f"--max-actions {max_actions}: give at least 1")


# The options `execute` and `tie` share: name -> (type, Typer option).
_WORLD_OPTIONS: dict[str, tuple[Any, Any]] = {
    "world": (
        str,
        typer.Option(
            "moderate",
            "--world",
            help="Perturbation level: none | mild | moderate | strong, optionally with overrides, e.g. "
            "'moderate,friction=0.5:2,observation_noise_m=0.003' (docs/DESIGN.md section 15.2).",
        ),
    ),
    "seed": (
        int,
        typer.Option(0, "--seed", min=0, max=2**63 - 1, help="The world's seed: one seed, one world."),
    ),
    "closed_loop": (
        bool,
        typer.Option(
            False, "--closed-loop/--open-loop", help="Observe after every action and replan when off plan."
        ),
    ),
    "timeout_s": (
        float,
        typer.Option(
            600.0, "--timeout", min=0.0, help="Wall-time budget of the episode in seconds, planning included."
        ),
    ),
    "max_actions": (
        int,
        typer.Option(30, "--max-actions", min=1, max=10_000, help="At most this many actions."),
    ),
    "drift_m": (
        float,
        typer.Option(
            0.05,
            "--drift",
            help="Closed loop: replan when the observed points lie further (RMS, m) from the plan's.",
        ),
    ),
    "straighten": (
        bool,
        typer.Option(
            True,
            "--straighten/--no-straighten",
            help="Closed loop: a rope in a dead end for the goal is pulled straight before the replan.",
        ),
    ),
    "stages": (
        bool,
        typer.Option(
            True,
            "--stages/--no-stages",
            help="Closed loop, a composite knot (granny, square): replan for the first summand (an overhand) "
            "until the rope ties one, then for the knot.",
        ),
    ),
    "workers": (int, typer.Option(1, "--workers", help="Simulator processes of each replan's search.")),
}


# `tie` and `robustness`: the planner option the model's plan and every replan search with (DESIGN 8)
_SAME_STATE = typer.Option(
    True,
    "--same-state/--no-same-state",
    help="Searches keep curves whose rope stays in its parent's state (--no-same-state: only curves that "
    "change the state, so a plan's every curve is a move).",
)


@dataclass(frozen=True)
class WorldRequest:
    """What `execute` / `tie` were asked for about the world and the episode (checked: :meth:`check`)."""

    world: str
    seed: int
    closed_loop: bool
    timeout_s: float
    max_actions: int
    drift_m: float
    straighten: bool
    stages: bool
    workers: int

    def check(self) -> tuple[Any, Any]:
        """The level and the episode's settings; exit 2 before anything is opened when one makes no sense."""
        from twisted.experiments.episodes import EpisodeSettings

        level = _level(self.world)
        _check_budget(self.timeout_s, self.max_actions, self.drift_m, self.workers)
        settings = EpisodeSettings(
            self.closed_loop, self.timeout_s, self.max_actions, self.drift_m, self.straighten, self.stages
        )
        return level, settings


def with_world_options(func: F) -> F:
    """Give a command the options of :data:`_WORLD_OPTIONS`; it gets them as one ``world: WorldRequest``."""
    signature = inspect.signature(func, eval_str=True)
    kept = [p for name, p in signature.parameters.items() if name != "world"]
    kind = inspect.Parameter.KEYWORD_ONLY
    added = [
        inspect.Parameter(name, kind, default=option, annotation=annotation)
        for name, (annotation, option) in _WORLD_OPTIONS.items()
    ]

    @functools.wraps(func)
    def command_function(*args: Any, **kwargs: Any) -> Any:
        request = WorldRequest(**{name: kwargs.pop(name) for name in _WORLD_OPTIONS})
        return func(*args, world=request, **kwargs)

    parameters = kept + added
    command_function.__signature__ = signature.replace(parameters=parameters)  # type: ignore[attr-defined]
    command_function.__annotations__ = {p.name: p.annotation for p in parameters}
    return command_function  # type: ignore[return-value]


def _report(result: Any, as_json: bool, episode: dict[str, Any]) -> None:
    data = {**episode, **result.to_dict()}
    if as_json:
        print_json(data)
    else:
        console.print(
            f"episode {result.run_id}: {result.outcome} ({result.final_knot or 'no pull test'}); "
            f"{result.actions} actions, {result.replans} replans, planning {result.planning_s:.1f} s, "
            f"wall {result.elapsed_s:.1f} s",
            highlight=False,
        )
    if result.outcome == "interrupted":
        err_console.print(
            f"interrupted: continue with `twisted execute --resume {result.run_id}`", highlight=False
        )


def _exit(result: Any, stop: Any) -> None:
    if result.outcome == "tied":
        raise typer.Exit(EXIT_OK)
    if result.outcome == "interrupted":
        raise typer.Exit(stop.exit_code)
    raise typer.Exit(EXIT_NOT_REACHED)


def _run(
    store: Any, plan: Any, goal: Any, planner: Any, level: Any, seed: int, settings: Any, as_json: bool
) -> Any:
    """One episode at ``level`` from ``seed`` (:func:`run_episode`); ``planner`` is closed afterwards."""
    from twisted.experiments.episodes import run_episode

    try:
        return run_episode(store, plan, goal, planner, level, seed, settings, _progress(as_json))
    finally:
        planner.close()


def _progress(as_json: bool) -> Any:
    def show(line: str) -> None:
        if not as_json:
            err_console.print(line, highlight=False)

    return show


@app.command("execute")
@with_world_options
def execute_command(
    ctx: typer.Context,
    run_id: int | None = typer.Argument(
        None, metavar="RUN_ID", help="A solved planner run.", show_default=False
    ),
    resume: int | None = typer.Option(
        None,
        "--resume",
        metavar="EPISODE",
        help="Continue a stopped episode from its last stored observation.",
    ),
    as_json: bool = json_option("the episode's outcome"),
    *,
    world: WorldRequest,
) -> None:
    """Execute a solved run's plan in a world apart from the planner's model; store the episode."""
    from twisted.experiments.episodes import ModelPlanner
    from twisted.runtime import StopSignals

    if resume is not None:
        # an option typed on the command line (Typer's own click: compare the source by name)
        given = [
            n for n in _WORLD_OPTIONS if getattr(ctx.get_parameter_source(n), "name", "") == "COMMANDLINE"
        ]
        if run_id is not None or given:
            dropped = ([f"RUN_ID {run_id}"] if run_id is not None else []) + [
                _WORLD_OPTIONS[n][1].param_decls[0].split("/")[0] for n in given
            ]
            fail(f"--resume {resume} continues an episode as it was asked: drop {', '.join(dropped)}")
        _resume(ctx, resume, as_json)
        return
    if run_id is None:
        fail(
            "RUN_ID is required: a solved planner run (`twisted plan ...` prints its id), or --resume EPISODE"
        )
    level, settings = world.check()
    store = open_db(ctx, needed_by=f"RUN_ID {run_id}")
    plan, goal, options, model_id = _stored_plan(store, run_id)
    stop = StopSignals()
    with stop.installed():
        planner = ModelPlanner(store, goal, options, model_id, world.workers, None, stop)
        result = _run(store, plan, goal, planner, level, world.seed, settings, as_json)
    _report(
        result,
        as_json,
        {"plan_run": run_id, "level": level.name, "seed": world.seed, "closed_loop": world.closed_loop},
    )
    _exit(result, stop)


def _stored_plan(store: Any, run_id: int) -> tuple[Any, Any, Any, Any]:
    """The plan of solved run ``run_id``, its goal, options and model (exit 2, nothing written, otherwise)."""
    from twisted.experiments.episodes import plan_of_run
    from twisted.planner import PlanInputError, stored_options
    from twisted.store.search_tree import load_run

    try:
        plan = plan_of_run(store, run_id)
        info = load_run(store, run_id, with_nodes=False)
        assert info is not None  # plan_of_run found it
        options = stored_options(info.parameters, run_id)
    except PlanInputError as exc:
        fail(f"RUN_ID {run_id}: {exc}")
    return plan, info.goal, options, info.parameters.get("model_id")


def _resume(ctx: typer.Context, episode_id: int, as_json: bool) -> None:
    from twisted.experiments.episodes import Episode, EpisodeSettings, ModelPlanner, resume_state
    from twisted.planner import PlanInputError
    from twisted.runtime import StopSignals, process_alive
    from twisted.store.episodes import EpisodeError, load_episode, reopen_episode
    from twisted.world import Level, LevelError, SimWorld

    store = open_db(ctx, needed_by=f"--resume {episode_id}")
    try:
        stored = load_episode(store, episode_id)
    except EpisodeError as exc:
        fail(f"--resume {episode_id}: {exc}")
    if stored.outcome not in ("interrupted", "running"):
        fail(f"--resume {episode_id}: the episode has ended ({stored.outcome}); nothing to continue")
    import socket

    if (
        stored.status == "running"
        and stored.host == socket.gethostname()
        and stored.pid
        and process_alive(stored.pid)
    ):
        fail(f"--resume {episode_id}: process {stored.pid} is still running it")
    if stored.plan_run_id is None:
        fail(f"--resume {episode_id}: the episode names no plan")
    plan, goal, options, model_id = _stored_plan(store, stored.plan_run_id)
    parameters = _episode_parameters(store, episode_id)
    drift_m = parameters.get("drift_m")
    workers = parameters.get("workers")
    if not isinstance(drift_m, float) or not 0 < drift_m <= 1 or not isinstance(workers, int) or workers < 1:
        fail(f"--resume {episode_id}: its stored parameters do not read back ({parameters!r:.120})")
    # an episode stored before straightening (stages) existed ran without it
    straighten = parameters.get("straighten", False)
    stages = parameters.get("stages", False)
    if not isinstance(straighten, bool) or not isinstance(stages, bool):
        fail(f"--resume {episode_id}: its stored parameters do not read back ({parameters!r:.120})")
    settings = EpisodeSettings(
        stored.closed_loop, stored.timeout_s, stored.max_actions, drift_m, straighten, stages
    )
    try:
        level = Level.from_dict(stored.level_ranges)
        world = SimWorld(level, stored.world_seed)
        state, checkpoint = resume_state(store, stored.steps, goal if stages else None)
        world.restore(checkpoint)
    except (LevelError, PlanInputError, ValueError, KeyError, TypeError) as exc:
        fail(f"--resume {episode_id}: the stored episode does not read back: {exc}")
    reopen_episode(store, episode_id)
    stop = StopSignals()
    with stop.installed():
        planner = ModelPlanner(store, goal, options, model_id, workers, episode_id, stop)
        try:
            episode = Episode(store, episode_id, world, goal, planner, settings, stop, _progress(as_json))
            result = episode.run(state)
        finally:
            planner.close()
    _report(result, as_json, {"resumed": True, "level": level.name, "seed": stored.world_seed})
    _exit(result, stop)


def _episode_parameters(store: Any, episode_id: int) -> dict[str, Any]:
    from twisted.store.models import Run

    with store.session() as session:
        run = session.get(Run, episode_id)
        return dict(run.parameters) if run is not None and isinstance(run.parameters, dict) else {}


@app.command("tie")
@with_world_options
def tie_command(
    ctx: typer.Context,
    knot: str = typer.Option(
        ..., "--knot", help="The knot to tie (overhand, figure-eight, 5_2, granny, ...)."
    ),
    planner_seed: int = typer.Option(0, "--planner-seed", min=0, max=2**63 - 1, help="Seed of the searches."),
    same_state: bool = _SAME_STATE,
    as_json: bool = json_option("the episode's outcome"),
    *,
    world: WorldRequest,
) -> None:
    """Plan KNOT in the model from the straight rope (with the pull test), then execute it in a world.

    A solved plan of the same knot and options already in the store is executed again (no search)."""
    from twisted.experiments.episodes import ModelPlanner
    from twisted.experiments.robustness import model_plan
    from twisted.planner import PlanInputError
    from twisted.planner.both_ways import make_any_goal
    from twisted.runtime import StopSignals

    level, settings = world.check()
    try:
        make_any_goal(None, knot, None)
    except PlanInputError as exc:
        fail(f"--knot {knot}: {exc}")
    store = open_db(ctx)
    stop = StopSignals()
    with stop.installed():
        try:
            plan, goal, options, planning_s = model_plan(
                store, knot, planner_seed, world.timeout_s, world.workers, stop, same_state
            )
        except PlanInputError as exc:
            err_console.print(str(exc), highlight=False)
            raise typer.Exit(stop.exit_code if stop() else EXIT_NOT_REACHED) from None
        if not as_json:
            err_console.print(
                f"the model's plan: run {plan.run_id} ({planning_s:.1f} s of search)", highlight=False
            )
        settings.timeout_s = max(world.timeout_s - planning_s, 1.0)
        planner = ModelPlanner(store, goal, options, None, world.workers, None, stop)
        result = _run(store, plan, goal, planner, level, world.seed, settings, as_json)
    shown = {"knot": knot, "plan_run": plan.run_id, "model_planning_s": round(planning_s, 3)}
    _report(
        result, as_json, {**shown, "level": level.name, "seed": world.seed, "closed_loop": world.closed_loop}
    )
    _exit(result, stop)


@app.command("robustness")
@with_world_options
def robustness_command(
    ctx: typer.Context,
    knots: Annotated[
        list[str], typer.Option("--knot", help="A knot to tie (repeatable): overhand, figure-eight, ...")
    ],
    levels: str = typer.Option(
        "none,mild,moderate,strong", "--levels", help="Perturbation levels, comma-separated (no overrides)."
    ),
    draws: int = typer.Option(
        3, "--draws", min=1, max=10_000, help="World draws (seeds --seed ...) per level."
    ),
    loops: str = typer.Option("open,closed", "--loops", help="open, closed or both (open,closed)."),
    same_state: bool = _SAME_STATE,
    as_json: bool = json_option("the table"),
    *,
    world: WorldRequest,
) -> None:
    """Tie each knot in DRAWS worlds at each level, open and closed loop; print success per level.

    Each knot is planned once in the model (a stored solved run of the same knot and options is reused);
    episodes already finished in the store are skipped, so the same command continues after a stop.
    `twisted report` plots the success against the level. `--world` is not taken: use --levels."""
    from twisted.experiments.robustness import robustness_markdown, robustness_table, run_robustness
    from twisted.planner import PlanInputError
    from twisted.planner.both_ways import make_any_goal
    from twisted.runtime import StopSignals

    chosen = [_level(name.strip()) for name in levels.split(",")]
    if any("," in name for name in levels.split(",")) or len({lv.name for lv in chosen}) != len(chosen):
        fail(f"--levels {levels}: name each level once")
    wanted = [part.strip() for part in loops.split(",")]
    if not wanted or set(wanted) - {"open", "closed"} or len(set(wanted)) != len(wanted):
        fail(f"--loops {loops}: give open, closed or open,closed")
    _, settings = world.check()
    for knot in knots:
        try:
            make_any_goal(None, knot, None)
        except PlanInputError as exc:
            fail(f"--knot {knot}: {exc}")
    seeds = list(range(world.seed, world.seed + draws))
    store = open_db(ctx)
    stop = StopSignals()
    with stop.installed():
        try:
            run_robustness(
                store,
                knots,
                chosen,
                seeds,
                [w == "closed" for w in wanted],
                settings,
                world.workers,
                stop,
                _progress(as_json),
                same_state,
            )
        except PlanInputError as exc:
            err_console.print(str(exc), highlight=False)
            raise typer.Exit(EXIT_NOT_REACHED) from None
    table = robustness_table(store)
    if as_json:
        print_json([row.to_dict() for row in table])
    else:
        console.print("\n".join(robustness_markdown(table)), highlight=False)
    if stop():
        raise typer.Exit(stop.exit_code)
