"""`twisted collect` (self-supervised data collection into the database) and `twisted stats`."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import typer
from rich.progress import BarColumn, Progress, TextColumn
from rich.table import Table

from cli.app import EXIT_BAD_INPUT, app, check_workers, console, fail, open_db, seed_option
from cli.options import json_option, print_json, ray_address_argument
from twisted.rope import MAX_CROSSINGS
from twisted.runtime import signal_exit_code

EXIT_FAILED = 1
EXIT_INTERRUPTED = 130  # the shell's convention for a run stopped by a signal: 128 + SIGINT (SIGTERM: 143)
MAX_RAY_WORKERS = 4096  # actors on a cluster; the local bound is per core (check_workers)


def _hms(seconds: float) -> str:
    seconds = max(0, int(round(seconds)))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


def _num(value: Any, spec: str = ",.0f") -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return format(value, spec)


def _pct(value: Any) -> str:
    return "-" if value is None else f"{100 * value:.1f} %"


def _collect_shown(store: Any, options: Any, use_ray: bool, address: Any, workers: int | None) -> Any:
    """Collect (on Ray with ``use_ray``) with a progress bar; the run's summary."""
    from twisted.collect import CollectProgress, collect
    from twisted.distributed import DistributedError, collect_on_ray

    columns = (
        TextColumn("[bold]run {task.fields[run]}"),
        BarColumn(bar_width=20),
        TextColumn("{task.fields[elapsed]}/{task.fields[span]}"),
        TextColumn("kept [bold]{task.fields[kept]}[/]/{task.fields[tried]} tried"),
        TextColumn("{task.fields[rate]} kept/h"),
        TextColumn("{task.fields[left]} left"),
        TextColumn("{task.fields[note]}"),
    )
    total_s = options.hours * 3600.0
    with store, Progress(*columns, console=console, transient=False) as bar:
        task = bar.add_task(
            "collect",
            total=total_s,
            run="-",
            elapsed="0:00:00",
            span=_hms(total_s),
            kept=0,
            tried=0,
            rate="-",
            left=_hms(total_s),
            note="",
        )

        def show(p: CollectProgress) -> None:
            bar.update(
                task,
                completed=min(p.elapsed_s, p.total_s),
                run=p.run_id,
                elapsed=_hms(p.elapsed_s),
                kept=f"{p.kept:,}",
                tried=f"{p.tried:,}",
                rate=_num(p.kept_per_hour) if p.elapsed_s > 5 else "-",
                left=_hms(p.total_s - p.elapsed_s),
                note="[yellow]stopping[/]" if p.stopping else "",
            )

        try:
            if use_ray:  # the same run on Ray actors (twisted/distributed.py)
                summary = collect_on_ray(store, options, address, workers=workers, on_progress=show)
            else:
                summary = collect(store, options, on_progress=show)
        except DistributedError as exc:
            fail(str(exc), EXIT_BAD_INPUT)

    return summary


def _report(summary: Any) -> None:
    """What a collect run kept; exit 1 when it failed, 130 / 143 when it was stopped."""
    console.print(
        f"run {summary.run_id} {summary.status}: kept {summary.kept:,} of {summary.tried:,} curves "
        f"({summary.rejected:,} rejected by the simulator) in {_hms(summary.wall_seconds)} with "
        f"{summary.workers} workers: {summary.kept_per_hour:,.0f} kept/h, "
        f"{summary.kept_per_hour_per_worker:,.0f} kept/h/worker (seed {summary.seed})"
    )
    if summary.kept_by_to_cross:
        reached = ", ".join(f"{c}: {n:,}" for c, n in summary.kept_by_to_cross.items())
        console.print(f"new configurations by crossing count: {reached}")
    if summary.status == "failed":
        fail(f"collect run {summary.run_id} failed: {summary.message}", EXIT_FAILED)
    if summary.status == "interrupted":
        console.print(f"[yellow]{summary.message}[/]; run `twisted collect` again to continue the same D_Q")
        raise typer.Exit(signal_exit_code(summary.signum) if summary.signum else EXIT_INTERRUPTED)


@app.command("collect")
def collect_command(
    ctx: typer.Context,
    hours: float = typer.Option(..., "--hours", help="How long to collect (hours, > 0; e.g. 0.5)."),
    workers: int | None = typer.Option(
        None, "--workers", help="Simulation processes (default: the machine's CPU cores)."
    ),
    seed: int | None = seed_option(None, "Seed of every random choice (default: random, stored)."),
    batch_size: int = typer.Option(
        20, "--batch-size", help="Kept transitions per committed batch (also ~2 s)."
    ),
    max_cross: int = typer.Option(
        MAX_CROSSINGS, "--max-cross", help="Keep transitions up to this many crossings."
    ),
    cross_bias: float = typer.Option(
        1.0,
        "--cross-bias",
        help="D_Q bias: start crossing count c weighs (1+c)**bias (0: uniform over counts).",
    ),
    max_kept: int | None = typer.Option(
        None, "--max-kept", help="Also stop after this many kept transitions."
    ),
    max_tries: int | None = typer.Option(None, "--max-tries", help="Also stop after this many tried curves."),
    friction_scale: float = typer.Option(1.0, "--friction-scale", help="Rope friction factor (1 = nominal)."),
    across_share: float = typer.Option(
        0.8,
        "--across-share",
        help="Share of curves aimed across another strand (the rest uniform; 0: all uniform).",
    ),
    remove_share: float = typer.Option(
        0.0,
        "--remove-share",
        help="Also keep a transition that removes crossings, with this probability (0: only those that "
        "add crossings, the paper's D_Q); see docs/untie.md.",
    ),
    use_ray: bool = typer.Option(
        False, "--ray", help="Run the workers on a Ray cluster (default --workers: its CPUs); see ADDRESS."
    ),
    ray_address: str | None = ray_address_argument(),
) -> None:
    """Collect transitions that add crossings (D_Q reset scheme) into the database, resumably.

    Running it again continues from the configurations already in the database. Ctrl-C or SIGTERM
    stops cleanly (the last batch is committed and the run marked interrupted).
    """
    from twisted.collect import CollectError, CollectOptions
    from twisted.distributed import DistributedError, import_ray, resolve_address
    from twisted.runtime import cpu_cores

    if not use_ray:
        check_workers(workers)
    elif workers is not None and not 1 <= workers <= MAX_RAY_WORKERS:
        fail(f"--workers {workers}: give 1 to {MAX_RAY_WORKERS} Ray workers", EXIT_BAD_INPUT)
    try:  # Ray problems first, before any database is created
        address = resolve_address(use_ray, ray_address)
        if use_ray:
            import_ray()
    except DistributedError as exc:
        fail(str(exc), EXIT_BAD_INPUT)

    options = CollectOptions(
        hours=hours,
        workers=cpu_cores() if workers is None else workers,
        seed=seed,
        batch_size=batch_size,
        max_cross=max_cross,
        cross_bias=cross_bias,
        max_kept=max_kept,
        max_tries=max_tries,
        friction_scale=friction_scale,
        across_share=across_share,
        remove_share=remove_share,
    )
    try:
        options.validate()
    except CollectError as exc:
        fail(str(exc), EXIT_BAD_INPUT)
    summary = _collect_shown(open_db(ctx), options, use_ray, address, workers)
    _report(summary)


@app.command("stats")
def stats_command(
    ctx: typer.Context,
    as_json: bool = json_option("the figures"),
) -> None:
    """Configurations, kept transitions and states per crossing count and per knot type; acceptance;
    throughput per run.

    Read-only: safe to run while a collector is writing.
    """
    from twisted.collect import collection_stats

    store = open_db(ctx, create=False, readonly=True)
    from twisted.store.knots import knot_visits

    with store:
        stats = collection_stats(store)
        with store.session() as session:
            stats["by_knot"] = [
                {
                    "knot_type": v.knot_type,
                    "states": v.states,
                    "visited_states": v.visited_states,
                    "configurations": v.configurations,
                }
                for v in knot_visits(session)
            ]
    if as_json:
        print_json(stats)
        return

    _print_table(
        "Per crossing count",
        ("cross", "states", "configurations", "kept in", "kept out"),
        [
            [str(row["cross"])]
            + [_num(row[k]) for k in ("states", "configurations", "transitions_in", "transitions_out")]
            for row in stats["by_cross"]
        ],
    )
    _print_table(
        "Per knot type (both closures agree; knotoid: they differ, no knot)",
        ("knot", "states", "visited states", "configurations"),
        [
            [row["knot_type"] or "-"] + [_num(row[k]) for k in ("states", "visited_states", "configurations")]
            for row in stats["by_knot"]
        ],
    )
    _print_table(
        "Random curves by start crossing count (collect)",
        ("from cross", "tried", "kept", "kept rate", "c->c+1", "reference", "rejected"),
        [
            [str(row["from_cross"]), _num(row["tried"]), _num(row["kept"])]
            + [_pct(row[k]) for k in ("kept_rate", "plus_one_rate", "reference_plus_one_rate")]
            + [_num(row["rejected"])]
            for row in stats["acceptance"]
        ],
    )
    _print_table(
        "Collect runs",
        ("run", "status", "workers", "hours", "tried", "kept", "kept/h", "kept/h/worker"),
        [
            [str(row[k]) for k in ("run_id", "status", "workers")]
            + [_num((row["wall_seconds"] or 0) / 3600, ".3f")]
            + [_num(row[k]) for k in ("tried", "kept", "kept_per_hour", "kept_per_hour_per_worker")]
            for row in stats["runs"]
        ],
    )


def _print_table(title: str, columns: Sequence[str], rows: Iterable[Sequence[str]]) -> None:
    """A table of right-aligned columns, one line per row."""
    table = Table(title=title)
    for name in columns:
        table.add_column(name, justify="right")
    for row in rows:
        table.add_row(*row)
    console.print(table)


@app.command("db")
def db_command(
    ctx: typer.Context, as_json: bool = json_option("where it is, its revisions and its rows")
) -> None:
    """Show the database: where it is, its schema revisions, and the rows in each table (read-only)."""
    import importlib
    import pkgutil

    from sqlalchemy import func, inspect, select, text

    import twisted.store
    from twisted.rope import ROPE
    from twisted.store import Base, head_revisions
    from twisted.store.rope_profile import ROPE_ROW_ID, StoredRope

    for module in pkgutil.iter_modules(twisted.store.__path__):
        importlib.import_module(f"twisted.store.{module.name}")
    store = open_db(ctx, create=False, readonly=True)
    with store, store.session() as session:
        revisions = sorted(r[0] for r in session.execute(text("SELECT version_num FROM alembic_version")))
        present = set(inspect(session.connection()).get_table_names())
        counts = {
            name: session.scalar(select(func.count()).select_from(table))
            for name, table in sorted(Base.metadata.tables.items())
            if name in present
        }
        stored = session.get(StoredRope, ROPE_ROW_ID) if "rope_profile" in present else None
    where = store.url.render_as_string(hide_password=True)
    rope = None
    if stored is not None:
        rope = {
            "n_links": stored.n_links,
            "link_spacing_m": stored.link_spacing_m,
            "max_crossings": stored.max_crossings,
        }
    if as_json:
        print_json(
            {
                "database": where,
                "dialect": store.dialect,
                "revisions": revisions,
                "rope": rope,
                "rows": counts,
            }
        )
        return
    console.print(f"database: {where} ({store.dialect})")
    if stored is None:
        console.print(f"rope: none recorded yet (no data written; this process runs {ROPE.name})")
    else:
        console.print(f"rope: {stored.profile().name}")
    console.print(
        f"schema revisions: {', '.join(revisions)} (this twisted: {', '.join(sorted(head_revisions()))})"
    )
    table = Table(title="Rows per table")
    table.add_column("table")
    table.add_column("rows", justify="right")
    for name, n in counts.items():
        table.add_row(name, _num(n))
    console.print(table)
