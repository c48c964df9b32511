"""The planar diagram of an open rope, rebuilt from its P-data, and the faces it cuts the table into.

Segments. Walking the projected rope from the head, the crossing visits 1..2n cut it into the
segments 0..2n: segment ``k`` runs from visit ``k`` to visit ``k + 1`` (visit 0 is the head tip,
visit 2n+1 the tail tip), so 0 and 2n are the *end segments*. Each segment has a left side ``L``
and a right side ``R``, seen walking head -> tail.

The graph. Vertices are the n crossings (4-valent) and the two rope tips (1-valent); edges are
the 2n+1 segments. A rope is one connected arc, so this graph is connected, and Euler's formula on
the sphere, ``V - E + F = (n + 2) - (2n + 1) + F = 2``, gives ``F = n + 1`` faces (the unbounded
region of the table counts as one face).

Why P-data fixes the embedding. An embedding of a connected graph on an oriented surface is
determined by its rotation system: the counter-clockwise (CCW) order of the edge ends at every
vertex. At a tip there is one edge end, so nothing to choose. At a crossing with over visit ``p``
and under visit ``q`` the four ends are over-in (end of segment p-1), over-out (start of segment
p), under-in (end of segment q-1) and under-out (start of segment q). The strands cross
transversally, so over-in is opposite over-out and under-in opposite under-out; what remains is
whether the under strand's forward direction ``d_under`` lies 90 degrees CCW or CW of
``d_over``, and that is exactly the crossing's sign ``sign((d_over x d_under) . e_z)``:

    sign +:  CCW order  over-out, under-out, over-in, under-in
    sign -:  CCW order  over-out, under-in,  over-in, under-out

So the signed P-data of an open rope determines its diagram on the sphere up to an orientation
preserving homeomorphism: the rope's P-data is enough to know which segment sides bound a common
face. What it does *not* say is which face is the unbounded one on the table. That never matters
for the moves, which all happen inside one face: on the sphere every face is a disc, so any two
points of its boundary can be joined by a path inside it, unique up to isotopy. A P-data list that
is valid but not drawable in the plane (a "virtual" rope) gives a rotation system of genus > 0;
:func:`diagram` reports it as a :class:`~twisted.topology.PDataError`.

Faces are traced with the face on the left: arriving at a vertex along an edge, leave along the
next edge end clockwise from the one we arrived by. Going along segment k head -> tail keeps its
left side in view, going tail -> head its right side, so each face is the cyclic list of the
segment sides that bound it. Around a rope tip the trace turns back, so both sides of an end
segment belong to the same face: the end segment lies *inside* that face.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

from twisted.topology import PData, PDataError

__all__ = ["Diagram", "Face", "SegmentSide", "diagram", "drawable"]

LEFT = "L"
RIGHT = "R"


class SegmentSide(NamedTuple):
    """One side of one segment: ``side`` is ``"L"`` or ``"R"`` seen walking head -> tail."""

    segment: int
    side: str


@dataclass(frozen=True, slots=True)
class Face:
    """A region of the table bounded by the rope: its segment sides in boundary order.

    The boundary is walked with the face on the left, starting from the side of lowest
    (segment, side) order, so equal diagrams give equal faces.
    """

    sides: tuple[SegmentSide, ...]

    def segments(self) -> frozenset[int]:
        """The segments that bound this face (on one or both sides)."""
        return frozenset(s.segment for s in self.sides)

    def __contains__(self, item: object) -> bool:
        return item in self.sides


@dataclass(frozen=True, slots=True)
class Diagram:
    """The planar diagram of an open rope: vertices, edges and the faces with their sides."""

    p_data: PData
    faces: tuple[Face, ...]
    face_index: dict[SegmentSide, int]  # which face each segment side bounds

    @property
    def n_segments(self) -> int:
        return 2 * self.p_data.cross + 1

    @property
    def n_vertices(self) -> int:
        """Crossings plus the two rope tips."""
        return self.p_data.cross + 2

    @property
    def n_edges(self) -> int:
        return self.n_segments

    @property
    def euler_characteristic(self) -> int:
        """``V - E + F``; 2 for every diagram :func:`diagram` returns (it is planar)."""
        return self.n_vertices - self.n_edges + len(self.faces)

    def face_of(self, segment: int, side: str) -> int:
        """Index in :attr:`faces` of the face that the given side of ``segment`` bounds."""
        return self.face_index[SegmentSide(segment, side)]

    def end_faces(self) -> tuple[int, int]:
        """The faces containing the head end segment and the tail end segment."""
        return self.face_of(0, LEFT), self.face_of(self.n_segments - 1, LEFT)


# Darts: segment k walked head -> tail is dart 2k, walked tail -> head is dart 2k+1.
# The face left of dart 2k is the L side of k, left of dart 2k+1 the R side.


def _cw_next_tables(p: PData) -> list[int]:
    """For every dart leaving a vertex, the next dart leaving that vertex clockwise."""
    n_darts = 2 * (2 * p.cross + 1)
    cw_next = [-1] * n_darts
    for over, under, sign in p.crossings():
        over_out, over_in = 2 * over, 2 * (over - 1) + 1
        under_out, under_in = 2 * under, 2 * (under - 1) + 1
        if sign > 0:
            ccw = (over_out, under_out, over_in, under_in)
        else:
            ccw = (over_out, under_in, over_in, under_out)
        for i in range(4):
            # clockwise next = counter-clockwise previous
            cw_next[ccw[i]] = ccw[i - 1]
    # the tips: one dart leaves each, so it is its own clockwise neighbour
    cw_next[0] = 0
    cw_next[n_darts - 1] = n_darts - 1
    return cw_next


@lru_cache(maxsize=4096)
def diagram(p: PData) -> Diagram:
    """Build the planar diagram of ``p`` and trace its faces.

    Raises :class:`PDataError` when ``p`` is valid P-data that no planar rope can have.
    """
    cw_next = _cw_next_tables(p)
    n_darts = len(cw_next)
    seen = [False] * n_darts
    faces: list[Face] = []
    for start in range(n_darts):
        if seen[start]:
            continue
        sides = []
        dart = start
        while not seen[dart]:
            seen[dart] = True
            sides.append(SegmentSide(dart >> 1, RIGHT if dart & 1 else LEFT))
            # arriving along `dart`, turn to the clockwise neighbour of the way back (dart ^ 1)
            dart = cw_next[dart ^ 1]
        faces.append(Face(tuple(sides)))
    euler = (p.cross + 2) - (2 * p.cross + 1) + len(faces)
    if euler != 2:
        genus = (2 - euler) // 2
        raise PDataError(
            f"P-data {p.key} is consistent but cannot be drawn in the plane: its crossings and signs "
            f"force a surface of genus {genus} (V - E + F = {euler}, planar needs 2)"
        )
    face_index = {side: i for i, face in enumerate(faces) for side in face.sides}
    return Diagram(p, tuple(faces), face_index)


def drawable(p: PData) -> bool:
    """Whether some planar rope has the P-data ``p`` (:func:`diagram` traces it). Deleting crossings from
    a goal (``twisted.moves.sub_states``) can leave P-data that none has."""
    try:
        diagram(p)
    except PDataError:
        return False
    return True
