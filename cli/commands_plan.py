"""`twisted plan` and `twisted replay`: search for a low-level plan to a goal state, re-simulate one.

Exit codes: 0 solved (replay: the plan still ends in the goal), 2 bad input (malformed goal, a goal
with more crossings than the model encodes, no model for a planner that needs one, unknown run id,
options that contradict the run being resumed), 3 goal not reached (``--timeout`` or
``--max-iterations`` ran out; replay: the plan no longer reaches the goal), 130 / 143 interrupted
by Ctrl-C / SIGTERM after saving a checkpoint (continue with ``--resume RUN_ID``).
"""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from cli.app import (
    EXIT_NOT_REACHED,
    EXIT_OK,
    app,
    check_workers,
    console,
    err_console,
    fail,
    open_db,
    shown_name,
    store_exists,
    unwritable,
)
from cli.options import json_option, print_json, with_planner_options


def _curve_row(curve: Any) -> dict[str, Any]:
    """A step of a low-level plan: its action, and the curve's parameters (None for a cinch)."""
    action = getattr(curve, "action", "curve")
    if action != "curve":
        return {"action": action, "link": None, "z_max_m": None, "x_m": None, "y_m": None}
    parameters = {"link": curve.link, "z_max_m": curve.z_max_m, "x_m": curve.x_m, "y_m": curve.y_m}
    return {"action": action, **parameters}


def _curve_cells(row: dict[str, Any]) -> list[str]:
    """The link, z_max_m, x_m and y_m cells of a plan step's table row (a cinch: "cinch", then blank)."""
    if row["action"] != "curve":
        return [str(row["action"]), "", "", ""]
    return [str(row["link"]), f"{row['z_max_m']:.4f}", f"{row['x_m']:+.4f}", f"{row['y_m']:+.4f}"]


@app.command("plan")
@with_planner_options("plan")
def plan_command(
    ctx: typer.Context,
    goal: str | None = typer.Option(
        None, "--goal", help='Goal P-data as JSON, e.g. \'[[1,"O",2,"+"],[2,"U",1,"+"]]\'.'
    ),
    knot: str | None = typer.Option(
        None,
        "--knot",
        help="Goal by knot name (overhand, figure-eight, 5_1, 5_2, granny, square; see `twisted knots "
        "list`): any rope state that really ties it (both closures are the knot; knotoids never are). "
        "Granny and square are knot types (two trefoils summed), tied as two overhands in a row on the "
        "one rope, not the sailor's reef knot joining two ends.",
    ),
    crossings: int | None = typer.Option(
        None,
        "--crossings",
        help="With --knot: states of this many crossings (default: the knot's crossing number, "
        "3 overhand, 4 figure-eight, 5 for 5_1/5_2, 6 granny/square).",
    ),
    timeout_s: float = typer.Option(
        1800.0, "--timeout", min=0.0, help="Search time limit in seconds (a resumed run's time counts)."
    ),
    workers: int = typer.Option(
        2, "--workers", help="Simulator processes (1: in this process; at most 4 per CPU core)."
    ),
    model_id: int | None = typer.Option(
        None,
        "--model",
        help="Model id (twisted: default the newest in the database, else the shipped one; "
        "sac: policy checkpoint id, default the newest).",
    ),
    start_config: int | None = typer.Option(
        None, "--start-config", help="Start from this configurations.id instead of the straight rope."
    ),
    from_run: int | None = typer.Option(
        None,
        "--from-run",
        help="Start from where solved run RUN_ID ended (its goal node); the search may remove crossings.",
    ),
    removal_curves: str | None = typer.Option(
        None, "--removal-curves", help="Curves of a removing step: random (default) | model."
    ),
    resume_run_id: int | None = typer.Argument(
        None, metavar="RUN_ID", help="With --resume: the run to continue.", show_default=False
    ),
    resume: bool = typer.Option(
        False,
        "--resume",
        help="Continue a stopped run: RUN_ID, or the newest unfinished one (for --goal when given).",
    ),
    max_iterations: int | None = typer.Option(
        None, "--max-iterations", min=0, help="Also stop after this many iterations (total, for tests)."
    ),
    checkpoint_every_s: float = typer.Option(
        2.0, "--checkpoint-every", min=0.0, help="Seconds between checkpoints."
    ),
    picture: Annotated[
        Path | None,
        typer.Option(
            "--picture",
            help="When solved, draw the final rope to this PNG (with --tighten beside the rope pulled "
            "tight), as `twisted render --run RUN_ID [--tightened]` does.",
        ),
    ] = None,
    as_json: bool = json_option("the result"),
    *,
    search_options: dict[str, Any],
) -> None:
    """Search for curves that tie GOAL (Algorithm 1); the search tree goes to the database.

    The set-up (enumerating a knot's states, loading the model, starting the workers) counts toward
    --timeout and stops at Ctrl-C like the search does.
    """
    request = _Request(
        goal=goal,
        knot=knot,
        crossings=crossings,
        resume=resume,
        run_id=resume_run_id,
        start_config=start_config,
        model_id=model_id,
        workers=workers,
        as_json=as_json,
        from_run=from_run,
        removal_curves=removal_curves,
        search_options=search_options,  # the planner options (twisted.planner.options), None: not given
    )
    _check(request)
    if picture is not None:
        picture = _picture_file(picture)
    search, result, setup_s, exit_code = _search(ctx, request, timeout_s, max_iterations, checkpoint_every_s)
    _print_result(search, result, as_json, setup_s)
    if result.solved:
        if picture is not None:
            _draw(ctx, result.run_id, picture, bool(search.options.tighten), as_json)
        raise typer.Exit(EXIT_OK)
    if result.status == "interrupted":
        err_console.print(
            f"interrupted: checkpoint saved; continue with `twisted plan --resume {result.run_id}`",
            highlight=False,
        )
        raise typer.Exit(exit_code)
    raise typer.Exit(EXIT_NOT_REACHED)


def _picture_file(path: Path) -> Path:
    """``--picture``: a writable PNG path (exit 2 before anything is opened otherwise)."""
    if path.suffix.lower() != ".png":
        fail(f"--picture {path}: the file must end in .png")
    problem = unwritable(path)
    if problem is not None:
        fail(f"--picture {path}: {problem}")
    return path


def _draw(ctx: typer.Context, run_id: int, png: Path, tightened: bool, as_json: bool) -> None:
    """Draw a solved run's final rope (beside its pull test when it had one) to ``png``."""
    from twisted.render import RenderError, render_run, render_tightened

    with open_db(ctx) as store:
        try:
            rendered = render_tightened(store, run_id, png) if tightened else render_run(store, run_id, png)
        except (RenderError, OSError) as exc:
            err_console.print(f"the run is solved, but its picture was not drawn: {exc}", highlight=False)
            return
    if not as_json:
        for path in rendered.files:
            console.print(f"picture: {path}")


def _check(request: _Request) -> None:
    """Exit 2 on a bad input that needs nothing stored to be seen as such (before anything is opened;
    the goal is checked by the set-up, which can take long for a knot, see :func:`_set_up`)."""
    check_workers(request.workers)
    if request.run_id is not None and not request.resume:
        fail(f"a run id is only taken with --resume: `twisted plan --resume {request.run_id}`")
    if request.goal is None and request.knot is None and request.crossings is None and not request.resume:
        fail(
            'a goal is required: --goal P-DATA (e.g. \'[[1,"O",2,"+"],[2,"U",1,"+"]]\') or --knot '
            "NAME (e.g. overhand); or continue a stopped run with --resume [RUN_ID]"
        )
    from twisted.planner import PlanInputError, check_request
    from twisted.planner.untie import check_start

    try:
        check_request(request.search_options, resume=request.resume, start_config=request.start_config)
        check_start(request.resume, request.start_config, request.from_run, request.removal_curves)
    except PlanInputError as exc:
        fail(str(exc))


def _search(
    ctx: typer.Context,
    request: _Request,
    timeout_s: float,
    max_iterations: int | None,
    checkpoint_every_s: float,
) -> tuple[Any, Any, float, int]:
    """Set up (the goal, the store, the model, the workers) and search, with a progress bar; the search,
    its result, the set-up's seconds and the exit code of a stop. The set-up counts toward --timeout
    and stops at Ctrl-C / SIGTERM; stopped there, the command exits (3 out of time, 130 / 143)."""
    from twisted.runtime import StopRequested, StopSignals

    started = time.perf_counter()
    stop = StopSignals()
    with stop.installed(), contextlib.ExitStack() as resources:
        bar = resources.enter_context(
            Progress(*_COLUMNS, console=err_console, transient=True, disable=request.as_json)
        )
        task = bar.add_task(
            "set-up", total=max(timeout_s, 1e-9), iteration=0, sims=0, nodes=1, states=1, max_cross=0
        )
        phase = ["checking the goal"]

        def setup_step(what: str) -> None:
            phase[0] = what
            spent = time.perf_counter() - started
            bar.update(task, description=f"set-up: {what}", completed=min(spent, timeout_s))

        try:
            with stop.setup(timeout_s):
                setup = _set_up(ctx, request, resources, stop, setup_step)
        except StopRequested:
            bar.stop()
            spent = time.perf_counter() - started
            unchanged = f": run {request.run_id} is unchanged" if request.run_id is not None else ""
            if stop.signum is None and stop.timed_out:
                fail(
                    f"--timeout {timeout_s:g} s ran out during the set-up ({phase[0]}, after {spent:.1f} s); "
                    f"nothing was searched{unchanged}",
                    EXIT_NOT_REACHED,
                )
            err_console.print(
                f"interrupted during the set-up ({phase[0]}, after {spent:.1f} s); "
                f"nothing was searched{unchanged}",
                highlight=False,
            )
            raise typer.Exit(stop.exit_code) from None
        search = _begin(setup, stop)
        setup_s = time.perf_counter() - started
        search.add_setup_time(setup_s)
        search.checkpoint_every_s = checkpoint_every_s

        def progress(search: Any) -> None:
            bar.update(
                task,
                completed=min(search.elapsed_s, timeout_s),
                iteration=search.iteration,
                sims=search.sim_calls,
                nodes=len(search.tree),
                states=len(search.tree.states),
                max_cross=max(p.cross for p in search.tree.states.values()),
            )

        search.progress = progress
        bar.update(task, description=f"run {search.run_id}")
        try:
            result = search.run(timeout_s=timeout_s, max_iterations=max_iterations)
        except Exception as exc:  # a run that dies is marked failed with the reason, not left running
            from twisted.store.search import mark_failed

            mark_failed(setup.store, search.run_id, f"{type(exc).__name__}: {exc}")
            raise
    return search, result, setup_s, stop.exit_code


_COLUMNS = (
    TextColumn("[bold]{task.description}"),
    BarColumn(),
    TextColumn("{task.completed:>6.0f}/{task.total:.0f} s"),
    TextColumn("it {task.fields[iteration]}  sims {task.fields[sims]}  nodes {task.fields[nodes]}"),
    TextColumn("states {task.fields[states]}  max cross {task.fields[max_cross]}"),
    TimeElapsedColumn(),
)


@dataclass
class _Request:
    """What `twisted plan` was asked for (the command line, before anything is checked or opened)."""

    goal: str | None
    knot: str | None
    crossings: int | None
    resume: bool
    run_id: int | None
    start_config: int | None
    model_id: int | None
    workers: int
    search_options: dict[str, Any]
    as_json: bool = False
    from_run: int | None = None  # start where this solved run ended (twisted.planner.untie)
    removal_curves: str | None = None


@dataclass
class _Setup:
    """What the set-up prepared: the store, the goal or the run to continue, the model, the workers."""

    store: Any
    goal: Any | None
    run_id: int | None
    start_config: int | None
    options: Any
    sampler: Any
    model_id: int | None
    pool: Any
    request: _Request | None = None


def _set_up(
    ctx: typer.Context,
    request: _Request,
    resources: contextlib.ExitStack,
    stop: Any,
    step: Callable[[str], None],
) -> _Setup:
    """Check the inputs (exit 2 before anything is written), open the store, load the model, start workers.

    Enumerating a knot's states and starting the workers stop at once at a signal or the deadline; the
    checks in between (database, run, model) finish first, so that a bad input is reported as such.
    """
    from twisted.planner import PlanInputError, curve_sampler
    from twisted.planner.untie import make_any_goal
    from twisted.sim.pool import SimPool
    from twisted.store.knots import keep_states_by_type

    goal_p = None
    kept_crossings = None
    if request.goal is not None or request.knot is not None or request.crossings is not None:
        step("making the knot's states" if request.knot is not None else "checking the goal")
        try:
            other_start = request.from_run is not None or request.start_config is not None
            kept_crossings = _load_knot_states(ctx, request)
            goal_p = make_any_goal(request.goal, request.knot, request.crossings, other_start=other_start)
        except PlanInputError as exc:
            fail(f"{'--knot' if request.knot is not None else '--goal'}: {exc}")
    step("opening the database")
    with stop.deferred():
        store = resources.enter_context(open_db(ctx, needed_by=_needs_stored(request)))
        if kept_crossings is not None:  # made in this process (or read): kept for the next plan
            keep_states_by_type(store, kept_crossings)
        run_id, options, model_id = _run_to_continue(store, request, goal_p)
        step("loading the model")
        try:
            sampler, used_model_id = curve_sampler(store, options.planner, model_id)
        except PlanInputError as exc:
            fail(f"--model {request.model_id}: {exc}" if request.model_id is not None else str(exc))
    _print_model(sampler, used_model_id, request.as_json)
    step(f"starting {request.workers} simulator worker{'s' if request.workers > 1 else ''}")
    pool = resources.enter_context(SimPool(request.workers))
    return _Setup(store, goal_p, run_id, request.start_config, options, sampler, used_model_id, pool, request)


def _load_knot_states(ctx: typer.Context, request: _Request) -> int | None:
    """A 5-crossing knot goal enumerates and names every state of 5 crossings (a minute); the database
    keeps the sets (``knot_state_sets``), so that this is paid once per database. Read here when an
    existing database has them (nothing is created before the goal is checked: a new database gets
    them once the run's store is open); the crossing count whose sets the run's store should keep, or
    None. A name that is no knot is left to the goal's own check (exit 2 before anything is opened)."""
    from twisted.store.knots import kept_crossings, load_states_by_type

    count = kept_crossings(request.knot, request.crossings)
    if count is None:
        return None
    if store_exists(ctx):
        with open_db(ctx, create=False) as store:
            load_states_by_type(store, count)
    return count


def _needs_stored(request: _Request) -> str | None:
    """The option that names something stored (a run, a model, a configuration), if any: a database
    that does not exist yet is then refused instead of created."""
    if request.resume:
        return "--resume" + ("" if request.run_id is None else f" {request.run_id}")
    if request.model_id is not None:
        return f"--model {request.model_id}"
    if request.start_config is not None:
        return f"--start-config {request.start_config}"
    if request.from_run is not None:
        return f"--from-run {request.from_run}"
    return None


def _print_model(sampler: Any, used_model_id: int | None, as_json: bool) -> None:
    """Which inverse model the search samples from, and how many samples of each source trained it."""
    info = _model_json(sampler)
    if not info or as_json:
        return
    sources = info["model_samples"]
    err_console.print(
        f"inverse model {'(shipped default)' if used_model_id is None else used_model_id}: trained on "
        + ", ".join(f"{n:,} {source}" for source, n in sources.items() if n)
        + " samples",
        highlight=False,
    )


def _run_to_continue(store: Any, request: _Request, goal_p: Any) -> tuple[int | None, Any, int | None]:
    """With --resume: the run, its options and model (exit 2 when it cannot be continued); else the new
    run's options and the model asked for."""
    from twisted.planner import PlanInputError, choose_run

    try:
        chosen = choose_run(
            store,
            goal_p,
            request.search_options,
            resume=request.resume,
            run_id=request.run_id,
            model_id=request.model_id,
            start_config=request.start_config,
        )
    except PlanInputError as exc:
        fail(str(exc))
    return chosen.run_id, chosen.options, chosen.model_id


def _begin(setup: _Setup, stop: Any) -> Any:
    """The search of a set-up: run ``setup.run_id`` continued (its lease taken) or a new run."""
    from twisted.planner import PlanInputError, resume_search, start_search

    try:
        if setup.run_id is not None:
            return resume_search(setup.store, setup.run_id, setup.pool, setup.sampler, stop=stop)
        assert setup.goal is not None
        return start_search(
            setup.store,
            setup.goal,
            setup.options,
            setup.pool,
            setup.sampler,
            start_configuration_id=setup.start_config,
            stop=stop,
            extra_parameters={"model_id": setup.model_id},
            **_both_ways(setup.request),
        )
    except PlanInputError as exc:
        fail(str(exc))


def _both_ways(request: _Request | None) -> dict[str, Any]:
    """The start_search arguments of a search that may remove crossings (twisted.planner.untie)."""
    if request is None:
        return {}
    return {
        "from_run": request.from_run,
        "removal_curves": request.removal_curves,
    }


def _model_json(sampler: Any) -> dict[str, Any]:
    """The inverse model the search sampled from (``model_id`` None: the shipped default) and its training
    samples per source; nothing for a planner without one."""
    model = getattr(sampler, "model", None)
    if model is None or not hasattr(model, "metadata"):
        return {}
    sources = model.metadata.get("data_sources") or {"collect": model.metadata.get("data_size")}
    return {"model_id": model.model_id, "model_samples": sources}


def _expand_share(result: Any) -> str:
    expand = result.calls_by_source().get("random_expand", 0)
    return f" ({expand} in random expansions)" if expand else ""


def _print_result(search: Any, result: Any, as_json: bool, setup_s: float = 0.0) -> None:
    steps = [
        {"step": i, **_curve_row(node.curve), "cross": node.p_data.cross, "state": node.p_data.to_list()}
        for i, node in enumerate(result.path[1:], start=1)
    ]
    if as_json:
        payload = {
            "run_id": result.run_id,
            "goal": search.goal.spec,
            "knot": search.goal.knot,
            "goal_states": [p.to_list() for p in search.goal.states],
            "reached_state": result.path[-1].p_data.to_list() if result.path else None,
            "outcome": result.status,
            "solved": result.solved,
            "search_time_s": round(result.elapsed_s, 3),
            "setup_s": round(setup_s, 3),
            "sim_calls": result.sim_calls,
            "sim_calls_by_source": result.calls_by_source(),
            "plan_steps_by_move": {
                kind: {"tried": tried, "reached": reached}
                for kind, (tried, reached) in result.steps_by_move().items()
            },
            "iterations": result.iterations,
            "nodes": result.nodes,
            "states": result.states,
            "plan": steps,
            "tighten": search.options.tighten,
            "pull_tests": search.pull_tests,
            **_model_json(search.sampler),
        }
        print_json(payload, indent=None)
        return
    outcome = "[bold green]solved[/]" if result.solved else f"[bold red]not solved ({result.status})[/]"
    console.print(
        f"run {result.run_id}: {outcome}"
        f"  goal {shown_name(search.goal.label)}"  # a knot name read back from the store
        + (f" reached {result.path[-1].p_data.key}" if result.path and search.goal.knot else "")
        + f"  search time {result.elapsed_s:.1f} s (set-up {setup_s:.1f} s)"
        f"  simulator calls {result.sim_calls}{_expand_share(result)}"
        f"  iterations {result.iterations}  nodes {result.nodes}  states {result.states}"
        + (f"  pull tests {search.pull_tests}" if search.options.tighten else ""),
        highlight=False,
    )
    if steps:
        table = Table(title="low-level plan (curves from the initial configuration)")
        for name in ("step", "link", "z_max_m", "x_m", "y_m", "state after"):
            table.add_column(name, justify="right" if name != "state after" else "left")
        for row in steps:
            table.add_row(
                str(row["step"]), *_curve_cells(row), json.dumps(row["state"], separators=(",", ":"))
            )
        console.print(table)


def _tightened_dict(t: Any) -> dict[str, Any] | None:
    if t is None:
        return None
    return {
        "ok": t.ok,
        "reason": t.reason,
        "p_data": None if t.p_data is None else t.p_data.to_list(),
        "knot": None if t.knot is None else t.knot.to_dict(),
        "knot_type": t.knot_name,
        "end_distance_m": t.end_distance_m,
        "sim_seconds": t.sim_seconds,
        "wall_seconds": t.wall_seconds,
    }


@app.command("replay")
def replay_command(
    ctx: typer.Context,
    run_id: int = typer.Argument(..., help="A solved planner run (see `twisted plan`)."),
    tighten: bool = typer.Option(
        False,
        "--tighten",
        help="Then hold both ends, lift them a little and pull them apart until the rope is taut; exit 0 "
        "only if the tightened rope ties the goal's knot (stored with the run).",
    ),
    as_json: bool = json_option("the result"),
) -> None:
    """Re-simulate a run's plan from its initial configuration; exit 0 if it still ends in the goal."""
    from twisted.planner import PlanInputError, replay

    store = open_db(ctx, readonly=not tighten, needed_by=f"RUN_ID {run_id}")  # --tighten stores a pull test
    try:
        result = replay(store, run_id, tighten=tighten)
    except PlanInputError as exc:
        fail(str(exc))
    ok = result.ties_goal if tighten else result.reached_goal
    if as_json:
        print_json(
            {
                "run_id": run_id,
                "goal": result.goal.spec,
                "reached_goal": result.reached_goal,
                "steps": [
                    {
                        **_curve_row(step.curve),
                        "recorded": step.recorded.to_list(),
                        "replayed": None if step.replayed is None else step.replayed.to_list(),
                        "reason": step.reason,
                    }
                    for step in result.steps
                ],
                **(
                    {
                        "goal_knot_types": sorted(result.goal.knot_types),
                        "tightened": _tightened_dict(result.tightened),
                        "ties_goal": result.ties_goal,
                    }
                    if tighten
                    else {}
                ),
            },
            indent=None,
        )
    else:
        table = Table(title=f"replay of run {run_id}")
        for name in ("step", "link", "recorded state", "replayed state", "same"):
            table.add_column(name)
        for i, step in enumerate(result.steps, start=1):
            replayed = step.replayed.key if step.replayed is not None else f"rejected: {step.reason}"
            same = "yes" if step.matches else "NO"
            table.add_row(str(i), _curve_cells(_curve_row(step.curve))[0], step.recorded.key, replayed, same)
        console.print(table)
        verdict = (
            "[bold green]reaches the goal[/]"
            if result.reached_goal
            else "[bold red]does not reach the goal[/]"
        )
        goal = shown_name(result.goal.label)  # a knot name read back from the store
        console.print(f"run {run_id}: the replayed plan {verdict} {goal}", highlight=False)
        if tighten:
            t = result.tightened
            wanted = ", ".join(sorted(result.goal.knot_types)) or "no knot (the goal state is a knotoid)"
            if t is None:
                console.print("pull test: not run (the replay did not finish)", highlight=False)
            elif not t.ok:
                console.print(f"pull test: [bold red]rejected[/] ({t.reason})", highlight=False)
            else:
                verdict = "[bold green]ties[/]" if result.ties_goal else "[bold red]does not tie[/]"
                console.print(
                    f"pull test: the tightened rope is {t.knot.describe()} (P-data {t.p_data.key}, ends "
                    f"{t.end_distance_m:.2f} m apart, {t.sim_seconds:.1f} s simulated in "
                    f"{t.wall_seconds:.2f} s): "
                    f"it {verdict} the goal's knot ({wanted})",
                    highlight=False,
                )
    raise typer.Exit(EXIT_OK if ok else EXIT_NOT_REACHED)
