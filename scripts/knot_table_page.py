"""Write the knot table's pictures and rows for docs/knots.md (issue 65).

    PYTHONPATH=. python scripts/knot_table_page.py [--out docs/img/knots]

For every knot of the table (``twisted knots list``) it writes the Gauss diagram of its first goal
state (by key) as a small SVG, drawn by :func:`twisted.browse.svg.gauss_svg` (what ``twisted browse``
shows), and prints the page's table rows: the knot's KnotInfo name (linked to KnotInfo's picture of it),
its type and common names, crossing number, goal states, the picture and the columns the measurement
fills (``not yet measured`` until it does). Nothing is measured here.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from twisted.browse.svg import gauss_svg
from twisted.knots import CATALOGUE, KNOT_NAMES, crossing_number, knotinfo_name, minimal_states
from twisted.rope import MAX_CROSSINGS

KNOTINFO_PAGE = "https://knotinfo.org/diagram_display.php?{name}"


def _file_name(knot_type: str) -> str:
    return knot_type.replace("+", "p").replace("-", "m").replace("#", "_sum_") + ".svg"


def _also(knot_type: str) -> str:
    """The names a user may type for exactly this type, besides the type itself."""
    names = [n for n, types in KNOT_NAMES.items() if types == {knot_type} and n != knot_type.lower()]
    return ", ".join(f"`{n}`" for n in names) or "-"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/img/knots"), help="where the SVGs go")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    not_measured = "not yet measured"
    print(
        "| KnotInfo | type | also typed as | crossings | goal states | a goal state (Gauss diagram) | "
        "success (5 seeds) | median wall time | median calls | pulled tight |"
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
        measured = (
            [not_measured] * 4
            if crossings <= MAX_CROSSINGS
            else [f"not plannable: the model encodes at most {MAX_CROSSINGS} crossings", "-", "-", "-"]
        )
        picture = f"![a state tying {knot_type}](img/knots/{_file_name(knot_type)})"
        row = [linked, f"`{knot_type}`", _also(knot_type), str(crossings), str(len(states)), picture]
        row += measured
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
