"""`twisted plan` and `twisted replay`: search for a low-level plan to a goal state, re-simulate one.

Exit codes: 0 solved (replay: the plan still ends in the goal), 2 bad input (malformed goal, a goal
with more crossings than the model encodes, no model for a planner that needs one, unknown run id,
options that contradict the run being resumed), 3 goal not reached (``--timeout`` or
``--max-iterations`` ran out; replay: the plan no longer reaches the goal), 130 / 143 interrupted
by Ctrl-C / SIGTERM after saving a checkpoint (continue with ``--resume RUN_ID``).
"""

from __future__ import annotations

import json
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
    done_before_interrupt,
    err_console,
    fail,
    open_db,
    shown_name,
    store_exists,
    unwritable,
)
from cli.options import json_option, print_json, with_planner_options
from twisted.planner.runs import SearchProgress, SearchRequest
from twisted.planner.tree import curve_row

# the panels of `plan --help` (the planner's own options: cli.options.PLANNER_PANEL; global ones: cli.app)
GOAL, START, BUDGET, OUTPUT = "Goal", "Start or resume", "Budget and workers", "Output"

Goal = Annotated[
    str | None,
    typer.Option(
        "--goal", help='Goal P-data as JSON, e.g. \'[[1,"O",2,"+"],[2,"U",1,"+"]]\'.', rich_help_panel=GOAL
    ),
]
Knot = Annotated[
    str | None,
    typer.Option(
        "--knot",
        help="Goal by knot name (overhand, figure-eight, 5_1, 5_2, granny, square; see `twisted knots "
        "list`): any rope state that really ties it (both closures are the knot; knotoids never are). "
        "Granny and square are knot types (two trefoils summed), tied as two overhands in a row on the "
        "one rope, not the sailor's reef knot joining two ends.",
        rich_help_panel=GOAL,
    ),
]
Crossings = Annotated[
    int | None,
    typer.Option(
        "--crossings",
        help="With --knot: states of this many crossings (default: the knot's crossing number, "
        "3 overhand, 4 figure-eight, 5 for 5_1/5_2, 6 granny/square).",
        rich_help_panel=GOAL,
    ),
]
Timeout = Annotated[
    float,
    typer.Option(
        "--timeout",
        min=0.0,
        help="Search time limit in seconds (a resumed run's time counts).",
        rich_help_panel=BUDGET,
    ),
]
Workers = Annotated[
    int,
    typer.Option(
        "--workers",
        help="Simulator processes (1: in this process; at most 4 per CPU core).",
        rich_help_panel=BUDGET,
    ),
]
MaxIterations = Annotated[
    int | None,
    typer.Option(
        "--max-iterations",
        min=0,
        help="Also stop after this many iterations (total, for tests).",
        rich_help_panel=BUDGET,
    ),
]
CheckpointEvery = Annotated[
    float,
    typer.Option("--checkpoint-every", min=0.0, help="Seconds between checkpoints.", rich_help_panel=BUDGET),
]
ModelId = Annotated[
    int | None,
    typer.Option(
        "--model",
        help="Model id (twisted: default the newest in the database, else the shipped one; "
        "sac: policy checkpoint id, default the newest).",
        rich_help_panel=START,
    ),
]
StartConfig = Annotated[
    int | None,
    typer.Option(
        "--start-config",
        help="Start from this configurations.id instead of the straight rope.",
        rich_help_panel=START,
    ),
]
FromRun = Annotated[
    int | None,
    typer.Option(
        "--from-run",
        help="Start from where solved run RUN_ID ended (its goal node); the search may remove crossings.",
        rich_help_panel=START,
    ),
]
RemovalCurves = Annotated[
    str | None,
    typer.Option(
        "--removal-curves", help="Curves of a removing step: random (default) | model.", rich_help_panel=START
    ),
]
ResumeRunId = Annotated[
    int | None,
    typer.Argument(metavar="RUN_ID", help="With --resume: the run to continue.", show_default=False),
]
Resume = Annotated[
    bool,
    typer.Option(
        "--resume",
        help="Continue a stopped run: RUN_ID, or the newest unfinished one (for --goal when given).",
        rich_help_panel=START,
    ),
]
Picture = Annotated[
    Path | None,
    typer.Option(
        "--picture",
        help="When solved, draw the final rope to this PNG (with --tighten beside the rope pulled "
        "tight), as `twisted render --run RUN_ID [--tightened]` does.",
        rich_help_panel=OUTPUT,
    ),
]


@app.command("plan")
@with_planner_options("plan")
def plan_command(
    ctx: typer.Context,
    goal: Goal = None,
    knot: Knot = None,
    crossings: Crossings = None,
    timeout_s: Timeout = 1800.0,
    workers: Workers = 2,
    model_id: ModelId = None,
    start_config: StartConfig = None,
    from_run: FromRun = None,
    removal_curves: RemovalCurves = None,
    resume_run_id: ResumeRunId = None,
    resume: Resume = False,
    max_iterations: MaxIterations = None,
    checkpoint_every_s: CheckpointEvery = 2.0,
    picture: Picture = None,
    as_json: bool = json_option("the result", panel=OUTPUT),
    *,
    search_options: dict[str, Any],
) -> None:
    """Search for curves that tie GOAL (Algorithm 1); the search tree goes to the database.

    The set-up (enumerating a knot's states, loading the model, starting the workers) counts toward
    --timeout and stops at Ctrl-C like the search does.
    """
    request = SearchRequest(
        goal=goal,
        knot=knot,
        crossings=crossings,
        options=search_options,  # the planner options (twisted.planner.options), None: not given
        resume=resume,
        run_id=resume_run_id,
        start_config=start_config,
        from_run=from_run,
        removal_curves=removal_curves,
        model_id=model_id,
        **budget(workers, timeout_s, max_iterations, checkpoint_every_s),
    )
    check_search(request)
    if picture is not None:
        picture = _picture_file(picture)
    result, exit_code = run_shown(ctx, request, as_json)
    if result.solved:
        done_before_interrupt(f"run {result.run_id} was solved and stored")
    print_result(result, as_json)
    if result.solved:
        if picture is not None:
            _draw(ctx, result.run_id, picture, result.tighten, as_json)
        raise typer.Exit(EXIT_OK)
    if result.status == "interrupted":
        err_console.print(
            f"interrupted: checkpoint saved; continue with `twisted plan --resume {result.run_id}`",
            highlight=False,
        )
        raise typer.Exit(exit_code)
    raise typer.Exit(EXIT_NOT_REACHED)


def budget(
    workers: int, timeout_s: float, max_iterations: int | None, checkpoint_every_s: float
) -> dict[str, Any]:
    """The :class:`SearchRequest` fields of the options in the "Budget and workers" panel."""
    return {
        "workers": workers,
        "timeout_s": timeout_s,
        "max_iterations": max_iterations,
        "checkpoint_every_s": checkpoint_every_s,
    }


def _picture_file(path: Path) -> Path:
    """``--picture``: a writable PNG path (exit 2 before anything is opened otherwise)."""
    if path.suffix.lower() != ".png":
        fail(f"--picture {path}: the file must end in .png")
    problem = unwritable(path)
    if problem is not None:
        fail(f"--picture {path}: {problem}")
    return path


def _draw(ctx: typer.Context, run_id: int | None, png: Path, tightened: bool, as_json: bool) -> None:
    """Draw a solved run's final rope (beside its pull test when it had one) to ``png``."""
    from twisted.render import RenderError, render_run, render_tightened

    assert run_id is not None
    with open_db(ctx) as store:
        try:
            rendered = render_tightened(store, run_id, png) if tightened else render_run(store, run_id, png)
        except (RenderError, OSError) as exc:
            err_console.print(f"the run is solved, but its picture was not drawn: {exc}", highlight=False)
            return
    if not as_json:
        for path in rendered.files:
            console.print(f"picture: {path}")


def check_search(request: SearchRequest) -> None:
    """Exit 2 on a bad input that needs nothing stored to be seen as such (before anything is opened;
    the goal is checked by the set-up, which can take long for a knot)."""
    from twisted.planner import PlanInputError

    check_workers(request.workers)
    try:
        request.check()
    except PlanInputError as exc:
        fail(str(exc))


def run_shown(ctx: typer.Context, request: SearchRequest, as_json: bool) -> tuple[Any, int]:
    """:func:`twisted.planner.runs.run_search` with a progress bar (none with --json); the result and
    the exit code of a stop. A bad input exits 2; a set-up stopped by --timeout 3, by Ctrl-C / SIGTERM
    130 / 143 (nothing searched)."""
    from twisted.planner import PlanInputError, SetupStopped, run_search
    from twisted.runtime import StopSignals

    stop = StopSignals()
    with stop.installed(), Progress(*_COLUMNS, console=err_console, transient=True, disable=as_json) as bar:
        try:
            result = run_search(_Opener(ctx, request), request, stop, _Bar(bar, request, as_json))
        except PlanInputError as exc:
            fail(str(exc))
        except SetupStopped as exc:
            bar.stop()
            unchanged = f": run {request.run_id} is unchanged" if request.run_id is not None else ""
            what = f"the set-up ({exc.phase}, after {exc.spent_s:.1f} s); nothing was searched{unchanged}"
            if exc.timed_out:
                fail(f"--timeout {request.timeout_s:g} s ran out during {what}", EXIT_NOT_REACHED)
            err_console.print(f"interrupted during {what}", highlight=False)
            raise typer.Exit(stop.exit_code) from None
    return result, stop.exit_code


class _Opener:
    """The store of --db for :func:`run_search`: an existing one only (``create=False``; None when there
    is none), else the one the search writes (a database that does not exist yet is refused when the
    request names something stored)."""

    def __init__(self, ctx: typer.Context, request: SearchRequest) -> None:
        self.ctx, self.request = ctx, request

    def __call__(self, *, create: bool) -> Any:
        if not create:
            return open_db(self.ctx, create=False) if store_exists(self.ctx) else None
        return open_db(self.ctx, needed_by=self.request.needs_stored())


_COLUMNS = (
    TextColumn("[bold]{task.description}"),
    BarColumn(),
    TextColumn("{task.completed:>6.0f}/{task.total:.0f} s"),
    TextColumn("it {task.fields[iteration]}  sims {task.fields[sims]}  nodes {task.fields[nodes]}"),
    TextColumn("states {task.fields[states]}  max cross {task.fields[max_cross]}"),
    TimeElapsedColumn(),
)


class _Bar(SearchProgress):
    """The progress bar of a search: the set-up's steps, then iterations, calls, nodes and states."""

    def __init__(self, bar: Progress, request: SearchRequest, as_json: bool) -> None:
        self.bar, self.as_json = bar, as_json
        self.timeout_s = request.timeout_s if request.timeout_s is not None else float("inf")
        total = max(self.timeout_s, 1e-9)
        self.task = bar.add_task("set-up", total=total, iteration=0, sims=0, nodes=1, states=1, max_cross=0)

    def phase(self, what: str, spent_s: float) -> None:
        self.bar.update(self.task, description=f"set-up: {what}", completed=min(spent_s, self.timeout_s))

    def started(self, search: Any) -> None:
        _print_model(search.sampler, self.as_json)
        self.bar.update(self.task, description=f"run {search.run_id}")

    def iteration(self, search: Any) -> None:
        self.bar.update(
            self.task,
            completed=min(search.elapsed_s, self.timeout_s),
            iteration=search.iteration,
            sims=search.sim_calls,
            nodes=len(search.tree),
            states=len(search.tree.states),
            max_cross=max(p.cross for p in search.tree.states.values()),
        )


def _print_model(sampler: Any, as_json: bool) -> None:
    """Which inverse model the search samples from, and how many samples of each source trained it."""
    from twisted.model.registry import shipped_model_file
    from twisted.planner import model_info

    info = model_info(sampler)
    if not info or as_json:
        return
    sources = info["model_samples"]
    used = info["model_id"]
    # the process's rope has its own shipped file (default_model.pt, model_31c7.pt, ...)
    name = f"(shipped, {shipped_model_file()})" if used is None else used
    err_console.print(
        f"inverse model {name}: trained on "
        + ", ".join(f"{n:,} {source}" for source, n in sources.items() if n)
        + " samples",
        highlight=False,
    )


def _curve_cells(row: dict[str, Any]) -> list[str]:
    """The link, z_max_m, x_m and y_m cells of a plan step's table row (a cinch: "cinch", then blank)."""
    if row["action"] != "curve":
        return [str(row["action"]), "", "", ""]
    return [str(row["link"]), f"{row['z_max_m']:.4f}", f"{row['x_m']:+.4f}", f"{row['y_m']:+.4f}"]


def print_result(result: Any, as_json: bool) -> None:
    """A search's result: its own ``to_dict()`` with --json, else a line and the plan as a table."""
    if as_json:
        print_json(result.to_dict(), indent=None)
        return
    outcome = "[bold green]solved[/]" if result.solved else f"[bold red]not solved ({result.status})[/]"
    expand = result.calls_by_source().get("random_expand", 0)
    console.print(
        f"run {result.run_id}: {outcome}"
        f"  goal {shown_name(result.goal.label)}"  # a knot name read back from the store
        + (f" reached {result.path[-1].p_data.key}" if result.path and result.goal.knot else "")
        + f"  search time {result.elapsed_s:.1f} s (set-up {result.setup_s:.1f} s)"
        f"  simulator calls {result.sim_calls}{f' ({expand} in random expansions)' if expand else ''}"
        f"  iterations {result.iterations}  nodes {result.nodes}  states {result.states}"
        + (f"  pull tests {result.pull_tests}" if result.tighten else ""),
        highlight=False,
    )
    steps = result.plan()
    if steps:
        table = Table(title="low-level plan (curves from the initial configuration)")
        for name in ("step", "link", "z_max_m", "x_m", "y_m", "state after"):
            table.add_column(name, justify="right" if name != "state after" else "left")
        for row in steps:
            table.add_row(
                str(row["step"]), *_curve_cells(row), json.dumps(row["state"], separators=(",", ":"))
            )
        console.print(table)


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
        print_json(result.to_dict(), indent=None)
    else:
        table = Table(title=f"replay of run {run_id}")
        for name in ("step", "link", "recorded state", "replayed state", "same"):
            table.add_column(name)
        for i, step in enumerate(result.steps, start=1):
            replayed = step.replayed.key if step.replayed is not None else f"rejected: {step.reason}"
            same = "yes" if step.matches else "NO"
            table.add_row(str(i), _curve_cells(curve_row(step.curve))[0], step.recorded.key, replayed, same)
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
