"""Experiments: `twisted problems make|import|list`, `twisted eval`, `twisted report`,
`twisted sensitivity run|plot`, `twisted discretise`, `twisted render`."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from cli.app import (
    app,
    check_workers,
    console,
    db_url,
    err_console,
    fail,
    open_db,
    seed_option,
    subcommands,
    unwritable,
)
from cli.options import (
    DEFAULT_SEEDS,
    Seeds,
    json_option,
    print_json,
    ray_address_argument,
    result_flags,
    seeds_option,
    with_planner_options,
)

if TYPE_CHECKING:
    from twisted.experiments import EvalOptions
    from twisted.experiments.runner import PreparedEval

problems_app = subcommands("problems", "Goal sets for evaluations (made from our data or imported).")
sensitivity_app = subcommands("sensitivity", "Friction sensitivity: evaluate at 95/100/105 % and plot.")


def _print_sets(records: list[Any]) -> None:
    table = Table("set", "goals", "cross", "frequency (min-max)", "tags")
    for r in records:
        freqs = [p.frequency for p in r.problems]
        tags = sorted({p.tag for p in r.problems})
        crosses = sorted({p.p_data.cross for p in r.problems})
        table.add_row(
            r.name,
            str(len(r.problems)),
            ",".join(map(str, crosses)),
            f"{min(freqs)}-{max(freqs)}" if freqs else "-",
            ", ".join(tags),
        )
    console.print(table)


@problems_app.command("make")
def problems_make(
    ctx: typer.Context,
    seed: int = seed_option(0, "Seed of the draw; the same seed gives the same sets."),
    per_set: int = typer.Option(10, "--per-set", min=1, help="Goals per set (10 in the paper)."),
    prefix: str = typer.Option("", "--prefix", help="Prefix of the set names (e.g. 's1-' -> s1-easy)."),
    replace: bool = typer.Option(
        False, "--replace", help="Replace sets of the same name that have no results."
    ),
    sets: Annotated[
        list[str] | None,
        typer.Option(
            "--set", help="Only these sets (easy, medium, hard, unseen-3, 4, 5); repeatable. Default: all."
        ),
    ] = None,
) -> None:
    """Make easy/medium/hard (3-crossing states by visit frequency), unseen-3 and 4 from our data."""
    from twisted.experiments import EvalInputError, make_problem_sets_in_store
    from twisted.experiments.problems import ALL_MADE_SETS

    unknown = [name for name in sets or () if name not in ALL_MADE_SETS]
    if unknown:
        fail(f"--set {unknown[0]}: no such set; choose from {', '.join(ALL_MADE_SETS)}")
    with open_db(ctx) as store:
        try:
            records = make_problem_sets_in_store(
                store, per_set=per_set, seed=seed, prefix=prefix, replace=replace, sets=sets or ALL_MADE_SETS
            )
        except EvalInputError as exc:
            fail(str(exc))
    _print_sets(records)


@problems_app.command("import")
def problems_import(
    ctx: typer.Context,
    file: Annotated[Path, typer.Argument(help="JSON: a list of P-data, or an object of named lists.")],
    name: str = typer.Option(
        None, "--name", help="Set name (a list) or prefix of the set names (an object)."
    ),
) -> None:
    """Import goal sets from a JSON file (every state is checked; nothing is stored on an error)."""
    from twisted.experiments import EvalInputError, import_problem_sets

    try:
        text = file.read_text()
    except OSError as exc:
        fail(f"cannot read goal file {str(file)!r}: {exc.strerror}")
    with open_db(ctx) as store:
        try:
            records = import_problem_sets(store, text, name)
        except EvalInputError as exc:
            fail(f"{file}: {exc}")
    _print_sets(records)


@problems_app.command("knots")
def problems_knots(
    ctx: typer.Context,
    knots: Annotated[
        list[str],
        typer.Argument(help="Knots (see `twisted knots list`): NAME or NAME@CROSSINGS, e.g. overhand@3."),
    ],
    name: str = typer.Option(..., "--name", help="Name of the new set."),
) -> None:
    """Make a set of knot goals: each is reached by any rope state that ties the knot."""
    from twisted.experiments import EvalInputError, save_goal_sets
    from twisted.goals import GoalError, goal_from_spec

    goals = []
    for i, knot in enumerate(knots, start=1):
        if knot.strip().startswith("["):
            fail(f"knot {i} ({knot!r}) is P-data: put P-data goals in a file for `twisted problems import`")
        try:
            goals.append(goal_from_spec(knot))
        except GoalError as exc:
            fail(f"knot {i} ({knot!r}): {exc}")
    with open_db(ctx) as store:
        try:
            records = save_goal_sets(store, {name: goals}, "knot")
        except EvalInputError as exc:
            fail(str(exc))
    _print_sets(records)


@problems_app.command("list")
def problems_list(
    ctx: typer.Context,
    show: str = typer.Option(None, "--show", help="Also print the goals of this set."),
    as_json: bool = json_option("the sets (with --show: that set's goals, importable)"),
) -> None:
    """The stored problem sets (and the goals of one with --show)."""
    from twisted.store.experiments import list_problem_sets, load_problem_set

    with open_db(ctx) as store, store.session() as session:
        sets = list_problem_sets(session)
        record = load_problem_set(session, show) if show else None
    if show and record is None:
        fail(f"no problem set {show!r}: see `twisted problems list`")
    if record is not None and as_json:
        print_json([p.p_data.to_list() if p.spec is None else p.spec for p in record.problems])
        return
    if as_json:
        print_json(sets)
        return
    table = Table("id", "set", "source", "seed", "goals", "cross", "frequency", "results")
    for s in sets:
        table.add_row(
            str(s["id"]),
            s["name"],
            s["source"],
            "-" if s["seed"] is None else str(s["seed"]),
            str(s["problems"]),
            "-".join(map(str, sorted(set(s["cross"])))) if s["cross"][0] is not None else "-",
            f"{s['frequency'][0]}-{s['frequency'][1]}" if s["frequency"][0] is not None else "-",
            str(s["results"]),
        )
    console.print(table)
    if record is not None:
        goals = Table("#", "goal", "cross", "frequency", "tag")
        for p in record.problems:
            goals.add_row(str(p.idx), p.goal_key, str(p.p_data.cross), str(p.frequency), p.tag)
        console.print(goals)


def _eval(
    ctx: typer.Context,
    requests: list[EvalOptions],
    use_ray: bool = False,
    ray_address: str | None = None,
) -> list[Any]:
    """Run the evaluations one after another; all of them are checked first, so that a bad second set
    is refused before the first one runs."""
    from twisted.distributed import RayBackend
    from twisted.experiments import EvalInputError
    from twisted.experiments.runner import ProcessBackend, prepare_eval

    backend = RayBackend(ray_address) if use_ray else ProcessBackend()
    needed_by = "--set " + ", ".join(dict.fromkeys(r.set_name for r in requests))
    with open_db(ctx, needed_by=needed_by) as store:
        try:
            prepared = [prepare_eval(store, request, backend.min_parallel) for request in requests]
        except EvalInputError as exc:
            fail(str(exc))
        return [_eval_one(ctx, store, p, backend) for p in prepared]


def _eval_one(ctx: typer.Context, store: Any, prepared: PreparedEval, backend: Any) -> Any:
    from twisted.distributed import DistributedError
    from twisted.experiments.runner import run_prepared

    columns = (
        TextColumn(f"[bold]{prepared.set_name} / {prepared.planner} / friction {prepared.friction_scale:g}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("solved {task.fields[solved]}"),
        TimeElapsedColumn(),
    )
    with Progress(*columns, console=console) as bar:
        task_id = None

        def on_start(summary: Any, pending: int) -> None:
            nonlocal task_id
            if summary.already_done:
                console.print(f"{summary.already_done} of {summary.total} already finished: not rerun")
            task_id = bar.add_task("eval", total=pending, solved=0)

        def on_outcome(outcome: Any, summary: Any) -> None:
            if task_id is not None:
                bar.update(task_id, advance=1, solved=summary.solved)
            if outcome.status == "failed":
                err_console.print(f"goal {outcome.goal_key} seed {outcome.seed} failed: {outcome.message}")

        try:
            summary = run_prepared(
                store,
                db_url(ctx),
                prepared,
                backend,  # --ray: the same tasks as Ray tasks
                on_start=on_start,
                on_outcome=on_outcome,
            )
        except DistributedError as exc:
            fail(str(exc))
        except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM
            from twisted import runtime

            err_console.print(
                "interrupted: finished goals are stored; run the same command again to continue"
            )
            raise typer.Exit(runtime.exit_code(exc) or 130) from None
    counts: dict[str, int] = {}
    for o in summary.outcomes:
        counts[o.status] = counts.get(o.status, 0) + 1
    ran = ", ".join(f"{n} {s}" for s, n in sorted(counts.items())) or "nothing left to run"
    console.print(
        f"eval run {summary.eval_run_id} ({prepared.set_name}, {summary.planner}): {summary.total} goal x "
        f"seed, {summary.already_done} finished before; this time: {ran}"
    )
    return summary


def _planner_options(model_id: int | None, given: dict[str, Any]) -> dict[str, Any]:
    """The planner options given (None: the planner's default) but the planner kind, as the evaluation
    stores them."""
    options: dict[str, Any] = {**given, "model_id": model_id}
    return {name: v for name, v in options.items() if v is not None and name != "planner"}


def _default_planner() -> str:
    from twisted.planner import PlannerOptions

    return PlannerOptions.planner


def _default_parallel() -> int:
    from twisted.runtime import cpu_cores

    return cpu_cores()


@app.command("eval")
@with_planner_options("eval")
def eval_command(
    ctx: typer.Context,
    set_names: Annotated[
        list[str],
        typer.Option(
            "--set", help="Problem set (see `twisted problems list`); repeatable: the sets run in turn."
        ),
    ],
    timeout_s: float = typer.Option(
        1800.0, "--timeout", min=0.0, help="Search time per goal in seconds (paper: 1800)."
    ),
    workers: int = typer.Option(
        1, "--workers", min=1, help="Simulator processes per planner (1 = in-process)."
    ),
    seeds: Annotated[Seeds, seeds_option()] = DEFAULT_SEEDS,
    friction_scale: float = typer.Option(
        1.0, "--friction-scale", min=0.01, max=100.0, help="Rope friction factor (0.95/1.05)."
    ),
    parallel: int = typer.Option(0, "--parallel", min=0, help="Goals at once (0 = one per CPU core)."),
    model_id: int = typer.Option(
        None, "--model", help="Inverse model id (twisted) or policy checkpoint id (sac); default: the newest."
    ),
    label: str = typer.Option(
        None,
        "--label",
        help="Name the results are stored under (default: planner[-heuristic]); results under one label "
        f"must share the model and {result_flags()}.",
    ),
    use_ray: bool = typer.Option(
        False, "--ray", help="Run the goals as tasks on a Ray cluster (--parallel 0: its CPUs); see ADDRESS."
    ),
    ray_address: str | None = ray_address_argument(),
    *,
    search_options: dict[str, Any],
) -> None:
    """Run a planner on every goal of a set; results are stored, a rerun continues where it stopped."""
    from twisted.distributed import DistributedError, import_ray, resolve_address
    from twisted.experiments import EvalOptions

    try:
        ray_address = resolve_address(use_ray, ray_address)
        if use_ray:
            import_ray()
    except DistributedError as exc:
        fail(str(exc))
    check_workers(workers)
    if not use_ray:
        check_workers(parallel or None, "--parallel")
    parallel = parallel or (0 if use_ray else _default_parallel())
    planner = search_options["planner"] or _default_planner()
    options = _planner_options(model_id, search_options)
    requests = [
        EvalOptions(name, planner, timeout_s, list(seeds), friction_scale, workers, parallel, options, label)
        for name in dict.fromkeys(set_names)
    ]
    _eval(ctx, requests, use_ray, ray_address)


@app.command("report")
def report_command(
    ctx: typer.Context,
    out: Annotated[Path, typer.Option("--out", help="Folder for report.md and the PNG plots.")] = Path(
        "report"
    ),
    sets: Annotated[list[str] | None, typer.Option("--set", help="Only these sets (repeatable).")] = None,
) -> None:
    """Success-vs-time curves (PNG, one per set) and a Markdown table from the stored results."""
    from twisted.experiments import write_report

    with open_db(ctx) as store:
        files = write_report(store, out, sets or None)
    console.print(f"wrote {files.markdown}")
    for p in files.plots + files.sensitivity:
        console.print(f"wrote {p}")
    if not files.plots:
        err_console.print("no finished evaluation results yet: run `twisted eval` first")


def _figure(x: float | None, fmt: str = ",.0f") -> str:
    return "-" if x is None else format(x, fmt)


def _interval(interval: tuple[float, float] | None) -> str:
    return "" if interval is None else f" [{interval[0]:.2f}, {interval[1]:.2f}]"


@app.command("compare")
def compare_command(
    ctx: typer.Context,
    label_a: Annotated[str, typer.Argument(metavar="A", help="Label of the eval results to measure.")],
    label_b: Annotated[str, typer.Argument(metavar="B", help="Label to measure it against.")],
    sets: Annotated[list[str] | None, typer.Option("--set", help="Only these sets (repeatable).")] = None,
    seeds: Annotated[Seeds | None, seeds_option()] = None,
    as_json: bool = json_option("the comparisons"),
) -> None:
    """Compare two eval labels run by run: the same goals, seeds, timeout and friction scale (all
    seeds and sets both ran unless --seeds / --set narrow them)."""
    from twisted.experiments import EvalInputError
    from twisted.experiments.compare import compare_in_store

    if label_a == label_b:
        fail(f"A and B are both {label_a!r}: give two different labels")
    with open_db(ctx, readonly=True, needed_by=f"labels {label_a!r} and {label_b!r}") as store:
        try:
            comparisons = compare_in_store(store, label_a, label_b, sets=sets or None, seeds=seeds)
        except EvalInputError as exc:
            fail(str(exc))
    if as_json:
        print_json([c.to_dict() for c in comparisons])
        return
    for c in comparisons:
        table = Table(
            "", label_a, label_b, f"{label_a} / {label_b}", title=f"{c.scope}: {label_a} against {label_b}"
        )
        table.add_row("runs (paired by goal and seed)", str(c.a.runs), str(c.b.runs), "")
        table.add_row("solved", str(c.a.solved), str(c.b.solved), "")
        table.add_row(
            "median time to solve (s)",
            _figure(c.a.median_time_s, ".1f"),
            _figure(c.b.median_time_s, ".1f"),
            "",
        )
        table.add_row("calls to solve (mean)", _figure(c.a.calls_to_solve), _figure(c.b.calls_to_solve), "")
        table.add_row(
            f"calls per goal, both solved ({c.both_solved})",
            _figure(c.calls_both_a),
            _figure(c.calls_both_b),
            f"{_figure(c.calls_both_ratio, '.2f')}{_interval(c.calls_both_interval)}; "
            f"median per run {_figure(c.median_ratio, '.2f')}; fewer in {c.a_fewer}/{c.both_solved}",
        )
        table.add_row(
            "all calls per solved goal",
            _figure(c.a.all_calls_per_solved),
            _figure(c.b.all_calls_per_solved),
            _figure(c.all_calls_ratio, ".2f") + _interval(c.all_calls_interval),
        )
        console.print(table)
    if any(c.calls_both_interval or c.all_calls_interval for c in comparisons):
        console.print("(in brackets: 95 % interval of the ratio, goals resampled with all their runs)")
    unpaired = comparisons[-1]
    if unpaired.only_a or unpaired.only_b:
        err_console.print(
            f"not compared: {unpaired.only_a} runs only under {label_a}, "
            f"{unpaired.only_b} only under {label_b}"
        )


@sensitivity_app.command("run")
@with_planner_options("sensitivity")
def sensitivity_run(
    ctx: typer.Context,
    set_name: str = typer.Option(..., "--set", help="Problem set."),
    timeout_s: float = typer.Option(1800.0, "--timeout", min=0.0, help="Search time per goal in seconds."),
    scales: Annotated[
        list[float] | None, typer.Option("--scales", help="Friction factors (default 0.95 1.0 1.05); repeat.")
    ] = None,
    seeds: Annotated[Seeds, seeds_option()] = DEFAULT_SEEDS,
    workers: int = typer.Option(1, "--workers", min=1),
    parallel: int = typer.Option(0, "--parallel", min=0, help="Goals at once (0 = one per CPU core)."),
    model_id: int = typer.Option(None, "--model"),
    label: str = typer.Option(None, "--label", help="Name the results are stored under."),
    *,
    search_options: dict[str, Any],
) -> None:
    """Evaluate one planner on a set at several friction scales (finished results are reused)."""
    from twisted.experiments import EvalInputError, EvalOptions
    from twisted.experiments.sensitivity import check_scales

    try:
        chosen = check_scales(scales)
    except EvalInputError as exc:
        fail(str(exc))
    check_workers(workers)
    check_workers(parallel or None, "--parallel")
    parallel = parallel or _default_parallel()
    options = _planner_options(model_id, search_options)
    planner = search_options["planner"] or _default_planner()
    requests = [
        EvalOptions(set_name, planner, timeout_s, list(seeds), scale, workers, parallel, options, label)
        for scale in chosen
    ]
    _eval(ctx, requests)


@sensitivity_app.command("plot")
def sensitivity_plot(
    ctx: typer.Context,
    out: Annotated[Path, typer.Option("--out", help="Folder for the PNG plots.")] = Path("report"),
    sets: Annotated[list[str] | None, typer.Option("--set", help="Only these sets (repeatable).")] = None,
) -> None:
    """Friction plots (one line per scale) for every set/planner evaluated at several scales."""
    from twisted.experiments import write_report

    with open_db(ctx) as store:
        files = write_report(store, out, sets or None)
    if not files.sensitivity:
        fail(
            "no set/planner has finished results at more than one friction scale: "
            "run `twisted sensitivity run`"
        )
    for p in files.sensitivity:
        console.print(f"wrote {p}")


@app.command("discretise")
def discretise_command(
    ctx: typer.Context,
    n: int = typer.Option(1000, "--n", min=1, help="Stored transitions to re-simulate."),
    seed: int = seed_option(0, "Seed of the draw of transitions."),
    from_cross: int = typer.Option(2, "--from-cross", help="Transitions from this crossing count (-1: any)."),
    to_cross: int = typer.Option(3, "--to-cross", help="... to this crossing count (-1: any)."),
    workers: int = typer.Option(0, "--workers", min=0, help="Simulator processes (0 = one per CPU core)."),
    friction_scale: float = typer.Option(
        None,
        "--friction-scale",
        min=0.01,
        max=100.0,
        help="Also re-simulate the unrounded curve at this friction (e.g. 1.05).",
    ),
) -> None:
    """Discretisation experiment (paper 5.1): share of transitions whose state changes when rounded."""
    from twisted.experiments import EvalInputError, run_discretisation
    from twisted.experiments.discretise import PAPER_DISCRETISATION_CHANGED

    check_workers(workers or None)
    workers = workers or _default_parallel()
    columns = (TextColumn("[bold]re-simulating"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    # the stored transitions are re-simulated: a new database has none
    with open_db(ctx, create=False) as store, Progress(*columns, console=console) as bar:
        task_id = bar.add_task("discretise", total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task_id, completed=done, total=total)

        try:
            summary = run_discretisation(
                store,
                n=n,
                seed=seed,
                from_cross=None if from_cross < 0 else from_cross,
                to_cross=None if to_cross < 0 else to_cross,
                workers=workers,
                friction_scale=friction_scale,
                progress=progress,
            )
        except EvalInputError as exc:
            fail(str(exc))
    table = Table("variant", "friction", "transitions", "changed", "share changed", "rejected")
    for v in summary.variants:
        table.add_row(
            v.variant,
            f"{v.friction_scale:g}",
            str(v.transitions),
            str(v.changed),
            f"{v.share_changed:.1%}",
            str(v.rejected),
        )
    console.print(table)
    tested = summary.variants[0].transitions if summary.variants else 0
    console.print(
        f"run {summary.run_id}: {tested} of {summary.available} matching transitions re-simulated; "
        f"the paper: {PAPER_DISCRETISATION_CHANGED:.0%} changed when rounded"
    )


def _output_file(option: str, path: Path, suffix: str) -> Path:
    """The file a picture is written to: ``path``, with ``suffix`` added when it has none (exit 2 when it
    has another, or its folder cannot be created or written)."""
    if path.suffix.lower() != suffix:
        if path.suffix:
            fail(f"{option} {path}: the file must end in {suffix} (it is written as {suffix[1:].upper()})")
        path = path.with_name(path.name + suffix)
    problem = unwritable(path)
    if problem is not None:
        fail(f"{option} {path}: {problem}")
    return path


@app.command("render")
def render_command(
    ctx: typer.Context,
    config: int = typer.Option(None, "--config", help="A configuration id: PNG of the rope."),
    run: int = typer.Option(
        None, "--run", help="A solved planner run: PNG of the final rope + GIF of the plan."
    ),
    goal: str = typer.Option(None, "--goal", help="A P-data state (JSON): knot diagram / Gauss diagram."),
    out: Annotated[
        Path | None, typer.Option("--out", help="Output PNG (default: config-ID.png, run-ID.png, goal.png).")
    ] = None,
    gif: Annotated[
        Path | None, typer.Option("--gif", help="Output GIF of --run (default: beside the PNG).")
    ] = None,
    gl: bool = typer.Option(
        True, "--gl/--no-gl", help="Use MuJoCo's offscreen OpenGL (EGL/OSMesa) if it works."
    ),
    tightened: bool = typer.Option(
        False,
        "--tightened",
        help="With --run: the plan's final rope beside the same rope pulled tight (runs the pull test of "
        "`twisted replay --tighten` first when none is stored).",
    ),
) -> None:
    """Draw a configuration, a run's plan or a goal state (look before you read)."""
    from twisted.render import RenderError, render_configuration, render_goal, render_run, render_tightened
    from twisted.topology import PDataError

    chosen = [
        name for name, value in (("--config", config), ("--run", run), ("--goal", goal)) if value is not None
    ]
    if len(chosen) != 1:
        fail("give exactly one of --config ID, --run ID or --goal P-DATA")
    if tightened and run is None:
        fail("--tightened draws a run: give --run ID")
    if gif is not None and run is None:
        fail("--gif goes with --run (a plan is drawn as a GIF)")
    p_data = None
    if goal is not None:
        from twisted.moves import parse_state

        try:
            p_data = parse_state(goal, "--goal")
        except PDataError as exc:
            fail(str(exc))
    default = f"config-{config}.png" if config is not None else f"run-{run}.png"
    if run is not None and tightened:
        default = f"run-{run}-tightened.png"
    if goal is not None:
        default = "goal.png"
    png = _output_file("--out", out or Path(default), ".png")
    gif_path = None
    if run is not None and not tightened:
        gif_path = _output_file("--gif", gif or png.with_suffix(".gif"), ".gif")
    needs = f"--config {config}" if config is not None else None if run is None else f"--run {run}"
    with open_db(ctx, needed_by=needs) as store:
        try:
            if config is not None:
                rendered = render_configuration(store, config, png, gl=gl)
            elif run is not None and tightened:
                from twisted.planner import PlanInputError, replay
                from twisted.store.knots import tightenings

                with store.session() as session:
                    stored = any(t.ok for t in tightenings(session, run))
                if not stored:
                    try:
                        replay(store, run, tighten=True)
                    except PlanInputError as exc:
                        fail(str(exc))
                rendered = render_tightened(store, run, png)
            elif run is not None:
                rendered = render_run(store, run, png, gif_path, gl=gl)
            else:
                assert p_data is not None
                rendered = render_goal(store, p_data, png)
        except RenderError as exc:
            fail(str(exc))
        except OSError as exc:  # the checks above cannot foresee everything (a full disk)
            fail(f"cannot write {exc.filename or png}: {exc.strerror}")
    for path in rendered.files:
        console.print(f"wrote {path}")
    console.print(f"drawn with: {rendered.backend}")
