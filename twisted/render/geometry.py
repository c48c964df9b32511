"""The geometry of a knot picture, without a plotting library: where the crossings of a projected rope
are and which P-data visits they carry, the strand pieces a diagram draws, the close-up on a small knot,
where the visit labels go, and the colours of rope and signs.

The matplotlib drawings (:mod:`twisted.render.draw`) and the SVG writer of ``twisted browse`` both draw
from these, so a picture in a file and one in the browser show the same crossings and labels.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from twisted.topology import PData, Visit, projected_crossings

__all__ = [
    "ROPE_COLOUR",
    "SIGN_COLOUR",
    "CrossingDrawing",
    "crossing_geometry",
    "knot_zoom",
    "p_data_of_drawing",
    "rope_pieces",
    "visit_labels",
]

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
