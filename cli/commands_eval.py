"""`twisted eval`, `twisted report`, `twisted compare`: run a planner on every goal of a set, and report
and compare the stored results. The helpers here also serve `twisted sensitivity run`."""

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
    shown_name,
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


def run_evaluations(
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


def given_planner_options(model_id: int | None, given: dict[str, Any]) -> dict[str, Any]:
    """The planner options given (None: the planner's default) but the planner kind, as the evaluation
    stores them."""
    options: dict[str, Any] = {**given, "model_id": model_id}
    return {name: v for name, v in options.items() if v is not None and name != "planner"}


def default_planner() -> str:
    from twisted.planner import PlannerOptions

    return PlannerOptions.planner


def default_parallel() -> int:
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
    parallel = parallel or (0 if use_ray else default_parallel())
    planner = search_options["planner"] or default_planner()
    options = given_planner_options(model_id, search_options)
    requests = [
        EvalOptions(name, planner, timeout_s, list(seeds), friction_scale, workers, parallel, options, label)
        for name in dict.fromkeys(set_names)
    ]
    run_evaluations(ctx, requests, use_ray, ray_address)


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

    check_out_folder(out)
    with open_db(ctx, readonly=True) as store:
        files = write_report(store, out, sets or None)
    console.print(f"wrote {files.markdown}")
    for p in files.plots + files.sensitivity:
        console.print(f"wrote {p}")
    if not files.plots:
        err_console.print("no finished evaluation results yet: run `twisted eval` first")


def check_out_folder(out: Path) -> None:
    """``--out`` of report / sensitivity plot: a folder to write into (exit 2 before anything is opened)."""
    from cli.app import unwritable_folder

    problem = unwritable_folder(out, "report.md")
    if problem is not None:
        fail(f"--out {out}: {problem}")


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
        a, b = shown_name(label_a), shown_name(label_b)
        table = Table("", a, b, f"{a} / {b}", title=f"{shown_name(c.scope)}: {a} against {b}")
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
