"""`twisted knots list` (named knots and the states that tie them) and `twisted knots identify`."""

from __future__ import annotations

import json
from typing import Any

import typer
from rich.table import Table

from cli.app import EXIT_BAD_INPUT, console, db_url, err_console, fail, subcommands
from cli.options import json_option, print_json

knots_app = subcommands(
    "knots",
    "Knots by name: which knot a rope state really ties (both closures, under and over the table, "
    "agree; otherwise it is a knotoid).",
)

def _store(ctx: typer.Context) -> Any | None:
    """The database to count visits in (read only), or None when there is none (a note says so)."""
    from twisted.store import StoreError, open_store

    try:
        return open_store(db_url(ctx), create=False, readonly=True)
    except StoreError as exc:
        err_console.print(f"note: no visit counts ({exc})", highlight=False)
        return None


@knots_app.command("list")
def list_command(
    ctx: typer.Context,
    crossings: int | None = typer.Option(
        None,
        "--crossings",
        help="List the states of this many crossings (default: each knot's crossing number, the least "
        "count at which a rope ties it; there the states are cut from the knot's KnotInfo diagram).",
    ),
    max_crossings: int = typer.Option(
        4,
        "--max-crossings",
        help="Above a knot's crossing number its states are enumerated, up to this many crossings (5 takes "
        "~1 min).",
    ),
    limit: int = typer.Option(10, "--limit", help="States shown per knot, most visited first (0: all)."),
    invariants: bool = typer.Option(
        False, "--invariants", help="Also a table of each knot's determinant and polynomials."
    ),
    as_json: bool = json_option("everything (all states, the invariants)"),
) -> None:
    """The knot table (KnotInfo's prime knots up to 7 crossings, each chirality, and the sums of two with at
    most 7 crossings in all): for each knot the P-data states that really tie it (both closures are the
    knot) at its crossing number, and how often the data in --db visited each: the configurations
    collected in that state and the planner tree nodes reached in it (a run's start left out)."""
    from twisted.knots import MAX_BUILT_CROSSINGS, MAX_ENUMERATED_CROSSINGS
    from twisted.store.knots import knot_table

    if crossings is not None and not 0 <= crossings <= MAX_BUILT_CROSSINGS:
        fail(f"--crossings must be between 0 and {MAX_BUILT_CROSSINGS}, got {crossings}")
    if not 0 <= max_crossings <= MAX_ENUMERATED_CROSSINGS:
        fail(f"--max-crossings must be between 0 and {MAX_ENUMERATED_CROSSINGS}, got {max_crossings}")
    if limit < 0:
        fail(f"--limit must be >= 0, got {limit}")
    store = _store(ctx)
    try:
        entries = knot_table(store, crossings, max_crossings)
    finally:
        if store is not None:
            store.close()
    if as_json:
        print_json(entries)
        return
    console.print(_summary(entries))
    if invariants:
        console.print(_invariants(entries))
    for e in entries:
        if e["states"]:
            console.print(_states(e, limit))


def _count(value: int | None) -> str:
    return "-" if value is None else str(value)


def _summary(entries: list[dict[str, Any]]) -> Table:
    """One row per knot: names, crossings, states, visited states and visits."""
    from twisted.knots import COMPOSITE_NOTE

    unlisted = [e["crossings"] for e in entries if not e["listed"]]
    notes = [f"?: not enumerated (--max-crossings {max(unlisted)})."] if unlisted else []
    summary = Table(
        title="The knot table (KnotInfo): states whose closures under and over the table are the knot",
        caption=" ".join([*notes, f"Note: {COMPOSITE_NOTE} (docs/knots.md)."]),
    )
    summary.add_column("name", no_wrap=True)
    summary.add_column("type", no_wrap=True)
    for column in ("crossings", "states", "visited", "visits"):
        summary.add_column(column, justify="right", no_wrap=True)
    for e in entries:
        summary.add_row(
            e["name"],
            e["knot_type"],
            str(e["crossings"]),
            str(len(e["states"])) if e["listed"] else "?",
            _count(e["visited_states"]),
            _count(e["visits"]),
        )
    return summary


def _invariants(entries: list[dict[str, Any]]) -> Table:
    """One row per knot: its name, determinant and Alexander and Jones polynomials."""
    table = Table(title="The knots' invariants")
    table.add_column("name", no_wrap=True)
    table.add_column("det", justify="right", no_wrap=True)
    table.add_column("Alexander", overflow="fold")
    table.add_column("Jones", overflow="fold")
    for e in entries:
        table.add_row(e["name"], str(e["determinant"]), e["alexander"], e["jones"])
    return table


def _states(e: dict[str, Any], limit: int) -> Table:
    """A knot's states, most visited first: P-data, configurations, planner nodes."""
    shown = e["states"] if limit == 0 else e["states"][:limit]
    title = f"{e['name']} ({e['knot_type']}): {len(e['states'])} states of {e['crossings']} crossings"
    table = Table(title=title)
    table.add_column("P-data", overflow="fold")
    table.add_column("configurations", justify="right", no_wrap=True)
    table.add_column("nodes", justify="right", no_wrap=True)
    for s in shown:
        p_data = json.dumps(s["p_data"], separators=(",", ":"))
        table.add_row(p_data, _count(s["configurations"]), _count(s["nodes"]))
    if len(shown) < len(e["states"]):
        table.caption = f"{len(e['states']) - len(shown)} more (--limit 0 shows all)"
    return table


@knots_app.command("identify")
def identify_command(
    p_data: str = typer.Argument(..., help='A P-data state, e.g. \'[[1,"O",4,"+"],[2,"U",5,"+"],...]\'.'),
    as_json: bool = json_option("both closures and the knot"),
) -> None:
    """Which knot a rope state ties: both closures (ends joined under / over the table); a knot only when
    they agree, otherwise a knotoid (pulling the ends decides)."""
    from twisted.knots import identify
    from twisted.topology import PDataError, parse_p_data

    try:
        k = identify(parse_p_data(p_data))
    except PDataError as exc:
        fail(f"P_DATA: {exc}", EXIT_BAD_INPUT)
    if as_json:
        print_json(k.to_dict(), indent=None)
        return
    console.print(k.describe(), highlight=False)
    for label, c in (("under", k.under), ("over", k.over)):
        console.print(
            f"  closed {label:<5} {c.name:<10} Alexander {c.alexander_text()}  det {c.determinant}  "
            f"Jones {c.jones_text()}",
            highlight=False,
        )
