"""`twisted problems make|import|knots|list`: the goal sets that evaluations run on."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table

from cli.app import (
    console,
    fail,
    open_db,
    seed_option,
    shown_name,
    subcommands,
)
from cli.options import (
    json_option,
    print_json,
)

problems_app = subcommands("problems", "Goal sets for evaluations (made from our data or imported).")


def _print_sets(records: list[Any]) -> None:
    table = Table("set", "goals", "cross", "frequency (min-max)", "tags")
    for r in records:
        freqs = [p.frequency for p in r.problems]
        tags = sorted({p.tag for p in r.problems})
        crosses = sorted({p.p_data.cross for p in r.problems})
        table.add_row(
            shown_name(r.name),
            str(len(r.problems)),
            ",".join(map(str, crosses)),
            f"{min(freqs)}-{max(freqs)}" if freqs else "-",
            ", ".join(map(shown_name, tags)),
        )
    console.print(table)


@problems_app.command("make")
def problems_make(
    ctx: typer.Context,
    seed: int = seed_option(0, "Seed of the draw; the same seed gives the same sets."),
    per_set: int = typer.Option(10, "--per-set", min=1, help="Goals per set (10 in the paper)."),
    prefix: str = typer.Option("", "--prefix", help="Prefix of the set names (e.g. 's1-' -> s1-easy)."),
    replace: bool = typer.Option(
        False, "--replace", help="Replace sets of the same name that have no results."
    ),
    sets: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            help="Only these sets (easy, medium, hard, unseen-3, 4, 5 from our data; u4, u5 uniform over "
            "all states of 4 and 5 crossings, u6 sampled near uniform, catalogue: every named knot up to 6 "
            "crossings in each hand, knots: overhand, figure-eight, 5_1, 5_2, granny, square in either hand; "
            "docs/goals.md); repeatable. Default: the sets from our data.",
        ),
    ] = None,
) -> None:
    """Make easy/medium/hard (3-crossing states by visit frequency), unseen-3 and 4 from our data."""
    from twisted.experiments import EvalInputError, make_problem_sets_in_store
    from twisted.experiments.problems import ALL_MADE_SETS, MAKEABLE_SETS

    unknown = [name for name in sets or () if name not in MAKEABLE_SETS]
    if unknown:
        fail(f"--set {unknown[0]}: no such set; choose from {', '.join(MAKEABLE_SETS)}")
    with open_db(ctx) as store:
        try:
            records = make_problem_sets_in_store(
                store, per_set=per_set, seed=seed, prefix=prefix, replace=replace, sets=sets or ALL_MADE_SETS
            )
        except EvalInputError as exc:
            fail(str(exc))
    _print_sets(records)


@problems_app.command("import")
def problems_import(
    ctx: typer.Context,
    file: Annotated[Path, typer.Argument(help="JSON: a list of P-data, or an object of named lists.")],
    name: str = typer.Option(
        None, "--name", help="Set name (a list) or prefix of the set names (an object)."
    ),
) -> None:
    """Import goal sets from a JSON file (every state is checked; nothing is stored on an error)."""
    from twisted.experiments import EvalInputError, import_problem_sets
    from twisted.experiments.problems import decode_goal_file, read_goal_file

    try:
        read = read_goal_file(decode_goal_file(file.read_bytes()), name)  # all checked before the store opens
    except OSError as exc:
        fail(f"cannot read goal file {str(file)!r}: {exc.strerror}")
    except EvalInputError as exc:
        fail(f"{file}: {exc}")
    with open_db(ctx) as store:
        try:
            records = import_problem_sets(store, read)
        except EvalInputError as exc:
            fail(f"{file}: {exc}")
    _print_sets(records)


@problems_app.command("knots")
def problems_knots(
    ctx: typer.Context,
    knots: Annotated[
        list[str],
        typer.Argument(help="Knots (see `twisted knots list`): NAME or NAME@CROSSINGS, e.g. overhand@3."),
    ],
    name: str = typer.Option(..., "--name", help="Name of the new set."),
) -> None:
    """Make a set of knot goals: each is reached by any rope state that ties the knot."""
    from twisted.experiments import EvalInputError, save_goal_sets
    from twisted.goals import GoalError, goal_from_spec

    goals = []
    for i, knot in enumerate(knots, start=1):
        if knot.strip().startswith("["):
            fail(f"knot {i} ({knot!r}) is P-data: put P-data goals in a file for `twisted problems import`")
        try:
            goals.append(goal_from_spec(knot))
        except GoalError as exc:
            fail(f"knot {i} ({knot!r}): {exc}")
    with open_db(ctx) as store:
        try:
            records = save_goal_sets(store, {name: goals}, "knot")
        except EvalInputError as exc:
            fail(str(exc))
    _print_sets(records)


@problems_app.command("list")
def problems_list(
    ctx: typer.Context,
    show: str = typer.Option(None, "--show", help="Also print the goals of this set."),
    as_json: bool = json_option("the sets (with --show: that set's goals, importable)"),
) -> None:
    """The stored problem sets (and the goals of one with --show)."""
    from twisted.store.experiments import list_problem_sets, load_problem_set

    with open_db(ctx, readonly=True) as store, store.session() as session:
        sets = list_problem_sets(session)
        record = load_problem_set(session, show) if show else None
    if show and record is None:
        fail(f"no problem set {show!r}: see `twisted problems list`")
    if record is not None and as_json:
        print_json([p.p_data.to_list() if p.spec is None else p.spec for p in record.problems])
        return
    if as_json:
        print_json(sets)
        return
    table = Table("id", "set", "source", "seed", "goals", "cross", "frequency", "results")
    for s in sets:
        table.add_row(
            str(s["id"]),
            shown_name(s["name"]),
            shown_name(s["source"]),
            "-" if s["seed"] is None else str(s["seed"]),
            str(s["problems"]),
            "-".join(map(str, sorted(set(s["cross"])))) if s["cross"][0] is not None else "-",
            f"{s['frequency'][0]}-{s['frequency'][1]}" if s["frequency"][0] is not None else "-",
            str(s["results"]),
        )
    console.print(table)
    if record is not None:
        goals = Table("#", "goal", "cross", "frequency", "tag")
        for p in record.problems:
            goals.add_row(
                str(p.idx), shown_name(p.goal_key), str(p.p_data.cross), str(p.frequency), shown_name(p.tag)
            )
        console.print(goals)
