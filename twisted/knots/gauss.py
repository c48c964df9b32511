"""Closed knot diagrams as signed Gauss codes, and the two closures of an open rope (docs/DESIGN.md 9.1).

:class:`GaussCode` is a closed diagram (crossing events walking once around, crossing signs);
:func:`simplify` removes Reidemeister I loops and II bigons. :func:`closed_gauss_code` closes the
diagram of a rope state by an arc under (or over) everything, routed through its faces;
:func:`gauss_code_from_polygon` reads the diagram of a closed polygon seen from above.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from twisted.diagram import LEFT, RIGHT, diagram
from twisted.topology import PData, projected_crossings

__all__ = ["GaussCode", "closed_gauss_code", "gauss_code_from_pd", "gauss_code_from_polygon", "simplify"]


@dataclass(frozen=True, slots=True)
class GaussCode:
    """A closed knot diagram: the crossing events met walking once around the knot.

    ``events[i] = (crossing, over)`` with ``crossing`` in ``0..N-1`` and ``over`` True when the knot
    passes over there; every crossing appears twice, once over and once under. ``signs[c]`` is
    crossing ``c``'s sign (+1 / -1, right-hand rule).
    """

    events: tuple[tuple[int, bool], ...]
    signs: tuple[int, ...]

    @property
    def n_crossings(self) -> int:
        return len(self.signs)

    @property
    def writhe(self) -> int:
        return sum(self.signs)

    def pd_code(self) -> list[tuple[int, int, int, int]]:
        """Planar-diagram code: per crossing its four edges, incoming under first, then counter-clockwise.

        Edge ``i`` runs from event ``i`` to event ``i + 1``. With the over strand along +x, a
        positive crossing has the under strand along +y, so counter-clockwise from under-in (south)
        come over-out (east), under-out (north), over-in (west); a negative one has the under strand
        along -y: under-in (north), over-in (west), under-out (south), over-out (east).
        """
        m = len(self.events)
        ends: dict[int, dict[str, int]] = {c: {} for c in range(self.n_crossings)}
        for i, (c, over) in enumerate(self.events):
            strand = "over" if over else "under"
            ends[c][strand + "_in"] = (i - 1) % m
            ends[c][strand + "_out"] = i
        pd = []
        for c in range(self.n_crossings):
            e = ends[c]
            if self.signs[c] > 0:
                pd.append((e["under_in"], e["over_out"], e["under_out"], e["over_in"]))
            else:
                pd.append((e["under_in"], e["over_in"], e["under_out"], e["over_out"]))
        return pd


def gauss_code_from_pd(pd: Sequence[Sequence[int]]) -> GaussCode:
    """The diagram of a PD code (KnotInfo's: per crossing its four edges from the incoming under edge,
    counter-clockwise, the edges numbered 1..2N along the knot), walked from edge 1.

    The under strand runs from the first edge to the third; the over strand enters at the fourth edge
    and leaves at the second when the crossing is positive (the inverse of :meth:`GaussCode.pd_code`),
    the other way when negative. Raises ValueError for a code that is not a knot's.
    """
    m = 2 * len(pd)
    ends: dict[int, tuple[int, bool]] = {}  # edge -> (crossing, over) where the edge ends
    signs: list[int] = []
    for c, edges in enumerate(pd):
        if len(edges) != 4 or sorted({*edges} - set(range(1, m + 1))):
            raise ValueError(f"PD crossing {list(edges)} is not four edges among 1..{m}")
        a, b, _, d = edges
        if m > 2 and (b - d) % m == 1:
            signs.append(1)
            ends[d] = (c, True)
        elif m > 2 and (d - b) % m == 1:
            signs.append(-1)
            ends[b] = (c, True)
        else:
            raise ValueError(f"PD crossing {list(edges)}: the over strand's edges do not follow each other")
        ends[a] = (c, False)
    if len(ends) != m:
        raise ValueError(f"PD code {[list(x) for x in pd]} does not walk every edge once")
    return GaussCode(tuple(ends[e] for e in range(1, m + 1)), tuple(signs))


def simplify(code: GaussCode) -> GaussCode:
    """Remove Reidemeister I loops and II bigons until none is left (the knot type is kept).

    R1: a crossing whose two passages follow each other along the knot. The loop between them holds
    no crossing, and the crossing's two other ends lie on one side of it, so on the sphere the loop
    bounds an empty disc. R2: crossings ``a, b`` of opposite signs passed over-over consecutively by
    one strand and under-under consecutively by another. The two edges between them form a closed
    curve without crossings; the rest of the knot is one arc, so it attaches to ``a`` and ``b`` from
    the same side of that curve, the other side is an empty bigon, and the over strand lifts off.
    """
    events, signs = list(code.events), list(code.signs)
    changed = True
    while changed and events:
        changed = False
        m = len(events)
        where = {(c, over): i for i, (c, over) in enumerate(events)}
        drop: set[int] = set()
        for i in range(m):
            a, b = events[i], events[(i + 1) % m]
            if a[0] == b[0]:
                drop = {a[0]}
                break
            if a[1] and b[1] and signs[a[0]] == -signs[b[0]]:
                ua, ub = where[(a[0], False)], where[(b[0], False)]
                if (ua - ub) % m in (1, m - 1):
                    drop = {a[0], b[0]}
                    break
        if drop:
            changed = True
            kept = [c for c in range(len(signs)) if c not in drop]
            renumber = {old: new for new, old in enumerate(kept)}
            events = [(renumber[c], over) for c, over in events if c not in drop]
            signs = [signs[c] for c in kept]
    return GaussCode(tuple(events), tuple(signs))


def _walking_order(code: GaussCode) -> GaussCode:
    """The same diagram with crossings numbered in order of first passage (keeps the bracket small)."""
    renumber: dict[int, int] = {}
    for c, _ in code.events:
        renumber.setdefault(c, len(renumber))
    signs = [0] * len(code.signs)
    for old, new in renumber.items():
        signs[new] = code.signs[old]
    return GaussCode(tuple((renumber[c], over) for c, over in code.events), tuple(signs))


def _closing_path(p: PData) -> list[tuple[int, str]]:
    """The closing arc from the tail tip to the head tip: the segments it passes under, in order.

    Each entry is ``(segment, side it comes from)``. Breadth-first search in the dual graph from the
    tail's face to the head's face, in a fixed order so the result is deterministic.
    """
    d = diagram(p)
    head_face, tail_face = d.end_faces()
    previous: dict[int, tuple[int, int, str] | None] = {tail_face: None}
    queue = deque([tail_face])
    while queue:
        f = queue.popleft()
        if f == head_face:
            break
        for seg, side in d.faces[f].sides:
            other = RIGHT if side == LEFT else LEFT
            g = d.face_of(seg, other)
            if g not in previous:
                previous[g] = (f, seg, side)
                queue.append(g)
    path: list[tuple[int, str]] = []
    f = head_face
    while (step := previous[f]) is not None:
        f, seg, side = step
        path.append((seg, side))
    path.reverse()
    return path


def closed_gauss_code(p: PData, over: bool = False) -> GaussCode:
    """The closed diagram of rope state ``p``: the rope, then the closing arc under (or over) everything.

    Rope crossings keep their P-data signs. Where the closing arc passes under segment ``k`` from its
    left side to its right side, the under strand points to the right of the over strand, so the
    sign is ``-``; from right to left ``+``. Passing *over* the segment swaps the strands' roles, so
    every closing crossing changes sign (``over=True``: the ends are lifted above the table and
    joined there).
    """
    n = p.cross
    signs = [s for _, _, s in p.crossings()]
    crossing_of = {}
    for c, (o, u, _) in enumerate(p.crossings()):
        crossing_of[o] = c
        crossing_of[u] = c
    closing: dict[int, int] = {}  # segment -> new crossing id
    closing_events: list[tuple[int, bool]] = []
    flip = -1 if over else 1
    for seg, side in _closing_path(p):
        c = len(signs)
        signs.append(flip * (-1 if side == LEFT else 1))
        closing[seg] = c
        closing_events.append((c, over))
    events: list[tuple[int, bool]] = []
    for k in range(2 * n + 1):
        if k > 0:
            v = p.visits[k - 1]
            events.append((crossing_of[k], v.over == "O"))
        if k in closing:
            events.append((closing[k], not over))
    events.extend(closing_events)
    return GaussCode(tuple(events), tuple(signs))


def gauss_code_from_polygon(points: npt.ArrayLike) -> GaussCode:
    """The diagram of a closed polygon (vertices in order, the last joined to the first) seen from above.

    Segments whose projections share an end point (neighbours, or neighbours through a vertical
    segment, whose projection is a point) are not tested against each other. Heights at a crossing
    are interpolated along each segment; signs by the right-hand rule
    (:func:`twisted.topology.projected_crossings` with ``closed=True``). Raises ``ValueError`` when the
    projection is degenerate at a crossing (equal heights, tie rule ``"raise"``), which a small
    perturbation fixes.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 3:
        raise ValueError(f"a closed polygon needs shape (N>=3, 3), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("polygon points contain NaN or infinity")
    pc = projected_crossings(pts, closed=True, ties="raise")
    k = len(pc)
    overs = np.concatenate([pc.i_over, ~pc.i_over])
    order = np.argsort(pc.position)  # the visits in walking order (position is a permutation of 1..2k)
    events = tuple((int(e % k), bool(overs[e])) for e in order) if k else ()
    signs = tuple(int(s) for s in pc.sign)
    return GaussCode(events, signs)
