"""`twisted discretise`: the discretisation experiment (paper 5.1)."""

from __future__ import annotations

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from cli.app import (
    app,
    check_workers,
    console,
    fail,
    open_db,
    seed_option,
)
from cli.commands_eval import default_parallel


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
    workers = workers or default_parallel()
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
