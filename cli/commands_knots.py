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

def _visits(ctx: typer.Context, keys: list[str]) -> dict[str, int] | None:
    """Configurations per state key from the database, or None when there is no database to read."""
    from twisted.store import StoreError, open_store
    from twisted.store.knots import configurations_per_state

    try:
        store = open_store(db_url(ctx), create=False, readonly=True)
    except StoreError as exc:
        err_console.print(f"note: no visit counts ({exc})", highlight=False)
        return None
    with store, store.session() as session:
        return configurations_per_state(session, keys)


def list_name(knot_type: str) -> str:
    """The name ``knots list`` shows: the common name with its chirality where one stands for exactly this
    type (``overhand+``, ``figure-eight``, ``square``), else the table type (``6_2+``)."""
    from twisted.knots import COMMON_NAMES, KNOT_NAMES, knotinfo_name

    for name in ("granny+", "granny-", "square"):
        if KNOT_NAMES[name] == {knot_type}:
            return name
    bare = knotinfo_name(knot_type)
    if knot_type == "0_1":
        return "unknot"
    if "#" in knot_type or bare not in COMMON_NAMES:
        return knot_type
    return COMMON_NAMES[bare][0] + knot_type[len(bare) :]


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
    as_json: bool = json_option("everything (all states)"),
) -> None:
    """The knot table (KnotInfo's prime knots up to 7 crossings, each chirality, and the sums of two with at
    most 7 crossings in all): for each knot its invariants, and the P-data states that really tie it (both
    closures are the knot) at its crossing number, with how often the data in --db visited each
    (configurations reached in that state)."""
    from twisted.knots import (
        CATALOGUE,
        COMPOSITE_NOTE,
        MAX_BUILT_CROSSINGS,
        MAX_ENUMERATED_CROSSINGS,
        crossing_number,
        knotinfo_name,
        states_tying,
    )

    if crossings is not None and not 0 <= crossings <= MAX_BUILT_CROSSINGS:
        fail(f"--crossings must be between 0 and {MAX_BUILT_CROSSINGS}, got {crossings}")
    if not 0 <= max_crossings <= MAX_ENUMERATED_CROSSINGS:
        fail(f"--max-crossings must be between 0 and {MAX_ENUMERATED_CROSSINGS}, got {max_crossings}")
    if limit < 0:
        fail(f"--limit must be >= 0, got {limit}")

    found: dict[str, list[Any] | None] = {}  # None: not enumerated at that count (see --max-crossings)
    counts: dict[str, int] = {}
    for knot_type in CATALOGUE:
        count = crossings if crossings is not None else crossing_number(knot_type)
        counts[knot_type] = count
        try:
            found[knot_type] = states_tying(knot_type, count, max_crossings=max_crossings)
        except ValueError:
            found[knot_type] = None
    visits = _visits(ctx, [p.key for states in found.values() for p in states or ()])

    entries: list[dict[str, Any]] = []
    for knot_type, k in CATALOGUE.items():
        listed = found[knot_type]
        states = sorted(listed or [], key=lambda p: (-(visits or {}).get(p.key, 0), p.key))
        entries.append(
            {
                "name": list_name(knot_type),
                "knot_type": knot_type,
                "knotinfo": knotinfo_name(knot_type),
                "alexander": k.alexander_text(),
                "determinant": k.determinant,
                "jones": k.jones_text(),
                "crossing_number": crossing_number(knot_type),
                "crossings": counts[knot_type],
                "listed": listed is not None,
                "states": [
                    {"p_data": p.to_list(), "configurations": None if visits is None else visits[p.key]}
                    for p in states
                ],
                "visited_states": None if visits is None else sum(visits[p.key] > 0 for p in states),
                "configurations": None if visits is None else sum(visits[p.key] for p in states),
            }
        )
    if as_json:
        print_json(entries)
        return

    summary = Table(
        title="The knot table (KnotInfo): states whose closures under AND over the table are the knot "
        "(knotoids excluded)",
        caption=f"Note: {COMPOSITE_NOTE} (docs/knots.md).",
    )
    for column in ("name", "type", "Alexander", "det", "Jones", "crossings", "states", "visited", "configs"):
        summary.add_column(column, justify="right" if column in ("det", "crossings", "states") else "left")
    for e in entries:
        summary.add_row(
            e["name"],
            e["knot_type"],
            e["alexander"],
            str(e["determinant"]),
            e["jones"],
            str(e["crossings"]),
            str(len(e["states"])) if e["listed"] else f"? (--max-crossings {e['crossings']})",
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
