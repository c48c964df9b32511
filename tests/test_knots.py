"""Knots by name (issues 10 and 14): both closures (under and over the table), knots and knotoids, the
invariants, the catalogue (composites too), the two routes, and independent cross-checks."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest

from twisted.diagram import diagram as rope_diagram
from twisted.knots import (
    CATALOGUE,
    KNOT_NAMES,
    KNOTOID,
    GaussCode,
    KnotNameError,
    KnotType,
    RopeKnot,
    closed_gauss_code,
    crossing_number,
    gauss_code_from_polygon,
    identify,
    identify_points,
    invariants,
    kauffman_bracket,
    least_crossings,
    mirror_type,
    resolve_knot,
    rotations,
    simplify,
    states_tying,
)
from twisted.moves import enumerate_states, plans_to_any, successors
from twisted.topology import EMPTY, PData, PDataError, parse_p_data

# The README's old picture of "an overhand knot": a loop with the tail end lying inside it plus a kink.
README_KNOTOID = parse_p_data(
    [
        [1, "O", 5, "-"],
        [2, "U", 6, "-"],
        [3, "O", 4, "+"],
        [4, "U", 3, "+"],
        [5, "U", 1, "-"],
        [6, "O", 2, "-"],
    ]
)
TREFOIL_JONES = ((1, 1), (3, 1), (4, -1))  # the right-handed trefoil, V = t + t^3 - t^4


def alternating(first: str, sign: str) -> PData:
    """The 3-crossing state whose visits alternate over/under with partners 1-4, 2-5, 3-6, one sign."""
    ou = [first, "U" if first == "O" else "O"] * 3
    return parse_p_data([[i + 1, ou[i], (i + 3) % 6 + 1, sign] for i in range(6)])


def swapped(p: PData) -> PData:
    """The rope reflected through the table (z -> -z): every O/U swapped and, so that the right-hand rule
    holds for the new over strand, every sign flipped. Its closure under the table is the mirror image of
    ``p``'s closure over the table."""
    return PData(
        tuple(
            v._replace(over="U" if v.over == "O" else "O", sign="-" if v.sign == "+" else "+")
            for v in p.visits
        )
    )


def ends_in_one_face(p: PData) -> bool:
    head_face, tail_face = rope_diagram(p).end_faces()
    return head_face == tail_face


def closures(k: RopeKnot) -> tuple[str, str]:
    return k.under.name, k.over.name


# --- the catalogue's defining cases -----------------------------------------------------------------


@pytest.mark.parametrize("first", ["O", "U"])
@pytest.mark.parametrize("sign", ["+", "-"])
def test_alternating_three_crossing_states_are_trefoils_under_both_closures_with_chirality_by_sign(
    first: str, sign: str
) -> None:
    p = alternating(first, sign)
    k = identify(p)
    assert isinstance(k, RopeKnot) and k.is_knot
    assert k.name == f"3_1{sign}" and k.describe() == f"3_1{sign}" and k.knot == k.under
    # the positive (right-handed) trefoil has V = t + t^3 - t^4; the mirror V(1/t)
    expected = TREFOIL_JONES if sign == "+" else tuple(sorted((-e, c) for e, c in TREFOIL_JONES))
    for closure in (k.under, k.over):
        assert closure.name == f"3_1{sign}"
        assert closure.alexander == (1, -1, 1) and closure.determinant == 3
        assert closure.jones == expected
    # the ends lie in one face: the closing arc crosses nothing either way, the closed diagram is the
    # standard trefoil with writhe +-3
    assert ends_in_one_face(p)
    assert closed_gauss_code(p).n_crossings == closed_gauss_code(p, over=True).n_crossings == 3
    assert k.under.writhe == k.over.writhe == (3 if sign == "+" else -3)
    # the mirror image (every sign flipped) is the other chirality; walking tail -> head changes nothing
    assert identify(p.mirror()).name == f"3_1{'-' if sign == '+' else '+'}"
    assert identify(p.reverse()) == k
    # they are exactly the states states_tying() gives for that chirality at 3 crossings
    assert p in states_tying(f"overhand{sign}")


def test_the_readmes_old_overhand_picture_is_a_knotoid() -> None:
    """Closed under the table the end tucked in the loop makes a trefoil; closed over it, nothing: pulling
    the ends decides, so the rope ties no knot."""
    k = identify(README_KNOTOID)
    assert closures(k) == ("3_1-", "0_1")
    assert not k.is_knot and k.knot is None
    assert k.name == KNOTOID == "knotoid"
    assert k.describe() == "knotoid: under 3_1-, over 0_1"
    d = k.to_dict()
    assert d["knot_type"] == "knotoid" and d["is_knot"] is False
    assert d["under"]["knot_type"] == "3_1-" and d["under"]["alexander"] == [1, -1, 1]
    assert (
        d["under"]["determinant"] == 3 and d["over"]["knot_type"] == "0_1" and d["over"]["jones"] == [[0, 1]]
    )
    assert json.loads(json.dumps(d)) == d
    # its ends lie in different faces (the tail inside the loop)
    assert not ends_in_one_face(README_KNOTOID)
    # reflected through the table the closures swap roles (and are mirrored)
    assert closures(identify(swapped(README_KNOTOID))) == ("0_1", "3_1+")
    assert README_KNOTOID not in states_tying("overhand") and README_KNOTOID.cross == 3


def test_states_with_zero_or_one_crossing_are_unknots() -> None:
    one = [parse_p_data([[1, a, 2, s], [2, b, 1, s]]) for a, b in (("O", "U"), ("U", "O")) for s in "+-"]
    assert set(enumerate_states(1)[1]) == set(one)
    for p in (EMPTY, *one):
        k = identify(p)
        assert k.is_knot and k.name == "0_1" and k.describe() == "0_1"
        for closure in (k.under, k.over):
            assert closure.alexander == (1,) and closure.jones == ((0, 1),) and closure.determinant == 1
            assert closure.is_unknot


def test_non_alternating_three_crossing_state_is_not_a_trefoil() -> None:
    # the alternating trefoil with one crossing switched: visits 1 and 4 swap over/under, and so that the
    # strands keep their directions the crossing's sign flips too
    p = parse_p_data([[1, "U", 4, "-"], [2, "U", 5, "+"], [3, "O", 6, "+"], [4, "O", 1, "-"],
                      [5, "O", 2, "+"], [6, "U", 3, "+"]])  # fmt: skip
    assert identify(p).name == "0_1" and identify(p).is_knot


def test_undrawable_p_data_is_refused() -> None:
    # switching O/U without flipping the sign turns the strands: this one needs a torus (a "virtual" rope)
    p = parse_p_data([[1, "U", 4, "+"], [2, "U", 5, "+"], [3, "O", 6, "+"], [4, "O", 1, "+"],
                      [5, "O", 2, "+"], [6, "U", 3, "+"]])  # fmt: skip
    with pytest.raises(PDataError):
        identify(p)


def _code(seq: str, signs: list[int]) -> GaussCode:
    events = tuple((int(tok[1:]) - 1, tok[0] == "O") for tok in seq.split())
    return GaussCode(events, tuple(signs))


def test_torus_knot_diagrams_are_named_positive_when_all_crossings_are() -> None:
    trefoil = _code("O1 U2 O3 U1 O2 U3", [1, 1, 1])
    cinquefoil = _code("O1 U2 O3 U4 O5 U1 O2 U3 O4 U5", [1] * 5)  # (2,5) torus knot
    for c, name in ((trefoil, "3_1+"), (cinquefoil, "5_1+")):
        k = invariants(c)
        assert k.name == name
        mirror = invariants(GaussCode(c.events, tuple(-s for s in c.signs)))
        assert mirror.name == name.replace("+", "-")
        assert mirror.jones == tuple(sorted((-e, x) for e, x in k.jones))
    assert len({(k.alexander, k.jones) for k in CATALOGUE.values()}) == len(CATALOGUE)
    determinants = {name: k.determinant for name, k in CATALOGUE.items()}
    assert [determinants[t] for t in ("0_1", "3_1+", "4_1", "5_1+", "5_2-", "3_1+#3_1+", "3_1+#3_1-")] == [
        1, 3, 5, 5, 7, 9, 9
    ]  # fmt: skip


def _code_from_pd(pd: list[tuple[int, int, int, int]]) -> GaussCode:
    """Our Gauss code of a knot PD code whose edges are numbered 0..2N-1 along the knot (spherogram's)."""
    m = 2 * len(pd)
    events: list[tuple[int, bool]] = [(-1, False)] * m
    signs = []
    for c, (a, b, cc, d) in enumerate(pd):
        assert cc == (a + 1) % m  # the under strand runs a -> c
        positive = b == (d + 1) % m  # the over strand runs d -> b: counter-clockwise after under-in
        events[cc] = (c, False)
        events[b if positive else d] = (c, True)
        signs.append(1 if positive else -1)
    return GaussCode(tuple(events), tuple(signs))


@pytest.mark.parametrize("rolfsen", ["3_1", "4_1", "5_1", "5_2"])
def test_catalogue_matches_the_knot_tables(rolfsen: str) -> None:
    """The table diagram of each catalogue knot (spherogram's) and its mirror get the catalogue's names;
    "+" is the chirality whose minimal diagram has positive writhe."""
    spherogram = pytest.importorskip("spherogram")
    link = spherogram.Link(rolfsen)
    for diagram in (link, link.mirror()):
        k = invariants(_code_from_pd([tuple(x) for x in diagram.PD_code()]))
        writhe = diagram.writhe()
        if rolfsen == "4_1":
            assert k.name == "4_1" and writhe == 0
        else:
            assert k.name == rolfsen + ("+" if writhe > 0 else "-")
            assert abs(writhe) == int(rolfsen[0])  # reduced alternating, one sign: minimal and positive


# --- composite knots: granny and square ----------------------------------------------------------------

GRANNY_PLUS, GRANNY_MINUS, SQUARE = "3_1+#3_1+", "3_1-#3_1-", "3_1+#3_1-"


def _product(a: dict[int, int], b: dict[int, int]) -> dict[int, int]:
    out: Counter[int] = Counter()
    for ea, ca in a.items():
        for eb, cb in b.items():
            out[ea + eb] += ca * cb
    return {e: c for e, c in out.items() if c}


def _alexander_dict(k: KnotType) -> dict[int, int]:
    d = (len(k.alexander) - 1) // 2
    return {i - d: c for i, c in enumerate(k.alexander)}


def test_composite_entries_have_product_invariants_and_granny_and_square_differ_by_jones() -> None:
    """Alexander and Jones polynomials of a connected sum are the products of the summands'. Granny and
    square share the Alexander polynomial and the determinant (9); the Jones polynomial tells them apart."""
    plus, minus = CATALOGUE["3_1+"], CATALOGUE["3_1-"]
    summands = {GRANNY_PLUS: (plus, plus), GRANNY_MINUS: (minus, minus), SQUARE: (plus, minus)}
    for name, (a, b) in summands.items():
        k = CATALOGUE[name]
        assert k.name == name
        assert _alexander_dict(k) == _product(_alexander_dict(a), _alexander_dict(b))
        assert dict(k.jones) == _product(dict(a.jones), dict(b.jones))
        assert k.determinant == a.determinant * b.determinant == 9
    granny, square = CATALOGUE[GRANNY_PLUS], CATALOGUE[SQUARE]
    assert granny.alexander == square.alexander == (1, -2, 3, -2, 1)  # (t^-1 - 1 + t)^2
    assert granny.jones != square.jones != CATALOGUE[GRANNY_MINUS].jones
    # the square knot is its own mirror image (symmetric Jones), the granny is chiral
    assert square.jones == tuple(sorted((-e, c) for e, c in square.jones))
    assert mirror_type(square).name == SQUARE
    assert (
        mirror_type(granny).name == GRANNY_MINUS and mirror_type(CATALOGUE[GRANNY_MINUS]).name == GRANNY_PLUS
    )
    assert mirror_type(plus).name == "3_1-" and mirror_type(CATALOGUE["4_1"]).name == "4_1"
    assert mirror_type(mirror_type(CATALOGUE["5_2+"])) == CATALOGUE["5_2+"]
    # the catalogue's invariants still separate every entry (granny vs square by Jones only)
    assert len({(k.alexander, k.jones) for k in CATALOGUE.values()}) == len(CATALOGUE)
    # Alexander polynomials alone do not: a knot and its mirror, granny and square share theirs
    assert CATALOGUE["3_1+#3_1+"].alexander == CATALOGUE["3_1+#3_1-"].alexander


def test_composite_catalogue_matches_spherogram_connected_sums() -> None:
    """spherogram's connected sums of its trefoil with itself / its mirror get our granny / square names
    (chirality by the writhe of the reduced alternating diagram), and its tau (additive: +-2 granny, 0
    square) agrees with our chirality."""
    spherogram = pytest.importorskip("spherogram")
    trefoil = spherogram.Link("3_1")
    for a, b in ((trefoil, trefoil), (trefoil.mirror(), trefoil.mirror()), (trefoil, trefoil.mirror())):
        link = a.connected_sum(b)
        code = _code_from_pd([tuple(x) for x in link.PD_code()])
        k = invariants(code)
        writhe, tau = link.writhe(), int(link.knot_floer_homology()["tau"])
        if writhe == 0:
            assert k.name == SQUARE and tau == 0
        else:
            assert k.name == (GRANNY_PLUS if writhe > 0 else GRANNY_MINUS)
            assert tau == (2 if writhe > 0 else -2)


@pytest.mark.parametrize(
    ("name", "knot_type", "count"),
    [("granny+", GRANNY_PLUS, 24), ("granny-", GRANNY_MINUS, 24), ("square", SQUARE, 48)],
)
def test_built_six_crossing_composite_states_tie_the_knot_and_are_reachable(
    name: str, knot_type: str, count: int
) -> None:
    found = states_tying(name)
    assert len(found) == count and {p.cross for p in found} == {6}
    assert len({p.key for p in found}) == count and found == sorted(found, key=lambda p: p.key)
    for p in found:
        k = identify(p)
        assert closures(k) == (knot_type, knot_type) and k.is_knot and k.name == knot_type
        assert ends_in_one_face(p)
    # granny = both chiralities
    if name == "square":
        assert found == states_tying("reef") == states_tying("square", crossings=6)
    # the planner can get there from the straight rope (the high level finds move sequences)
    for p in found[:: max(1, count // 3)][:3]:
        plan = plans_to_any(EMPTY, [p], 3)
        assert plan and plan[0].states[0] == EMPTY and plan[0].states[-1] == p


def test_granny_goal_holds_both_chiralities() -> None:
    granny = states_tying("granny")
    assert len(granny) == 48
    assert set(granny) == set(states_tying("granny+")) | set(states_tying("granny-"))
    assert not set(granny) & set(states_tying("square"))
    assert {p.mirror() for p in states_tying("granny+")} == set(states_tying("granny-"))


def test_composite_closures_agree_with_spherogram() -> None:
    """Independent check of the built states: spherogram's knot Floer homology of each closure gives the
    squared trefoil Alexander polynomial and tau +2 (granny+), -2 (granny-), 0 (square)."""
    pytest.importorskip("spherogram")
    for name, tau_expected in (("granny+", 2), ("granny-", -2), ("square", 0)):
        for p in states_tying(name)[:4]:
            for over in (False, True):
                alexander, tau = _spherogram_alexander_and_tau(closed_gauss_code(p, over=over).pd_code())
                assert alexander == (1, -2, 3, -2, 1) and tau == tau_expected, (name, p.key, over)


def test_kauffman_bracket_of_the_hopf_diagram_kink() -> None:
    # one crossing with a kink: <X[1,1,2,2]> = -A^3 (R1 multiplies the bracket by -A^{+-3})
    assert kauffman_bracket([(0, 0, 1, 1)]) in ({3: -1}, {-3: -1})


def test_simplify_removes_kinks_and_bigons_only() -> None:
    trefoil = GaussCode(((0, True), (1, False), (2, True), (0, False), (1, True), (2, False)), (1, 1, 1))
    assert simplify(trefoil) == trefoil  # reduced alternating: nothing to remove
    # the closed diagram of a 4-crossing unknot state whose closure adds R1/R2-removable crossings
    for p in enumerate_states(2)[2]:
        k = identify(p)
        for over, closure in ((False, k.under), (True, k.over)):
            reduced = simplify(closed_gauss_code(p, over=over))
            assert reduced.n_crossings in (0, 3)
            assert (reduced.n_crossings == 3) == (closure.name != "0_1")


# --- the enumeration ------------------------------------------------------------------------------------


def test_r1_and_r2_successors_keep_both_closures_cross_moves_change_them() -> None:
    """R1 and R2 are Reidemeister moves of both closed diagrams (under and over): only Cross moves change
    what the rope ties. Property test over every state of up to 3 crossings and all its successors."""
    states = enumerate_states(3)
    changed_by_cross = 0
    checked = 0
    knotoids_checked = 0
    for c in range(4):
        for p in states[c]:
            k = identify(p)
            for s in successors(p):
                if s.move.kind in ("R1", "R2"):
                    checked += 1
                    got = identify(s.state)
                    assert (got.under, got.over) == (k.under, k.over), (p.key, s.move, s.state.key)
                    assert got.name == k.name
                    knotoids_checked += not k.is_knot
                elif changed_by_cross < 20 and identify(s.state) != k:
                    changed_by_cross += 1
    assert checked > 50_000
    assert knotoids_checked > 1_000  # the property covers knotoids, not only unknots and knots
    assert changed_by_cross > 0


def test_catalogue_counts_over_the_enumeration() -> None:
    """Both closures of every state up to 4 crossings (the table of issue 14): a knot only when they agree."""
    states = enumerate_states(4)
    pairs = {c: Counter(closures(identify(p)) for p in states[c]) for c in range(5)}
    names = {c: Counter(identify(p).name for p in states[c]) for c in range(5)}

    def both(c: int, a: str, b: str) -> int:  # states whose closures are a and b, either way round
        return pairs[c][(a, b)] + (pairs[c][(b, a)] if a != b else 0)

    assert names[0] == {"0_1": 1} and names[1] == {"0_1": 4}
    # 2 crossings: the closing arc makes a trefoil of the end tucked in a loop one way only
    assert pairs[2] == {("0_1", "0_1"): 36, ("3_1+", "0_1"): 1, ("3_1-", "0_1"): 1,
                        ("0_1", "3_1+"): 1, ("0_1", "3_1-"): 1}  # fmt: skip
    assert names[2] == {"0_1": 36, KNOTOID: 4}
    # 3 crossings: 428 unknots, 88 trefoil/unknot knotoids, 4 trefoils, 8 figure-eight/unknot knotoids
    assert both(3, "0_1", "0_1") == 428
    assert sum(both(3, t, "0_1") for t in ("3_1+", "3_1-")) == 88
    assert both(3, "3_1+", "3_1+") == both(3, "3_1-", "3_1-") == 2
    assert both(3, "4_1", "0_1") == 8 and both(3, "4_1", "4_1") == 0
    assert names[3] == {"0_1": 428, KNOTOID: 96, "3_1+": 2, "3_1-": 2}
    # 4 crossings
    assert both(4, "0_1", "0_1") == 5864
    assert sum(both(4, t, "0_1") for t in ("3_1+", "3_1-")) == 1636
    assert both(4, "3_1+", "3_1+") == both(4, "3_1-", "3_1-") == 70
    assert both(4, "4_1", "0_1") == 244 and both(4, "4_1", "4_1") == 8
    assert names[4]["0_1"] == 5864 and names[4]["3_1+"] == names[4]["3_1-"] == 70 and names[4]["4_1"] == 8
    assert set(names[4]) == {"0_1", "3_1+", "3_1-", "4_1", KNOTOID}
    assert sum(names[4].values()) == len(states[4])
    # the old "2-crossing trefoils", "3-crossing figure-eights", "4-crossing 5_1 / 5_2 / granny / square"
    # are all knotoids: one of their closures is something else
    assert (
        pairs[4][("5_1+", "0_1")] > 0 and pairs[4][("5_2+", "0_1")] > 0 and pairs[4][("3_1+#3_1-", "0_1")] > 0
    )
    # chirality: a state and its mirror tie mirror knots (each closure mirrored)
    for p in states[3]:
        k, m = identify(p), identify(p.mirror())
        assert m.under == mirror_type(k.under) and m.over == mirror_type(k.over)
        assert m.name == k.name.translate(str.maketrans("+-", "-+"))


def test_no_state_below_the_crossing_number_ties_the_knot() -> None:
    """A knot of crossing number n needs n crossings in the rope: below, only knotoids show it."""
    states = enumerate_states(3)
    for c in range(4):
        tied = {identify(p).name for p in states[c]}
        assert "4_1" not in tied
        if c < 3:
            assert not tied & {"3_1+", "3_1-"}
            assert tied <= {"0_1", KNOTOID}
        else:
            assert tied == {"0_1", "3_1+", "3_1-", KNOTOID}
    assert least_crossings("overhand") == 3 and least_crossings("overhand-") == 3
    assert least_crossings("figure-eight") == 4 and least_crossings("5_1") == least_crossings("5_2") == 5
    assert least_crossings("granny") == least_crossings("square") == least_crossings("reef") == 6
    assert least_crossings("unknot") == 0
    assert crossing_number("3_1+") == 3 and crossing_number("4_1") == 4 and crossing_number("5_2-") == 5
    assert crossing_number("3_1+#3_1+") == crossing_number("3_1+#3_1-") == 6
    with pytest.raises(ValueError, match="not a catalogue knot type"):
        crossing_number("granny")


def test_over_closure_is_the_mirrored_under_closure_of_the_rope_reflected_through_the_table() -> None:
    """An independent route to the over-closure: lift the ends over everything = reflect the rope through
    the table (every O/U swapped, signs flipped), lower them under everything, reflect back (mirror)."""
    states = enumerate_states(4)
    every = {p for layer in states.values() for p in layer}
    checked = 0
    for layer in states.values():
        for p in layer:
            q = swapped(p)
            assert q in every  # the enumeration is closed under the reflection
            k, kq = identify(p), identify(q)
            assert k.over == mirror_type(kq.under), p.key
            assert k.under == mirror_type(kq.over), p.key
            # and directly from the closed diagrams (invariants() of the over-closure of p)
            if p.cross <= 3:
                assert invariants(closed_gauss_code(p, over=True)) == mirror_type(
                    invariants(closed_gauss_code(q))
                )
            checked += 1
    assert checked == sum(len(layer) for layer in states.values()) > 8_000


def test_states_tying_takes_the_crossing_number_and_only_real_knots() -> None:
    overhand = states_tying("overhand")
    # the four alternating states, two per chirality
    assert sorted(overhand, key=lambda p: p.key) == overhand
    assert set(overhand) == {alternating(f, s) for f in "OU" for s in "+-"}
    assert all(identify(p).is_knot for p in overhand)
    assert states_tying("overhand+") == [p for p in overhand if identify(p).name == "3_1+"]
    assert len(states_tying("overhand+")) == len(states_tying("trefoil-")) == 2
    figure_eight = states_tying("figure-eight")
    assert len(figure_eight) == 8 and {p.cross for p in figure_eight} == {4}
    assert all(closures(identify(p)) == ("4_1", "4_1") for p in figure_eight)
    assert states_tying("figure-8", crossings=4) == figure_eight
    assert len(states_tying("3_1+", crossings=4)) == len(states_tying("3_1-", crossings=4)) == 70
    assert len(states_tying("overhand", crossings=4)) == 140
    assert states_tying("unknot") == [EMPTY]
    # below the crossing number nothing ties the knot (the knotoids are left out)
    assert states_tying("overhand", crossings=2) == [] and states_tying("figure-eight", crossings=3) == []
    assert states_tying("5_1", crossings=2) == []
    # 5_1 and 5_2 at their crossing number are cut from their diagrams, not enumerated
    assert len(states_tying("5_2")) == 20 and len(states_tying("5_1")) == 4
    with pytest.raises(ValueError, match="would have to be enumerated"):
        states_tying("overhand", crossings=4, max_crossings=3)
    with pytest.raises(ValueError, match="crossings must be >= 0"):
        states_tying("overhand", crossings=-1)
    with pytest.raises(ValueError, match="more than its crossing number 6"):
        states_tying("granny", crossings=7)
    with pytest.raises(KnotNameError):
        states_tying("bowline")


def test_states_tying_a_knot_at_its_crossing_number_have_their_ends_in_one_face() -> None:
    """What the composite construction relies on (below 6 crossings): every minimal state that ties a
    knot is a closed knot diagram cut open at an edge."""
    for name in ("overhand", "figure-eight"):
        found = states_tying(name)
        assert found and all(ends_in_one_face(p) for p in found)
    # not so above the crossing number
    assert not all(ends_in_one_face(p) for p in states_tying("overhand", crossings=4))
    # ends in one face: the closing arc crosses nothing, under or over, so a knotoid never has them
    knotoids = [p for p in enumerate_states(3)[3] if identify(p).name == KNOTOID]
    assert len(knotoids) == 96 and not any(ends_in_one_face(p) for p in knotoids)


@pytest.mark.parametrize("sign", ["+", "-"])
def test_rotations_of_one_overhand_give_every_overhand_of_its_chirality(sign: str) -> None:
    p = alternating("O", sign)
    turned = rotations(p)
    assert p in turned and all(q.cross == 3 and ends_in_one_face(q) for q in turned)
    assert all(identify(q) == identify(p) for q in turned)
    minimal = [q for q in enumerate_states(3)[3] if ends_in_one_face(q) and identify(q).name == f"3_1{sign}"]
    assert sorted(turned, key=lambda q: q.key) == turned
    assert turned == sorted(minimal, key=lambda q: q.key) == states_tying(f"overhand{sign}")


def test_knot_names_resolve_and_unknown_names_list_the_valid_ones() -> None:
    assert resolve_knot("overhand") == resolve_knot("Trefoil") == resolve_knot("3_1") == {"3_1+", "3_1-"}
    assert resolve_knot("overhand+") == {"3_1+"} and resolve_knot("3_1-") == {"3_1-"}
    assert resolve_knot("figure-eight") == resolve_knot("figure-8") == {"4_1"}
    assert resolve_knot("unknot") == {"0_1"}
    assert resolve_knot("5_2") == {"5_2+", "5_2-"}
    assert resolve_knot("granny") == {"3_1+#3_1+", "3_1-#3_1-"} and resolve_knot("granny+") == {"3_1+#3_1+"}
    assert resolve_knot("square") == resolve_knot("reef") == resolve_knot("3_1-#3_1+") == {"3_1+#3_1-"}
    assert all(types <= set(CATALOGUE) for types in KNOT_NAMES.values())
    assert set(CATALOGUE) == set().union(*KNOT_NAMES.values())
    with pytest.raises(KnotNameError, match="valid names: .*overhand.*figure-eight.*granny.*square") as info:
        resolve_knot("bowline")
    assert isinstance(info.value, ValueError) and "'bowline'" in str(info.value)
    with pytest.raises(KnotNameError):
        resolve_knot(KNOTOID)  # a knotoid is not a knot one can ask for


# --- link points and independent cross-checks -------------------------------------------------------------


def _closed_rope(pts: np.ndarray, z: float) -> np.ndarray:
    """The rope with its ends taken to height z and joined there (what identify_points closes)."""
    return np.vstack([pts, [pts[-1, 0], pts[-1, 1], z], [pts[0, 0], pts[0, 1], z]])


def _tau_sign(name: str) -> int | None:
    """Sign of tau for the chiral prime table knots, None where it is 0 or not known here. Every table knot
    is alternating, so tau = -signature / 2 (KnotInfo's signature of its ``+`` chirality)."""
    from twisted.knots import KNOTINFO

    bare = name.rstrip("+-")
    if "#" in name or not name.endswith(("+", "-")) or bare not in KNOTINFO:
        return None
    tau = -KNOTINFO[bare].signature // 2 * (1 if name.endswith("+") else -1)
    return None if tau == 0 else (1 if tau > 0 else -1)


def test_identify_points_closes_under_and_over_the_table() -> None:
    # a straight rope, and a rope drawn as an open trefoil (an alternating 3-crossing helix in plan view)
    straight = identify_points(np.c_[np.linspace(0, 0.84, 22), np.zeros(22), np.full(22, 0.01)])
    assert straight.is_knot and straight.name == "0_1" and closures(straight) == ("0_1", "0_1")
    s = np.linspace(0.15, 2 * np.pi - 0.15, 120)
    # the standard trefoil curve, with a gap cut out near its top so the ends are apart (outside the knot)
    x, y = np.sin(s) + 2 * np.sin(2 * s), np.cos(s) - 2 * np.cos(2 * s)
    z = -np.sin(3 * s) + 2.0
    k = identify_points(np.c_[x, y, z])
    assert k.is_knot and k.name in ("3_1+", "3_1-")
    mirrored = identify_points(np.c_[x, -y, z])
    assert {k.name, mirrored.name} == {"3_1+", "3_1-"}
    # reflected through the table the closures swap and are mirrored (z -> -z)
    rng = np.random.default_rng(5)
    knotoids = 0
    for _ in range(60):
        pts = rng.uniform(-1, 1, size=(int(rng.integers(8, 15)), 3))
        a, b = identify_points(pts), identify_points(pts * [1, 1, -1])
        assert a.under == mirror_type(b.over) and a.over == mirror_type(b.under)
        assert a.is_knot == b.is_knot
        knotoids += not a.is_knot
    assert knotoids >= 3
    with pytest.raises(ValueError, match="shape"):
        identify_points(np.zeros((1, 3)))


def _spherogram_alexander_and_tau(pd: list[tuple[int, int, int, int]]) -> tuple[tuple[int, ...], int]:
    """Alexander polynomial (normalised as ours) and tau from spherogram's knot Floer homology."""
    import spherogram

    link = spherogram.Link([list(x) for x in pd])
    link.simplify("global")
    if not link.crossings:
        return (1,), 0
    hfk = link.knot_floer_homology()
    poly: Counter[int] = Counter()
    for (alexander_grading, maslov), rank in hfk["ranks"].items():
        poly[alexander_grading] += (-1) ** maslov * rank
    coeffs = [poly[e] for e in range(min(poly), max(poly) + 1)]
    while coeffs[0] == 0:
        coeffs.pop(0)
    while coeffs[-1] == 0:
        coeffs.pop()
    if sum(coeffs) < 0:
        coeffs = [-c for c in coeffs]
    return tuple(coeffs), int(hfk["tau"])


def _check_against_spherogram(closed: np.ndarray, expected: KnotType, rng: np.random.Generator) -> None:
    code = gauss_code_from_polygon(closed)
    assert invariants(code) == expected
    alexander, tau = _spherogram_alexander_and_tau(code.pd_code())
    assert alexander == expected.alexander, (closed.tolist(), expected)
    if (sign := _tau_sign(expected.name)) is not None:
        assert tau * sign > 0, (closed.tolist(), expected, tau)
    # the knot of a space polygon does not depend on the direction it is seen from
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    assert invariants(gauss_code_from_polygon(closed @ rotation.T)) == expected


def test_invariants_agree_with_spherogram_on_random_closed_polygons() -> None:
    """Alexander polynomial against knot Floer homology (spherogram, an independent implementation);
    chirality against its tau invariant; our knot type against a second projection direction."""
    pytest.importorskip("spherogram")
    rng = np.random.default_rng(2024)
    names: Counter[str] = Counter()
    for _ in range(200):
        pts = rng.uniform(-1, 1, size=(int(rng.integers(8, 17)), 3))
        k = invariants(gauss_code_from_polygon(pts))
        names[k.name] += 1
        _check_against_spherogram(pts, k, rng)
    # the sample exercises knots, not only unknots
    assert names["0_1"] < 180 and names["3_1+"] + names["3_1-"] >= 10
    assert sum(n for name, n in names.items() if name not in ("0_1", "3_1+", "3_1-")) >= 1


def test_both_closures_of_random_open_ropes_agree_with_spherogram() -> None:
    """identify_points' two closures of random open polygons (ends lowered below / lifted above everything
    and joined there) against spherogram, and against other projection directions of the closed curve."""
    pytest.importorskip("spherogram")
    rng = np.random.default_rng(14)
    kinds: Counter[str] = Counter()
    for _ in range(150):
        pts = rng.uniform(-1, 1, size=(int(rng.integers(8, 17)), 3))
        k = identify_points(pts)
        low = min(float(pts[:, 2].min()), 0.0) - 1.0
        high = float(pts[:, 2].max()) + 1.0
        _check_against_spherogram(_closed_rope(pts, low), k.under, rng)
        _check_against_spherogram(_closed_rope(pts, high), k.over, rng)
        kinds["knotoid" if not k.is_knot else "unknot" if k.name == "0_1" else "knot"] += 1
    # the sample has proper knotoids (closures differ) and real knots
    assert kinds["knotoid"] >= 10 and kinds["knot"] >= 3, kinds


def test_p_data_closures_agree_with_spherogram_for_every_three_crossing_state() -> None:
    pytest.importorskip("spherogram")
    for p in enumerate_states(3)[3]:
        k = identify(p)
        for over, closure in ((False, k.under), (True, k.over)):
            code = closed_gauss_code(p, over=over)
            alexander, tau = _spherogram_alexander_and_tau(code.pd_code())  # spherogram checks planarity too
            assert alexander == closure.alexander, (p.key, over)
            if (sign := _tau_sign(closure.name)) is not None:
                assert tau * sign > 0, (p.key, over)
            elif closure.name in ("0_1", "4_1"):
                assert tau == 0


@pytest.mark.slow
def test_p_data_route_agrees_with_link_point_route_on_a_collected_store(tmp_path) -> None:
    from sqlalchemy import select

    from twisted.collect import CollectOptions, collect
    from twisted.store import Configuration, TopologicalState, blob_to_array, open_store

    url = f"sqlite:///{tmp_path / 'knots.db'}"
    with open_store(url) as store:
        options = CollectOptions(hours=0.03, workers=1, seed=11, max_kept=16, batch_size=4, cross_bias=3.0)
        collect(store, options)
    checked: Counter[int] = Counter()
    with open_store(url) as store, store.session() as session:
        rows = session.execute(
            select(
                Configuration.points,
                TopologicalState.key,
                TopologicalState.knot_type,
                TopologicalState.closure_under,
                TopologicalState.closure_over,
            ).join(TopologicalState, TopologicalState.id == Configuration.state_id)
        ).all()
        for points, key, knot_type, under, over in rows:
            by_p_data = identify(parse_p_data(key))
            by_points = identify_points(blob_to_array(points, (-1, 3)))
            assert by_p_data == by_points, key  # both closures
            # filled where the row was inserted
            assert (knot_type, under, over) == (by_p_data.name, by_p_data.under.name, by_p_data.over.name)
            checked[parse_p_data(key).cross] += 1
    assert sum(checked.values()) >= 10 and max(checked) >= 2
