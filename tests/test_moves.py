"""Planar diagram faces, R1 / R2 / Cross successors (checked against drawn ropes read by Top),
enumeration counts, BFS plans, and the mirror / reverse symmetries."""

from __future__ import annotations

import itertools
import json
from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twisted.diagram import SegmentSide, diagram, drawable
from twisted.moves import (
    Move,
    Plan,
    enumerate_states,
    explains,
    neighbours,
    plans,
    plans_both_ways,
    removals,
    sub_states,
    successor_states,
    successors,
)
from twisted.topology import EMPTY, PData, PDataError, Visit, parse_p_data, top

HI, MID, LO = 0.03, 0.02, 0.0  # heights (m) of drawn strands: HI passes over MID passes over LO

CURL_RIGHT = parse_p_data('[[1,"O",2,"+"],[2,"U",1,"+"]]')


def drawn(*xyz: tuple[float, float, float]) -> PData:
    """Top of a hand-drawn rope (points head first)."""
    return top(np.array(xyz, dtype=float))


def moves_to(start: PData, end: PData) -> list[Move]:
    return [s.move for s in successors(start) if s.state == end]


@pytest.fixture(scope="module")
def states_to_3() -> dict[int, list[PData]]:
    return enumerate_states(3)


# --------------------------------------------------------------------------------------------
# the planar diagram


def test_empty_rope_has_one_face_around_the_whole_rope() -> None:
    d = diagram(EMPTY)
    assert [f.sides for f in d.faces] == [(SegmentSide(0, "L"), SegmentSide(0, "R"))]
    assert (d.n_vertices, d.n_edges, len(d.faces)) == (2, 1, 1)
    assert d.euler_characteristic == 2


def test_curl_faces_the_monogon_is_on_the_side_the_curl_turns_to() -> None:
    """A clockwise curl (drawn below, the rope walking east) encloses a monogon on the right of
    its loop segment; the counter-clockwise one on the left.

        head ---->--+-->--.            head ---->--+-->--.   (loop above)
                    |      \\                       |      /
                    ^ (1,R) )                       v (1,L)
                     `-----'   -> tail               ...
    """
    right = drawn((0, 0, HI), (2, 0, HI), (2.5, -1, LO), (1.5, -1.5, LO), (1, 1, LO), (3, 1, LO))
    left = drawn((0, 0, HI), (2, 0, HI), (2.5, 1, LO), (1.5, 1.5, LO), (1, -1, LO), (3, -1, LO))
    assert right == CURL_RIGHT
    faces_right = [f.sides for f in diagram(right).faces]
    faces_left = [f.sides for f in diagram(left).faces]
    assert ((SegmentSide(1, "R"),)) in faces_right
    assert ((SegmentSide(1, "L"),)) in faces_left
    # the other face is the outside: both end segments lie inside it, and the loop's outer side
    outside = [f for f in diagram(right).faces if len(f.sides) > 1][0]
    assert set(outside.sides) == {(0, "L"), (0, "R"), (1, "L"), (2, "L"), (2, "R")}


def test_every_reached_state_is_planar_with_n_plus_one_faces(states_to_3: dict[int, list[PData]]) -> None:
    for n, layer in states_to_3.items():
        for p in layer:
            d = diagram(p)
            assert d.n_vertices - d.n_edges + len(d.faces) == 2
            assert len(d.faces) == n + 1
            every_side = [s for f in d.faces for s in f.sides]
            assert sorted(every_side) == [(k, side) for k in range(2 * n + 1) for side in "LR"]
            # an end segment lies inside one face: its two sides bound the same one
            assert d.face_of(0, "L") == d.face_of(0, "R")
            assert d.face_of(2 * n, "L") == d.face_of(2 * n, "R")


def test_p_data_no_rope_can_have_is_refused() -> None:
    """Visits 1-2-1-2 with equal signs: the rope between visits 1 and 3 closes a loop through
    crossing A; the tail leaves A on one side of that loop and must cross it at B back to the
    other side, which forces B's sign opposite to A's. The rotation system has genus 1."""
    virtual = parse_p_data('[[1,"O",3,"+"],[2,"O",4,"+"],[3,"U",1,"+"],[4,"U",2,"+"]]')
    with pytest.raises(PDataError, match="cannot be drawn in the plane"):
        diagram(virtual)
    assert successors(parse_p_data('[[1,"O",3,"+"],[2,"O",4,"-"],[3,"U",1,"+"],[4,"U",2,"-"]]'))


# --------------------------------------------------------------------------------------------
# each move against a drawn rope


def test_r1_right_and_left_curls_match_their_drawings() -> None:
    right = drawn((0, 0, HI), (2, 0, HI), (2.5, -1, LO), (1.5, -1.5, LO), (1, 1, LO), (3, 1, LO))
    left = drawn((0, 0, HI), (2, 0, HI), (2.5, 1, LO), (1.5, 1.5, LO), (1, -1, LO), (3, -1, LO))
    assert moves_to(EMPTY, right) == [Move("R1", 0, side="R", sign="+", over="O")]
    assert moves_to(EMPTY, left) == [Move("R1", 0, side="L", sign="-", over="O")]


def test_r1_gives_four_states_per_segment() -> None:
    for p in (EMPTY, CURL_RIGHT):
        r1 = [s for s in successors(p) if s.move.kind == "R1"]
        assert len(r1) == 4 * (2 * p.cross + 1)
        for k in range(2 * p.cross + 1):
            assert len({s.state for s in r1 if s.move.segment == k}) == 4


def test_r2_hairpin_matches_its_drawing() -> None:
    """The rope runs east (piece E), turns left and comes back west (piece F); a finger of E is
    pushed north over F. E's left faces F's left: the crossings nest (E meets 1 then 2, F meets
    2 then 1).

         0 <--------F--+---+-----.
                       |   |     |
         head ---E-----'   `---->'     E over F
    """
    hairpin = drawn(
        (0, 0, HI), (1, 0, HI), (1.2, 1.5, HI), (1.6, 1.5, HI), (1.8, 0, HI), (4, 0, LO), (4, 1, LO),
        (0, 1, LO),
    )  # fmt: skip
    assert hairpin.to_list() == [[1, "O", 4, "+"], [2, "O", 3, "-"], [3, "U", 2, "-"], [4, "U", 1, "+"]]
    assert moves_to(EMPTY, hairpin) == [Move("R2", 0, "L", "+", "O", 0, "L")]


def test_r2_parallel_pieces_the_reference_did_not_have() -> None:
    """Why we find 8 R2 moves from the empty rope where the reference found 4.

    The reference paired a piece only with pieces seen from the same side (the hairpin above).
    But the empty rope's single face touches both sides of the rope, so a piece's left side can
    meet a later piece's right side: draw the rope going east (E), round the head tip, and east
    again above it (F); E's left faces F's right, the two run parallel, and pushing a finger of E
    over F gives crossings met in the SAME order along both (visits 1-2-1-2, opposite signs):

           .----------F--+---+---->  tail
           |             |   |
           |    head --E-'   `--.
           |                    |
           `--------------------'
    """
    parallel = drawn(
        (0, 0, HI), (1, 0, HI), (1.2, 2.5, HI), (1.6, 2.5, HI), (1.8, 0, HI), (3, 0, LO), (3, -1, LO),
        (-1, -1, LO), (-1, 2, LO), (4, 2, LO),
    )  # fmt: skip
    assert parallel.to_list() == [[1, "O", 3, "-"], [2, "O", 4, "+"], [3, "U", 1, "-"], [4, "U", 2, "+"]]
    assert moves_to(EMPTY, parallel) == [Move("R2", 0, "L", "-", "O", 0, "R")]
    r2 = [s for s in successors(EMPTY) if s.move.kind == "R2"]
    assert len(r2) == 8 and len({s.state for s in r2}) == 8
    hairpins = [s for s in r2 if s.move.side == s.move.other_side]
    assert len(hairpins) == 4  # the reference's four
    # each parallel state is a genuine 2-crossing state (the enumeration reaches it anyway)
    assert all(s.state in enumerate_states(2)[2] for s in r2)


def test_r2_needs_no_common_face_for_the_rope_ends() -> None:
    """The reference allowed R2 only when both rope ends lay in one face. Here the tail has
    crossed into the curl (ends in different faces) and the head piece can still be folded into
    a hairpin over itself, out in the open: a real R2 the reference would have refused.

        hairpin at the head         curl with the tail tucked in
         <--.-.--.                 ---->----+-->--.
            | | '-------------->            |  <--+--  tail inside
            '-'                             `-----'
    """
    curl_tail_in = [
        (0, 0, MID), (2, 0, MID), (2.5, -1, LO), (1.5, -1.5, LO), (1, 1, LO), (3, 1, LO), (3, -0.5, HI),
        (1.8, -0.7, HI),
    ]  # fmt: skip
    start = drawn(*curl_tail_in)
    d = diagram(start)
    head_face, tail_face = d.end_faces()
    assert head_face != tail_face
    hairpin = [(-0.5, 0.5, HI), (-0.8, 0.5, HI), (-0.9, -0.5, HI), (-1.2, -0.5, HI), (-1.3, 0.5, HI)]
    end = drawn(*hairpin, (-2, 0.5, HI), (-2, 0, MID), *curl_tail_in)
    assert moves_to(start, end) == [Move("R2", 0, "L", "+", "O", 0, "L")]


def test_cross_tail_and_head_match_their_drawings() -> None:
    """From the right curl: the tail laid over segment 0 coming from its left, and the head
    extended across the tail segment. Head over tail and tail under head are one state, so each
    drawing is explained by two moves."""
    tail_over = drawn(
        (0, 0, LO), (2, 0, 0.04), (2.5, -1, LO), (1.5, -1.5, LO), (1, 1, HI), (0.5, 1, HI), (0.5, -0.5, HI)
    )
    assert moves_to(CURL_RIGHT, tail_over) == [
        Move("Cross", 0, sign="+", over="U", other_segment=2, other_side="L"),
        Move("Cross", 2, sign="+", over="O", other_segment=0, other_side="L"),
    ]
    head_over = drawn(
        (2, 0.5, HI), (2, 1.5, HI), (0, 1.5, HI), (0, 0, HI), (2, 0, HI), (2.5, -1, LO), (1.5, -1.5, LO),
        (1, 1, LO), (3, 1, LO),
    )  # fmt: skip
    assert moves_to(CURL_RIGHT, head_over)[0] == Move("Cross", 0, sign="-", over="O", other_segment=2,
                                                      other_side="L")  # fmt: skip


def test_cross_puts_the_new_visit_at_the_tip() -> None:
    for s in successors(CURL_RIGHT):
        if s.move.kind == "Cross":
            tip = 1 if s.move.segment == 0 else 4
            assert s.state.visits[tip - 1].over == s.move.over
            assert s.state.visits[tip - 1].sign == s.move.sign


def test_successor_counts_from_empty_and_one_crossing() -> None:
    """From the empty rope: 4 R1 + 8 R2 (no Cross: the tip across its own, only, segment is a
    curl). From the right curl (faces: outside {1L, 0R, 0L, 2L, 2R}, monogon {1R}):
      R1    4 x 3 segments                                              = 12
      R2    outside: 15 pairs of its 5 sides (with repeats) + the two    = 34
            end segments' L/R pairs counted in both assignments, x 2 on top
            monogon: 1R with itself, x 2                                 =  2
      Cross head: 1L, 2L, 2R x over/under = 6; tail: 1L, 0L, 0R x 2       = 12
    60 moves, 52 distinct states: head-over-tail equals tail-under-head (4 states), a curl
    before the curl equals one after it, and so on. The reference had 40 moves / 36 states; its
    enumeration counts are still ours (next test), because Cross alone reaches every state."""
    kinds = Counter(s.move.kind for s in successors(EMPTY))
    assert kinds == {"R1": 4, "R2": 8}
    assert len(successor_states(EMPTY)) == 12
    succ = successors(CURL_RIGHT)
    assert Counter(s.move.kind for s in succ) == {"R1": 12, "R2": 36, "Cross": 12}
    assert len(successor_states(CURL_RIGHT)) == 52


# --------------------------------------------------------------------------------------------
# enumeration


def _all_p_data(n: int) -> list[PData]:
    """Every valid P-data list with n crossings, drawable or not."""

    def pairings(items: list[int]):  # type: ignore[no-untyped-def]
        if not items:
            yield []
            return
        for i in range(1, len(items)):
            for rest in pairings(items[1:i] + items[i + 1 :]):
                yield [(items[0], items[i])] + rest

    out = []
    for pairs in pairings(list(range(1, 2 * n + 1))):
        for overs in itertools.product((True, False), repeat=n):
            for signs in itertools.product("+-", repeat=n):
                visits = []
                for (a, b), a_over, sign in zip(pairs, overs, signs, strict=True):
                    visits += [
                        Visit(a, "O" if a_over else "U", b, sign),
                        Visit(b, "U" if a_over else "O", a, sign),
                    ]
                out.append(PData(tuple(sorted(visits))))
    return out


def test_enumeration_counts_match_the_reference() -> None:
    layers = enumerate_states(4)
    assert [len(layers[n]) for n in range(5)] == [1, 4, 40, 528, 7968]
    assert all(layer == sorted(layer, key=lambda p: p.key) for layer in layers.values())


@pytest.mark.parametrize("n", [1, 2, 3])
def test_enumeration_is_exactly_the_planar_p_data(n: int, states_to_3: dict[int, list[PData]]) -> None:
    """Moves from the empty rope reach every drawable P-data and nothing else (brute force)."""
    planar = {p for p in _all_p_data(n) if drawable(p)}
    assert set(states_to_3[n]) == planar


# --------------------------------------------------------------------------------------------
# BFS plans


# the overhand knot (an open trefoil): visits 1..6 alternate O/U, crossings 1-4, 2-5, 3-6
GOAL_3 = parse_p_data('[[1,"O",4,"+"],[2,"U",5,"+"],[3,"O",6,"+"],[4,"U",1,"+"],[5,"O",2,"+"],[6,"U",3,"+"]]')
# a curl followed by a bigon: reached by R1 + R2 (2 moves) or by three 1-crossing moves
GOAL_MIXED = parse_p_data(
    '[[1,"O",2,"+"],[2,"U",1,"+"],[3,"U",6,"+"],[4,"U",5,"-"],[5,"O",4,"-"],[6,"O",3,"+"]]'
)


def _check_plan(plan: Plan, start: PData, goal: PData) -> None:
    assert plan.states[0] == start and plan.states[-1] == goal
    assert len(plan.states) == len(plan.moves) + 1
    for before, after, move in zip(plan.states[:-1], plan.states[1:], plan.moves, strict=True):
        assert after in {s.state for s in successors(before) if s.move == move}
        assert after.cross > before.cross
    assert all(s.cross < goal.cross for s in plan.states[:-1])


@pytest.mark.parametrize("goal", [GOAL_3, GOAL_MIXED])
def test_plans_from_the_empty_rope_are_valid_shortest_first(goal: PData) -> None:
    found = plans(EMPTY, goal, limit=1000)
    assert found
    for plan in found:
        _check_plan(plan, EMPTY, goal)
    lengths = [p.length for p in found]
    assert lengths == sorted(lengths)
    assert len({tuple(p.states) for p in found}) == len(found)
    assert len(plans(EMPTY, goal, limit=3)) == 3
    assert plans(EMPTY, goal, limit=3) == found[:3]


def test_overhand_knot_plans_and_a_mixed_length_goal() -> None:
    # the trefoil: a curl then two tip crossings, four ways
    assert [p.length for p in plans(EMPTY, GOAL_3, limit=1000)] == [3, 3, 3, 3]
    assert [p.moves[0].kind for p in plans(EMPTY, GOAL_3)] == ["R1"] * 4
    mixed = plans(EMPTY, GOAL_MIXED, limit=1000)
    assert [p.length for p in mixed] == [2, 2, 3, 3, 3, 3, 3, 3]
    assert {m.kind for m in mixed[0].moves} == {"R1", "R2"}


@pytest.mark.parametrize("goal", [GOAL_3, GOAL_MIXED])
def test_plans_from_every_intermediate_state(goal: PData) -> None:
    """The reference compared a relative depth with the goal's absolute crossing count, so from a
    reached 1- or 2-crossing state it pruned everything and found no plan. Every state on a plan
    to a 3-crossing goal must itself have a plan to that goal, starting from it."""
    crossings_seen = set()
    for plan in plans(EMPTY, goal, limit=1000):
        for i, mid in enumerate(plan.states[1:-1], start=1):
            crossings_seen.add(mid.cross)
            from_mid = plans(mid, goal, limit=1000)
            assert from_mid, f"no plan from {mid} (cross {mid.cross})"
            for p in from_mid:
                _check_plan(p, mid, goal)
            # the rest of the original plan is one of them
            assert plan.states[i:] in [p.states for p in from_mid]
    assert crossings_seen == {1, 2}


def test_plans_are_all_state_sequences_bfs_would_find() -> None:
    """Against an unpruned depth-first search (no sub-state pruning) on a 3-crossing goal."""

    def all_paths(u: PData) -> list[list[PData]]:
        if u == GOAL_3:
            return [[u]]
        if u.cross >= GOAL_3.cross:
            return []
        return [[u, *rest] for v in successor_states(u) for rest in all_paths(v)]

    expected = sorted(all_paths(EMPTY), key=len)
    assert len(expected) == 4
    got = plans(EMPTY, GOAL_3, limit=10_000)

    def keys(seqs: list[list[PData]]) -> list[list[str]]:
        return sorted([s.key for s in seq] for seq in seqs)

    assert keys([p.states for p in got]) == keys(expected)
    assert [p.length for p in got] == [len(s) - 1 for s in expected]


def test_unreachable_and_trivial_goals() -> None:
    minus_curl = parse_p_data('[[1,"O",2,"-"],[2,"U",1,"-"]]')
    two_plus = parse_p_data('[[1,"O",2,"+"],[2,"U",1,"+"],[3,"O",4,"+"],[4,"U",3,"+"]]')
    assert plans(minus_curl, two_plus) == []  # a crossing is never removed
    assert plans(two_plus, CURL_RIGHT) == []  # fewer crossings
    assert plans(CURL_RIGHT, CURL_RIGHT) == [Plan([CURL_RIGHT], [])]
    assert plans(CURL_RIGHT, two_plus)  # reachable
    with pytest.raises(ValueError):
        plans(EMPTY, CURL_RIGHT, limit=0)


def test_sub_states_are_the_goal_with_crossings_deleted() -> None:
    subs = sub_states(GOAL_3)
    # 2^3 subsets of crossings; keeping crossing 1 alone or 3 alone gives the same curl
    assert Counter(p.cross for p in subs) == {0: 1, 1: 2, 2: 3, 3: 1}
    assert EMPTY in subs and GOAL_3 in subs
    # deleting the middle crossing leaves the undrawable 1-2-1-2: sub-states are only a necessary
    # condition, the BFS itself only ever meets drawable states
    virtual = parse_p_data('[[1,"O",3,"+"],[2,"O",4,"+"],[3,"U",1,"+"],[4,"U",2,"+"]]')
    assert [p for p in subs if not drawable(p)] == [virtual]


def test_plan_to_dict_is_json_and_round_trips() -> None:
    plan = plans(EMPTY, GOAL_3)[0]
    text = json.dumps(plan.to_dict())
    back = Plan.from_dict(json.loads(text))
    assert back == plan
    assert json.loads(text)["states"][0] == []


def test_explains() -> None:
    assert explains(EMPTY, CURL_RIGHT) == Move("R1", 0, side="R", sign="+", over="O")
    assert explains(EMPTY, GOAL_3) is None
    assert explains(CURL_RIGHT, EMPTY) == Move("R1", 1, side="R", sign="+", over="O", remove=True)
    assert explains(GOAL_3, EMPTY) is None


# --------------------------------------------------------------------------------------------
# properties over reached states

_STATES = [p for layer in enumerate_states(3).values() for p in layer]
some_state = st.sampled_from(_STATES)


@settings(max_examples=60, deadline=None)
@given(some_state)
def test_every_successor_is_valid_p_data_with_more_crossings(p: PData) -> None:
    for s in successors(p):
        assert parse_p_data(s.state.to_list()) == s.state
        assert drawable(s.state)
        added = 2 if s.move.kind == "R2" else 1
        assert s.state.cross == p.cross + added
        # the old crossings are all still there
        assert p in sub_states(s.state)


@settings(max_examples=60, deadline=None)
@given(some_state)
def test_mirror_and_reverse_commute_with_successors(p: PData) -> None:
    assert set(successor_states(p.mirror())) == {t.mirror() for t in successor_states(p)}
    assert set(successor_states(p.reverse())) == {t.reverse() for t in successor_states(p)}


# --------------------------------------------------------------------------------------------
# removing moves: the inverse of each adding move

HAIRPIN = parse_p_data('[[1,"O",4,"+"],[2,"O",3,"-"],[3,"U",2,"-"],[4,"U",1,"+"]]')


@pytest.fixture(scope="module")
def states_to_4() -> dict[int, list[PData]]:
    return enumerate_states(4)


def test_removals_are_exactly_the_inverse_moves_up_to_4_crossings(
    states_to_4: dict[int, list[PData]],
) -> None:
    """For every state s' of up to 4 crossings, the (state, kind) pairs its removing moves reach are
    exactly the (s, kind) with an adding move of that kind from s to s', found independently by
    running the adding moves of every state with 1 or 2 crossings fewer: s -> m -> s' -> m^-1 -> s,
    and every removing move is undone by an adding move of its kind."""
    made_by: dict[PData, set[tuple[PData, str]]] = {}
    for c in range(4):
        for s in states_to_4[c]:
            for succ in successors(s):
                if succ.state.cross <= 4:
                    made_by.setdefault(succ.state, set()).add((s, succ.move.kind))
    for c in range(5):
        for p in states_to_4[c]:
            undone = {(r.state, r.move.kind) for r in removals(p)}
            assert undone == made_by.get(p, set()), p.key


def test_removal_counts_per_crossing_level(states_to_4: dict[int, list[PData]]) -> None:
    """Removing moves per level (R1, R2, Cross), and the distinct (s', s) pairs they make, which
    equal the distinct (s, s') pairs of the adding moves into that level (counted independently from
    the states below): 4, 80, 1,460 and 26,564 pairs into 1..4 crossings."""
    counts = {}
    for c in range(1, 5):
        kinds = Counter(r.move.kind for p in states_to_4[c] for r in removals(p))
        pairs = sum(len({r.state for r in removals(p)}) for p in states_to_4[c])
        forward = sum(
            len({s.state for s in successors(q) if s.state.cross == c})
            for below in (c - 1, c - 2)
            if below >= 0
            for q in states_to_4[below]
        )
        assert pairs == forward
        counts[c] = (kinds["R1"], kinds["R2"], kinds["Cross"], pairs)
    assert counts == {
        1: (4, 0, 0, 4),
        2: (48, 8, 48, 80),
        3: (800, 144, 736, 1460),
        4: (14784, 2736, 11712, 26564),
    }
    assert removals(EMPTY) == []


def test_removals_from_a_curl_and_a_hairpin() -> None:
    """The right curl: only its curl straightened (segment 1 is the loop, monogon on its right).
    The hairpin R2 of the empty rope (visits 1-4 and 2-3): the inner loop 2-3 is a curl (R1), the
    bigon between segments 1 and 3 pulls apart (R2), and the head and the tail can each be pulled
    back across the other end (Cross, twice): 4 removing moves."""
    assert [str(r.move) for r in removals(CURL_RIGHT)] == ["R1^-1(segment=1, side=R, over=O, sign=+)"]
    assert [r.state for r in removals(CURL_RIGHT)] == [EMPTY]
    found = removals(HAIRPIN)
    assert [r.move.kind for r in found] == ["R1", "R2", "Cross", "Cross"]
    assert all(r.move.remove for r in found)
    assert found[1].state == EMPTY
    assert found[1].move == Move(
        "R2", 1, side="R", sign="+", over="O", other_segment=3, other_side="R", remove=True
    )
    assert {r.state.cross for r in found} == {0, 1}
    assert HAIRPIN in successor_states(EMPTY)


@settings(max_examples=60, deadline=None)
@given(some_state)
def test_r1_removal_names_the_curl_it_straightens(p: PData) -> None:
    """An R1 curl made on segment k (side, sign, over) is straightened by the removing R1 on its
    loop, segment k + 1 of the new state, with the same side, sign and over."""
    for s in successors(p):
        if s.move.kind != "R1":
            continue
        back = {
            (r.move.segment, r.move.side, r.move.sign, r.move.over) for r in removals(s.state) if r.state == p
        }
        assert (s.move.segment + 1, s.move.side, s.move.sign, s.move.over) in back


def test_move_dicts_say_which_way() -> None:
    undo = removals(CURL_RIGHT)[0].move
    assert undo.to_dict()["remove"] is True and Move.from_dict(undo.to_dict()) == undo
    add = successors(EMPTY)[0].move
    assert "remove" not in add.to_dict() and not Move.from_dict(add.to_dict()).remove


def _check_both_ways_plan(plan: Plan, start: PData, goals: set[PData]) -> None:
    assert plan.states[0] == start and plan.states[-1] in goals
    assert not any(s in goals for s in plan.states[:-1])
    for before, after, move in zip(plan.states[:-1], plan.states[1:], plan.moves, strict=True):
        assert after in {s.state for s in neighbours(before) if s.move == move}
        assert (after.cross < before.cross) == move.remove


def _distance(start: PData, goals: set[PData], top: int) -> int:
    """Unpruned BFS over adding and removing moves (at most ``top`` crossings)."""
    seen, frontier, d = {start}, [start], 0
    while frontier:
        if any(p in goals for p in frontier):
            return d
        d += 1
        nxt = []
        for u in frontier:
            for s in neighbours(u, top):
                if s.state not in seen:
                    seen.add(s.state)
                    nxt.append(s.state)
        frontier = nxt
    return -1


def test_untie_plans_from_every_3_crossing_state(states_to_3: dict[int, list[PData]]) -> None:
    """From every 3-crossing state there is a shortest plan to the straight rope; its length is the
    unpruned BFS distance (checked on every 11th state), and it removes crossings only."""
    lengths = Counter()
    for i, p in enumerate(states_to_3[3]):
        found = plans_both_ways(p, [EMPTY], limit=10)
        assert found
        for plan in found:
            _check_both_ways_plan(plan, p, {EMPTY})
            assert plan.length == found[0].length
            assert all(m.remove for m in plan.moves)
        assert len({tuple(plan.states) for plan in found}) == len(found)
        if i % 11 == 0:
            assert found[0].length == _distance(p, {EMPTY}, 3)
        lengths[found[0].length] += 1
    assert sum(lengths.values()) == 528 and set(lengths) <= {2, 3}


def test_retie_plans_mix_removing_and_adding_moves() -> None:
    """Overhand (3 crossings) to a figure-eight state (4): the shortest plans take crossings out and
    put others in; a goal below the start (a 2-crossing state) too; the length is the BFS distance."""
    from twisted.goals import knot_goal

    figure_eight = set(knot_goal("figure-eight").states)
    found = plans_both_ways(GOAL_3, figure_eight, limit=20)
    assert found and len(found) == 20
    for plan in found:
        _check_both_ways_plan(plan, GOAL_3, figure_eight)
    assert any(m.remove for m in found[0].moves) and any(not m.remove for m in found[0].moves)
    assert found[0].length == _distance(GOAL_3, figure_eight, 4)
    two = parse_p_data('[[1,"O",2,"-"],[2,"U",1,"-"],[3,"O",4,"-"],[4,"U",3,"-"]]')
    down = plans_both_ways(GOAL_3, [two], limit=5)
    assert down and down[0].length == _distance(GOAL_3, {two}, 3)
    for plan in down:
        _check_both_ways_plan(plan, GOAL_3, {two})


def test_granny_to_square_plans_meet_in_the_middle() -> None:
    """Between 6-crossing states the plans are found from both ends at once: a granny (two right-handed
    overhands in a row) to any square state is 6 moves (the rope end pulled back out of a crossing of the
    second overhand and laid across again the other way, three times), and every plan found is a valid
    path of that length through states of at most 6 crossings, each a different one."""
    from twisted.goals import knot_goal

    granny = parse_p_data(
        '[[1,"O",4,"+"],[2,"U",5,"+"],[3,"O",6,"+"],[4,"U",1,"+"],[5,"O",2,"+"],[6,"U",3,"+"],'
        '[7,"U",10,"+"],[8,"O",11,"+"],[9,"U",12,"+"],[10,"O",7,"+"],[11,"U",8,"+"],[12,"O",9,"+"]]'
    )
    square = set(knot_goal("square").states)
    found = plans_both_ways(granny, square, limit=30)
    assert len(found) == 30 and {plan.length for plan in found} == {6}
    assert len({tuple(plan.states) for plan in found}) == 30
    for plan in found:
        _check_both_ways_plan(plan, granny, square)
        assert max(p.cross for p in plan.states) == 6


def test_plans_both_ways_do_not_depend_on_earlier_queries() -> None:
    """The goals' layers are kept between queries; an answer (which plans, in which order, under a
    limit) is the same with them cold or grown by queries from elsewhere."""
    from twisted.goals import knot_goal
    from twisted.moves import _goal_layers

    figure_eight = list(knot_goal("figure-eight").states)
    starts = [GOAL_3, *enumerate_states(3)[3][:40:8]]
    answers = []
    for order in (starts, starts[::-1]):
        _goal_layers.cache_clear()
        answers.append({p: plans_both_ways(p, figure_eight, limit=7) for p in order})
    assert answers[0] == answers[1]
    assert all(answers[0].values())


def test_plans_both_ways_trivial_bounded_and_bad_input() -> None:
    assert plans_both_ways(CURL_RIGHT, [CURL_RIGHT]) == [Plan([CURL_RIGHT], [])]
    assert plans_both_ways(GOAL_3, [CURL_RIGHT], max_cross=2) == []  # the start is above the bound
    assert plans_both_ways(EMPTY, [GOAL_3])[0].length == 3  # adding only, as plans() finds
    with pytest.raises(ValueError):
        plans_both_ways(EMPTY, [CURL_RIGHT], limit=0)
    with pytest.raises(ValueError):
        plans_both_ways(EMPTY, [])
