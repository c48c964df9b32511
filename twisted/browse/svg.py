"""Small inline SVG pictures for table cells: a rope's knot diagram from its link points, a P-data state's
Gauss diagram, and the words for a knot type.

They show what :func:`twisted.render.draw_knot_diagram` and :func:`twisted.render.draw_gauss_diagram`
show (the same crossings, gaps, visit labels, zoom and colours, from :mod:`twisted.render.geometry`),
written as SVG text directly: a matplotlib SVG costs 0.1-0.2 s and 15-20 kB per picture, one of these
about a millisecond and 1-2 kB, so a page of 100 rows stays fast. The full
matplotlib drawing of a state (``render --goal``) is one link away (:mod:`twisted.browse.plugin`).
"""

from __future__ import annotations

from functools import lru_cache
from html import escape

import numpy as np
import numpy.typing as npt

from twisted.knots.catalogue import CATALOGUE
from twisted.knots.catalogue import knot_words as knot_words_of
from twisted.render.geometry import (
    ROPE_COLOUR,
    SIGN_COLOUR,
    crossing_geometry,
    knot_zoom,
    rope_pieces,
    visit_labels,
)
from twisted.rope import ROPE
from twisted.topology import PData, PDataError, parse_p_data, top

__all__ = ["KNOT_WORDS", "blob_points", "gauss_svg", "knot_words", "p_data_of_cell", "rope_svg"]

# What each stored knot_type means in words (the knot table's, docs/DESIGN.md section 9.3).
KNOT_WORDS = {
    **{knot_type: knot_words_of(knot_type) for knot_type in CATALOGUE},
    "knotoid": "the two closures differ: no knot",
    "unknown": "a knot outside the table",
}

_MAX_KEY_CHARS = 4096  # a P-data key of 6 crossings is about 80 characters; longer text is not parsed


def knot_words(knot_type: object) -> str | None:
    """The words for a stored knot type (``"3_1+"`` -> right-handed trefoil), None for anything else."""
    return KNOT_WORDS.get(knot_type) if isinstance(knot_type, str) else None


def blob_points(value: object) -> npt.NDArray[np.float64] | None:
    """The (n, 3) link points of a ``points`` BLOB (little-endian float64), None when it is not the rope
    of this store (the rope profile: ``ROPE.n_points`` finite points; a store of another rope is refused
    when it is opened)."""
    if not isinstance(value, bytes) or len(value) != 24 * ROPE.n_points:
        return None
    points = np.frombuffer(value, "<f8").reshape(-1, 3)
    if not np.isfinite(points).all():
        return None
    return points


def p_data_of_cell(value: object) -> PData | None:
    """The P-data state in a cell (JSON text of a ``p_data`` or ``key`` column), None when it is not one."""
    if not isinstance(value, str) or not value.startswith("[") or len(value) > _MAX_KEY_CHARS:
        return None
    try:
        return parse_p_data(value)
    except (PDataError, ValueError):
        return None


def _f(v: float) -> str:
    return f"{v:.1f}"


def _dot(x: float, y: float, r: float, fill: str, ring: bool = False) -> str:
    stroke = ' stroke="black" stroke-width="1.5"' if ring else ""
    return f'<circle cx="{_f(x)}" cy="{_f(y)}" r="{r}" fill="{fill}"{stroke}/>'


def _text(x: float, y: float, text: str, size: int, fill: str = "black", extra: str = "") -> str:
    return (
        f'<text x="{_f(x)}" y="{_f(y)}" font-size="{size}" font-family="sans-serif" text-anchor="middle" '
        f'fill="{fill}"{extra}>{escape(text)}</text>'
    )


def _ends(head: tuple[float, float], tail: tuple[float, float]) -> list[str]:
    """The head (link-0 tip) as a filled dot, the tail as a ring."""
    return [_dot(*head, 4, "black"), _dot(*tail, 4, "white", ring=True)]


@lru_cache(maxsize=8192)
def rope_svg(blob: bytes, width: int = 170, height: int = 136, labels: bool = True) -> str | None:
    """A rope from above as an SVG knot diagram (the points of a ``points`` BLOB), None when the BLOB
    is not link points.

    The projected rope broken at every under-crossing, the head a filled dot, the tail a ring, each
    crossing a dot in its sign's colour with its two visits (``3O+``, ``4U+``) when ``labels``; a knot
    small against the rope is shown close up, as :func:`twisted.render.draw_knot_diagram` does. The
    state (P-data key) is the picture's tooltip. Cached per BLOB.
    """
    points = blob_points(blob)
    if points is None:
        return None
    crossings = crossing_geometry(points)
    view = knot_zoom(points, crossings)
    xy = points[:, :2]
    if view is None:
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        margin = max(0.08 * float((hi - lo).max()), 0.01)
        lo, hi = lo - margin, hi + margin
    else:
        lo, hi = view
    scale = min(width / max(float(hi[0] - lo[0]), 1e-9), height / max(float(hi[1] - lo[1]), 1e-9))
    centre = (lo + hi) / 2

    def px(p: npt.NDArray[np.float64]) -> tuple[float, float]:
        return width / 2 + (p[0] - centre[0]) * scale, height / 2 - (p[1] - centre[1]) * scale

    key = top(points).key
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" class="twisted-rope" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}" style="overflow:hidden;background:#fbfaf7">',
        f"<title>{escape(key)}</title>",
    ]
    for piece in rope_pieces(points, crossings):
        coords = " ".join(f"{_f(x)},{_f(y)}" for x, y in map(px, piece))
        parts.append(
            f'<polyline points="{coords}" fill="none" stroke="{ROPE_COLOUR}" stroke-width="3.5" '
            'stroke-linecap="round" stroke-linejoin="round"/>'
        )
    parts += _ends(px(xy[0]), px(xy[-1]))
    halo = ' dominant-baseline="middle" stroke="white" stroke-width="2.5" paint-order="stroke"'
    for c in crossings:
        x, y = px(np.asarray(c.xy))
        colour = SIGN_COLOUR[c.sign]
        parts.append(_dot(x, y, 2.5, colour))
        if labels:
            for text, d in visit_labels(points, c):
                parts.append(_text(x + 13 * d[0], y - 13 * d[1], text, 9, colour, halo))
    if view is not None:
        parts.append(_text(18, height - 4, "zoomed", 8, "grey"))
    parts.append("</svg>")
    return "".join(parts)


@lru_cache(maxsize=4096)
def gauss_svg(key: str, step: int = 20) -> str:
    """A P-data state (its key) as an SVG Gauss diagram of the open rope, as
    :func:`twisted.render.draw_gauss_diagram` draws it: visits 1..2n on a straight rope (head left),
    each crossing an arc from its over visit to its under visit with the arrow head at the under end,
    green for ``+``, purple for ``-``. Cached per key."""
    p_data = parse_p_data(key)
    m = len(p_data.visits)
    crossings = p_data.crossings()
    pad = 10
    top_arc = max([abs(o - u) * step / 2 for o, u, _ in crossings], default=0.0)
    base = pad + top_arc + 12  # the rope's y: room for the widest arc and its sign above it
    width, height = 2 * pad + (m + 1) * step, int(base + 26)

    def x(position: float) -> float:
        return pad + position * step

    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" class="twisted-gauss" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}">',
        f"<title>Gauss diagram (arrow: over to under) {escape(p_data.key)}</title>",
        f'<line x1="{_f(x(0))}" y1="{_f(base)}" x2="{_f(x(m + 1))}" y2="{_f(base)}" stroke="{ROPE_COLOUR}" '
        'stroke-width="3.5" stroke-linecap="round"/>',
    ]
    for over, under, sign in crossings:
        colour = SIGN_COLOUR["+" if sign > 0 else "-"]
        a, b = sorted((over, under))
        r = (b - a) * step / 2
        parts.append(
            f'<path d="M {_f(x(a))} {_f(base)} A {_f(r)} {_f(r)} 0 0 1 {_f(x(b))} {_f(base)}" fill="none" '
            f'stroke="{colour}" stroke-width="1.6"/>'
        )
        ux = x(under)  # the arrow head: over -> under
        head = f"{_f(ux - 3.5)},{_f(base - 9)} {_f(ux + 3.5)},{_f(base - 9)} {_f(ux)},{_f(base - 2)}"
        parts.append(f'<polygon points="{head}" fill="{colour}"/>')
        parts.append(_text((x(a) + x(b)) / 2, base - r - 3, "+" if sign > 0 else "-", 10, colour))
    for v in p_data.visits:
        parts.append(_dot(x(v.position), base, 2.5, SIGN_COLOUR[v.sign]))
        parts.append(_text(x(v.position), base + 16, f"{v.position}{v.over}", 9))
    parts += _ends((x(0), base), (x(m + 1), base))
    parts.append("</svg>")
    return "".join(parts)
