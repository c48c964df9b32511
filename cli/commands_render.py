"""`twisted render`: draw a configuration, a run's plan or a goal state."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from cli.app import (
    app,
    console,
    fail,
    open_db,
    unwritable,
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


def _render_tightened(store: Any, run: int, png: Path) -> Any:
    """``render --run --tightened``: the run's final rope beside it pulled tight (the pull test of
    ``twisted replay --tighten`` run first when none is stored)."""
    from twisted.planner import PlanInputError, replay
    from twisted.render import render_tightened
    from twisted.store.knots import tightenings

    with store.session() as session:
        stored = any(t.ok for t in tightenings(session, run))
    if not stored:
        try:
            replay(store, run, tighten=True)
        except PlanInputError as exc:
            fail(str(exc))
    return render_tightened(store, run, png)


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
    from twisted.render import RenderError, render_configuration, render_goal, render_run
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
    # only a pull test not stored yet (--tightened) writes to the database
    with open_db(ctx, readonly=not tightened, needed_by=needs) as store:
        try:
            if config is not None:
                rendered = render_configuration(store, config, png, gl=gl)
            elif run is not None and tightened:
                rendered = _render_tightened(store, run, png)
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
