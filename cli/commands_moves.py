"""`twisted moves ...`: successors of a state, the enumeration from the empty rope, BFS plans (cached).

States are read and printed as P-data JSON (docs/DESIGN.md section 4); outputs are one JSON value per line.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, NoReturn

import typer

from cli.app import EXIT_BAD_INPUT, EXIT_NOT_REACHED, db_url, err_console, fail, subcommands

if TYPE_CHECKING:
    from twisted.topology import PData

moves_app = subcommands(
    "moves",
    "High-level moves (R1, R2, Cross) on P-data: successors, enumeration, BFS plans.",
)

MAX_ENUMERATE_CROSSES = 5  # 4 takes about a second; 5 about half a minute and ~150k states


def _fail(message: str, code: int = EXIT_BAD_INPUT) -> NoReturn:
    fail(message, code)  # fail() escapes rich markup (P-data messages are full of [...])


def _state(text: str, option: str) -> PData:
    from twisted.diagram import diagram
    from twisted.topology import PDataError, parse_p_data

    try:
        p = parse_p_data(text)
    except PDataError as exc:
        _fail(f'{option}: {exc} (example: \'[[1,"O",2,"+"],[2,"U",1,"+"]]\'; [] is the straight rope)')
    try:
        diagram(p)
    except PDataError as exc:
        _fail(f"{option}: {exc}")
    return p


def _line(value: object) -> None:
    typer.echo(json.dumps(value, separators=(",", ":")))


@moves_app.command("successors")
def successors_command(
    state: str = typer.Option(..., "--state", help="P-data JSON of the state, e.g. '[]'."),
    distinct: bool = typer.Option(False, "--distinct", help="Print each distinct successor state once."),
) -> None:
    """Every move from STATE: one JSON object {"move": ..., "state": ...} per line."""
    from twisted.moves import successor_states, successors

    p = _state(state, "--state")
    if distinct:
        for s in successor_states(p):
            typer.echo(s.to_json())
        return
    for succ in successors(p):
        _line({"move": succ.move.to_dict(), "state": succ.state.to_list()})


@moves_app.command("enumerate")
def enumerate_command(
    max_crosses: int = typer.Option(
        ..., "--max-crosses", min=0, max=MAX_ENUMERATE_CROSSES, help="Largest crossing count to list."
    ),
) -> None:
    """Every state reachable by moves from the empty rope with at most N crossings, one per line,
    ordered by crossing count then key (counts per crossing count go to stderr)."""
    from twisted.moves import enumerate_states

    with err_console.status(f"enumerating states up to {max_crosses} crossings"):
        layers = enumerate_states(max_crosses)
    for layer in layers.values():
        for p in layer:
            typer.echo(p.to_json())
    counts = ", ".join(f"{c}: {len(layer)}" for c, layer in layers.items())
    err_console.print(f"states per crossing count: {counts}", highlight=False)


@moves_app.command("plan")
def plan_command(
    ctx: typer.Context,
    goal: str = typer.Option(..., "--goal", help="P-data JSON of the goal state."),
    start: str = typer.Option(
        "[]", "--start", help="P-data JSON of the start state (default [], the straight rope)."
    ),
    limit: int = typer.Option(100, "--limit", min=1, help="At most this many plans, shortest first."),
    cache: bool = typer.Option(True, "--cache/--no-cache", help="Use the plan cache in the --db database."),
) -> None:
    """BFS plans from START to GOAL: one JSON object per plan and line, shortest first
    ({"length", "states", "moves"}). Exits 3 when no sequence of moves reaches the goal."""
    from twisted.moves import plans

    start_p = _state(start, "--start")
    goal_p = _state(goal, "--goal")
    if cache:
        from twisted.store import StoreError, open_store
        from twisted.store.plans import cached_plans

        try:
            with open_store(db_url(ctx)) as store:
                found = cached_plans(store, start_p, goal_p, limit)
        except StoreError as exc:
            _fail(str(exc))
    else:
        found = plans(start_p, goal_p, limit)
    if not found:
        why = (
            f"it has {goal_p.cross} crossings and the start {start_p.cross}; moves only add crossings"
            if goal_p.cross <= start_p.cross
            else "moves never remove or change a crossing, and no sequence of moves builds it from the start"
        )
        _fail(f"goal {goal_p.key} cannot be reached from {start_p.key}: {why}", EXIT_NOT_REACHED)
    for plan in found:
        _line(plan.to_dict())
