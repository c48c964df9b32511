"""Write the knot table's pictures and rows for docs/knots.md (issue 65).

    PYTHONPATH=. python scripts/knot_table_page.py [--out docs/img/knots] [--measured DB LABEL ...]

For every knot of the table (``twisted knots list``) it writes the Gauss diagram of its first goal
state (by key) as a small SVG, drawn by :func:`twisted.browse.svg.gauss_svg` (what ``twisted browse``
shows), and prints the page's table rows: the knot's KnotInfo name (linked to KnotInfo's picture of it),
its type and common names, crossing number, goal states, the picture and the columns the measurement
fills. Nothing is measured here: ``--measured DB LABEL`` (a SQLite file and the ``eval --label`` of a
measurement in it, or several labels joined by commas; repeatable) reads ``eval_results``, read-only.
A knot's row has one line per store that measured it, naming the store's rope when it is not the
default or when several did, and the picture of the first solved seed (of the first store that has
one) pulled tight, drawn by ``twisted render --run N --tightened`` run with the store's own
``TWISTED_ROPE`` (that command opens the store to write: it upgrades an older schema and stores the pull
test when none is stored); a knot no store holds reads ``not yet measured``.
"""

from __future__ import annotations

import argparse
import os
import sqlite3
import statistics
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy import create_engine, text

from twisted.browse.svg import gauss_svg
from twisted.knots import (
    CATALOGUE,
    KNOT_NAMES,
    crossing_number,
    knotinfo_name,
    minimal_states,
    resolve_knot,
)
from twisted.rope import DEFAULT_ROPE, MAX_CROSSINGS, RopeProfile
from twisted.store import stored_rope

KNOTINFO_PAGE = "https://knotinfo.org/diagram_display.php?{name}"


def _file_name(knot_type: str) -> str:
    return knot_type.replace("+", "p").replace("-", "m").replace("#", "_sum_") + ".svg"


def _also(knot_type: str) -> str:
    """The names a user may type for exactly this type, besides the type itself."""
    names = [n for n, types in KNOT_NAMES.items() if types == {knot_type} and n != knot_type.lower()]
    return ", ".join(f"`{n}`" for n in names) or "-"


@dataclass
class Measured:
    """One knot's rows of a measurement: (solved, wall seconds, simulator calls, plan run) per seed."""

    rope: RopeProfile
    seeds: list[tuple[bool, float | None, int | None, int | None]]


def _read_measurement(path: Path, label: str) -> dict[str, Measured]:
    """The knot goals of ``label`` (one ``eval --label``, or several joined by commas) in the SQLite store
    ``path`` (read-only), by knot type; finished rows only (solved or out of time), each value checked for
    its type."""
    uri = f"{path.resolve().as_uri()}?mode=ro"
    engine = create_engine("sqlite://", creator=lambda: sqlite3.connect(uri, uri=True))
    labels = [name for name in label.split(",") if name]
    marks = ", ".join(f":label{i}" for i in range(len(labels)))
    try:
        with engine.connect() as conn:
            rope = stored_rope(conn) or DEFAULT_ROPE  # the store's own reading, checked
            rows = conn.execute(
                text(
                    "SELECT goal_key, seed, solved, wall_s, sim_calls, plan_run_id FROM eval_results "
                    f"WHERE planner IN ({marks}) AND status IN ('solved', 'timeout') "
                    "ORDER BY goal_key, seed LIMIT 10000"
                ),
                {f"label{i}": name for i, name in enumerate(labels)},
            ).all()
    finally:
        engine.dispose()
    found: dict[str, Measured] = {}
    for goal_key, _seed, solved, wall_s, calls, run_id in rows:
        if not (isinstance(goal_key, str) and goal_key.startswith("knot:") and "@" in goal_key):
            continue
        types = resolve_knot(goal_key[len("knot:") : goal_key.rindex("@")])  # "granny+" is "3_1+#3_1+"
        if len(types) != 1:
            continue
        entry = found.setdefault(next(iter(types)), Measured(rope, []))
        entry.seeds.append(
            (
                bool(solved),
                float(wall_s) if isinstance(wall_s, (int, float)) else None,
                int(calls) if isinstance(calls, int) else None,
                int(run_id) if isinstance(run_id, int) else None,
            )
        )
    return found


def _pulled_tight(path: Path, measured: Measured, png: Path) -> bool:
    """Draw the first solved seed's rope pulled tight to ``png`` (``twisted render --tightened``)."""
    run = next((run_id for solved, _w, _c, run_id in measured.seeds if solved and run_id is not None), None)
    if run is None:
        return False
    env = {k: v for k, v in os.environ.items() if k != "TWISTED_ROPE"}
    if measured.rope != DEFAULT_ROPE:
        env["TWISTED_ROPE"] = measured.rope.env_value
    command = [sys.executable, "-m", "cli.main", "--db", f"sqlite:///{path}", "--force", "render"]
    command += ["--run", str(run), "--tightened", "--out", str(png)]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        print(f"render of run {run} in {path} failed: {done.stderr.strip()}", file=sys.stderr)
    return done.returncode == 0


def _measured_columns(knot_type: str, found: list[Measured], picture: str | None) -> list[str]:
    """The four measured columns of a knot's row: one line per store (its rope named when it is not the
    default, or when several stores measured the knot), the picture of the first solved seed."""
    if not found:
        return ["not yet measured"] * 4
    columns: list[list[str]] = [[], [], []]
    for measured in found:
        solved = [s for s in measured.seeds if s[0]]
        rope = measured.rope
        on = f" ({rope.n_links} links)" if rope != DEFAULT_ROPE or len(found) > 1 else ""
        walls = [w for _ok, w, _c, _r in solved if w is not None]
        calls = [c for _ok, _w, c, _r in solved if c is not None]
        columns[0].append(f"{len(solved)} / {len(measured.seeds)}{on}")
        columns[1].append(f"{statistics.median(walls):.1f} s" if walls else "-")
        columns[2].append(f"{statistics.median(calls):,.0f}" if calls else "-")
    shown = f"![{knot_type} pulled tight]({picture})" if picture else "-"
    return ["<br>".join(column) for column in columns] + [shown]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/img/knots"), help="where the SVGs go")
    parser.add_argument(
        "--measured",
        nargs=2,
        action="append",
        default=[],
        metavar=("DB", "LABEL"),
        help="a SQLite store and the eval --label of a measurement in it (repeatable)",
    )
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    stores = [(Path(db), _read_measurement(Path(db), label)) for db, label in args.measured]
    print(
        "| KnotInfo | type | also typed as | crossings | goal states | a goal state (Gauss diagram) | "
        "tied / seeds (rope) | median wall time (tied) | median calls (tied) | pulled tight |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for knot_type in CATALOGUE:
        if knot_type == "0_1":
            continue
        states = minimal_states(knot_type)
        (args.out / _file_name(knot_type)).write_text(gauss_svg(states[0].key) + "\n")
        parts = knotinfo_name(knot_type).split("#")
        linked = " # ".join(f"[{p}]({KNOTINFO_PAGE.format(name=p)})" for p in parts)
        crossings = crossing_number(knot_type)
        held = [(path, found[knot_type]) for path, found in stores if knot_type in found]
        if not held and crossings > MAX_CROSSINGS:
            measured = [f"not plannable: the model encodes at most {MAX_CROSSINGS} crossings", "-", "-", "-"]
        else:
            png = args.out / _file_name(knot_type).replace(".svg", "_tight.png")
            drawn = any(_pulled_tight(path, measured, png) for path, measured in held)  # first that solved
            tight = f"img/knots/{png.name}" if drawn else None
            measured = _measured_columns(knot_type, [m for _p, m in held], tight)
        picture = f"![a state tying {knot_type}](img/knots/{_file_name(knot_type)})"
        row = [linked, f"`{knot_type}`", _also(knot_type), str(crossings), str(len(states)), picture]
        row += measured
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
