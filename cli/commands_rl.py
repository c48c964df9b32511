"""`twisted rl train` / `twisted rl list`: the SAC+HER baseline, trained into the database (rl extra)."""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any

import typer
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from cli.app import EXIT_BAD_INPUT, console, fail, open_db, seed_option, subcommands
from cli.options import CrossingCounts, json_option, parse_crossing_counts, print_json

rl_app = subcommands(
    "rl",
    "SAC+HER baseline on the rope env (needs the rl extra: pip install 'twisted-knots\\[rl]').",
)


def _rate(counts: dict[int, tuple[int, int]]) -> str:
    return "  ".join(
        f"{cross}x {hits}/{episodes}" + (f" ({100.0 * hits / episodes:.0f}%)" if episodes else "")
        for cross, (episodes, hits) in sorted(counts.items())
    )


Goals = Annotated[
    list[str] | None,
    typer.Option(
        "--goal", help="A goal P-data state (repeatable); default: every state of --goal-crossings."
    ),
]
GoalCrossings = Annotated[
    CrossingCounts | None,
    typer.Option(
        "--goal-crossings",
        parser=parse_crossing_counts,
        metavar="COUNTS",
        show_default="1,2,3",  # SacConfig's (twisted.rl is imported when the command runs: torch)
        help="Crossing counts of default goals.",
    ),
]


def _check_goals(config: Any) -> None:
    """Exit 2 when the goals given name no state (before the database is opened)."""
    from twisted.envs import GoalError, goal_pool

    try:
        goal_pool(
            config.goals,
            knot=config.knot,
            knot_crossings=config.knot_crossings,
            goal_crossings=config.goal_crossings,
        )
    except GoalError as exc:
        fail(str(exc))


def _train_shown(
    store: Any, config: Any, resume: int | None, steps: int, minutes: float | None, replay_buffer: bool
) -> Any:
    """Train (or continue run ``resume``) with a progress bar and a success row per interval; the outcome."""
    from twisted.envs import GoalError
    from twisted.rl import train_sac

    columns = (
        TextColumn("[bold]run {task.fields[run]}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} steps"),
        TextColumn("{task.fields[episodes]} episodes"),
        TimeElapsedColumn(),
    )
    with Progress(*columns, console=console, transient=False) as bar:
        task = bar.add_task("rl", total=steps, run="-", episodes=0)

        def on_progress(p) -> None:  # noqa: ANN001 - RlProgress
            bar.update(task, total=p.total_steps, completed=p.steps, run=p.run_id, episodes=p.episodes)
            bar.console.print(f"{p.steps:7d} steps  success during the interval: {_rate(p.interval) or '-'}")

        try:
            outcome = train_sac(
                store,
                config,
                resume_run_id=resume,
                progress=on_progress,
                time_limit_s=None if minutes is None else 60.0 * minutes,
                read_replay_buffer=replay_buffer,
            )
        except (GoalError, ValueError) as exc:
            fail(str(exc), EXIT_BAD_INPUT)
        except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM
            from twisted import runtime

            console.print("interrupted: checkpoint saved; continue with `twisted rl train --resume RUN`")
            raise typer.Exit(runtime.exit_code(exc) or 130) from None
    return outcome


def _report(outcome: Any) -> None:
    """What an RL training run did, and its policy."""
    console.print(
        f"run {outcome.run_id} {outcome.status}: {outcome.steps} steps, {outcome.episodes} episodes, "
        f"{outcome.elapsed_s:.0f} s; policy {outcome.checkpoint_id} (`twisted plan --planner sac --model "
        f"{outcome.checkpoint_id}`)"
    )
    console.print(f"success of the training episodes per goal crossings: {_rate(outcome.success) or '-'}")
    if outcome.status != "finished":
        console.print(f"continue with `twisted rl train --resume {outcome.run_id}`")


@rl_app.command("train")
def train_command(
    ctx: typer.Context,
    steps: int = typer.Option(20_000, "--steps", min=1, help="Environment steps (curves) in all."),
    seed: int = seed_option(0, "Seed of goals, exploration and weights."),
    goal: Goals = None,
    problem_set: str | None = typer.Option(None, "--problem-set", help="Goals of a stored problem set."),
    knot: str | None = typer.Option(None, "--knot", help="Goals: the states that tie this knot."),
    knot_crossings: int | None = typer.Option(
        None, "--knot-crossings", min=1, help="Crossings of --knot states."
    ),
    goal_crossings: GoalCrossings = None,
    max_curves: int = typer.Option(
        10, "--max-curves", min=1, max=10_000, help="Curves per episode (truncation)."
    ),
    friction_scale: float = typer.Option(
        1.0, "--friction-scale", min=0.01, max=100.0, help="Rope friction x this."
    ),
    learning_starts: int = typer.Option(
        500, "--learning-starts", min=0, help="Random steps before learning."
    ),
    batch_size: int = typer.Option(256, "--batch-size", min=1, max=1_000_000),
    log_every: int = typer.Option(500, "--log-every", min=1, help="Steps between success rows."),
    checkpoint_every: int = typer.Option(
        2_000, "--checkpoint-every", min=1, help="Steps between checkpoints."
    ),
    replay_buffer: bool = typer.Option(
        True,
        "--replay-buffer/--no-replay-buffer",
        help="Keep the replay buffer with the newest checkpoint; with --resume: continue without the "
        "stored one (e.g. one pickled by an earlier version, which is not read).",
    ),
    minutes: float | None = typer.Option(
        None, "--minutes", min=0.0, help="Stop (resumable) after this time."
    ),
    resume: int | None = typer.Option(None, "--resume", help="Continue this interrupted run (its settings)."),
    threads: int = typer.Option(
        1, "--threads", min=1, max=1024, help="torch CPU threads (1 is best on a busy machine)."
    ),
) -> None:
    """Train a SAC+HER policy; checkpoints (policies for `twisted plan --planner sac`) go to the database."""
    try:
        import torch

        from twisted.rl import SacConfig, require_rl

        require_rl()
    except ImportError as exc:
        fail(str(exc))

    torch.set_num_threads(threads)
    config = SacConfig(
        total_steps=steps,
        seed=seed,
        goals=tuple(goal) if goal else None,
        problem_set=problem_set,
        knot=knot,
        knot_crossings=knot_crossings,
        max_curves=max_curves,
        friction_scale=friction_scale,
        learning_starts=learning_starts,
        batch_size=batch_size,
        log_every=log_every,
        checkpoint_every=checkpoint_every,
        keep_replay_buffer=replay_buffer,
    )
    if goal_crossings is not None:
        config = dataclasses.replace(config, goal_crossings=tuple(goal_crossings))
    given = goal or knot or goal_crossings is not None
    if given and resume is None and problem_set is None:  # the goals given, before the database is opened
        _check_goals(config)
    needs = f"--resume {resume}" if resume is not None else problem_set and f"--problem-set {problem_set}"
    store = open_db(ctx, needed_by=needs or None)
    given_config = None if resume is not None else config  # a resumed run keeps its own settings
    outcome = _train_shown(store, given_config, resume, steps, minutes, replay_buffer)
    _report(outcome)


@rl_app.command("list")
def list_command(ctx: typer.Context, as_json: bool = json_option("the runs and their policies")) -> None:
    """SAC runs with their success per goal crossing count, and their stored policies."""
    from sqlalchemy import select

    from twisted.store.rl import RlRun, list_checkpoints

    store = open_db(ctx, readonly=True)
    with store.session() as session:
        runs = session.scalars(select(RlRun).order_by(RlRun.id)).all()
        checkpoints = list_checkpoints(session)
    if as_json:
        print_json(
            [
                {
                    "run_id": run.id,
                    "status": run.status,
                    "steps_done": run.steps_done,
                    "total_steps": run.total_steps,
                    "episodes": run.episodes,
                    "elapsed_s": run.elapsed_s,
                    "success_by_goal_cross": (run.metrics or {}).get("success_by_goal_cross", {}),
                    "policies": [
                        {"id": c.id, "final": c.final} for c in checkpoints if c.rl_run_id == run.id
                    ],
                }
                for run in runs
            ]
        )
        return
    if not runs:
        console.print("no SAC runs in this database: train one with `twisted rl train`")
        return
    table = Table(
        "run", "status", "steps", "episodes", "time", "success (goal crossings: hits/episodes)", "policies"
    )
    for run in runs:
        success = {int(k): tuple(v) for k, v in (run.metrics or {}).get("success_by_goal_cross", {}).items()}
        ids = [str(c.id) + ("*" if c.final else "") for c in checkpoints if c.rl_run_id == run.id]
        table.add_row(
            str(run.id),
            run.status,
            f"{run.steps_done}/{run.total_steps}",
            str(run.episodes),
            f"{run.elapsed_s / 60:.1f} min",
            _rate(success) or "-",  # type: ignore[arg-type]
            ", ".join(ids) or "-",
        )
    console.print(table)
    console.print("policies: checkpoint ids, newest first (* = final); use with --planner sac --model ID")
