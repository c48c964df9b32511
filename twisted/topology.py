"""P-data: the topological state of an open rope (docs/DESIGN.md section 4).

A state lists the crossing *visits* met when walking the projected rope from the head (link-0 tip)
to the tail (the last link's tip). Visit ``p`` (1..2n) records whether the rope passes over (``O``) or
under (``U``) there, the position of the other visit of the same crossing (its partner), and the
crossing's sign ``sign((d_over x d_under) . e_z)`` with both strand directions taken head->tail.

The exchange format is a JSON list ``[[position, "O"|"U", partner, "+"|"-"], ...]`` sorted by
position; the empty rope is ``[]``. Because positions are 1..2n in walking order, that sorted list
is already canonical: two states are equal exactly when their lists are equal, and the compact JSON
text is the state's key.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, NamedTuple

import numpy as np
import numpy.typing as npt

__all__ = [
    "PData",
    "PDataError",
    "ProjectedCrossings",
    "TieRule",
    "Visit",
    "cross",
    "cross2",
    "crossing_signs",
    "json_int",
    "mirror",
    "p_data_of",
    "parse_p_data",
    "projected_crossings",
    "reverse",
    "segment_hits",
    "top",
    "Top",
]


class PDataError(ValueError):
    """A P-data state that is malformed; the message says which entry and what is wrong."""


class Visit(NamedTuple):
    """One visit of the rope to a crossing."""

    position: int
    over: str  # "O" or "U"
    partner: int
    sign: str  # "+" or "-"


@dataclass(frozen=True, slots=True)
class PData:
    """An immutable, validated P-data state (use :func:`parse_p_data` or :func:`top` to make one)."""

    visits: tuple[Visit, ...] = ()

    @property
    def cross(self) -> int:
        """Number of crossings ``Cross(s)``."""
        return len(self.visits) // 2

    def to_list(self) -> list[list[Any]]:
        return [[v.position, v.over, v.partner, v.sign] for v in self.visits]

    def to_json(self) -> str:
        """The exchange format, compact (also the canonical key)."""
        return json.dumps(self.to_list(), separators=(",", ":"))

    @property
    def key(self) -> str:
        """Canonical key: equal states have equal keys."""
        return self.to_json()

    def __str__(self) -> str:
        return self.to_json()

    def crossings(self) -> list[tuple[int, int, int]]:
        """Each crossing once as ``(over_position, under_position, sign)`` with sign in {+1, -1}."""
        out = []
        for v in self.visits:
            if v.over == "O":
                out.append((v.position, v.partner, 1 if v.sign == "+" else -1))
        return out

    def mirror(self) -> PData:
        """The state of the rope reflected y -> -y: every sign flips."""
        return PData(tuple(v._replace(sign="-" if v.sign == "+" else "+") for v in self.visits))

    def reverse(self) -> PData:
        """The same rope walked tail -> head: positions p -> 2n+1-p; O/U and signs are kept."""
        m = len(self.visits) + 1
        flipped = [Visit(m - v.position, v.over, m - v.partner, v.sign) for v in self.visits]
        return PData(tuple(sorted(flipped)))

    @classmethod
    def from_crossings(cls, crossings: Iterable[tuple[int, int, int]]) -> PData:
        """Build from ``(over_position, under_position, sign)`` triples (validated)."""
        visits = []
        for over, under, sign in crossings:
            s = "+" if sign > 0 else "-"
            visits.append([over, "O", under, s])
            visits.append([under, "U", over, s])
        return parse_p_data(visits)


EMPTY = PData(())


def _quote(value: Any, limit: int = 80) -> str:
    """``repr(value)``, cut to about ``limit`` characters: error messages quote input, never all of it."""
    try:
        text = repr(value)
    except RecursionError:
        text = f"<a {type(value).__name__} nested too deeply to print>"
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text):,} characters)"


# Every integer in P-data fits 64 bits (positions are small); anything larger is refused as such, before
# Python's own limit on reading integers (4,300 digits) would raise a bare ValueError.
INT64_MIN, INT64_MAX = -(2**63), 2**63 - 1
_INT64_DIGITS = 19


def _beyond_64_bits(digits: str) -> PDataError:
    shown = digits if len(digits) <= 40 else f"{digits[:20]}...{digits[-8:]}"
    return PDataError(
        f"integer {shown} ({len(digits.lstrip('-')):,} digits) is beyond 64 bits: P-data positions are 1..2n"
    )


def json_int(digits: str) -> int:
    """``parse_int`` for :func:`json.loads` of P-data and goal files: a 64-bit integer, else PDataError."""
    if len(digits.lstrip("-")) <= _INT64_DIGITS:
        value = int(digits)
        if INT64_MIN <= value <= INT64_MAX:
            return value
    raise _beyond_64_bits(digits)


def _validate(entries: Sequence[Any]) -> PData:
    if not isinstance(entries, (list, tuple)):
        raise PDataError(
            f"P-data must be a JSON list of [position, O|U, partner, +|-], got {type(entries).__name__}"
        )
    visits: list[Visit] = []
    for i, entry in enumerate(entries):
        if not isinstance(entry, (list, tuple)) or len(entry) != 4:
            raise PDataError(
                f'entry {i}: expected [position, "O"|"U", partner, "+"|"-"], got {_quote(entry)}'
            )
        pos, over, partner, sign = entry
        for name, value in (("position", pos), ("partner", partner)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise PDataError(f"entry {i}: {name} must be an integer, got {_quote(value)}")
            if not INT64_MIN <= value <= INT64_MAX:  # compared, never printed: repr fails beyond 4,300 digits
                raise PDataError(f"entry {i}: {name} is beyond 64 bits (P-data positions are 1..2n)")
        if over not in ("O", "U"):
            raise PDataError(f'entry {i}: over/under must be "O" or "U", got {_quote(over)}')
        if sign not in ("+", "-"):
            raise PDataError(f'entry {i}: sign must be "+" or "-", got {_quote(sign)}')
        visits.append(Visit(int(pos), over, int(partner), sign))
    m = len(visits)
    if m % 2:
        raise PDataError(f"P-data has {m} visits; every crossing is visited twice, so the count must be even")
    visits.sort()
    positions = [v.position for v in visits]
    if positions != list(range(1, m + 1)):
        raise PDataError(f"positions must be exactly 1..{m} (each once), got {_quote(sorted(positions))}")
    for v in visits:
        if not 1 <= v.partner <= m:
            raise PDataError(f"position {v.position}: partner {v.partner} is outside 1..{m}")
        if v.partner == v.position:
            raise PDataError(f"position {v.position}: a visit cannot be its own partner")
        w = visits[v.partner - 1]
        if w.partner != v.position:
            raise PDataError(
                f"position {v.position}: partner {v.partner} names {w.partner} as its partner, "
                f"not {v.position}"
            )
        if w.over == v.over:
            raise PDataError(
                f"positions {v.position} and {v.partner}: both are {v.over!r}; one must be O, one U"
            )
        if w.sign != v.sign:
            raise PDataError(f"positions {v.position} and {v.partner}: signs differ ({v.sign} vs {w.sign})")
    return PData(tuple(visits))


def parse_p_data(value: str | Sequence[Any] | PData) -> PData:
    """Parse and validate P-data given as JSON text, a list of entries, or a :class:`PData`."""
    if isinstance(value, PData):
        return value
    if isinstance(value, str):
        try:
            value = json.loads(value, parse_int=json_int)
        except json.JSONDecodeError as exc:
            raise PDataError(
                f"P-data is not valid JSON ({exc.msg} at column {exc.colno}): {_quote(value)}"
            ) from None
        except RecursionError:
            # P-data nests two levels deep; the JSON decoder recurses once per "["
            message = f"P-data nests lists far too deeply (it is a list of lists): {_quote(value)}"
            raise PDataError(message) from None
    return _validate(value)  # type: ignore[arg-type]


def cross(p: PData) -> int:
    """``Cross(s)``: the number of crossings."""
    return p.cross


def mirror(p: PData) -> PData:
    return p.mirror()


def reverse(p: PData) -> PData:
    return p.reverse()


IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

TieRule = Literal["earlier_over", "raise"]
"""What :func:`projected_crossings` does when two strands are at exactly the same height at a crossing.

* ``"earlier_over"``: the strand on the earlier segment (nearer the head) is over. :func:`top` and the
  drawings of ``twisted.render`` use it: P-data must exist for every configuration the simulator
  returns, and since the rope has a thickness an exact tie of two centrelines does not come from the
  physics; a fixed choice keeps ``Top`` total and deterministic.
* ``"raise"``: :class:`ValueError`. ``twisted.knots.gauss_code_from_polygon`` uses it: the knot type of
  a closed polygon depends on which strand is over, so an arbitrary choice could silently name the
  wrong knot; its caller perturbs the polygon instead.

Without a tie both rules give the same result.
"""


def cross2(a: FloatArray, b: FloatArray) -> FloatArray:
    """The z component of the cross product of 2-D vectors (last axis ``x, y``), broadcast."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


@dataclass(frozen=True)
class ProjectedCrossings:
    """The crossings of a projected polyline (made by :func:`projected_crossings`), one entry each.

    Crossing ``c`` lies at parameter ``t[c]`` on segment ``i[c]`` and ``u[c]`` on segment ``j[c]``
    (``i < j``; segment ``s`` runs from point ``s`` to the next point). ``i_over[c]``: the strand on
    segment ``i`` is over. ``sign[c]``: +1 / -1, ``sign((d_over x d_under) . e_z)`` (docs/DESIGN.md
    section 4.3). ``position`` has length ``2k``: entry ``c`` is the visit number (1..2k) of crossing
    ``c`` on segment ``i``, entry ``c + k`` its visit on segment ``j``; visits are numbered in walking
    order, by ``segment + parameter`` (stable sort, so equal parameters keep their order).
    """

    i: IntArray
    j: IntArray
    t: FloatArray
    u: FloatArray
    i_over: BoolArray
    sign: IntArray
    position: IntArray

    def __len__(self) -> int:
        return len(self.i)


def segment_hits(
    start_i: FloatArray, d_i: FloatArray, start_j: FloatArray, d_j: FloatArray
) -> tuple[npt.NDArray[np.bool_], FloatArray, FloatArray]:
    """Whether 2-D segments ``start_i + t d_i`` and ``start_j + u d_j`` cross, with ``t`` and ``u`` in
    the half-open ``[0, 1)``; parallel segments (``|d_i x d_j| <= 1e-15``) never do. Broadcast over the
    leading axes; returns (hit, t, u)."""
    w = start_j - start_i
    denom = cross2(d_i, d_j)
    ok = np.abs(denom) > 1e-15
    safe = np.where(ok, denom, 1.0)
    t = cross2(w, d_j) / safe
    u = cross2(w, d_i) / safe
    return ok & (t >= 0) & (t < 1) & (u >= 0) & (u < 1), t, u


def crossing_signs(d_i: FloatArray, d_j: FloatArray, i_over: npt.NDArray[np.bool_]) -> IntArray:
    """The sign of each crossing of strands with 2-D directions ``d_i`` and ``d_j`` (walking order),
    strand ``i`` over where ``i_over``: ``sign((d_over x d_under) . e_z)`` (docs/DESIGN.md section 4.3)."""
    d_over = np.where(i_over[:, None], d_i, d_j)
    d_under = np.where(i_over[:, None], d_j, d_i)
    return np.where(cross2(d_over, d_under) > 0, 1, -1).astype(np.int64)


def projected_crossings(
    points: npt.ArrayLike, *, closed: bool = False, ties: TieRule = "earlier_over"
) -> ProjectedCrossings:
    """Where the projection of a polyline to the table crosses itself, with over/under and signs.

    The one segment-crossing computation of the code (docs/DESIGN.md section 4.2): :func:`top`
    (P-data), ``twisted.knots.gauss_code_from_polygon`` (closed polygons) and ``twisted.render``
    (drawings) read it. ``points`` has shape (N, 3) and is not validated here (each caller checks it
    with its own message). Every pair of segments is tested at once (numpy broadcasting); the
    parameter interval is half-open, ``[0, 1)``, so a crossing exactly at a joint counts once;
    parallel segments (``|cross| <= 1e-15``) never cross. Heights are interpolated linearly along
    each segment; the higher strand is over.

    * ``closed=False``: an open rope, segments ``s -> s + 1``; neighbours are not tested.
    * ``closed=True``: a closed polygon, the last point joined to the first; segments whose
      projections share an end point (neighbours, or neighbours through a vertical segment, whose
      projection is a point) are not tested.
    * ``ties``: what an exact height tie means (:data:`TieRule`).
    """
    pts = np.asarray(points, dtype=np.float64)
    if closed:
        start = pts
        d = np.roll(pts, -1, axis=0) - pts
        m = len(pts)
        i_idx, j_idx = np.triu_indices(m, k=1)
        # projected vertex identity: vertices with equal (x, y) are one point of the projection
        _, vid = np.unique(pts[:, :2], axis=0, return_inverse=True)
        vid = vid.reshape(-1)
        a0, a1 = vid[i_idx], vid[(i_idx + 1) % m]
        b0, b1 = vid[j_idx], vid[(j_idx + 1) % m]
        tested = ~((a0 == b0) | (a0 == b1) | (a1 == b0) | (a1 == b1))
    else:
        start = pts[:-1]
        d = pts[1:] - pts[:-1]
        i_idx, j_idx = np.triu_indices(len(d), k=2)
        tested = np.ones(len(i_idx), dtype=bool)
    hit, t, u = segment_hits(start[i_idx, :2], d[i_idx, :2], start[j_idx, :2], d[j_idx, :2])
    hit &= tested
    i_idx, j_idx, t, u = i_idx[hit], j_idx[hit], t[hit], u[hit]
    zi = start[i_idx, 2] + t * d[i_idx, 2]
    zj = start[j_idx, 2] + u * d[j_idx, 2]
    if ties == "raise" and np.any(zi == zj):
        raise ValueError("two strands cross at equal heights in the projection; perturb the polygon")
    i_over = zi >= zj
    sign = crossing_signs(d[i_idx, :2], d[j_idx, :2], i_over)
    k = len(i_idx)
    order = np.argsort(np.concatenate([i_idx + t, j_idx + u]), kind="stable")
    position = np.empty(2 * k, dtype=np.int64)
    position[order] = np.arange(1, 2 * k + 1)
    return ProjectedCrossings(i_idx, j_idx, t, u, i_over, sign, position)


def top(points: npt.ArrayLike) -> PData:
    """``Top(q)``: P-data of a rope given its centreline points, head first, shape (N+1, 3).

    The crossings are those of :func:`projected_crossings` (open rope; on an exact height tie the
    earlier segment is over): a crossing's visits are placed along the rope by ``segment + t``; the
    segment parameter interval is half-open so a crossing exactly at a joint counts once.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 2:
        raise ValueError(f"points must have shape (N+1, 3), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points contain NaN or infinity")
    return p_data_of(projected_crossings(pts))


def p_data_of(pc: ProjectedCrossings) -> PData:
    """The P-data of an open rope's crossings (:func:`projected_crossings`, or crossings whose over
    strands and signs a caller decided otherwise)."""
    k = len(pc)
    if k == 0:
        return EMPTY
    visits = []
    for c in range(k):
        pi, pj = int(pc.position[c]), int(pc.position[c + k])
        oi, oj = ("O", "U") if pc.i_over[c] else ("U", "O")
        sign = "+" if pc.sign[c] > 0 else "-"
        visits.append(Visit(pi, oi, pj, sign))
        visits.append(Visit(pj, oj, pi, sign))
    visits.sort()
    return PData(tuple(visits))


Top = top  # the paper's name
