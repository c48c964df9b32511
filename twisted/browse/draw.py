"""The child process that draws one picture of ``twisted browse`` (matplotlib, as ``twisted render``).

    python -m twisted.browse.draw DB_URL OUT state KEY
    python -m twisted.browse.draw DB_URL OUT plan RUN_ID

writes ``OUT`` and exits 0, or prints why it cannot be drawn and exits 2. ``state``: ``render --goal``
as SVG. ``plan``: as PNG, the picture ``plan --picture`` draws (the run's final rope, beside the same
rope pulled tight when it has a pull test); as GIF (``OUT`` ends in ``.gif``), the plan one frame a
step, every frame on the same axes. Every rope it draws is first checked against the rope profile (the
store's link count, finite points), so a planted row of 1,000 links is refused instead of drawn. The
server (:mod:`twisted.browse.plugin`) starts one child per picture and kills it past its time limit,
so no picture can hold the server, and a signal that stops the server ends the drawing too.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["check_rope", "draw", "main"]


def check_rope(points: Any, where: str) -> None:
    """Raise :class:`twisted.render.RenderError` unless ``points`` are the link points of this
    process's rope (the store's, checked when it was opened): (n_points, 3), finite."""
    from twisted.render import RenderError
    from twisted.rope import ROPE

    shape = getattr(points, "shape", None)
    if shape != (ROPE.n_points, 3):
        raise RenderError(
            f"{where} is not a rope of this store: its points have shape {shape}, the rope "
            f"({ROPE.name}) has {ROPE.n_points} points; not drawn"
        )
    if not np.isfinite(points).all():
        raise RenderError(f"{where} holds points that are not finite numbers; not drawn")


def draw(store: Any, out: Path, kind: str, arg: str) -> None:
    """Draw one picture (``state`` KEY or ``plan`` RUN_ID) into ``out``; RenderError when it cannot be."""
    from twisted.render import RenderError, find_drawing, render_goal, render_run, render_tightened
    from twisted.store.boundary import StoredValueError
    from twisted.store.search_tree import NoPlanError, solved_run
    from twisted.topology import PDataError, parse_p_data

    if kind == "state":
        try:
            p_data = parse_p_data(arg)
        except (PDataError, ValueError) as exc:
            raise RenderError(f"key {arg[:80]!r} is not a P-data state: {exc}") from None
        found = find_drawing(store, p_data)
        if found is not None:
            check_rope(found[1], found[0])
        render_goal(store, p_data, out)
    elif kind == "plan":
        run_id = int(arg)
        try:
            _, path = solved_run(store, run_id)
        except NoPlanError as exc:
            raise RenderError(f"{exc}: nothing to draw") from None
        except StoredValueError as exc:  # the boundary's node checks (q, points, counts) refused a node
            rope = "; not a rope of this store" if exc.field in ("q", "points") else ""
            raise RenderError(f"run {run_id}: {exc}{rope}; not drawn") from None
        for node in path:
            check_rope(node.points, f"search node {node.id} of run {run_id}")
        if out.suffix == ".gif":
            render_run(store, run_id, out.with_suffix(".png"), out, gl=False)
        elif _pull_test_points(store, run_id, path[-1].seq) is not None:  # what `plan --picture` draws
            render_tightened(store, run_id, out)
        else:
            render_run(store, run_id, out, gl=False)
    else:
        raise RenderError(f"no picture of kind {kind!r}")


def _pull_test_points(store: Any, run_id: int, final_seq: int) -> Any:
    """The pulled-tight rope that :func:`twisted.render.render_tightened` would draw (checked against
    the rope profile), or None when the run has no pull test."""
    from twisted.store.knots import tightenings

    with store.session() as session:
        tests = [t for t in tightenings(session, run_id) if t.ok and t.points is not None]
    tests = [t for t in tests if t.node_seq == final_seq] or tests
    if not tests:
        return None
    check_rope(tests[-1].points, f"pull test {tests[-1].id} of run {run_id}")
    return tests[-1].points


def main(argv: list[str]) -> int:
    """Exit 0: drawn; 2: cannot be drawn (the reason on stderr, one line)."""
    from twisted.render import RenderError
    from twisted.store import StoreError, open_store

    db_url, out, kind, arg = argv
    try:
        with open_store(db_url, create=False, readonly=True) as store:
            draw(store, Path(out), kind, arg)
    except (RenderError, StoreError) as exc:
        print(" ".join(str(exc).split())[:500], file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
