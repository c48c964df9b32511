"""High level of TWISTED: R1 / R2 / Cross moves on the P-data of an open rope, and BFS plans.

Every move happens inside one face of the rope's planar diagram (:mod:`twisted.diagram`) and adds
crossings (the paper has no undo moves). A move inserts new visits into the segments it touches and
keeps every old crossing with its order along the rope, O/U and sign. Removing moves, the inverse of
each (``Move.remove``; :func:`removals`, :func:`plans_both_ways`), are described at the end.

Sign rule used throughout: a strand X crossing a strand B from B's left to B's right gives
``+`` when X is over and ``-`` when X is under; from right to left the signs swap. (With B along
+x, "left to right" means X runs along -y: ``(0,-1) x (1,0) = +1`` when X is over.)

R1(segment k, side, sign). A small curl on segment k lying in the face on the given side of k.
A curl on the right turns clockwise, one on the left counter-clockwise; with its first visit over,
a clockwise curl has sign + and a counter-clockwise one sign -. So (side, sign) fixes the O/U of the
two new consecutive visits, and the four choices give four different states: 4 x (2n+1) moves.

R2(strand E on segment a, side sa; strand F on segment b, side sb; E over or under). Two pieces of
rope that bound a common face through the sides sa, sb are pushed across each other inside that
face, making a bigon: two new crossings of opposite sign. E is the piece met first along the rope
(a <= b). Working the geometry out (drawings in tests/test_moves.py) gives:
  - the two crossings are met in the same order along F as along E when sa != sb (the pieces run
    "parallel" around the face) and in reverse order when sa == sb ("antiparallel", the hairpin);
  - E's first new visit crosses F coming from F's side sb, so its sign follows the rule above.
Which pieces may be paired: any two sides of one face, a side with itself (two pieces of one
segment side, e.g. a hairpin folded from one straight piece), and for a segment with both sides on
one face (an end segment, or a bridge) its left with its right side, in both assignments.
The reference also demanded that both rope ends lie in one face. We do not: a face is a disc on
the sphere, so a path from one side to the other always exists inside it and the rope ends have
no say (see ``test_r2_needs_no_common_face_for_the_rope_ends``). A piece pushed over another piece
of the same segment (a == b) is physical for an open rope: fold a straight piece into a hairpin, or
into an S around a rope tip, and push one part across the other; from the empty rope every R2 is
of this kind. That gives 8 R2 moves from the empty rope where the reference had 4 (presumably the
4 hairpins, sa == sb); the 4 "parallel" ones (``test_r2_parallel_pieces_the_reference_did_not_have``)
are drawn and read back by Top in the tests. From a 1-crossing curl we list 60 moves giving 52
states (reference: 40 / 36), itemised in ``test_successor_counts_from_empty_and_one_crossing``;
the enumeration counts agree all the same, because they are the counts of all planar P-data.

Cross(end segment e, segment b, side sb, over/under). The rope tip of the end segment e moves
across segment b, a segment of the face that e lies in, coming from b's side sb. The new visit on
e is at the tip end of e (the new first visit for the head, the new last for the tail), and the
sign is forced: walking head -> tail the head enters the face across b (from the far side to sb),
the tail leaves it (from sb to the far side). When b is also an end segment both sides of b are in
the face, so both signs occur. The tip crossing its own end segment is a curl at the tip, which
is exactly R1 on that end segment, so it is left to R1 (hence no Cross from the empty rope).

Why the moves reach every state (and the enumeration counts). Retracting the head tip past its
first crossing undoes a Cross (or an R1 on segment 0), so every planar P-data with n crossings is
one move away from one with n-1. Hence enumerating by moves from the empty rope reaches exactly the
planar P-data: 4, 40, 528 and 7,968 states with 1, 2, 3 and 4 crossings, the reference's numbers
(``test_enumeration_is_exactly_the_planar_p_data`` checks this against brute force).

Removing moves. Each takes whole crossings out and keeps the others, so it undoes one adding move:
  - R1^-1 (a curl straightened): a crossing whose two visits i, i + 1 are consecutive. Its loop,
    segment i, has nothing on it, and the rope's other two ends at the crossing are neighbours there,
    so one side of the loop bounds a monogon; the move names the loop and that side (the side the R1
    that made the curl names, with the same sign and over).
  - R2^-1 (two strands pulled apart): a bigon face bounded by segments a < b that both run between
    the same two crossings, with the piece on a over (or under) the piece on b at both.
  - Cross^-1 (a rope end pulled back out across a strand): the head's first visit or the tail's
    last one, unless its partner is the next visit along (then it is R1^-1).
Segments are those of the state the move starts from (the one with more crossings). For every state
up to 4 crossings the states and kinds the removing moves reach are exactly those of the adding
moves into it (tests/test_moves.py). With both kinds the move graph has cycles; plans through it
(:func:`plans_both_ways`) are the shortest ones, and a plan may take crossings out and put others in.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Literal

from twisted.diagram import LEFT, RIGHT, Diagram, diagram
from twisted.topology import EMPTY, PData, PDataError, Visit, parse_p_data

__all__ = [
    "DEFAULT_PLAN_LIMIT",
    "MOVES_VERSION",
    "REMOVALS_VERSION",
    "Move",
    "Plan",
    "Successor",
    "enumerate_states",
    "explains",
    "parse_state",
    "neighbours",
    "plans",
    "plans_both_ways",
    "plans_to_any",
    "removals",
    "successors",
    "sub_states",
]

MoveKind = Literal["R1", "R2", "Cross"]

DEFAULT_PLAN_LIMIT = 100
# Bumped whenever the move set changes, so that plans cached in a database are recomputed.
MOVES_VERSION = 1
# Bumped whenever the removing moves or plans_both_ways change; part of the plan cache's key of a
# query answered both ways (twisted.store.plans), so adding-only answers stay valid when it moves.
REMOVALS_VERSION = 3
# plans_both_ways grows the goals' side unless its frontier is this many times the start's: the goals'
# layers are kept for the next query, the start's are not (80 queries of a granny-to-square search:
# 10 took half the time of 1, 100 no less than 10)
GOAL_SIDE_WEIGHT = 10


@dataclass(frozen=True, slots=True)
class Move:
    """One high-level move, with what a plan needs to say how to make it.

    - ``R1``: ``segment`` gets a curl on ``side`` (``"L"``/``"R"``) with crossing ``sign``;
      ``over`` is the O/U of the curl's first visit (implied by side and sign).
    - ``R2``: the piece on ``segment`` (met first along the rope), seen from its ``side``, and the
      piece on ``other_segment``, seen from ``other_side``, are pushed across each other; ``over``
      is ``"O"`` when the first piece ends on top; ``sign`` is that of the first new crossing.
    - ``Cross``: the tip of end segment ``segment`` is laid over (``over="O"``) or under
      (``"U"``) ``other_segment``, arriving from its ``other_side``; ``sign`` is forced by that.

    Segments are numbered in the state the move starts from.
    """

    kind: MoveKind
    segment: int
    side: str | None = None
    sign: str | None = None
    over: str | None = None
    other_segment: int | None = None
    other_side: str | None = None
    remove: bool = False  # the inverse move: takes crossings out (see "Removing moves" above)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict; fields that do not apply to this kind are left out (``remove`` when False,
        so an adding move's dict is what it was before removing moves existed)."""
        out: dict[str, Any] = {"kind": self.kind, "segment": self.segment}
        for name in ("side", "other_segment", "other_side", "over", "sign"):
            value = getattr(self, name)
            if value is not None:
                out[name] = value
        if self.remove:
            out["remove"] = True
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Move:
        return cls(
            kind=d["kind"],
            segment=d["segment"],
            side=d.get("side"),
            sign=d.get("sign"),
            over=d.get("over"),
            other_segment=d.get("other_segment"),
            other_side=d.get("other_side"),
            remove=bool(d.get("remove", False)),
        )

    def __str__(self) -> str:
        args = ", ".join(f"{k}={v}" for k, v in self.to_dict().items() if k not in ("kind", "remove"))
        return f"{self.kind}{'^-1' if self.remove else ''}({args})"


@dataclass(frozen=True, slots=True)
class Successor:
    """A state one move away, and the move."""

    state: PData
    move: Move


@dataclass(frozen=True)
class Plan:
    """A high-level plan: ``states[0]`` is the start, ``states[-1]`` the goal, ``moves[i]`` takes
    ``states[i]`` to ``states[i + 1]``."""

    states: list[PData]
    moves: list[Move] = field(default_factory=list)

    @property
    def length(self) -> int:
        return len(self.moves)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: states as P-data lists, moves as dicts."""
        return {
            "length": self.length,
            "states": [s.to_list() for s in self.states],
            "moves": [m.to_dict() for m in self.moves],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Plan:
        return cls([parse_p_data(s) for s in d["states"]], [Move.from_dict(m) for m in d["moves"]])


# ---------------------------------------------------------------------------------------------
# building a successor: insert new visits into segments

# Visits are shared between states (there are few distinct ones), which keeps cached states small.
_VISITS: dict[tuple[int, str, int, str], Visit] = {}


def _visit(position: int, over: str, partner: int, sign: str) -> Visit:
    key = (position, over, partner, sign)
    v = _VISITS.get(key)
    if v is None:
        v = _VISITS[key] = Visit(position, over, partner, sign)
    return v


# A new visit to insert: (crossing id, "O"|"U", sign). Crossing ids are local to one move.
_NewVisit = tuple[int, str, str]


def _insert(p: PData, inserts: dict[int, list[_NewVisit]]) -> PData:
    """``p`` with new visits inserted: ``inserts[k]`` lists those on segment k in rope order."""
    old = p.visits
    n_old = len(old)
    new_position = [0] * (n_old + 1)  # old position -> new position
    placed: dict[int, list[tuple[int, str, str]]] = {}  # crossing id -> [(position, O/U, sign)]
    pos = 0
    for k in range(n_old + 1):
        for cid, over, sign in inserts.get(k, ()):
            pos += 1
            placed.setdefault(cid, []).append((pos, over, sign))
        if k < n_old:
            pos += 1
            new_position[k + 1] = pos
    out: list[Visit | None] = [None] * pos
    for v in old:
        np_ = new_position[v.position]
        out[np_ - 1] = _visit(np_, v.over, new_position[v.partner], v.sign)
    for (pa, oa, sa), (pb, ob, sb) in placed.values():
        out[pa - 1] = _visit(pa, oa, pb, sa)
        out[pb - 1] = _visit(pb, ob, pa, sb)
    return PData(tuple(out))  # type: ignore[arg-type]


def _flip(over: str) -> str:
    return "U" if over == "O" else "O"


def _crossing_sign(x_over: bool, left_to_right: bool) -> str:
    """Sign of a crossing where strand X crosses strand B from B's left to right (or back)."""
    return "+" if x_over == left_to_right else "-"


# ---------------------------------------------------------------------------------------------
# the three moves


def _r1_moves(p: PData) -> Iterator[Successor]:
    for k in range(2 * p.cross + 1):
        for side in (LEFT, RIGHT):
            for sign in ("+", "-"):
                # clockwise (right) curl: first visit over <=> +; counter-clockwise: over <=> -
                first = "O" if (sign == "+") == (side == RIGHT) else "U"
                state = _insert(p, {k: [(0, first, sign), (0, _flip(first), sign)]})
                yield Successor(state, Move("R1", k, side=side, sign=sign, over=first))


def _r2_state(p: PData, a: int, sa: str, b: int, sb: str, e_over: bool) -> tuple[PData, str]:
    """Push the piece on segment a (side sa) and the later piece on b (side sb) across each other."""
    e_mark = "O" if e_over else "U"
    f_mark = _flip(e_mark)
    # E's first visit crosses F coming from F's side sb
    s1 = _crossing_sign(e_over, left_to_right=(sb == LEFT))
    s2 = "-" if s1 == "+" else "+"
    e_visits: list[_NewVisit] = [(0, e_mark, s1), (1, e_mark, s2)]
    # same order along F when the sides differ, reversed (nested) when they agree
    f_visits: list[_NewVisit] = [(0, f_mark, s1), (1, f_mark, s2)]
    if sa == sb:
        f_visits.reverse()
    if a == b:
        inserts = {a: e_visits + f_visits}
    else:
        inserts = {a: e_visits, b: f_visits}
    return _insert(p, inserts), s1


def _r2_moves(p: PData, d: Diagram) -> Iterator[Successor]:
    for face in d.faces:
        sides = sorted(face.sides)
        for i, (a, sa) in enumerate(sides):
            for b, sb in sides[i:]:
                if a == b and sa != sb:
                    # both sides of one segment on this face: either piece may face either way
                    pairs = [(sa, sb), (sb, sa)]
                else:
                    pairs = [(sa, sb)]
                for s_first, s_second in pairs:
                    for e_over in (True, False):
                        state, s1 = _r2_state(p, a, s_first, b, s_second, e_over)
                        move = Move(
                            "R2",
                            a,
                            side=s_first,
                            sign=s1,
                            over="O" if e_over else "U",
                            other_segment=b,
                            other_side=s_second,
                        )
                        yield Successor(state, move)


def _cross_moves(p: PData, d: Diagram) -> Iterator[Successor]:
    last = 2 * p.cross
    ends = (0,) if last == 0 else (0, last)
    for e in ends:
        face = d.faces[d.face_of(e, LEFT)]
        head = e == 0
        for b, sb in sorted(face.sides):
            if b == e:
                continue  # the tip across its own segment is an R1 curl on it
            for end_over in (True, False):
                # head -> tail, the head enters the face across b, the tail leaves it
                left_to_right = (sb == RIGHT) if head else (sb == LEFT)
                sign = _crossing_sign(end_over, left_to_right)
                tip: _NewVisit = (0, "O" if end_over else "U", sign)
                crossed: _NewVisit = (0, "U" if end_over else "O", sign)
                if head:
                    inserts = {0: [tip], b: [crossed]}
                else:
                    inserts = {b: [crossed], last: [tip]}
                move = Move("Cross", e, sign=sign, over=tip[1], other_segment=b, other_side=sb)
                yield Successor(_insert(p, inserts), move)


# A cached list is ~70 KiB for a 4-crossing state; 1024 of them cover the states one BFS expands
# (at most 2^Cross(goal)) many times over while keeping the memory of a planner worker bounded.
@lru_cache(maxsize=1024)
def _successors(p: PData) -> tuple[Successor, ...]:
    d = diagram(p)
    return (*_r1_moves(p), *_r2_moves(p, d), *_cross_moves(p, d))


def successors(p: PData) -> list[Successor]:
    """All moves from ``p`` with the state each makes, in a fixed order (R1, R2, Cross).

    Different moves can make the same state (e.g. the head laid over the tail, or the tail over
    the head); they are all listed. Raises :class:`PDataError` if ``p`` cannot be drawn.
    """
    return list(_successors(p))


def successor_states(p: PData) -> list[PData]:
    """The distinct states one move away, in first-seen order."""
    return list(dict.fromkeys(s.state for s in _successors(p)))


def explains(start: PData, end: PData) -> Move | None:
    """The first move taking ``start`` to ``end``, or None when no single move does (a removing move
    when ``end`` has fewer crossings)."""
    if abs(end.cross - start.cross) not in (1, 2):
        return None
    for s in _successors(start) if end.cross > start.cross else _removals(start):
        if s.state == end:
            return s.move
    return None


# ---------------------------------------------------------------------------------------------
# the removing moves: each undoes one adding move


def _without(p: PData, positions: Iterable[int]) -> PData:
    """``p`` with the visits at ``positions`` (whole crossings: both visits) taken out, renumbered."""
    gone = set(positions)
    kept = [pos for pos in range(1, 2 * p.cross + 1) if pos not in gone]
    renumber = {old: new for new, old in enumerate(kept, start=1)}
    return PData(
        tuple(
            _visit(renumber[pos], v.over, renumber[v.partner], v.sign)
            for pos in kept
            for v in (p.visits[pos - 1],)
        )
    )


def _r1_removals(p: PData, d: Diagram) -> Iterator[Successor]:
    """A crossing whose two visits are consecutive (i, i + 1) closes a loop, segment i, that has
    nothing on it; the rest of the rope leaves the crossing by the two other ends, which are
    neighbours there, so one side of the loop bounds a face of its own (a monogon). Straightening
    the curl is R1 backwards: the move names the loop segment and the monogon's side."""
    for v in p.visits:
        if v.partner != v.position + 1:
            continue
        loop = v.position
        side = LEFT if d.faces[d.face_of(loop, LEFT)].sides == ((loop, LEFT),) else RIGHT
        move = Move("R1", loop, side=side, sign=v.sign, over=v.over, remove=True)
        yield Successor(_without(p, (loop, loop + 1)), move)


def _r2_removals(p: PData, d: Diagram) -> Iterator[Successor]:
    """A bigon, a face bounded by two segments a < b that both run between the same two crossings,
    is pulled apart when the piece on a passes over (or under) the piece on b at both crossings.
    The move names the two segments and the sides by which they bound the bigon; ``over`` and
    ``sign`` are those of a's first visit."""
    last = 2 * p.cross
    for face in d.faces:
        if len(face.sides) != 2:
            continue
        (a, sa), (b, sb) = sorted(face.sides)
        if a == b or not (0 < a and b < last):
            continue  # an end segment ends at a tip, not at a crossing
        first, second = p.visits[a - 1], p.visits[a]  # visits a and a + 1 (positions are 1-based)
        if {first.partner, second.partner} != {b, b + 1}:
            continue
        if first.over != second.over:
            continue  # one piece over at one crossing and under at the other: a clasp, not a bigon
        move = Move(
            "R2", a, side=sa, sign=first.sign, over=first.over, other_segment=b, other_side=sb, remove=True
        )
        yield Successor(_without(p, (a, a + 1, b, b + 1)), move)


def _cross_removals(p: PData) -> Iterator[Successor]:
    """A rope tip pulled back across the strand it last crossed: the head's first visit or the
    tail's last one is taken out (when its partner is the next visit along, the tip closes a curl,
    which is R1's). ``other_segment`` is the segment of the crossed strand that ends at the
    crossing; ``over`` is the tip's O/U."""
    last = 2 * p.cross
    if last == 0:
        return
    for tip, e in ((p.visits[0], 0), (p.visits[-1], last)):
        if abs(tip.partner - tip.position) == 1:
            continue
        move = Move("Cross", e, sign=tip.sign, over=tip.over, other_segment=tip.partner - 1, remove=True)
        yield Successor(_without(p, (tip.position, tip.partner)), move)


@lru_cache(maxsize=4096)
def _removals(p: PData) -> tuple[Successor, ...]:
    d = diagram(p)
    return (*_r1_removals(p, d), *_r2_removals(p, d), *_cross_removals(p))


def removals(p: PData) -> list[Successor]:
    """All removing moves from ``p`` (``move.remove`` is True) with the state each leaves, in a fixed
    order (R1, R2, Cross). Each undoes an adding move: ``s`` is among the states :func:`removals`
    of ``s'`` lists exactly when ``s'`` is among :func:`successor_states` of ``s``, with a move of
    the same kind both ways (tests/test_moves.py checks this for every state up to 4 crossings)."""
    return list(_removals(p))


def neighbours(p: PData, max_cross: int | None = None) -> list[Successor]:
    """Adding moves (those to at most ``max_cross`` crossings when given) and then removing moves."""
    out = list(_removals(p))
    if max_cross is not None and p.cross + 1 == max_cross:
        out[:0] = _one_more(p)  # an R2 adds two crossings: none is allowed, and none is computed
    elif max_cross is None or p.cross < max_cross:
        out[:0] = [s for s in _successors(p) if max_cross is None or s.state.cross <= max_cross]
    return out


@lru_cache(maxsize=4096)
def _one_more(p: PData) -> tuple[Successor, ...]:
    """The adding moves that add one crossing (R1 and Cross), in the order :func:`_successors` has them;
    R2 moves, most of the work of :func:`_successors`, are left out."""
    return (*_r1_moves(p), *_cross_moves(p, diagram(p)))


# ---------------------------------------------------------------------------------------------
# enumeration and BFS plans


def enumerate_states(max_crosses: int) -> dict[int, list[PData]]:
    """Every state reachable from the empty rope with at most ``max_crosses`` crossings, by moves.

    Returns ``{cross: states sorted by key}`` for cross = 0..max_crosses.
    """
    if max_crosses < 0:
        raise ValueError(f"max_crosses must be >= 0, got {max_crosses}")
    layers: dict[int, set[PData]] = {c: set() for c in range(max_crosses + 1)}
    layers[0].add(EMPTY)
    # moves only add crossings, so expanding layer by layer visits every state once
    for c in range(max_crosses):
        for p in layers[c]:
            for s in _successors(p):
                if s.state.cross <= max_crosses:
                    layers[s.state.cross].add(s.state)
    return {c: sorted(layers[c], key=lambda p: p.key) for c in layers}


def sub_states(goal: PData) -> frozenset[PData]:
    """Every state obtained from ``goal`` by deleting some of its crossings (both visits).

    Moves insert visits and keep the old crossings untouched, so a state can lead to ``goal`` only
    if it is one of these: the BFS explores nothing else.
    """
    crossings = goal.crossings()
    n = len(crossings)
    out = set()
    for mask in range(1 << n):
        deleted = (pos for i, (o, u, _) in enumerate(crossings) if mask >> i & 1 for pos in (o, u))
        out.add(_without(goal, deleted))
    return frozenset(out)


@lru_cache(maxsize=64)
def _allowed_states(goals: frozenset[PData]) -> frozenset[PData]:
    """The union of the goals' :func:`sub_states`: the states a plan toward them may pass. Kept per goal
    set, since a search asks for plans from every state it reaches toward the same goals (a knot
    goal's 48 states of 6 crossings make 3,072 sub-state computations a query otherwise)."""
    return frozenset().union(*(sub_states(goal) for goal in goals))


def _goal_set(start: PData, goals: Iterable[PData], limit: int) -> frozenset[PData]:
    """The goals as a set, after the checks every plan search makes (ValueError / PDataError)."""
    if limit < 1:
        raise ValueError(f"limit must be >= 1, got {limit}")
    targets = frozenset(goals)
    if not targets:
        raise ValueError("give at least one goal state")
    for goal in sorted(targets, key=lambda p: p.key):
        diagram(goal)  # a goal no rope can have is an input error, not "unreachable"
    return targets


def plans(start: PData, goal: PData, limit: int = DEFAULT_PLAN_LIMIT) -> list[Plan]:
    """Move sequences from ``start`` to ``goal``, shortest first, at most ``limit`` of them.

    BFS over moves that prunes every state with ``Cross >= Cross(goal)`` other than the goal; the
    comparison uses absolute crossing counts, so it works from any start state. Plans differ in
    their state sequences; where several moves make the same step, the plan names the first (all
    of them are in :func:`successors`). An unreachable goal gives ``[]``.
    """
    return plans_to_any(start, [goal], limit)


def plans_to_any(start: PData, goals: Iterable[PData], limit: int = DEFAULT_PLAN_LIMIT) -> list[Plan]:
    """Move sequences from ``start`` to any of ``goals`` (e.g. every state that ties a knot), shortest first.

    One BFS over the union of the goals' sub-states; a plan stops at the first goal it reaches. With one
    goal this is :func:`plans`.
    """
    targets = _goal_set(start, goals, limit)
    if start in targets:
        return [Plan([start], [])]
    reachable = frozenset(goal for goal in targets if goal.cross > start.cross)
    allowed = _allowed_states(reachable)
    if start not in allowed:
        return []
    # forward: the part of the move graph between start and the goals
    children: dict[PData, list[tuple[PData, Move]]] = {}
    frontier = [start]
    while frontier:
        next_frontier: list[PData] = []
        for u in frontier:
            if u in children or u in targets:
                continue
            edges: dict[PData, Move] = {}
            for s in _successors(u):
                if s.state in allowed and s.state not in edges:
                    edges[s.state] = s.move
            children[u] = list(edges.items())
            next_frontier.extend(edges)
        frontier = next_frontier
    # backward: for each state, the plan lengths it has to a goal (moves add 1 or 2 crossings,
    # so lengths vary); states in decreasing crossing count form a topological order
    lengths: dict[PData, frozenset[int]] = {goal: frozenset({0}) for goal in reachable}
    for u in sorted(children, key=lambda q: -q.cross):
        acc: set[int] = set()
        for v, _ in children[u]:
            acc.update(n + 1 for n in lengths.get(v, ()))
        if acc:
            lengths[u] = frozenset(acc)
    out: list[Plan] = []
    for total in sorted(lengths.get(start, ())):
        for states, moves in _paths(start, total, children, lengths):
            out.append(Plan(states, moves))
            if len(out) >= limit:
                return out
    return out


def plans_both_ways(
    start: PData, goals: Iterable[PData], limit: int = DEFAULT_PLAN_LIMIT, max_cross: int | None = None
) -> list[Plan]:
    """The shortest move sequences from ``start`` to any of ``goals`` with adding and removing moves.

    Every state on the way has at most ``max_cross`` crossings (default: the most of the start and the
    goals), so untying (a goal of fewer crossings, or ``[]``) and tying again (a goal elsewhere) both
    work, and a plan may take some crossings out and add others. Only plans of the least length are
    returned (up to ``limit``, in a fixed order; each a different state sequence): unlike
    :func:`plans_to_any` the move graph has cycles here, so "all plans, shortest first" has no end.

    The moves both ways make an undirected graph (every removing move undoes an adding move, and the
    reverse: tested on every state up to 4 crossings), so the search grows breadth-first layers from
    the start and from the goals at once, always the side with the smaller frontier, until they meet.
    Their meeting layer then holds one state of every shortest plan: the plans are the shortest paths
    from the start to a meeting state followed by those from there to a goal. Searching from both ends
    keeps a 6-move plan between 6-crossing states (a granny to a square) to two layers of about three
    moves each, where one search from the start had to reach six. The goals' side is kept between
    queries and grown in preference (:data:`GOAL_SIDE_WEIGHT`). An unreachable goal gives ``[]``.
    """
    targets = _goal_set(start, goals, limit)
    if start in targets:
        return [Plan([start], [])]
    top_cross = max(start.cross, max(goal.cross for goal in targets)) if max_cross is None else max_cross
    ends = sorted((goal for goal in targets if goal.cross <= top_cross), key=lambda p: p.key)
    if not ends or start.cross > top_cross:
        return []
    ahead, behind = _Layers([start], top_cross), _goal_layers(tuple(ends), top_cross)
    meeting = [start]  # when the goals' layers, kept from an earlier query, already hold the start
    while start not in behind.depth:
        start_side = GOAL_SIDE_WEIGHT * len(ahead.frontier) <= len(behind.frontier)
        grown, other = (ahead, behind) if start_side else (behind, ahead)
        if not grown.grow():
            return []  # one side ran dry before meeting the other: no plan within the crossing bound
        meeting = [v for v in grown.frontier if v in other.depth]
        if meeting:
            break
    out: list[Plan] = []
    for states in _shortest_paths(start, meeting, ahead, behind):
        out.append(Plan(states, [_move(u, v, top_cross) for u, v in itertools.pairwise(states)]))
        if len(out) >= limit:
            break
    return out


def _shortest_paths(
    start: PData, meeting: list[PData], ahead: _Layers, behind: _Layers
) -> Iterator[list[PData]]:
    """Every shortest path from ``start`` through a meeting state to a goal, in the order of their state
    keys (the first state that differs decides): the same order whichever layer the two sides met in,
    so an answer does not depend on what earlier queries grew."""
    after: dict[PData, list[PData]] = {}  # each state's next states on shortest paths
    todo, seen = list(meeting), set(meeting)
    while todo:  # back from the meeting states to the start
        v = todo.pop()
        for u, _ in ahead.parents.get(v, ()):
            after.setdefault(u, []).append(v)
            if u not in seen:
                seen.add(u)
                todo.append(u)
    todo = list(meeting)
    while todo:  # on from the meeting states to the goals
        v = todo.pop()
        for w, _ in behind.parents.get(v, ()):
            if v not in after or w not in after[v]:
                after.setdefault(v, []).append(w)
                todo.append(w)
    for nexts in after.values():
        nexts.sort(key=lambda p: p.key)

    def walk(path: list[PData]) -> Iterator[list[PData]]:
        nexts = after.get(path[-1])
        if not nexts:
            yield path
            return
        for v in nexts:
            yield from walk([*path, v])

    yield from walk([start])


@lru_cache(maxsize=8)
def _goal_layers(ends: tuple[PData, ...], top_cross: int) -> _Layers:
    """The layers grown from a goal set, kept between queries: a search asks for plans to the same goals
    from every state it reaches, and the goals' side is where the layers are widest. Each query checks
    every layer it grows against the whole of the other side, so layers grown by an earlier query keep
    the plans exact (the meeting layer still holds one state of every shortest plan)."""
    return _Layers(list(ends), top_cross)


class _Layers:
    """Breadth-first layers over the moves both ways from ``roots``, within ``top_cross`` crossings:
    each state's depth, the states of the last layer and, per state, its neighbours one layer nearer
    the roots (with the move from each of them, in the order :func:`neighbours` gives)."""

    def __init__(self, roots: list[PData], top_cross: int) -> None:
        self.top_cross = top_cross
        self.depth = {root: 0 for root in roots}
        self.frontier = list(roots)
        self.parents: dict[PData, list[tuple[PData, Move]]] = {}

    def grow(self) -> bool:
        """Add the next layer; False when it is empty."""
        if not self.frontier:
            return False
        d = self.depth[self.frontier[0]] + 1
        layer: list[PData] = []
        for u in self.frontier:
            for s in neighbours(u, self.top_cross):
                v = s.state
                if v not in self.depth:
                    self.depth[v] = d
                    layer.append(v)
                    self.parents[v] = []
                if self.depth[v] == d and all(w != u for w, _ in self.parents[v]):
                    self.parents[v].append((u, s.move))
        self.frontier = layer
        return bool(layer)


def _move(u: PData, v: PData, top_cross: int) -> Move:
    """The first move that takes ``u`` to its neighbour ``v`` (as :func:`neighbours` lists them)."""
    return next(s.move for s in neighbours(u, top_cross) if s.state == v)


def _paths(
    u: PData,
    remaining: int,
    children: dict[PData, list[tuple[PData, Move]]],
    lengths: dict[PData, frozenset[int]],
) -> Iterator[tuple[list[PData], list[Move]]]:
    """Paths of exactly ``remaining`` moves from ``u`` to the goal (depth-first, fixed order)."""
    if remaining == 0:
        yield [u], []
        return
    for v, move in children.get(u, ()):
        if remaining - 1 in lengths.get(v, ()):
            for states, moves in _paths(v, remaining - 1, children, lengths):
                yield [u, *states], [move, *moves]


def parse_state(value: str | Sequence[Any] | PData, what: str = "state") -> PData:
    """Parse P-data and check that a rope can have it; errors name ``what`` was wrong."""
    try:
        p = parse_p_data(value)
        diagram(p)
    except PDataError as exc:
        raise PDataError(f"{what}: {exc}") from None
    return p
