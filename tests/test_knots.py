"""Knots by name (issue 10): the closure under the table, the invariants, the catalogue, the two routes."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from twisted.knots import (
    CATALOGUE,
    KNOT_NAMES,
    GaussCode,
    KnotNameError,
    closed_gauss_code,
    gauss_code_from_polygon,
    identify,
    identify_points,
    invariants,
    kauffman_bracket,
    resolve_knot,
    simplify,
    states_tying,
)
from twisted.moves import enumerate_states, successors
from twisted.topology import EMPTY, PData, PDataError, parse_p_data


def alternating(first: str, sign: str) -> PData:
    """The 3-crossing state whose visits alternate over/under with partners 1-4, 2-5, 3-6, one sign."""
    ou = [first, "U" if first == "O" else "O"] * 3
    return parse_p_data([[i + 1, ou[i], (i + 3) % 6 + 1, sign] for i in range(6)])


# --- the catalogue's defining cases -----------------------------------------------------------------


@pytest.mark.parametrize("first", ["O", "U"])
@pytest.mark.parametrize("sign", ["+", "-"])
def test_alternating_three_crossing_states_are_trefoils_with_chirality_by_sign(first: str, sign: str) -> None:
    p = alternating(first, sign)
    k = identify(p)
    assert k.name == f"3_1{sign}"
    assert k.alexander == (1, -1, 1) and k.determinant == 3
    # the positive (right-handed) trefoil has V = t + t^3 - t^4; the mirror V(1/t)
    expected = ((1, 1), (3, 1), (4, -1)) if sign == "+" else ((-4, -1), (-3, 1), (-1, 1))
    assert k.jones == expected
    # the mirror image (every sign flipped) is the other chirality; walking tail -> head changes nothing
    assert identify(p.mirror()).name == f"3_1{'-' if sign == '+' else '+'}"
    assert identify(p.reverse()) == k


def test_states_with_zero_or_one_crossing_are_unknots() -> None:
    one = [
        parse_p_data([[1, a, 2, s], [2, b, 1, s]]) for a, b in (("O", "U"), ("U", "O")) for s in "+-"
    ]
    assert set(enumerate_states(1)[1]) == set(one)
    for p in (EMPTY, *one):
        k = identify(p)
        assert k.name == "0_1" and k.alexander == (1,) and k.jones == ((0, 1),) and k.determinant == 1


def test_non_alternating_three_crossing_state_is_not_a_trefoil() -> None:
    # the alternating trefoil with one crossing switched: visits 1 and 4 swap over/under, and so that the
    # strands keep their directions the crossing's sign flips too
    p = parse_p_data([[1, "U", 4, "-"], [2, "U", 5, "+"], [3, "O", 6, "+"], [4, "O", 1, "-"],
                      [5, "O", 2, "+"], [6, "U", 3, "+"]])  # fmt: skip
    assert identify(p).name == "0_1"


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
    assert [k.determinant for k in CATALOGUE.values()] == [1, 3, 3, 5, 5, 5, 7, 7]


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


def test_kauffman_bracket_of_the_hopf_diagram_kink() -> None:
    # one crossing with a kink: <X[1,1,2,2]> = -A^3 (R1 multiplies the bracket by -A^{+-3})
    assert kauffman_bracket([(0, 0, 1, 1)]) in ({3: -1}, {-3: -1})


def test_simplify_removes_kinks_and_bigons_only() -> None:
    trefoil = GaussCode(((0, True), (1, False), (2, True), (0, False), (1, True), (2, False)), (1, 1, 1))
    assert simplify(trefoil) == trefoil  # reduced alternating: nothing to remove
    # the closed diagram of a 4-crossing unknot state whose closure adds R1/R2-removable crossings
    for p in enumerate_states(2)[2]:
        reduced = simplify(closed_gauss_code(p))
        assert reduced.n_crossings in (0, 3)
        assert (reduced.n_crossings == 3) == (identify(p).name != "0_1")


# --- the enumeration ------------------------------------------------------------------------------------


def test_r1_and_r2_successors_keep_the_knot_type_cross_moves_change_it() -> None:
    """R1 and R2 are Reidemeister moves of the closed diagram too: only Cross moves change the knot."""
    states = enumerate_states(3)
    changed_by_cross = 0
    checked = 0
    for c in range(4):
        for p in states[c]:
            k = identify(p)
            for s in successors(p):
                if s.move.kind in ("R1", "R2"):
                    checked += 1
                    assert identify(s.state) == k, (p.key, s.move, s.state.key)
                elif identify(s.state) != k:
                    changed_by_cross += 1
    assert checked > 50_000
    assert changed_by_cross > 0


def test_catalogue_counts_over_the_enumeration() -> None:
    states = enumerate_states(4)
    counts = {c: Counter(identify(p).name for p in states[c]) for c in range(5)}
    assert counts[0] == {"0_1": 1} and counts[1] == {"0_1": 4}
    # the closing arc adds crossings: a 2-crossing rope already ties each trefoil once
    assert counts[2] == {"0_1": 38, "3_1+": 1, "3_1-": 1}
    assert counts[3] == {"0_1": 476, "3_1+": 24, "3_1-": 24, "4_1": 4}
    assert counts[4]["4_1"] == 134 and counts[4]["3_1+"] == counts[4]["3_1-"] == 489
    assert counts[4]["5_1+"] == counts[4]["5_1-"] == 4 and counts[4]["5_2+"] == counts[4]["5_2-"] == 9
    # chirality: a state and its mirror tie mirror knots
    for p in states[3]:
        name = identify(p).name
        assert identify(p.mirror()).name == name.translate(str.maketrans("+-", "-+"))


def test_states_tying_takes_the_smallest_count() -> None:
    overhand = states_tying("overhand")
    assert [p.cross for p in overhand] == [2, 2]
    assert {identify(p).name for p in overhand} == {"3_1+", "3_1-"}
    assert states_tying("overhand+") == [p for p in overhand if identify(p).name == "3_1+"]
    figure_eight = states_tying("figure-eight")
    assert len(figure_eight) == 4 and {p.cross for p in figure_eight} == {3}
    assert len(states_tying("figure-8", crossings=4)) == 134
    assert states_tying("unknot") == [EMPTY]
    assert len(states_tying("5_2")) == 18 and states_tying("5_2")[0].cross == 4
    assert states_tying("5_1", crossings=2) == []
    assert all(identify(p).name == "4_1" for p in states_tying("4_1", crossings=4))


def test_knot_names_resolve_and_unknown_names_list_the_valid_ones() -> None:
    assert resolve_knot("overhand") == resolve_knot("Trefoil") == resolve_knot("3_1") == {"3_1+", "3_1-"}
    assert resolve_knot("overhand+") == {"3_1+"} and resolve_knot("3_1-") == {"3_1-"}
    assert resolve_knot("figure-eight") == resolve_knot("figure-8") == {"4_1"}
    assert resolve_knot("unknot") == {"0_1"}
    assert resolve_knot("5_2") == {"5_2+", "5_2-"}
    assert all(types <= set(CATALOGUE) for types in KNOT_NAMES.values())
    with pytest.raises(KnotNameError, match="valid names: .*overhand.*figure-eight") as info:
        resolve_knot("bowline")
    assert isinstance(info.value, ValueError) and "'bowline'" in str(info.value)


# --- link points and independent cross-checks -------------------------------------------------------------


def test_identify_points_closes_under_the_table() -> None:
    # a straight rope, and a rope drawn as an open trefoil (an alternating 3-crossing helix in plan view)
    assert identify_points(np.c_[np.linspace(0, 0.84, 22), np.zeros(22), np.full(22, 0.01)]).name == "0_1"
    s = np.linspace(0.15, 2 * np.pi - 0.15, 120)
    # the standard trefoil curve, with a gap cut out near its top so the ends are apart
    x, y = np.sin(s) + 2 * np.sin(2 * s), np.cos(s) - 2 * np.cos(2 * s)
    z = -np.sin(3 * s) + 2.0
    k = identify_points(np.c_[x, y, z])
    assert k.name in ("3_1+", "3_1-")
    mirrored = identify_points(np.c_[x, -y, z])
    assert {k.name, mirrored.name} == {"3_1+", "3_1-"}


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


def test_invariants_agree_with_spherogram_on_random_closed_polygons() -> None:
    """Alexander polynomial against knot Floer homology (spherogram, an independent implementation);
    chirality against its tau invariant; our knot type against a second projection direction."""
    pytest.importorskip("spherogram")
    rng = np.random.default_rng(2024)
    names: Counter[str] = Counter()
    for _ in range(200):
        pts = rng.uniform(-1, 1, size=(int(rng.integers(8, 17)), 3))
        code = gauss_code_from_polygon(pts)
        k = invariants(code)
        names[k.name] += 1
        alexander, tau = _spherogram_alexander_and_tau(code.pd_code())
        assert alexander == k.alexander, (pts.tolist(), k)
        if k.name.endswith(("+", "-")):
            assert (tau > 0) == k.name.endswith("+"), (pts.tolist(), k, tau)
        rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        assert invariants(gauss_code_from_polygon(pts @ rotation.T)) == k
    # the sample exercises knots, not only unknots
    assert names["0_1"] < 180 and names["3_1+"] + names["3_1-"] >= 10 and names["unknown"] >= 1


def test_p_data_closure_agrees_with_spherogram_for_every_three_crossing_state() -> None:
    pytest.importorskip("spherogram")
    for p in enumerate_states(3)[3]:
        code = closed_gauss_code(p)
        alexander, tau = _spherogram_alexander_and_tau(code.pd_code())  # spherogram checks planarity too
        k = identify(p)
        assert alexander == k.alexander
        if k.name.endswith(("+", "-")):
            assert (tau > 0) == k.name.endswith("+")


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
            select(Configuration.points, TopologicalState.key, TopologicalState.knot_type).join(
                TopologicalState, TopologicalState.id == Configuration.state_id
            )
        ).all()
        for points, key, knot_type in rows:
            by_p_data = identify(parse_p_data(key))
            by_points = identify_points(blob_to_array(points, (-1, 3)))
            assert by_p_data == by_points, key
            assert knot_type == by_p_data.name  # filled where the row was inserted
            checked[parse_p_data(key).cross] += 1
    assert sum(checked.values()) >= 10 and max(checked) >= 2
