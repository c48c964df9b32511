"""`twisted improve` (expert iteration, docs/goals.md) and `twisted problems export` (goal-set files)."""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table

from cli.app import app, console, err_console, fail, open_db, seed_option, unwritable
from cli.commands_problems import problems_app
from cli.options import parse_device

Draw = Annotated[
    list[str] | None,
    typer.Option("--draw", help="Training-goal distributions, taken in turn: u4, u5, u6 (default u4 u5)."),
]
Goalsets = Annotated[
    Path | None,
    typer.Option(
        "--goalsets",
        help="Goal-set files; final-, eval-, tune-*.json are evaluation goals (default: the project's "
        "goalsets/, wherever the command runs).",
    ),
]
Device = Annotated[
    str, typer.Option("--device", parser=parse_device, metavar="DEVICE", help="Fine-tune on cpu or cuda.")
]


@app.command("improve")
def improve_command(
    ctx: typer.Context,
    tune_set: str = typer.Option(..., "--tune-set", help="Stored problem set each generation is scored on."),
    hours: float = typer.Option(1.0, "--hours", help="Stop after this time (a later call continues)."),
    name: str = typer.Option("improve", "--name", help="The lineage: a later call with it continues."),
    seed: int = seed_option(0, "Seed of the training goals, the searches and the training."),
    generations: int = typer.Option(3, "--generations", help="Generations after generation 0."),
    goals: int = typer.Option(8, "--goals", help="Training goals per generation."),
    draw: Draw = None,
    train_set: str | None = typer.Option(
        None, "--train-set", help="A stored set as the training goals (never an evaluation set)."
    ),
    goal_timeout: float = typer.Option(60.0, "--goal-timeout", help="Search seconds per training goal."),
    goal_iterations: int | None = typer.Option(
        None, "--goal-iterations", help="Also stop a training search after this many iterations."
    ),
    tune_goals: int | None = typer.Option(None, "--tune-goals", help="Score on the set's first N goals."),
    tune_iterations: int | None = typer.Option(
        None,
        "--tune-iterations",
        help="Also stop a tuning search after this many iterations (a budget load does not move).",
    ),
    tune_seeds: int = typer.Option(1, "--tune-seeds", help="Seeds per tuning goal."),
    tune_timeout: float = typer.Option(60.0, "--tune-timeout", help="Search seconds per tuning run."),
    epochs: int = typer.Option(10, "--epochs", help="Fine-tuning epochs per generation."),
    batch_size: int = typer.Option(128, "--batch-size"),
    init_model: int | None = typer.Option(
        None, "--init-model", help="Generation 0's model (default: the shipped model, stored as 'shipped')."
    ),
    goalsets: Goalsets = None,
    parallel: int = typer.Option(
        1, "--parallel", help="Searches at once, each its own process on one core (training and tuning)."
    ),
    device: Device = "cpu",
) -> None:
    """Expert iteration: plan toward drawn training goals, fine-tune on the trees, score on a tuning set;
    each generation is a row of improve_generations (`twisted improve-status`)."""
    from twisted.experiments.improve import ImproveConfig, improve
    from twisted.experiments.problems import EvalInputError

    config = ImproveConfig(
        tune_set=tune_set,
        lineage=name,
        hours=hours,
        seed=seed,
        generations=generations,
        goals=goals,
        distributions=tuple(draw or ("u4", "u5")),
        train_set=train_set,
        goal_timeout_s=goal_timeout,
        goal_iterations=goal_iterations,
        tune_iterations=tune_iterations,
        tune_goals=tune_goals,
        tune_seeds=tune_seeds,
        tune_timeout_s=tune_timeout,
        epochs=epochs,
        batch_size=batch_size,
        init_model_id=init_model,
        goalsets_dir=None if goalsets is None else str(goalsets),
        parallel=parallel,
        device=device,
    )
    try:
        config.check()
    except EvalInputError as exc:
        fail(str(exc))
    with open_db(ctx) as store:
        try:
            rows = improve(store, config, say=lambda m: err_console.print(m, highlight=False))
        except EvalInputError as exc:
            fail(str(exc))
    _print_generations(rows)


def _print_generations(rows: list) -> None:  # type: ignore[type-arg]
    table = Table(
        "gen",
        "status",
        "parent",
        "model",
        "goals solved",
        "samples (train/val)",
        "tune solved",
        "calls / solved",
        "wall",
    )
    for r in rows:
        planned = r.training_goals or []
        data = r.data or {}
        n_train = sum(v for k, v in data.items() if k.startswith("n_train_"))
        n_val = sum(v for k, v in data.items() if k.startswith("n_val_"))
        table.add_row(
            str(r.generation),
            r.status,
            "-" if r.parent_model_id is None or r.generation == 0 else str(r.parent_model_id),
            "-" if r.model_id is None else str(r.model_id),
            "-" if r.generation == 0 else f"{sum(p['solved'] for p in planned)}/{len(planned)}",
            "-" if r.generation == 0 else f"{n_train:,} / {n_val:,}",
            f"{r.tune_solved}/{r.tune_runs}",
            "-" if not r.tune_solved else f"{r.tune_calls / r.tune_solved:,.0f}",
            f"{r.wall_s / 60:.1f} min",
        )
    console.print(table)


@app.command("improve-status")
def improve_status_command(
    ctx: typer.Context, name: str = typer.Option("improve", "--name", help="The lineage.")
) -> None:
    """The generations of an expert-iteration lineage: data, training goals solved, tuning scores."""
    from sqlalchemy import select

    from twisted.store.improve import ImproveGeneration

    with open_db(ctx) as store, store.session() as session:
        rows = list(
            session.scalars(
                select(ImproveGeneration)
                .where(ImproveGeneration.lineage == name)
                .order_by(ImproveGeneration.generation)
            )
        )
        if not rows:
            fail(f"--name {name}: no such lineage in the database")
        _print_generations(rows)


@problems_app.command("export")
def problems_export(
    ctx: typer.Context,
    set_name: Annotated[str, typer.Argument(help="A stored problem set.")],
    out: Annotated[Path, typer.Option("--out", help="The goal-set file to write (JSON).")],
    kind: str | None = typer.Option(
        None,
        "--kind",
        help="How it was drawn: u4, u5, u6, catalogue, ... (default: as stored, else imported).",
    ),
    command: str | None = typer.Option(None, "--command", help="The command that drew it (default: stored)."),
) -> None:
    """Write a stored set as a goal-set file (name, kind, seed, command, goals) for `problems import`."""
    from twisted.experiments.problems import goal_set_file
    from twisted.runtime import name_problem
    from twisted.store.experiments import ProblemSet, load_problem_set

    problem = name_problem(kind) if kind is not None else None
    if problem is not None:
        fail(f"--kind {kind!r} {problem}")
    if out.suffix != ".json":
        fail(f"--out {str(out)!r}: the file must end in .json")
    problem = unwritable(out)
    if problem is not None:
        fail(f"--out {str(out)!r}: {problem}")
    with open_db(ctx, readonly=True, needed_by=f"the set {set_name!r}") as store, store.session() as session:
        record = load_problem_set(session, set_name)
        if record is None:
            fail(f"no problem set named {set_name!r}")
        row = session.get(ProblemSet, record.id)
        assert row is not None
        seed, parameters = row.seed, dict(row.parameters or {})
        stored_command = parameters.pop("command", None)  # an imported set's, from its file
        parameters.pop("goals", None)  # the file lists them
        drawn_by = command or stored_command or _make_command(record.name, seed, parameters)
        if drawn_by is None:
            fail(f"the set {set_name!r} does not say how it was drawn: give --command")
    kind = kind or str(parameters.get("kind", "imported"))
    out.write_text(goal_set_file(record, kind=kind, seed=seed, command=drawn_by, parameters=parameters))
    console.print(f"wrote {out} ({len(record.problems)} goals, seed {seed})")


def _make_command(name: str, seed: int | None, parameters: dict[str, Any]) -> str | None:
    """The ``twisted problems make`` command that draws set ``name`` again (its kind and size are in its
    parameters, its prefix in its name), or None when it was not drawn by ``problems make``."""
    kind = parameters.get("kind")
    if not isinstance(kind, str) or not name.endswith(kind) or seed is None:
        return None
    words = ["twisted", "problems", "make", "--set", kind, "--seed", str(seed)]
    if name != kind:
        words += ["--prefix", name[: -len(kind)]]
    per_set = parameters.get("per_set")
    if per_set not in (None, 10):
        words += ["--per-set", str(per_set)]
    return " ".join(shlex.quote(w) for w in words)
