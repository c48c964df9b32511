"""`twisted plan` and `twisted replay`: search for a low-level plan to a goal state, re-simulate one.

Exit codes: 0 solved (replay: the plan still ends in the goal), 2 bad input (malformed goal, a goal
with more crossings than the model encodes, no model for a planner that needs one, unknown run id,
options that contradict the run being resumed), 3 goal not reached (``--timeout`` or
``--max-iterations`` ran out; replay: the plan no longer reaches the goal), 130 / 143 interrupted
by Ctrl-C / SIGTERM after saving a checkpoint (continue with ``--resume RUN_ID``).
"""

from __future__ import annotations

import json
from typing import Any

import typer
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from cli.app import EXIT_NOT_REACHED, EXIT_OK, app, console, err_console, fail, open_db


def _curve_row(curve: Any) -> dict[str, Any]:
    return {"link": curve.link, "z_max_m": curve.z_max_m, "x_m": curve.x_m, "y_m": curve.y_m}


def _options(
    *,
    planner: str | None,
    heuristic: str | None,
    seed: int | None,
    k: int | None,
    p_expand: float | None,
    k_expand: int | None,
    plan_limit: int | None,
    base: dict[str, Any] | None = None,
) -> Any:
    """PlannerOptions from the command line, over the stored ones of a resumed run (which must agree)."""
    from twisted.planner import PlannerOptions

    given: dict[str, Any] = {
        "planner": planner,
        "heuristic": heuristic,
        "seed": seed,
        "k": k,
        "p_expand": p_expand,
        "k_expand": k_expand,
        "plan_limit": plan_limit,
    }
    given = {name: value for name, value in given.items() if value is not None}
    if base is not None:
        stored = PlannerOptions.from_dict(base).to_dict()
        clash = [
            f"--{n.replace('_', '-')} {v} (run has {stored[n]})" for n, v in given.items() if stored[n] != v
        ]
        if clash:
            fail(f"a resumed run keeps its own search options; drop or fix: {', '.join(clash)}")
        return PlannerOptions.from_dict(stored)
    options = PlannerOptions(**given)
    try:
        options.validate()
    except ValueError as exc:
        fail(str(exc))
    return options


@app.command("plan")
def plan_command(
    ctx: typer.Context,
    goal: str | None = typer.Option(
        None, "--goal", help='Goal P-data as JSON, e.g. \'[[1,"O",2,"+"],[2,"U",1,"+"]]\'.'
    ),
    knot: str | None = typer.Option(
        None,
        "--knot",
        help="Goal by knot name (overhand, figure-eight, 5_1, 5_2; see `twisted knots list`): "
        "any rope state that ties it.",
    ),
    crossings: int | None = typer.Option(
        None,
        "--crossings",
        help="With --knot: states of this many crossings (default: the knot's crossing number).",
    ),
    timeout_s: float = typer.Option(
        1800.0, "--timeout", min=0.0, help="Search time limit in seconds (a resumed run's time counts)."
    ),
    heuristic: str | None = typer.Option(None, "--heuristic", help="rnd | crs (default) | ucb."),
    planner: str | None = typer.Option(
        None,
        "--planner",
        help="twisted (default, inverse model) | sac (SAC+HER policy) | random-low | low-level-only.",
    ),
    workers: int = typer.Option(2, "--workers", min=1, help="Simulator processes (1: in this process)."),
    seed: int | None = typer.Option(None, "--seed", help="Seed of the search (default 0)."),
    k: int | None = typer.Option(None, "--k", min=1, help="Curves sampled per plan step (default 6)."),
    p_expand: float | None = typer.Option(
        None, "--p-expand", min=0.0, max=1.0, help="RandomExpand probability after a failed iteration (0.05)."
    ),
    k_expand: int | None = typer.Option(None, "--k-expand", min=1, help="Curves per RandomExpand (100)."),
    plan_limit: int | None = typer.Option(
        None, "--plan-limit", min=1, help="High-level plans kept per reached state (100)."
    ),
    model_id: int | None = typer.Option(
        None,
        "--model",
        help="Model id (twisted: default the newest in the database, else the shipped one; "
        "sac: policy checkpoint id, default the newest).",
    ),
    start_config: int | None = typer.Option(
        None, "--start-config", help="Start from this configurations.id instead of the straight rope."
    ),
    resume_run_id: int | None = typer.Argument(
        None, metavar="RUN_ID", help="With --resume: the run to continue.", show_default=False
    ),
    resume: bool = typer.Option(
        False,
        "--resume",
        help="Continue a stopped run: RUN_ID, or the newest unfinished one (for --goal when given).",
    ),
    max_iterations: int | None = typer.Option(
        None, "--max-iterations", min=0, help="Also stop after this many iterations (total, for tests)."
    ),
    checkpoint_every_s: float = typer.Option(
        2.0, "--checkpoint-every", min=0.0, help="Seconds between checkpoints."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Search for curves that tie GOAL (Algorithm 1); the search tree goes to the database."""
    from twisted.planner import (
        PlanInputError,
        StopSignals,
        curve_sampler,
        make_goal,
        resume_search,
        start_search,
    )
    from twisted.sim.pool import SimPool
    from twisted.store.search import find_resumable_run, load_run

    goal_p = None
    if goal is not None or knot is not None or crossings is not None:
        try:
            goal_p = make_goal(goal, knot, crossings)
        except PlanInputError as exc:
            fail(f"{'--knot' if knot is not None else '--goal'}: {exc}")
    elif not resume:
        fail(
            "a goal is required: --goal P-DATA (e.g. '[[1,\"O\",2,\"+\"],[2,\"U\",1,\"+\"]]') "
            "or --knot NAME (e.g. overhand)"
        )
    store = open_db(ctx)

    run_id: int | None = None
    parameters: dict[str, Any] | None = None
    if resume_run_id is not None and not resume:
        fail(f"a run id is only taken with --resume: `twisted plan --resume {resume_run_id}`")
    if resume:
        run_id = resume_run_id if resume_run_id is not None else find_resumable_run(store, goal_p)
        if run_id is None:
            fail("--resume: no unfinished planner run" + (f" for goal {goal_p.spec}" if goal_p else ""))
        info = load_run(store, run_id, with_nodes=False)
        if info is None:
            fail(f"--resume {run_id}: there is no planner run {run_id} in this database")
        if goal_p is not None and info.goal.spec != goal_p.spec:
            fail(f"--resume {run_id}: that run's goal is {info.goal.spec}, not {goal_p.spec}")
        if start_config is not None:
            fail("--start-config cannot change the start of a resumed run")
        parameters = info.parameters
        if model_id is not None and parameters.get("model_id") not in (None, model_id):
            fail(f"--model {model_id}: run {run_id} was searched with model {parameters.get('model_id')}")
        model_id = parameters.get("model_id", model_id)

    options = _options(
        planner=planner,
        heuristic=heuristic,
        seed=seed,
        k=k,
        p_expand=p_expand,
        k_expand=k_expand,
        plan_limit=plan_limit,
        base=parameters,
    )
    try:
        sampler, used_model_id = curve_sampler(store, options.planner, model_id)
    except PlanInputError as exc:
        fail(str(exc))
    model = getattr(sampler, "model", None)
    if model is not None and hasattr(model, "metadata") and not as_json:
        sources = model.metadata.get("data_sources") or {"collect": model.metadata.get("data_size")}
        err_console.print(
            f"inverse model {'(shipped default)' if used_model_id is None else used_model_id}: trained on "
            + ", ".join(f"{n:,} {source}" for source, n in sources.items() if n)
            + " samples",
            highlight=False,
        )

    stop = StopSignals()
    columns = (
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:>6.0f}/{task.total:.0f} s"),
        TextColumn("it {task.fields[iteration]}  sims {task.fields[sims]}  nodes {task.fields[nodes]}"),
        TextColumn("states {task.fields[states]}  max cross {task.fields[max_cross]}"),
        TimeElapsedColumn(),
    )
    with (
        Progress(*columns, console=err_console, transient=True, disable=as_json) as bar,
        SimPool(workers) as pool,
        stop.installed(),
    ):
        task = bar.add_task(
            "plan", total=max(timeout_s, 1e-9), iteration=0, sims=0, nodes=1, states=1, max_cross=0
        )

        def progress(search: Any) -> None:
            bar.update(
                task,
                completed=min(search.elapsed_s, timeout_s),
                iteration=search.iteration,
                sims=search.sim_calls,
                nodes=len(search.tree),
                states=len(search.tree.states),
                max_cross=max(p.cross for p in search.tree.states.values()),
            )

        try:
            if run_id is not None:
                search = resume_search(store, run_id, pool, sampler, stop=stop, progress=progress)
            else:
                assert goal_p is not None
                search = start_search(
                    store,
                    goal_p,
                    options,
                    pool,
                    sampler,
                    start_configuration_id=start_config,
                    stop=stop,
                    progress=progress,
                    extra_parameters={"model_id": used_model_id},
                )
        except PlanInputError as exc:
            fail(str(exc))
        search.checkpoint_every_s = checkpoint_every_s
        bar.update(task, description=f"run {search.run_id}")
        result = search.run(timeout_s=timeout_s, max_iterations=max_iterations)

    _print_result(search, result, as_json)
    if result.solved:
        raise typer.Exit(EXIT_OK)
    if result.status == "interrupted":
        err_console.print(
            f"interrupted: checkpoint saved; continue with `twisted plan --resume {result.run_id}`",
            highlight=False,
        )
        raise typer.Exit(stop.exit_code)
    raise typer.Exit(EXIT_NOT_REACHED)


def _print_result(search: Any, result: Any, as_json: bool) -> None:
    steps = [
        {"step": i, **_curve_row(node.curve), "cross": node.p_data.cross, "state": node.p_data.to_list()}
        for i, node in enumerate(result.path[1:], start=1)
    ]
    if as_json:
        payload = {
            "run_id": result.run_id,
            "goal": search.goal.spec,
            "knot": search.goal.knot,
            "goal_states": [p.to_list() for p in search.goal.states],
            "reached_state": result.path[-1].p_data.to_list() if result.path else None,
            "outcome": result.status,
            "solved": result.solved,
            "search_time_s": round(result.elapsed_s, 3),
            "sim_calls": result.sim_calls,
            "iterations": result.iterations,
            "nodes": result.nodes,
            "states": result.states,
            "plan": steps,
        }
        typer.echo(json.dumps(payload))
        return
    outcome = "[bold green]solved[/]" if result.solved else f"[bold red]not solved ({result.status})[/]"
    console.print(
        f"run {result.run_id}: {outcome}"
        f"  goal {search.goal.label}"
        + (f" reached {result.path[-1].p_data.key}" if result.path and search.goal.knot else "")
        + f"  search time {result.elapsed_s:.1f} s  simulator calls {result.sim_calls}"
        f"  iterations {result.iterations}  nodes {result.nodes}  states {result.states}",
        highlight=False,
    )
    if steps:
        table = Table(title="low-level plan (curves from the initial configuration)")
        for name in ("step", "link", "z_max_m", "x_m", "y_m", "state after"):
            table.add_column(name, justify="right" if name != "state after" else "left")
        for row in steps:
            table.add_row(
                str(row["step"]),
                str(row["link"]),
                f"{row['z_max_m']:.4f}",
                f"{row['x_m']:+.4f}",
                f"{row['y_m']:+.4f}",
                json.dumps(row["state"], separators=(",", ":")),
            )
        console.print(table)


@app.command("replay")
def replay_command(
    ctx: typer.Context,
    run_id: int = typer.Argument(..., help="A solved planner run (see `twisted plan`)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Re-simulate a run's plan from its initial configuration; exit 0 if it still ends in the goal."""
    from twisted.planner import PlanInputError, replay

    store = open_db(ctx)
    try:
        result = replay(store, run_id)
    except PlanInputError as exc:
        fail(str(exc))
    if as_json:
        typer.echo(
            json.dumps(
                {
                    "run_id": run_id,
                    "goal": result.goal.spec,
                    "reached_goal": result.reached_goal,
                    "steps": [
                        {
                            **_curve_row(step.curve),
                            "recorded": step.recorded.to_list(),
                            "replayed": None if step.replayed is None else step.replayed.to_list(),
                            "reason": step.reason,
                        }
                        for step in result.steps
                    ],
                }
            )
        )
    else:
        table = Table(title=f"replay of run {run_id}")
        for name in ("step", "link", "recorded state", "replayed state", "same"):
            table.add_column(name)
        for i, step in enumerate(result.steps, start=1):
            replayed = step.replayed.key if step.replayed is not None else f"rejected: {step.reason}"
            same = "yes" if step.matches else "NO"
            table.add_row(str(i), str(step.curve.link), step.recorded.key, replayed, same)
        console.print(table)
        verdict = (
            "[bold green]reaches the goal[/]"
            if result.reached_goal
            else "[bold red]does not reach the goal[/]"
        )
        console.print(f"run {run_id}: the replayed plan {verdict} {result.goal.label}", highlight=False)
    raise typer.Exit(EXIT_OK if result.reached_goal else EXIT_NOT_REACHED)
