"""`twisted untie`: straighten the rope a stored run ended with (plan to the straight rope ``[]``).

The search is `twisted plan --from-run RUN_ID --goal '[]'`: Algorithm 1 with moves that remove
crossings (twisted.planner.untie); its tree, checkpoints and resume are a plan run's. Exit codes as
`twisted plan`: 0 straightened, 2 bad input (unknown or unsolved run, ...), 3 not reached in time,
130 / 143 interrupted after saving a checkpoint (continue with `twisted untie --resume UNTIE_RUN_ID`).
"""

from __future__ import annotations

from typing import Annotated

import typer

from cli.app import (
    EXIT_NOT_REACHED,
    EXIT_OK,
    app,
    done_before_interrupt,
    err_console,
    fail,
    open_db,
    seed_option,
)
from cli.commands_plan import (
    OUTPUT,
    START,
    CheckpointEvery,
    MaxIterations,
    RemovalCurves,
    Timeout,
    Workers,
    budget,
    check_search,
    print_result,
    run_shown,
)
from cli.options import PLANNER_PANEL, json_option
from twisted.planner.session import SearchRequest

RunId = Annotated[
    int,
    typer.Argument(
        metavar="RUN_ID",
        help="A solved planner run whose end configuration is to be straightened (with --resume: the "
        "untie run to continue).",
    ),
]


@app.command("untie")
def untie_command(
    ctx: typer.Context,
    run_id: RunId,
    timeout_s: Timeout = 1800.0,
    planner: str | None = typer.Option(
        None,
        "--planner",
        help="twisted (default: the inverse model for adding steps) | random-low.",
        rich_help_panel=PLANNER_PANEL,
    ),
    removal_curves: RemovalCurves = None,
    workers: Workers = 2,
    seed: int | None = seed_option(None, "Seed of the search (default 0)."),
    model_id: int | None = typer.Option(
        None,
        "--model",
        help="Inverse model id (default: the newest in the database, else the shipped one).",
        rich_help_panel=START,
    ),
    resume: bool = typer.Option(
        False, "--resume", help="Continue the stopped untie run RUN_ID.", rich_help_panel=START
    ),
    max_iterations: MaxIterations = None,
    checkpoint_every_s: CheckpointEvery = 2.0,
    as_json: bool = json_option("the result", panel=OUTPUT),
) -> None:
    """Plan from where run RUN_ID ended to the straight rope, removing crossings (see docs/untie.md)."""
    request = SearchRequest(
        goal=None if resume else "[]",
        options={"planner": planner, "seed": seed},
        resume=resume,
        run_id=run_id if resume else None,
        from_run=None if resume else run_id,
        removal_curves=removal_curves,
        model_id=model_id,
        **budget(workers, timeout_s, max_iterations, checkpoint_every_s),
    )
    check_search(request)
    if resume:
        _check_untie_run(ctx, run_id)
    result, exit_code = run_shown(ctx, request, as_json)
    if result.solved:
        done_before_interrupt(f"run {result.run_id} was solved and stored")
    print_result(result, as_json)
    interrupted = result.status == "interrupted"
    if interrupted:
        resume_hint = f"`twisted untie --resume {result.run_id}`"
        err_console.print(f"interrupted: checkpoint saved; continue with {resume_hint}", highlight=False)
    raise typer.Exit(EXIT_OK if result.solved else exit_code if interrupted else EXIT_NOT_REACHED)


def _check_untie_run(ctx: typer.Context, run_id: int) -> None:
    """``--resume RUN_ID``: exit 2 unless the run is an untie run (a tying search is `plan --resume`'s)."""
    from twisted.planner import PlanInputError
    from twisted.planner.untie import check_untie_run

    with open_db(ctx, readonly=True, needed_by=f"--resume {run_id}") as store:
        try:
            check_untie_run(store, run_id)
        except PlanInputError as exc:
            fail(str(exc))
