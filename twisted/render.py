"""Pictures of the rope: a top view (MuJoCo offscreen), knot diagrams, Gauss diagrams, plan replays.

Researchers look before they read. Three kinds of picture:

- **Knot diagram** of a rope given by its 22 centreline points: the projection to the table as a
  line, broken where it passes *under* another strand, every crossing visit numbered as in P-data
  (``3O+`` = visit 3, over, positive crossing). Drawn from the same segment intersection test as
  :func:`twisted.topology.top`, so the numbers on the picture are the numbers in the state.
- **Gauss diagram** of a P-data state without a configuration (an unseen goal): the rope as a
  straight line from head to tail, visits 1..2n along it, one chord per crossing drawn as an
  arrow from its over visit to its under visit, coloured by sign. It is the exact content of the
  P-data; an actual planar layout of an arbitrary state is not computed here.
- **Top view** rendered by MuJoCo (EGL or OSMesa). OpenGL is chosen when ``mujoco`` is imported,
  and in a headless shell the default (GLFW) fails, so the offscreen rendering runs in a child
  interpreter started with ``MUJOCO_GL`` set (``egl`` first, then ``osmesa``). When neither works
  the knot diagram of the link points is the picture (the fallback).
"""

from __future__ import annotations

import io
import os
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only; never a window

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Arc, FancyArrowPatch  # noqa: E402

from twisted.topology import PData, Visit, projected_crossings  # noqa: E402

__all__ = [
    "CrossingDrawing",
    "GL_BACKENDS",
    "crossing_geometry",
    "draw_gauss_diagram",
    "draw_knot_diagram",
    "gl_top_views",
    "knot_zoom",
    "rope_pieces",
    "save_gif",
    "save_png",
    "visit_labels",
]

GL_BACKENDS = ("egl", "osmesa")
ROPE_COLOUR = "#8c510a"
SIGN_COLOUR = {"+": "#1b7837", "-": "#762a83"}
_GAP_M = 0.014  # half-length of the break in an under strand: the rope radius (0.01 m) plus a margin
_ZOOM_MARGIN_M = 0.07  # around the crossings when the knot is small against the whole rope


@dataclass(frozen=True)
class CrossingDrawing:
    """Where one crossing is on the table and which visits of the P-data it carries."""

    xy: tuple[float, float]
    over_segment: int
    over_t: float
    under_segment: int
    under_t: float
    over_visit: int
    under_visit: int
    sign: str  # "+" or "-"


def crossing_geometry(points: npt.ArrayLike) -> list[CrossingDrawing]:
    """The crossings of a projected rope with their positions and visit numbers.

    The crossings of :func:`twisted.topology.projected_crossings`, read as :func:`twisted.topology.top`
    reads them (half-open segment parameters, visits ordered by ``segment + t``, the same tie rule),
    so :func:`p_data_of_drawing` of the result equals ``top(points)``.
    """
    pts = np.asarray(points, dtype=np.float64)
    start, d = pts[:-1], pts[1:] - pts[:-1]
    pc = projected_crossings(pts)
    k = len(pc)
    out = []
    for c in range(k):
        i, j, ti, uj = int(pc.i[c]), int(pc.j[c]), float(pc.t[c]), float(pc.u[c])
        xy = start[i, :2] + ti * d[i, :2]
        if pc.i_over[c]:
            over = (i, ti, int(pc.position[c]))
            under = (j, uj, int(pc.position[c + k]))
        else:
            over = (j, uj, int(pc.position[c + k]))
            under = (i, ti, int(pc.position[c]))
        sign = "+" if pc.sign[c] > 0 else "-"
        out.append(
            CrossingDrawing(
                xy=(float(xy[0]), float(xy[1])),
                over_segment=over[0],
                over_t=over[1],
                under_segment=under[0],
                under_t=under[1],
                over_visit=over[2],
                under_visit=under[2],
                sign=sign,
            )
        )
    return out


def p_data_of_drawing(crossings: Sequence[CrossingDrawing]) -> PData:
    """The P-data a drawing shows (used to check that the picture tells the truth)."""
    visits = []
    for c in crossings:
        visits.append(Visit(c.over_visit, "O", c.under_visit, c.sign))
        visits.append(Visit(c.under_visit, "U", c.over_visit, c.sign))
    return PData(tuple(sorted(visits)))


def _unit(v: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else np.array([1.0, 0.0])


def _arc_length(points: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    seg = np.linalg.norm(np.diff(points[:, :2], axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def _piece(points: npt.NDArray[np.float64], s0: float, s1: float) -> npt.NDArray[np.float64]:
    """The projected polyline between arc lengths s0 < s1 (clipped to the rope)."""
    s = _arc_length(points)
    s0, s1 = max(s0, 0.0), min(s1, float(s[-1]))
    inner = (s > s0) & (s < s1)
    xs = np.interp(np.concatenate([[s0], s[inner], [s1]]), s, points[:, 0])
    ys = np.interp(np.concatenate([[s0], s[inner], [s1]]), s, points[:, 1])
    return np.stack([xs, ys], axis=1)


def rope_pieces(
    points: npt.NDArray[np.float64], crossings: Sequence[CrossingDrawing]
) -> list[npt.NDArray[np.float64]]:
    """The projected rope as the polylines a knot diagram draws: broken around each under-crossing."""
    s = _arc_length(points)
    under_at = sorted(
        s[c.under_segment] + c.under_t * (s[c.under_segment + 1] - s[c.under_segment]) for c in crossings
    )
    cuts = [0.0]
    for sc in under_at:
        cuts += [sc - _GAP_M, sc + _GAP_M]
    cuts.append(float(s[-1]))
    return [_piece(points, a, b) for a, b in zip(cuts[0::2], cuts[1::2], strict=True) if b > a]


def knot_zoom(
    points: npt.NDArray[np.float64], crossings: Sequence[CrossingDrawing]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None:
    """The (lower, upper) corners of a close-up on the crossings when the knot is small against the
    rope, else None (show the whole rope)."""
    if not crossings:
        return None
    span = float(np.ptp(points[:, :2], axis=0).max()) or 1.0
    xy = np.array([c.xy for c in crossings])
    lo, hi = xy.min(axis=0) - _ZOOM_MARGIN_M, xy.max(axis=0) + _ZOOM_MARGIN_M
    return (lo, hi) if float((hi - lo).max()) < 0.6 * span else None


def visit_labels(
    points: npt.NDArray[np.float64], c: CrossingDrawing
) -> tuple[tuple[str, npt.NDArray[np.float64]], ...]:
    """The two visit labels of a crossing (``3O+``, ``4U+``), each with the unit direction (on the
    table) from the crossing to where it goes: along its own strand, the under one on the side
    farther from the over one."""
    d_o = _unit(points[c.over_segment + 1, :2] - points[c.over_segment, :2])
    d_u = _unit(points[c.under_segment + 1, :2] - points[c.under_segment, :2])
    s_u = 1.0 if np.linalg.norm(d_o - d_u) >= np.linalg.norm(d_o + d_u) else -1.0
    return (f"{c.over_visit}O{c.sign}", d_o), (f"{c.under_visit}U{c.sign}", s_u * d_u)


def draw_knot_diagram(
    ax: Axes, points: npt.ArrayLike, *, title: str | None = None, label_visits: bool = True, zoom: bool = True
) -> list[CrossingDrawing]:
    """Draw the rope from above as a knot diagram: gaps at under-crossings, visits numbered.

    Returns the crossings drawn. The head (link-0 tip) is a filled dot, the tail a ring. With
    ``zoom``, a knot much smaller than the rope is shown close up (the rest of the rope runs off
    the panel).
    """
    pts = np.asarray(points, dtype=np.float64)
    crossings = crossing_geometry(pts)
    for piece in rope_pieces(pts, crossings):
        ax.plot(piece[:, 0], piece[:, 1], color=ROPE_COLOUR, lw=4, solid_capstyle="round", zorder=2)
    ax.plot(pts[0, 0], pts[0, 1], "o", color="black", ms=8, zorder=4, label="head (link 0)")
    ax.plot(pts[-1, 0], pts[-1, 1], "o", mfc="white", mec="black", ms=8, zorder=4, label="tail (link 20)")
    view = knot_zoom(pts, crossings) if zoom else None
    lo, hi = view if view is not None else (pts[:, :2].min(axis=0), pts[:, :2].max(axis=0))
    span = float((hi - lo).max()) or 1.0
    if label_visits:
        off = max(0.07 * span, 0.012)
        for c in crossings:
            x, y = c.xy
            ax.plot(x, y, ".", color=SIGN_COLOUR[c.sign], ms=6, zorder=5)
            for text, direction in visit_labels(pts, c):
                ax.annotate(
                    text,
                    (x + off * direction[0], y + off * direction[1]),
                    ha="center",
                    va="center",
                    fontsize=8,
                    color=SIGN_COLOUR[c.sign],
                    zorder=6,
                    bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.7},
                )
    if view is not None:
        (x0, y0), (x1, y1) = view
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal", adjustable="box")
        ax.text(0.01, 0.01, "zoomed on the crossings", transform=ax.transAxes, fontsize=7, color="grey")
    else:
        ax.margins(0.12)
        ax.set_aspect("equal", adjustable="datalim")  # fill the panel rather than shrink it
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best", fontsize=7, frameon=False)
    if title:
        ax.set_title(_wrap(title), fontsize=9)
    return crossings


def _wrap(text: str, width: int = 70) -> str:
    """Break long P-data keys between visits so titles fit their panel."""
    lines = []
    for line in text.split("\n"):
        while len(line) > width:
            cut = line.rfind("],", 0, width)
            cut = width if cut <= 0 else cut + 2
            lines.append(line[:cut])
            line = line[cut:]
        lines.append(line)
    return "\n".join(lines)


def draw_gauss_diagram(ax: Axes, p_data: PData, *, title: str | None = None) -> None:
    """Draw a P-data state as a Gauss diagram of the open rope (exact, no layout guessed).

    Visits 1..2n sit on the rope (a straight line, head left); each crossing is an arc above the
    line from its over visit to its under visit, with an arrow head at the under end, green for
    ``+`` and purple for ``-``.
    """
    m = len(p_data.visits)
    ax.plot([0, m + 1], [0, 0], color=ROPE_COLOUR, lw=4, solid_capstyle="round", zorder=2)
    ax.plot(0, 0, "o", color="black", ms=8, zorder=4)
    ax.plot(m + 1, 0, "o", mfc="white", mec="black", ms=8, zorder=4)
    ax.annotate("head", (0, -0.25), ha="center", va="top", fontsize=8)
    ax.annotate("tail", (m + 1, -0.25), ha="center", va="top", fontsize=8)
    top = 0.5
    for over, under, sign in p_data.crossings():
        s = "+" if sign > 0 else "-"
        colour = SIGN_COLOUR[s]
        a, b = sorted((over, under))
        width = b - a
        ax.add_patch(
            Arc(((a + b) / 2, 0), width, width, theta1=0, theta2=180, color=colour, lw=1.8, zorder=3)
        )
        top = max(top, width / 2)
        # arrow head at the under visit, along the arc's tangent (vertical at the line)
        ax.add_patch(
            FancyArrowPatch(
                (under, 0.12 * max(width, 1)),
                (under, 0.02),
                arrowstyle="-|>",
                mutation_scale=12,
                color=colour,
                zorder=4,
            )
        )
        ax.annotate(s, ((a + b) / 2, width / 2 + 0.08), ha="center", va="bottom", fontsize=10, color=colour)
    for v in p_data.visits:
        ax.plot(v.position, 0, "o", color=SIGN_COLOUR[v.sign], ms=6, zorder=5)
        ax.annotate(f"{v.position}{v.over}", (v.position, -0.12), ha="center", va="top", fontsize=9)
    ax.set_xlim(-0.6, m + 1.6)
    ax.set_ylim(-0.8, top + 0.6)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title(title or f"Gauss diagram (arrow: over -> under)\n{p_data.key}", fontsize=8)


def save_png(fig: Figure, path: str | Path, dpi: int = 120) -> Path:
    """Save a figure as PNG (creating the folder) and close it."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return out


def figure_to_array(fig: Figure, dpi: int = 100) -> npt.NDArray[np.uint8]:
    """Rasterise a figure to an RGB uint8 array (for GIF frames); closes the figure."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    buf.seek(0)
    from PIL import Image

    return np.asarray(Image.open(buf).convert("RGB"))


def save_gif(
    frames: Sequence[npt.NDArray[np.uint8]],
    path: str | Path,
    frame_s: float = 0.5,
    last_frame_s: float | None = None,
) -> Path:
    """Write RGB frames as an animated GIF (looping); frames are padded to a common size.

    ``last_frame_s`` holds the final frame longer (a replay should rest on its result).
    """
    from PIL import Image

    if not frames:
        raise ValueError("no frames to write")
    h = max(f.shape[0] for f in frames)
    w = max(f.shape[1] for f in frames)
    images = []
    for f in frames:
        canvas = np.full((h, w, 3), 255, dtype=np.uint8)
        canvas[: f.shape[0], : f.shape[1]] = f[..., :3]
        images.append(Image.fromarray(canvas))
    durations = [int(frame_s * 1000)] * len(images)
    if last_frame_s is not None:
        durations[-1] = int(last_frame_s * 1000)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(
        out,
        save_all=True,
        append_images=images[1:],
        duration=durations,
        loop=0,
        optimize=False,
    )
    return out


# ---------------------------------------------------------------- pictures of stored things


class RenderError(ValueError):
    """Something asked for cannot be drawn (unknown id, a run without a plan); the message says why."""


@dataclass
class Rendered:
    """Files written and how the rope was drawn (``backend``: egl/osmesa, or ``matplotlib`` + why)."""

    files: list[Path]
    backend: str


def _panel_figure(gl_image: npt.NDArray[np.uint8] | None) -> tuple[Figure, Axes | None, Axes]:
    if gl_image is None:
        fig, ax = plt.subplots(figsize=(6.4, 5.2))
        return fig, None, ax
    fig, (ax_gl, ax) = plt.subplots(1, 2, figsize=(12.8, 5.2), gridspec_kw={"width_ratios": [1.25, 1]})
    ax_gl.imshow(gl_image)
    ax_gl.axis("off")
    ax_gl.set_title("MuJoCo, from above", fontsize=9)
    return fig, ax_gl, ax


def _draw_curve(ax: Axes, points: npt.NDArray[np.float64], curve: Sequence[float]) -> None:
    """The next curve as an arrow: from the grasped link's centre by its (x, y) displacement."""
    link, z_max_m, x_m, y_m = curve
    i = int(link)
    centre = (points[i, :2] + points[i + 1, :2]) / 2
    ax.annotate(
        "",
        xy=(centre[0] + x_m, centre[1] + y_m),
        xytext=(centre[0], centre[1]),
        arrowprops={"arrowstyle": "->", "color": "#2166ac", "lw": 1.6, "ls": "--"},
        zorder=7,
    )
    ax.annotate(
        f"link {i}, z {z_max_m * 100:.1f} cm",
        (centre[0] + x_m, centre[1] + y_m),
        fontsize=7,
        color="#2166ac",
        xytext=(4, 4),
        textcoords="offset points",
    )
    # keep the arrow head inside the axes
    ax.update_datalim([(centre[0] + x_m, centre[1] + y_m)])
    ax.autoscale_view()


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
    fig, _, ax = _panel_figure(images[0] if images else None)
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
            from twisted.store.search import SearchNode
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
    from twisted.store.search import load_run, solution_path

    info = load_run(store, run_id, with_nodes=False)
    if info is None:
        raise RenderError(f"run {run_id} is not a planner run in this database")
    path = solution_path(store, run_id)
    if not path:
        raise RenderError(f"run {run_id} found no plan (outcome: {info.outcome}); nothing to draw")
    return info, path


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

    def frame(i: int) -> Figure:
        node = path[i]
        fig, _, ax = _panel_figure(images[i] if images else None)
        what = "start" if i == 0 else f"after curve {i}/{n_steps}"
        goal_mark = ""
        if node.p_data in info.goal:
            tied = f" ({info.goal.knot}: {knot_type_name(node.p_data)})" if info.goal.knot else ""
            # knot_type_name: the knot when both closures agree, else "knotoid"
            goal_mark = f"  = goal{tied}"
        draw_knot_diagram(ax, node.points, title=f"run {run_id}, {what}: {node.p_data.key}{goal_mark}")
        next_curve = path[i + 1].curve if i < n_steps else None
        if next_curve is not None:
            _draw_curve(ax, node.points, next_curve)
        return fig

    files = [save_png(frame(n_steps), out_png)]
    if out_gif is not None:
        frames = [figure_to_array(frame(i), dpi=80) for i in range(len(path))]
        files.append(save_gif(frames, out_gif, frame_s=1.0, last_frame_s=3.0))
    return Rendered(files, backend if images is not None else f"matplotlib ({backend})")


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


# ---------------------------------------------------------------- MuJoCo offscreen top view


def gl_top_views(
    states: Sequence[npt.NDArray[np.float64]],
    *,
    friction_scale: float = 1.0,
    width: int = 640,
    height: int = 480,
    backends: Sequence[str] | None = None,
    timeout_s: float = 300.0,
) -> tuple[list[npt.NDArray[np.uint8]] | None, str]:
    """Render rope states (``RopeSim.state()`` vectors) from above with MuJoCo offscreen OpenGL.

    Returns ``(images, backend)``; ``images`` is None when no backend works, and then ``backend``
    says why (the caller draws the link points instead). Tried in order: ``MUJOCO_GL`` if set,
    then EGL, then OSMesa, each in a child interpreter so the choice does not depend on whether
    this process already imported MuJoCo.
    """
    if backends is None:
        env_gl = os.environ.get("MUJOCO_GL", "").lower().strip()
        backends = (
            [env_gl] + [b for b in GL_BACKENDS if b != env_gl] if env_gl in GL_BACKENDS else list(GL_BACKENDS)
        )
    errors = []
    with tempfile.TemporaryDirectory(prefix="twisted-render-") as tmp:
        src = Path(tmp) / "states.npz"
        np.savez(src, states=np.stack([np.asarray(s, dtype=np.float64) for s in states]))
        for backend in backends:
            dst = Path(tmp) / f"images-{backend}.npz"
            env = dict(os.environ, MUJOCO_GL=backend)
            env.pop("PYOPENGL_PLATFORM", None)  # let mujoco's egl/osmesa module pick the matching one
            cmd = [
                sys.executable,
                "-m",
                "twisted.render",
                str(src),
                str(dst),
                str(friction_scale),
                str(width),
                str(height),
            ]
            try:
                proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout_s)
            except subprocess.TimeoutExpired:
                errors.append(f"{backend}: timed out")
                continue
            if proc.returncode == 0 and dst.exists():
                with np.load(dst) as data:
                    return list(data["images"]), backend
            tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
            errors.append(f"{backend}: {tail}")
    return None, "; ".join(errors)


def _top_camera(points: npt.NDArray[np.float64], aspect: float) -> Any:
    import mujoco

    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = (lo + hi) / 2
    cam.lookat[:] = [centre[0], centre[1], 0.0]
    half = max((hi[0] - lo[0]) / 2 / aspect, (hi[1] - lo[1]) / 2, 0.15) + 0.08
    cam.distance = half / np.tan(np.radians(45.0 / 2))  # MuJoCo's default vertical field of view is 45 deg
    cam.elevation = -90.0
    cam.azimuth = 90.0  # +x to the right, +y up in the image
    return cam


def _gl_worker(src: str, dst: str, friction_scale: float, width: int, height: int) -> None:
    """Child-process side of :func:`gl_top_views` (``MUJOCO_GL`` is already set here)."""
    import mujoco

    from twisted.sim import RopeSim

    sim = RopeSim(friction_scale=friction_scale)
    model, data = sim.model, sim.data
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    images = []
    with np.load(src) as f:
        states = f["states"]
    # one camera for every frame (a replay must not jump), framing all the states
    all_points = []
    for state in states:
        sim.set_state(state)
        all_points.append(sim.link_points())
    cam = _top_camera(np.concatenate(all_points), width / height)
    with mujoco.Renderer(model, height=height, width=width) as renderer:
        for state in states:
            sim.set_state(state)
            renderer.update_scene(data, camera=cam)
            images.append(renderer.render().copy())
    np.savez(dst, images=np.stack(images))


if __name__ == "__main__":
    _gl_worker(sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]))
