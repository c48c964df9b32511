"""`twisted sensitivity run|plot`: one evaluation per friction scale, and its plots."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from cli.app import (
    check_workers,
    console,
    fail,
    open_db,
    subcommands,
)
from cli.commands_eval import (
    check_out_folder,
    default_parallel,
    default_planner,
    given_planner_options,
    run_evaluations,
)
from cli.options import (
    DEFAULT_SEEDS,
    Seeds,
    seeds_option,
    with_planner_options,
)

sensitivity_app = subcommands("sensitivity", "Friction sensitivity: evaluate at 95/100/105 % and plot.")


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
    parallel = parallel or default_parallel()
    options = given_planner_options(model_id, search_options)
    planner = search_options["planner"] or default_planner()
    requests = [
        EvalOptions(set_name, planner, timeout_s, list(seeds), scale, workers, parallel, options, label)
        for scale in chosen
    ]
    run_evaluations(ctx, requests)


@sensitivity_app.command("plot")
def sensitivity_plot(
    ctx: typer.Context,
    out: Annotated[Path, typer.Option("--out", help="Folder for the PNG plots.")] = Path("report"),
    sets: Annotated[list[str] | None, typer.Option("--set", help="Only these sets (repeatable).")] = None,
) -> None:
    """Friction plots (one line per scale) for every set/planner evaluated at several scales."""
    from twisted.experiments import write_report

    check_out_folder(out)
    with open_db(ctx, readonly=True) as store:
        files = write_report(store, out, sets or None)
    if not files.sensitivity:
        fail(
            "no set/planner has finished results at more than one friction scale: "
            "run `twisted sensitivity run`"
        )
    for p in files.sensitivity:
        console.print(f"wrote {p}")
