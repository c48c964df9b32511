"""Knots by name: which knot a rope state really ties (issues 10 and 14; docs/DESIGN.md section 9).

Closing the rope. An open rope ties no knot in the strict sense; it needs a closure. Two are natural:
lower both ends below the table and join them there by an arc that passes *under* everything, or lift
them and join them above everything (*over*). Each is well defined: the rope lies in a slab, the arc
consists of two vertical pieces plus a simple arc in a plane outside the slab, and any two simple arcs
in that plane with the same end points are isotopic there, so any two closures of one kind are
isotopic knots. In a diagram: route the closing arc through any faces, passing under (over) the rope
wherever it must, and the invariants come out the same.

The two closures can differ: when an end lies inside a loop, passing under or over the loop's strand
on the way out decides whether a knot forms. Such a diagram is a knotoid (Turaev, "Knotoids", 2012),
and pulling the rope's ends apart does not give one answer. So a state ties knot K only when BOTH
closures are K (:class:`RopeKnot`; true, for example, whenever both ends lie in one face, since then the
closing arc crosses nothing); otherwise it ties no knot and is named ``"knotoid"``. Under this rule
each catalogue knot first appears at its crossing number (``bench/bench_knots.py``).

The two routes (they must agree, ``tests/test_knots.py`` checks it on collected data):

* from P-data (:func:`identify`): :func:`twisted.diagram.diagram` rebuilds the planar diagram of the
  open rope with its faces; the head tip lies in one face, the tail tip in another; a shortest path
  in the dual graph (faces joined across the segment sides that separate them) gives the closing
  arc. It crosses each segment at most once and enters each face once, so inside every face it is
  one chord and the closed diagram is planar.
* from link points (:func:`identify_points`): the ends are lowered below the table (lifted above the
  rope) and joined by a straight segment there; the closed polygon is projected to the table and its
  crossings read as in :func:`twisted.topology.top`.

Invariants (computed here, no dependency):

* ``alexander``: the Alexander polynomial from the Wirtinger presentation (Fox calculus), an
  ``(N-1) x (N-1)`` minor of the ``N x N`` Alexander matrix of a diagram with ``N`` crossings,
  normalised to be symmetric (``Delta(t) = Delta(1/t)``) with ``Delta(1) = +1`` (Conway's
  normalisation); stored as the coefficients of ``t^-d .. t^d``, e.g. the trefoil ``(1, -1, 1)``.
* ``determinant``: ``|Delta(-1)|``.
* ``jones``: the Jones polynomial from the Kauffman bracket, ``V(t) = (-A^3)^(-w) <K>`` at
  ``A = t^(-1/4)``, stored as ``((exponent of t, coefficient), ...)`` by increasing exponent. It
  tells a knot from its mirror (``V_mirror(t) = V(1/t)``).

Chirality. A crossing's sign is the P-data sign ``sign((d_over x d_under) . e_z)``, the usual
right-hand rule. ``"+"`` names the mirror image whose minimal diagram has only positive crossings:
``3_1+`` is the right-handed trefoil, ``V = t + t^3 - t^4``; so the 3-crossing rope whose visits
alternate O/U with one common sign ``+`` ties ``3_1+``. Likewise ``5_1+`` and ``5_2+`` are the
positive 5-crossing knots (their Jones polynomials have positive exponents). ``4_1`` is its own
mirror image.

Identification compares ``(alexander, jones)`` with the catalogue (the knots up to five crossings and
the granny and square knots); a diagram whose invariants match no entry is ``"unknown"`` (it still
carries its invariants).
Within the catalogue the pair separates every entry; a larger knot with the same pair would be
misnamed, a risk that does not arise for the small diagrams a 21-link rope makes.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from twisted.diagram import LEFT, RIGHT, diagram
from twisted.topology import PData, PDataError, parse_p_data, projected_crossings

__all__ = [
    "CATALOGUE",
    "KNOTOID",
    "KNOT_NAMES",
    "UNKNOWN",
    "GaussCode",
    "KnotNameError",
    "KnotType",
    "RopeKnot",
    "closed_gauss_code",
    "crossing_number",
    "gauss_code_from_polygon",
    "identify",
    "identify_points",
    "invariants",
    "knot_type_name",
    "least_crossings",
    "mirror_type",
    "resolve_knot",
    "rotations",
    "simplify",
    "states_tying",
]

UNKNOWN = "unknown"


@dataclass(frozen=True, slots=True)
class KnotType:
    """The knot a (closed) rope ties: its catalogue name and the invariants that named it.

    ``alexander``: coefficients of ``t^-d .. t^d``, symmetric, ``Delta(1) = 1``. ``jones``:
    ``((exponent of t, coefficient), ...)``. ``writhe``: of the diagram the invariants were computed
    from (not an invariant; left out of equality). ``name`` is ``"unknown"`` outside the catalogue.
    """

    name: str
    alexander: tuple[int, ...]
    determinant: int
    jones: tuple[tuple[int, int], ...]
    writhe: int | None = field(default=None, compare=False)

    @property
    def crossing_number(self) -> int | None:
        """The minimal crossing number for catalogue knots (``3_1+`` -> 3), None when unknown."""
        if self.name not in CATALOGUE:
            return None
        return crossing_number(self.name)

    @property
    def is_unknot(self) -> bool:
        return self.name == "0_1"

    def alexander_text(self) -> str:
        """The Alexander polynomial as text, e.g. ``t^-1 - 1 + t``."""
        d = (len(self.alexander) - 1) // 2
        return _poly_text([(i - d, c) for i, c in enumerate(self.alexander)])

    def jones_text(self) -> str:
        """The Jones polynomial as text, e.g. ``t + t^3 - t^4``."""
        return _poly_text(list(self.jones))


def _poly_text(terms: Sequence[tuple[int, int]]) -> str:
    out = []
    for e, c in terms:
        if c == 0:
            continue
        mag = abs(c)
        mono = "" if e == 0 else ("t" if e == 1 else f"t^{e}")
        body = str(mag) if not mono else (mono if mag == 1 else f"{mag}{mono}")
        out.append(("- " if c < 0 else "+ ") + body)
    if not out:
        return "0"
    text = " ".join(out)
    return text[2:] if text.startswith("+ ") else "-" + text[2:]


# ---------------------------------------------------------------------------------------------
# Closed diagrams as signed Gauss codes


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


# ---------------------------------------------------------------------------------------------
# Invariants


def _int_det(rows: list[list[int]]) -> int:
    """Exact determinant of an integer matrix (fraction-free Bareiss elimination)."""
    a = [row[:] for row in rows]
    n = len(a)
    if n == 0:
        return 1
    sign, prev = 1, 1
    for k in range(n - 1):
        if a[k][k] == 0:
            swap = next((r for r in range(k + 1, n) if a[r][k] != 0), None)
            if swap is None:
                return 0
            a[k], a[swap] = a[swap], a[k]
            sign = -sign
        for i in range(k + 1, n):
            for j in range(k + 1, n):
                a[i][j] = (a[i][j] * a[k][k] - a[i][k] * a[k][j]) // prev
        prev = a[k][k]
    return sign * a[n - 1][n - 1]


def _interpolate(xs: Sequence[int], ys: Sequence[int]) -> list[int]:
    """Integer coefficients (constant first) of the polynomial through the points (Lagrange)."""
    n = len(xs)
    coeffs = [Fraction(0)] * n
    for i in range(n):
        basis = [Fraction(1)]  # product of (t - x_j) / (x_i - x_j), built coefficient by coefficient
        denom = 1
        for j in range(n):
            if j == i:
                continue
            basis = [Fraction(0), *basis]
            for m in range(len(basis) - 1):
                basis[m] -= xs[j] * basis[m + 1]
            denom *= xs[i] - xs[j]
        for m in range(n):
            coeffs[m] += Fraction(ys[i], denom) * basis[m]
    if any(c.denominator != 1 for c in coeffs):
        raise ArithmeticError("Alexander interpolation gave non-integer coefficients")
    return [int(c) for c in coeffs]


def alexander_polynomial(code: GaussCode) -> tuple[int, ...]:
    """Normalised Alexander polynomial (coefficients of ``t^-d .. t^d``, ``Delta(1) = 1``).

    Wirtinger arcs run from one under-passage to the next. Crossing ``c`` with over arc ``k``,
    incoming under arc ``i`` and outgoing ``j`` gives the relation ``x_j = x_k^s x_i x_k^-s``
    (``s`` its sign); its Fox derivatives, abelianised (every ``x -> t``) and multiplied by a unit,
    are the row ``(1 - t) at k, t at i, -1 at j`` for ``s = +1`` and ``(1 - t), -1, t`` for ``s = -1``.
    """
    n = code.n_crossings
    if n == 0:
        return (1,)
    # arc of each event: the arc index advances after each under-passage
    first_under = next(i for i, (_, over) in enumerate(code.events) if not over)
    m = len(code.events)
    arc_at: dict[int, int] = {}
    in_arc: dict[int, int] = {}
    out_arc: dict[int, int] = {}
    arc = n - 1  # walking from the first under-passage: the arc entering it is the last one
    for step in range(m):
        c, over = code.events[(first_under + step) % m]
        if over:
            arc_at[c] = arc
        else:
            in_arc[c] = arc
            arc = (arc + 1) % n
            out_arc[c] = arc

    def minor_at(t: int) -> int:
        rows = [[0] * n for _ in range(n)]
        for c in range(n):
            s = code.signs[c]
            row = rows[c]
            row[arc_at[c]] += 1 - t
            row[in_arc[c]] += t if s > 0 else -1
            row[out_arc[c]] += -1 if s > 0 else t
        return _int_det([r[:-1] for r in rows[:-1]])

    xs = list(range(2, n + 2))
    coeffs = _interpolate(xs, [minor_at(x) for x in xs])
    while coeffs and coeffs[-1] == 0:
        coeffs.pop()
    while coeffs and coeffs[0] == 0:
        coeffs.pop(0)
    if not coeffs:
        raise ArithmeticError("Alexander polynomial vanished: the diagram is not a knot")
    if sum(coeffs) < 0:
        coeffs = [-c for c in coeffs]
    if sum(coeffs) != 1 or coeffs != coeffs[::-1] or len(coeffs) % 2 == 0:
        raise ArithmeticError(f"Alexander polynomial {coeffs} is not a knot's (symmetric, Delta(1)=1)")
    return tuple(coeffs)


def _loop_poly(a: dict[int, int], b: dict[int, int]) -> dict[int, int]:
    out: dict[int, int] = {}
    for ea, ca in a.items():
        for eb, cb in b.items():
            out[ea + eb] = out.get(ea + eb, 0) + ca * cb
    return {e: c for e, c in out.items() if c}


_LOOP = {2: -1, -2: -1}  # d = -A^2 - A^-2, the value of a closed loop


def _greedy_order(pd: Sequence[tuple[int, int, int, int]]) -> list[tuple[int, int, int, int]]:
    """Crossings ordered so each one shares as many edges as possible with those before it."""
    left = list(pd)
    open_edges: set[int] = set()
    order = []
    while left:
        best = max(range(len(left)), key=lambda i: (sum(e in open_edges for e in left[i]), -i))
        x = left.pop(best)
        order.append(x)
        open_edges ^= {e for e in x if x.count(e) == 1}
    return order


def kauffman_bracket(pd: Sequence[tuple[int, int, int, int]]) -> dict[int, int]:
    """Kauffman bracket ``<K>`` in ``A`` (exponent -> coefficient), normalised so ``<O> = 1``.

    Crossings are smoothed one at a time (``<X[a,b,c,d]> = A <(ab)(cd)> + A^-1 <(ad)(bc)>``) while
    a table maps each matching of the still open edge ends to its polynomial. The table grows with
    the number of open ends, so the next crossing is always the one that closes the most of them.
    """
    if not pd:
        return {0: 1}
    states: dict[tuple[tuple[int, int], ...], dict[int, int]] = {(): {0: 1}}
    for a, b, c, dd in _greedy_order(pd):
        new_states: dict[tuple[tuple[int, int], ...], dict[int, int]] = {}
        for matching, poly in states.items():
            for weight, pairs in ((1, ((a, b), (c, dd))), (-1, ((a, dd), (b, c)))):
                ends = dict(matching)
                ends.update({y: x for x, y in matching})
                loops = 0
                for x, y in pairs:
                    # ends maps each open edge end to the other open end of its partial strand
                    ux, uy = ends.get(x), ends.get(y)
                    if x == y or (ux is not None and ux == y):
                        loops += 1  # the new arc closes a strand into a loop
                        ends.pop(x, None)
                        ends.pop(y, None)
                    elif ux is not None and uy is not None:
                        del ends[x], ends[y]
                        ends[ux], ends[uy] = uy, ux
                    elif ux is not None:
                        del ends[x]
                        ends[ux], ends[y] = y, ux
                    elif uy is not None:
                        del ends[y]
                        ends[uy], ends[x] = x, uy
                    else:
                        ends[x], ends[y] = y, x
                key = tuple(sorted((x, y) for x, y in ends.items() if x < y))
                term = {e + weight: cf for e, cf in poly.items()}
                for _ in range(loops):
                    term = _loop_poly(term, _LOOP)
                acc = new_states.setdefault(key, {})
                for e, cf in term.items():
                    acc[e] = acc.get(e, 0) + cf
        states = {k: {e: c for e, c in v.items() if c} for k, v in new_states.items()}
    total = states.get((), {})
    # every state ends in at least one loop, so <K> counted d once too many: divide by d
    return _divide_by_loop(total)


def _divide_by_loop(poly: dict[int, int]) -> dict[int, int]:
    """Exact division by ``d = -A^2 - A^-2 = -A^-2 (1 + A^4)``."""
    if not poly:
        raise ArithmeticError("Kauffman bracket vanished")
    lo = min(poly)
    coeffs = [0] * (max(poly) - lo + 1)
    for e, c in poly.items():
        coeffs[e - lo] = c
    # divide by (1 + A^4), lowest degree first
    q = [0] * max(len(coeffs) - 4, 0)
    rem = coeffs[:]
    for i in range(len(q)):
        q[i] = rem[i]
        rem[i] -= q[i]
        rem[i + 4] -= q[i]
    if any(rem):
        raise ArithmeticError("Kauffman bracket is not divisible by the loop value")
    # times -A^2 (the inverse of -A^-2)
    return {lo + i + 2: -c for i, c in enumerate(q) if c}


def jones_polynomial(code: GaussCode) -> tuple[tuple[int, int], ...]:
    """Jones polynomial ``V(t) = (-A^3)^(-w) <K>`` at ``A = t^(-1/4)``: ``((exponent, coeff), ...)``."""
    bracket = kauffman_bracket(code.pd_code())
    w = code.writhe
    factor_sign = -1 if w % 2 else 1
    out = {}
    for e, c in bracket.items():
        a_exp = e - 3 * w
        if a_exp % 4:
            raise ArithmeticError("Jones polynomial has fractional exponents: the diagram is not a knot")
        out[-a_exp // 4] = factor_sign * c
    return tuple(sorted((e, c) for e, c in out.items() if c))


def invariants(code: GaussCode) -> KnotType:
    """The invariants of a closed diagram, named from the catalogue (``"unknown"`` outside it)."""
    reduced = _walking_order(simplify(code))
    alexander = alexander_polynomial(reduced)
    determinant = abs(sum(c * (-1) ** i for i, c in enumerate(alexander)))
    jones = jones_polynomial(reduced)
    name = _BY_INVARIANTS.get((alexander, jones), UNKNOWN)
    return KnotType(name, alexander, determinant, jones, code.writhe)


# ---------------------------------------------------------------------------------------------
# Catalogue of knots up to five crossings


def _entry(name: str, alexander: tuple[int, ...], jones: dict[int, int]) -> KnotType:
    det = abs(sum(c * (-1) ** i for i, c in enumerate(alexander)))
    return KnotType(name, alexander, det, tuple(sorted(jones.items())))


def _mirror_jones(jones: dict[int, int]) -> dict[int, int]:
    return {-e: c for e, c in jones.items()}


def _times(a: dict[int, int], b: dict[int, int]) -> dict[int, int]:
    """Product of two Laurent polynomials (exponent -> coefficient)."""
    return _loop_poly(a, b)


def _alexander_times(a: tuple[int, ...], b: tuple[int, ...]) -> tuple[int, ...]:
    out = [0] * (len(a) + len(b) - 1)
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            out[i + j] += x * y
    return tuple(out)


# Jones polynomials of the positive (right-handed) versions; the "-" ones are their mirrors.
_J31 = {1: 1, 3: 1, 4: -1}
_J51 = {2: 1, 4: 1, 5: -1, 6: 1, 7: -1}
_J52 = {1: 1, 2: -1, 3: 2, 4: -1, 5: 1, 6: -1}
_A31 = (1, -1, 1)
# Composite knots: the Alexander and Jones polynomials of a connected sum are the products of the
# summands' (docs/DESIGN.md section 9.3). Granny and square share Alexander polynomial and determinant
# (9); the Jones polynomial tells them apart (the square knot's is symmetric: it is its own mirror).
CATALOGUE: dict[str, KnotType] = {
    k.name: k
    for k in (
        _entry("0_1", (1,), {0: 1}),
        _entry("3_1+", _A31, _J31),
        _entry("3_1-", _A31, _mirror_jones(_J31)),
        _entry("4_1", (-1, 3, -1), {-2: 1, -1: -1, 0: 1, 1: -1, 2: 1}),
        _entry("5_1+", (1, -1, 1, -1, 1), _J51),
        _entry("5_1-", (1, -1, 1, -1, 1), _mirror_jones(_J51)),
        _entry("5_2+", (2, -3, 2), _J52),
        _entry("5_2-", (2, -3, 2), _mirror_jones(_J52)),
        _entry("3_1+#3_1+", _alexander_times(_A31, _A31), _times(_J31, _J31)),
        _entry("3_1-#3_1-", _alexander_times(_A31, _A31), _mirror_jones(_times(_J31, _J31))),
        _entry("3_1+#3_1-", _alexander_times(_A31, _A31), _times(_J31, _mirror_jones(_J31))),
    )
}
_BY_INVARIANTS = {(k.alexander, k.jones): k.name for k in CATALOGUE.values()}
assert len(_BY_INVARIANTS) == len(CATALOGUE), "the catalogue's invariants must separate its entries"


def crossing_number(knot_type: str) -> int:
    """The minimal crossing number of a catalogue type: ``3_1+`` -> 3, ``3_1+#3_1-`` -> 6.

    (Additivity of the crossing number under connected sum holds for these alternating summands.)
    """
    if knot_type not in CATALOGUE:
        raise ValueError(f"{knot_type!r} is not a catalogue knot type")
    return sum(int(part.split("_")[0]) for part in knot_type.split("#"))


def mirror_type(knot: KnotType) -> KnotType:
    """The mirror image: the Jones polynomial at ``1/t``, the name's chirality signs swapped."""
    jones = tuple(sorted((-e, c) for e, c in knot.jones))
    name = _BY_INVARIANTS.get((knot.alexander, jones), UNKNOWN)
    writhe = None if knot.writhe is None else -knot.writhe
    return KnotType(name, knot.alexander, knot.determinant, jones, writhe)


# ---------------------------------------------------------------------------------------------
# Identification: both closures


KNOTOID = "knotoid"


@dataclass(frozen=True, slots=True)
class RopeKnot:
    """What an open rope ties: its two closures, and the knot when they agree.

    ``under``: the ends lowered below the table and joined there (the closing arc passes under
    everything); ``over``: the ends lifted and joined above everything. When both closures are the
    same knot, pulling the ends apart cannot change it (the ends can be led out either way), and the
    rope ties that knot: :attr:`name` is its catalogue name (``"unknown"`` outside the catalogue).
    When they differ the diagram is a proper knotoid (Turaev 2012): an end lies inside a loop and what
    the rope becomes depends on which way the end leaves; :attr:`name` is ``"knotoid"`` and no knot
    is tied.
    """

    under: KnotType
    over: KnotType

    @property
    def is_knot(self) -> bool:
        """True when both closures are the same knot (by their invariants)."""
        return self.under == self.over

    @property
    def name(self) -> str:
        """The knot's name when both closures agree, else ``"knotoid"`` (the store's ``knot_type``)."""
        return self.under.name if self.is_knot else KNOTOID

    @property
    def knot(self) -> KnotType | None:
        """The knot tied (both closures), None for a knotoid."""
        return self.under if self.is_knot else None

    def describe(self) -> str:
        """``3_1+`` for a knot, ``knotoid: under 3_1-, over 0_1`` otherwise."""
        if self.is_knot:
            return self.name
        return f"{KNOTOID}: under {self.under.name}, over {self.over.name}"

    def to_dict(self) -> dict[str, object]:
        """JSON-ready: name, both closures with their invariants."""

        def one(k: KnotType) -> dict[str, object]:
            return {
                "knot_type": k.name,
                "alexander": list(k.alexander),
                "determinant": k.determinant,
                "jones": [list(t) for t in k.jones],
                "writhe": k.writhe,
            }

        return {
            "knot_type": self.name,
            "is_knot": self.is_knot,
            "under": one(self.under),
            "over": one(self.over),
        }


@lru_cache(maxsize=1 << 16)
def identify(p: PData) -> RopeKnot:
    """What rope state ``p`` ties: both closures (under and over the table) through its faces, named."""
    q = parse_p_data(p)
    return RopeKnot(invariants(closed_gauss_code(q)), invariants(closed_gauss_code(q, over=True)))


def identify_points(points: npt.ArrayLike, depth_m: float = 1.0) -> RopeKnot:
    """What a rope with these centreline points (head first, shape (N, 3)) ties: both closures.

    For the under closure both ends are lowered ``depth_m`` below the rope's lowest point (and the
    table) and joined there by a straight segment; for the over closure they are lifted ``depth_m``
    above its highest point. Each closed polygon is projected to the table (its vertical segments
    project to the tips themselves).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2:
        raise ValueError(f"points must have shape (N>=2, 3), got {pts.shape}")
    low = min(float(pts[:, 2].min()), 0.0) - depth_m
    high = float(pts[:, 2].max()) + depth_m

    def closed(z: float) -> KnotType:
        tail = np.array([pts[-1, 0], pts[-1, 1], z])
        head = np.array([pts[0, 0], pts[0, 1], z])
        return invariants(gauss_code_from_polygon(np.vstack([pts, tail, head])))

    return RopeKnot(closed(low), closed(high))


def knot_type_name(p: PData) -> str:
    """Shorthand for ``identify(p).name``: the knot, or ``"knotoid"`` (the store's ``knot_type``)."""
    return identify(p).name


# ---------------------------------------------------------------------------------------------
# Names a user may type


class KnotNameError(ValueError):
    """A knot name that is not in :data:`KNOT_NAMES`; the message lists the valid names."""


KNOT_NAMES: dict[str, frozenset[str]] = {
    "unknot": frozenset({"0_1"}),
    "0_1": frozenset({"0_1"}),
    "overhand": frozenset({"3_1+", "3_1-"}),
    "trefoil": frozenset({"3_1+", "3_1-"}),
    "3_1": frozenset({"3_1+", "3_1-"}),
    "overhand+": frozenset({"3_1+"}),
    "trefoil+": frozenset({"3_1+"}),
    "3_1+": frozenset({"3_1+"}),
    "overhand-": frozenset({"3_1-"}),
    "trefoil-": frozenset({"3_1-"}),
    "3_1-": frozenset({"3_1-"}),
    "figure-eight": frozenset({"4_1"}),
    "figure-8": frozenset({"4_1"}),
    "4_1": frozenset({"4_1"}),
    "5_1": frozenset({"5_1+", "5_1-"}),
    "5_1+": frozenset({"5_1+"}),
    "5_1-": frozenset({"5_1-"}),
    "5_2": frozenset({"5_2+", "5_2-"}),
    "5_2+": frozenset({"5_2+"}),
    "5_2-": frozenset({"5_2-"}),
    "granny": frozenset({"3_1+#3_1+", "3_1-#3_1-"}),
    "granny+": frozenset({"3_1+#3_1+"}),
    "granny-": frozenset({"3_1-#3_1-"}),
    "3_1+#3_1+": frozenset({"3_1+#3_1+"}),
    "3_1-#3_1-": frozenset({"3_1-#3_1-"}),
    "square": frozenset({"3_1+#3_1-"}),
    "reef": frozenset({"3_1+#3_1-"}),
    "3_1+#3_1-": frozenset({"3_1+#3_1-"}),
    "3_1-#3_1+": frozenset({"3_1+#3_1-"}),
}


def resolve_knot(name: str) -> frozenset[str]:
    """The canonical knot types a user's name stands for (``"overhand"`` -> ``{"3_1+", "3_1-"}``)."""
    key = name.strip().lower()
    if key in KNOT_NAMES:
        return KNOT_NAMES[key]
    raise KnotNameError(f"unknown knot name {name!r}; valid names: {', '.join(KNOT_NAMES)}")


# ---------------------------------------------------------------------------------------------
# States that tie a knot


# Enumerating every state stops here (5 crossings: 130,304 states, ~30 s); 6 would be millions.
MAX_ENUMERATED_CROSSINGS = 5
# Composite knots are built up to this many crossings (see _composite_states).
MAX_BUILT_CROSSINGS = 6


@lru_cache(maxsize=16)
def _states_by_type(crossings: int) -> dict[str, tuple[PData, ...]]:
    from twisted.moves import enumerate_states

    out: dict[str, list[PData]] = {}
    for p in enumerate_states(crossings)[crossings]:
        out.setdefault(identify(p).name, []).append(p)
    return {name: tuple(states) for name, states in out.items()}


def _shifted(p: PData, offset: int) -> list[tuple[int, int, int]]:
    return [(o + offset, u + offset, s) for o, u, s in p.crossings()]


def rotations(p: PData) -> list[PData]:
    """The open diagrams made by cutting the closure of ``p`` at each of its edges, in both directions.

    Meant for a state whose ends lie in one face: its closing arc then crosses nothing, the closed
    diagram has the same crossings, and cutting it at another edge gives a state with the same two
    closures (a rotation of the visit sequence; the reverse walks it tail to head). States that
    cannot be drawn are skipped.
    """
    from twisted.moves import parse_state

    m = len(p.visits)
    out: dict[str, PData] = {}
    for r in range(max(m, 1)):
        triples = [(((o - 1 - r) % m) + 1, ((u - 1 - r) % m) + 1, s) for o, u, s in p.crossings()]
        for q in (PData.from_crossings(triples),):
            for candidate in (q, q.reverse()):
                try:
                    out.setdefault(candidate.key, parse_state(candidate))
                except PDataError:
                    continue
    return sorted(out.values(), key=lambda q: q.key)


@lru_cache(maxsize=16)
def _composite_states(knot_type: str, crossings: int) -> tuple[PData, ...]:
    """States of ``crossings`` crossings that tie the composite ``knot_type``, built from its summands.

    A minimal diagram of a connected sum of alternating knots is visibly composite (Menasco 1984): one
    summand's diagram, then the other's. So: a rope that ties the first summand (ends in one face)
    followed by a rope that ties the second, every cut of that closed diagram (:func:`rotations`), and
    only the states whose two closures are both ``knot_type`` are kept. Only the states whose ends lie
    in one face are found this way (``tests/test_knots.py`` checks that below 6 crossings every state
    tying a knot at its crossing number has its ends in one face).
    """
    parts = knot_type.split("#")
    if len(parts) != 2:
        raise ValueError(f"{knot_type!r} is not a composite of two knots")
    first, second = parts
    c1, c2 = crossing_number(first), crossing_number(second)
    if c1 + c2 != crossings:
        return ()
    found: dict[str, PData] = {}
    for order in ((first, second), (second, first)):
        heads = [p for p in _states_by_type(crossing_number(order[0])).get(order[0], ()) if _ends_together(p)]
        tails = [p for p in _states_by_type(crossing_number(order[1])).get(order[1], ()) if _ends_together(p)]
        for a in heads:
            for b in tails:
                joined = PData.from_crossings(_shifted(a, 0) + _shifted(b, len(a.visits)))
                for q in rotations(joined):
                    if q.key not in found and identify(q).name == knot_type:
                        found[q.key] = q
    return tuple(sorted(found.values(), key=lambda q: q.key))


def _ends_together(p: PData) -> bool:
    head_face, tail_face = diagram(p).end_faces()
    return head_face == tail_face


def least_crossings(name: str) -> int:
    """The default crossing count of a knot goal: the knot's crossing number (the least over its types).

    A state ties a knot only when both closures are it; ``bench/bench_knots.py`` and the tests check up
    to 5 crossings that no state with fewer crossings than the crossing number does.
    """
    return min(crossing_number(t) for t in resolve_knot(name))


def states_tying(name: str, crossings: int | None = None, max_crossings: int = 4) -> list[PData]:
    """States (reachable by moves) with ``crossings`` crossings that really tie knot ``name``.

    Both closures of each state are the knot (:class:`RopeKnot`): knotoids are never included.
    ``crossings=None`` takes :func:`least_crossings` (3 for the overhand knot, 6 for granny and
    square); ``max_crossings`` bounds the count that may be enumerated. Up to
    :data:`MAX_ENUMERATED_CROSSINGS` every state is enumerated (5 crossings take tens of seconds, cached
    per count); composite knots at 6 crossings are built from their summands
    (:func:`_composite_states`). Sorted by key.
    """
    types = resolve_knot(name)
    if crossings is None:
        crossings = least_crossings(name)
    if crossings < 0:
        raise ValueError(f"crossings must be >= 0, got {crossings}")
    found: list[PData] = []
    for t in sorted(types):
        if "#" in t and crossings > MAX_ENUMERATED_CROSSINGS:
            if crossings > MAX_BUILT_CROSSINGS:
                raise ValueError(
                    f"states of {crossings} crossings are not built (at most {MAX_BUILT_CROSSINGS})"
                )
            found.extend(_composite_states(t, crossings))
        elif crossings > min(max_crossings, MAX_ENUMERATED_CROSSINGS):
            raise ValueError(
                f"{name}: states of {crossings} crossings would have to be enumerated; at most "
                f"{min(max_crossings, MAX_ENUMERATED_CROSSINGS)} are (only composite knots are built at "
                f"{MAX_BUILT_CROSSINGS})"
            )
        else:
            found.extend(_states_by_type(crossings).get(t, ()))
    return sorted(found, key=lambda p: p.key)
