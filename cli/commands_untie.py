"""`twisted untie`: straighten the rope a stored run ended with (plan to the straight rope ``[]``).

The search is `twisted plan --from-run RUN_ID --goal '[]'`: Algorithm 1 with moves that remove
crossings (twisted.planner.untie); its tree, checkpoints and resume are a plan run's. Exit codes as
`twisted plan`: 0 straightened, 2 bad input (unknown or unsolved run, ...), 3 not reached in time,
130 / 143 interrupted after saving a checkpoint (continue with `twisted untie --resume UNTIE_RUN_ID`).
"""

from __future__ import annotations

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
from cli.commands_plan import _check, _print_result, _Request, _search
from cli.options import json_option


@app.command("untie")
def untie_command(
    ctx: typer.Context,
    run_id: int = typer.Argument(
        ...,
        metavar="RUN_ID",
        help="A solved planner run whose end configuration is to be straightened (with --resume: the "
        "untie run to continue).",
    ),
    timeout_s: float = typer.Option(
        1800.0, "--timeout", min=0.0, help="Search time limit in seconds (a resumed run's time counts)."
    ),
    planner: str | None = typer.Option(
        None, "--planner", help="twisted (default: the inverse model for adding steps) | random-low."
    ),
    removal_curves: str | None = typer.Option(
        None, "--removal-curves", help="Curves of a removing step: random (default) | model."
    ),
    workers: int = typer.Option(
        2, "--workers", help="Simulator processes (1: in this process; at most 4 per CPU core)."
    ),
    seed: int | None = seed_option(None, "Seed of the search (default 0)."),
    model_id: int | None = typer.Option(
        None, "--model", help="Inverse model id (default: the newest in the database, else the shipped one)."
    ),
    resume: bool = typer.Option(False, "--resume", help="Continue the stopped untie run RUN_ID."),
    max_iterations: int | None = typer.Option(
        None, "--max-iterations", min=0, help="Also stop after this many iterations (total, for tests)."
    ),
    checkpoint_every_s: float = typer.Option(
        2.0, "--checkpoint-every", min=0.0, help="Seconds between checkpoints."
    ),
    as_json: bool = json_option("the result"),
) -> None:
    """Plan from where run RUN_ID ended to the straight rope, removing crossings (see docs/untie.md)."""
    request = _Request(
        goal=None if resume else "[]",
        knot=None,
        crossings=None,
        resume=resume,
        run_id=run_id if resume else None,
        start_config=None,
        model_id=model_id,
        workers=workers,
        as_json=as_json,
        from_run=None if resume else run_id,
        removal_curves=removal_curves,
        search_options={"planner": planner, "seed": seed},
    )
    _check(request)
    if resume:
        _check_untie_run(ctx, run_id)
    search, result, setup_s, exit_code = _search(ctx, request, timeout_s, max_iterations, checkpoint_every_s)
    if result.solved:
        done_before_interrupt(f"run {result.run_id} was solved and stored")
    _print_result(search, result, as_json, setup_s)
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
