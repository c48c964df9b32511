"""Matplotlib drawings: knot diagrams of link points, Gauss diagrams of P-data, figures to PNG and GIF.

Nothing here reads the database or starts MuJoCo: :mod:`twisted.render.stored` draws stored things with
these, and :mod:`twisted.render.gl` makes the MuJoCo top views.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never a window

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Arc, FancyArrowPatch  # noqa: E402

from twisted.render.geometry import (  # noqa: E402
    ROPE_COLOUR,
    SIGN_COLOUR,
    CrossingDrawing,
    crossing_geometry,
    knot_zoom,
    rope_pieces,
    visit_labels,
)
from twisted.rope import N_LINKS, ROPE  # noqa: E402
from twisted.topology import PData  # noqa: E402

__all__ = [
    "draw_curve",
    "draw_gauss_diagram",
    "draw_knot_diagram",
    "figure_to_array",
    "panel_figure",
    "save_gif",
    "save_png",
]


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
    tail = f"tail (link {N_LINKS - 1})"
    ax.plot(pts[-1, 0], pts[-1, 1], "o", mfc="white", mec="black", ms=8, zorder=4, label=tail)
    view = knot_zoom(pts, crossings) if zoom else None
    lo, hi = view if view is not None else (pts[:, :2].min(axis=0), pts[:, :2].max(axis=0))
    span = float((hi - lo).max()) or 1.0
    if view is not None:
        (x0, y0), (x1, y1) = view
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal", adjustable="box")
        ax.text(0.01, 0.01, "zoomed on the crossings", transform=ax.transAxes, fontsize=7, color="grey")
    else:
        ax.margins(0.12)
        ax.set_aspect("equal", adjustable="datalim")  # fill the panel rather than shrink it
    if label_visits:
        labels = []
        for c in crossings:
            colour = SIGN_COLOUR[c.sign]
            ax.plot(c.xy[0], c.xy[1], ".", color=colour, ms=6, zorder=5)
            labels += [(text, c.xy, direction, colour) for text, direction in visit_labels(pts, c)]
        _place_labels(ax, pts, labels, max(0.07 * span, 0.012))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best", fontsize=7, frameon=False)
    if title:
        ax.set_title(_wrap(title), fontsize=9)
    return crossings


LABEL_FONT_PT = 8
# where a visit label may go, tried in this order: times the offset, and degrees turned from its strand
_LABEL_SPOTS = [(r, a) for r in (1.0, 1.6, 2.3) for a in (0, 35, -35, 70, -70, 110, -110, 180)]


def _place_labels(
    ax: Axes,
    pts: npt.NDArray[np.float64],
    labels: list[tuple[str, tuple[float, float], npt.NDArray[np.float64], str]],
    off: float,
) -> None:
    """Write each visit label (text, its crossing, the direction along its strand, colour) ``off`` from its
    crossing, at the first spot (:data:`_LABEL_SPOTS`) whose box overlaps no label placed before, stays
    inside the panel and covers no rope; where none does, at the spot that does least of these."""
    ax.apply_aspect()  # the data-to-pixel transform as it will be drawn
    to_px = ax.transData.transform
    frame = ax.bbox.extents
    font_px = LABEL_FONT_PT * ax.figure.dpi / 72.0
    # the rope's centreline sampled densely, in pixels
    t = np.linspace(0.0, 1.0, 8, endpoint=False)
    along = pts[:-1, None, :2] + t[None, :, None] * (pts[1:, None, :2] - pts[:-1, None, :2])
    rope = to_px(along.reshape(-1, 2))
    placed: list[npt.NDArray[np.float64]] = []
    for text, (x, y), direction, colour in labels:
        half = np.array([0.32 * font_px * len(text) + 2.0, 0.62 * font_px + 1.0])
        best: tuple[float, tuple[float, float], npt.NDArray[np.float64]] | None = None
        for r, degrees in _LABEL_SPOTS:
            a = np.radians(degrees)
            d = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) @ direction
            spot = (x + r * off * d[0], y + r * off * d[1])
            centre = to_px(spot)
            lo, hi = centre - half, centre + half
            overlap = sum(_overlap(lo, hi, b) for b in placed) / float(np.prod(2 * half))
            outside = bool(np.any(lo < frame[:2]) or np.any(hi > frame[2:]))
            on_rope = bool(np.any(np.all((rope >= lo) & (rope <= hi), axis=1)))
            cost = 10.0 * overlap + 5.0 * outside + 1.0 * on_rope
            if best is None or cost < best[0]:
                best = (cost, spot, np.concatenate([lo, hi]))
            if cost == 0.0:
                break
        assert best is not None
        _, spot, box = best
        placed.append(box)
        ax.annotate(
            text,
            spot,
            ha="center",
            va="center",
            fontsize=LABEL_FONT_PT,
            color=colour,
            zorder=6,
            bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.7},
        )


def _overlap(lo: npt.NDArray[np.float64], hi: npt.NDArray[np.float64], box: npt.NDArray[np.float64]) -> float:
    """The area two boxes share (pixels): ``lo``-``hi`` and ``box`` = (x0, y0, x1, y1)."""
    w = min(hi[0], box[2]) - max(lo[0], box[0])
    h = min(hi[1], box[3]) - max(lo[1], box[1])
    return float(max(w, 0.0) * max(h, 0.0))


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


def name_rope(fig: Figure) -> None:
    """Write the rope profile (``ROPE.name``) in the figure's bottom right corner: figures of different
    ropes are not comparable."""
    fig.text(0.99, 0.005, f"rope: {ROPE.name}", ha="right", va="bottom", fontsize=6, color="0.4")


def save_png(fig: Figure, path: str | Path, dpi: int = 120) -> Path:
    """Save a figure as PNG (creating the folder), naming the rope it shows, and close it."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    name_rope(fig)
    fig.savefig(out, dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return out


def figure_to_array(fig: Figure, dpi: int = 100) -> npt.NDArray[np.uint8]:
    """Rasterise a figure to an RGB uint8 array (for GIF frames), naming the rope; closes the figure."""
    buf = io.BytesIO()
    name_rope(fig)
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


def panel_figure(gl_image: npt.NDArray[np.uint8] | None) -> tuple[Figure, Axes | None, Axes]:
    """A figure for one rope: its knot diagram panel, after a MuJoCo image panel when there is one."""
    if gl_image is None:
        fig, ax = plt.subplots(figsize=(6.4, 5.2))
        return fig, None, ax
    fig, (ax_gl, ax) = plt.subplots(1, 2, figsize=(12.8, 5.2), gridspec_kw={"width_ratios": [1.25, 1]})
    ax_gl.imshow(gl_image)
    ax_gl.axis("off")
    ax_gl.set_title("MuJoCo, from above", fontsize=9)
    return fig, ax_gl, ax


def draw_curve(ax: Axes, points: npt.NDArray[np.float64], curve: Sequence[float]) -> None:
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
