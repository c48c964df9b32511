"""`twisted knots list` (named knots and the states that tie them) and `twisted knots identify`."""

from __future__ import annotations

import json
from typing import Any

import typer
from rich.table import Table

from cli.app import EXIT_BAD_INPUT, app, console, db_url, err_console, fail

knots_app = typer.Typer(
    no_args_is_help=True,
    help="Knots by name: which knot a rope state ties (its ends joined under the table).",
)
app.add_typer(knots_app, name="knots")

# The names shown by `knots list`, one per catalogue entry (resolve_knot accepts more spellings).
LIST_NAMES = (
    ("unknot", "0_1"),
    ("overhand+", "3_1+"),
    ("overhand-", "3_1-"),
    ("figure-eight", "4_1"),
    ("5_1+", "5_1+"),
    ("5_1-", "5_1-"),
    ("5_2+", "5_2+"),
    ("5_2-", "5_2-"),
)


def _visits(ctx: typer.Context, keys: list[str]) -> dict[str, int] | None:
    """Configurations per state key from the database, or None when there is no database to read."""
    from twisted.store import StoreError, open_store
    from twisted.store.knots import configurations_per_state

    try:
        store = open_store(db_url(ctx), create=False)
    except StoreError as exc:
        err_console.print(f"note: no visit counts ({exc})", highlight=False)
        return None
    with store, store.session() as session:
        return configurations_per_state(session, keys)


@knots_app.command("list")
def list_command(
    ctx: typer.Context,
    crossings: int | None = typer.Option(
        None, "--crossings", help="List the states of this many crossings (default: the smallest count)."
    ),
    max_crossings: int = typer.Option(
        4, "--max-crossings", help="Search the smallest count up to this many crossings (5 takes ~1 min)."
    ),
    limit: int = typer.Option(10, "--limit", help="States shown per knot, most visited first (0: all)."),
    as_json: bool = typer.Option(False, "--json", help="Print everything (all states) as JSON."),
) -> None:
    """For each named knot: its invariants, and the P-data states of the smallest crossing count that tie
    it, with how often the data in --db visited each (configurations reached in that state)."""
    from rich.progress import Progress

    from twisted.knots import CATALOGUE, states_tying

    # 5 crossings enumerate 130,304 states (~30 s); 6 would take many minutes and gigabytes
    if crossings is not None and not 0 <= crossings <= 5:
        fail(f"--crossings must be between 0 and 5, got {crossings}")
    if not 0 <= max_crossings <= 5:
        fail(f"--max-crossings must be between 0 and 5, got {max_crossings}")
    if limit < 0:
        fail(f"--limit must be >= 0, got {limit}")

    found: dict[str, list[Any]] = {}
    with Progress(console=err_console, transient=True) as progress:
        task = progress.add_task("enumerating states", total=len(LIST_NAMES))
        for _name, canonical in LIST_NAMES:
            found[canonical] = states_tying(canonical, crossings, max_crossings=max_crossings)
            progress.advance(task)
    visits = _visits(ctx, [p.key for states in found.values() for p in states])

    entries: list[dict[str, Any]] = []
    for name, canonical in LIST_NAMES:
        k = CATALOGUE[canonical]
        states = sorted(found[canonical], key=lambda p: (-(visits or {}).get(p.key, 0), p.key))
        entries.append(
            {
                "name": name,
                "knot_type": canonical,
                "alexander": k.alexander_text(),
                "determinant": k.determinant,
                "jones": k.jones_text(),
                "crossings": states[0].cross if states else None,
                "states": [
                    {"p_data": p.to_list(), "configurations": None if visits is None else visits[p.key]}
                    for p in states
                ],
                "visited_states": None if visits is None else sum(visits[p.key] > 0 for p in states),
                "configurations": None if visits is None else sum(visits[p.key] for p in states),
            }
        )
    if as_json:
        typer.echo(json.dumps(entries, indent=2))
        return

    summary = Table(title="Named knots (rope closed under the table)")
    for column in ("name", "type", "Alexander", "det", "Jones", "crossings", "states", "visited", "configs"):
        summary.add_column(column, justify="right" if column in ("det", "crossings", "states") else "left")
    for e in entries:
        summary.add_row(
            e["name"],
            e["knot_type"],
            e["alexander"],
            str(e["determinant"]),
            e["jones"],
            "-" if e["crossings"] is None else str(e["crossings"]),
            str(len(e["states"])),
            "-" if e["visited_states"] is None else str(e["visited_states"]),
            "-" if e["configurations"] is None else str(e["configurations"]),
        )
    console.print(summary)
    for e in entries:
        if not e["states"]:
            continue
        shown = e["states"] if limit == 0 else e["states"][:limit]
        title = f"{e['name']} ({e['knot_type']}): {len(e['states'])} states of {e['crossings']} crossings"
        table = Table(title=title)
        table.add_column("P-data", overflow="fold")
        table.add_column("configurations", justify="right")
        for s in shown:
            table.add_row(
                json.dumps(s["p_data"], separators=(",", ":")),
                "-" if s["configurations"] is None else str(s["configurations"]),
            )
        if len(shown) < len(e["states"]):
            table.caption = f"{len(e['states']) - len(shown)} more (--limit 0 shows all)"
        console.print(table)


@knots_app.command("identify")
def identify_command(
    p_data: str = typer.Argument(..., help='A P-data state, e.g. \'[[1,"O",4,"+"],[2,"U",5,"+"],...]\'.'),
    as_json: bool = typer.Option(False, "--json", help="Print the knot type as JSON."),
) -> None:
    """Which knot a rope state ties when its ends are joined under the table."""
    from twisted.knots import identify
    from twisted.topology import PDataError, parse_p_data

    try:
        k = identify(parse_p_data(p_data))
    except PDataError as exc:
        fail(f"P_DATA: {exc}", EXIT_BAD_INPUT)
    if as_json:
        typer.echo(
            json.dumps(
                {
                    "knot_type": k.name,
                    "alexander": list(k.alexander),
                    "determinant": k.determinant,
                    "jones": [list(t) for t in k.jones],
                    "writhe": k.writhe,
                }
            )
        )
        return
    console.print(
        f"{k.name}  Alexander {k.alexander_text()}  det {k.determinant}  Jones {k.jones_text()}",
        highlight=False,
    )
