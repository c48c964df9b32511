"""Pictures of stored things: a configuration, a goal state, a planner run's plan, a run's pull test.

Each reads what it draws from the store and hands it to the drawings (:mod:`twisted.render.draw`) and,
for the rope seen from above, the MuJoCo child (:mod:`twisted.render.gl`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt
from matplotlib.figure import Figure

from twisted.render.draw import (
    draw_curve,
    draw_gauss_diagram,
    draw_knot_diagram,
    figure_to_array,
    panel_figure,
    save_gif,
    save_png,
)
from twisted.render.geometry import p_data_of_drawing
from twisted.render.gl import gl_top_views
from twisted.topology import PData

__all__ = [
    "RenderError",
    "Rendered",
    "find_drawing",
    "render_configuration",
    "render_goal",
    "render_run",
    "render_tightened",
]


class RenderError(ValueError):
    """Something asked for cannot be drawn (unknown id, a run without a plan); the message says why."""


@dataclass
class Rendered:
    """Files written and how the rope was drawn (``backend``: egl/osmesa, or ``matplotlib`` + why)."""

    files: list[Path]
    backend: str


def render_configuration(store: Any, configuration_id: int, out: str | Path, *, gl: bool = True) -> Rendered:
    """PNG of a stored configuration: MuJoCo top view (if OpenGL works) beside its knot diagram."""
    from twisted.store.models import Configuration, TopologicalState

    with store.session() as session:
        row = session.get(Configuration, configuration_id)
        if row is None:
            raise RenderError(f"configuration {configuration_id} is not in this database")
        q, points = row.q_array(), row.points_array()
        key = session.get(TopologicalState, row.state_id).key
    images, backend = gl_top_views([q]) if gl else (None, "OpenGL not requested (--no-gl)")
    fig, _, ax = panel_figure(images[0] if images else None)
    draw_knot_diagram(ax, points, title=f"configuration {configuration_id}: {key}")
    if images is None:
        fig.text(
            0.01,
            0.005,
            f"drawn from the link points (MuJoCo rendering unavailable: {backend})"[:160],
            fontsize=6,
        )
    path = save_png(fig, out)
    return Rendered([path], backend if images is not None else f"matplotlib ({backend})")


def find_drawing(store: Any, p_data: PData) -> tuple[str, npt.NDArray[np.float64]] | None:
    """Link points of some stored rope in state ``p_data`` (collected data first, then search trees)."""
    from sqlalchemy import select

    from twisted.store.models import Configuration, TopologicalState

    with store.session() as session:
        state_id = session.scalar(select(TopologicalState.id).where(TopologicalState.key == p_data.key))
        if state_id is None:
            return None
        row = session.scalars(
            select(Configuration)
            .where(Configuration.state_id == state_id)
            .order_by(Configuration.id)
            .limit(1)
        ).first()
        if row is not None:
            return f"configuration {row.id}", row.points_array()
        try:
            from twisted.store.search_tree import SearchNode
        except ImportError:  # the planner's tables are not part of this installation
            return None
        node = session.scalars(
            select(SearchNode).where(SearchNode.state_id == state_id).order_by(SearchNode.id).limit(1)
        ).first()
        if node is not None:
            from twisted.store.models import blob_to_array

            return f"search node {node.id} of run {node.run_id}", blob_to_array(node.points, (-1, 3))
    return None


def render_goal(store: Any | None, p_data: PData, out: str | Path) -> Rendered:
    """PNG of a P-data state: a stored rope in that state as a knot diagram (if any) and its Gauss diagram."""
    found = find_drawing(store, p_data) if store is not None else None
    if found is None:
        fig, ax = plt.subplots(figsize=(max(6.0, 0.9 * len(p_data.visits) + 2), 3.8))
        draw_gauss_diagram(ax, p_data, title=f"{p_data.key}\n(no stored rope has this state: Gauss diagram)")
        return Rendered([save_png(fig, out)], "gauss")
    source, points = found
    fig, (ax_k, ax_g) = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"width_ratios": [1.1, 1]})
    crossings = draw_knot_diagram(ax_k, points, title=f"{p_data.key}\nas reached by {source}")
    if p_data_of_drawing(crossings) != p_data:  # never expected: the store keeps Top(points)
        raise RenderError(
            f"{source} is stored as {p_data.key} but its points give {p_data_of_drawing(crossings)}"
        )
    draw_gauss_diagram(ax_g, p_data)
    return Rendered([save_png(fig, out)], "knot")


def _solved_run(store: Any, run_id: int) -> tuple[Any, list[Any]]:
    """A planner run and the stored path of its plan; RenderError when there is none to draw."""
    from twisted.store.search_tree import NoPlanError, solved_run

    try:
        return solved_run(store, run_id)
    except NoPlanError as exc:
        raise RenderError(f"{exc}: nothing to draw") from None


def render_run(
    store: Any, run_id: int, out_png: str | Path, out_gif: str | Path | None = None, *, gl: bool = True
) -> Rendered:
    """A solved planner run: PNG of the final rope and a GIF of the plan, one frame per curve.

    The frames are the configurations stored in the search tree along the found path (the exact
    states the planner reached; ``twisted replay`` re-simulates them). Each frame shows the next
    curve as an arrow.
    """
    from twisted.knots import knot_type_name

    info, path = _solved_run(store, run_id)
    images, backend = gl_top_views([n.q for n in path]) if gl else (None, "OpenGL not requested (--no-gl)")
    n_steps = len(path) - 1
    unit = "step" if any(node.action == "cinch" for node in path) else "curve"  # a cinch is a step, no curve

    view = _plan_view(path)

    def frame(i: int, fixed: bool = False) -> Figure:
        node = path[i]
        fig, _, ax = panel_figure(images[i] if images else None)
        cinched = ": the cinch" if node.action == "cinch" else ""
        what = "start" if i == 0 else f"after {unit} {i}/{n_steps}{cinched}"
        goal_mark = ""
        if node.p_data in info.goal:
            tied = f" ({info.goal.knot}: {knot_type_name(node.p_data)})" if info.goal.knot else ""
            # knot_type_name: the knot when both closures agree, else "knotoid"
            goal_mark = f"  = goal{tied}"
        title = f"run {run_id}, {what}: {node.p_data.key}{goal_mark}"
        draw_knot_diagram(ax, node.points, title=title, zoom=not fixed)
        next_curve = path[i + 1].curve if i < n_steps else None
        if next_curve is not None:
            draw_curve(ax, node.points, next_curve)
        if fixed:  # every frame of the GIF on the same axes, so the rope does not jump between frames
            (x0, y0), (x1, y1) = view
            ax.set_xlim(x0, x1)
            ax.set_ylim(y0, y1)
            ax.set_aspect("equal", adjustable="box")
        return fig

    files = [save_png(frame(n_steps), out_png)]
    if out_gif is not None:
        frames = [figure_to_array(frame(i, fixed=True), dpi=80) for i in range(len(path))]
        files.append(save_gif(frames, out_gif, frame_s=1.0, last_frame_s=3.0))
    return Rendered(files, backend if images is not None else f"matplotlib ({backend})")


def _plan_view(path: list[Any]) -> tuple[tuple[float, float], tuple[float, float]]:
    """The (x, y) box that holds every rope of a plan and the head of every curve's arrow, with a margin:
    the axes of each GIF frame."""
    corners = []
    for i, node in enumerate(path):
        xy = np.asarray(node.points, dtype=np.float64)[:, :2]
        corners += [xy.min(axis=0), xy.max(axis=0)]
        curve = path[i + 1].curve if i + 1 < len(path) else None
        if curve is not None:
            link, _, x_m, y_m = curve
            centre = (xy[int(link)] + xy[int(link) + 1]) / 2
            corners.append(centre + (x_m, y_m))
    lo, hi = np.min(corners, axis=0), np.max(corners, axis=0)
    margin = 0.08 * float((hi - lo).max()) + 0.02
    return (float(lo[0] - margin), float(lo[1] - margin)), (float(hi[0] + margin), float(hi[1] + margin))


def render_tightened(store: Any, run_id: int, out_png: str | Path) -> Rendered:
    """A run's final rope beside the same rope pulled tight (its newest stored pull test).

    The pull test is stored by ``twisted replay --tighten`` / ``twisted plan --tighten``; both panels are
    drawn from link points, each titled with what the rope ties (both closures).
    """
    from twisted.knots import identify
    from twisted.store.knots import tightenings

    info, path = _solved_run(store, run_id)
    with store.session() as session:
        tests = [t for t in tightenings(session, run_id) if t.ok and t.points is not None]
    final = path[-1]
    tests = [t for t in tests if t.node_seq == final.seq] or tests
    if not tests:
        raise RenderError(f"run {run_id} has no pull test stored: run `twisted replay {run_id} --tighten`")
    test = tests[-1]
    fig, (ax_plan, ax_taut) = plt.subplots(1, 2, figsize=(12.8, 5.2))
    draw_knot_diagram(
        ax_plan,
        final.points,
        title=f"run {run_id}, end of the plan: {identify(final.p_data).describe()}\n{final.p_data.key}",
    )
    assert test.points is not None
    verdict = "ties" if test.ties_goal else "does NOT tie"
    wanted = info.goal.knot or ", ".join(sorted(info.goal.knot_types)) or "no knot"
    draw_knot_diagram(
        ax_taut,
        test.points,
        title=f"both ends pulled apart ({test.end_distance_m or 0:.2f} m): {test.knot_after}\n"
        f"{verdict} the goal's knot ({wanted})",
    )
    return Rendered([save_png(fig, out_png)], "matplotlib (link points)")
