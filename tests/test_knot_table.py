"""The knot table from KnotInfo (issue 65): every prime knot up to 7 crossings and the sums of two with at
most 7 in all; KnotInfo's invariants against ours; goal states cut from the knots' diagrams."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.main import app
from twisted.goals import PlanInputError, knot_goal, make_goal
from twisted.knots import (
    CATALOGUE,
    KNOTINFO,
    GaussCode,
    KnotNameError,
    crossing_number,
    gauss_code_from_pd,
    identify,
    invariants,
    knotinfo_name,
    minimal_states,
    mirror_name,
    resolve_knot,
    states_tying,
)
from twisted.knots.states import _shifted
from twisted.topology import PData

runner = CliRunner()

PRIMES_UP_TO_7 = ["3_1", "4_1", "5_1", "5_2", "6_1", "6_2", "6_3"] + [f"7_{i}" for i in range(1, 8)]
TABLE = [t for t in CATALOGUE if t != "0_1"]


def _mirrored(code: GaussCode) -> GaussCode:
    return GaussCode(code.events, tuple(-s for s in code.signs))


def test_the_table_holds_every_prime_knot_up_to_7_crossings_each_chirality_and_the_sums_of_two() -> None:
    assert list(KNOTINFO) == PRIMES_UP_TO_7
    amphicheiral = {"4_1", "6_3"}
    assert {k.name for k in KNOTINFO.values() if not k.chiral} == amphicheiral
    primes = [t for t in TABLE if "#" not in t]
    assert primes == [
        n + s for n in PRIMES_UP_TO_7 for s in ([""] if n in amphicheiral else ["+", "-"])
    ]
    composites = [t for t in TABLE if "#" in t]
    assert composites == ["3_1+#3_1+", "3_1+#3_1-", "3_1+#4_1", "3_1-#3_1-", "3_1-#4_1"]
    assert len(TABLE) == 26 + 5
    assert {crossing_number(t) for t in composites} == {6, 7}
    # names a user types: KnotInfo's (both chiralities), each type, and the common names
    assert resolve_knot("6_1") == {"6_1+", "6_1-"} and resolve_knot("7_7-") == {"7_7-"}
    assert resolve_knot("6_3") == {"6_3"} and resolve_knot("stevedore") == {"6_1+", "6_1-"}
    assert resolve_knot("3_1#4_1") == resolve_knot("4_1#3_1") == {"3_1+#4_1", "3_1-#4_1"}
    assert resolve_knot("granny") == {"3_1+#3_1+", "3_1-#3_1-"} and resolve_knot("square") == {"3_1+#3_1-"}


@pytest.mark.parametrize("name", PRIMES_UP_TO_7)
def test_knotinfos_invariants_agree_with_ours_on_its_diagram_and_its_mirror(name: str) -> None:
    """Our invariants of KnotInfo's PD code are KnotInfo's (its Alexander and Jones polynomials and
    determinant): the table's ``+`` entry is that diagram's knot, the ``-`` entry its mirror's."""
    k = KNOTINFO[name]
    code = gauss_code_from_pd(k.pd)
    ours = invariants(code)
    plus = name + ("+" if k.chiral else "")
    assert ours.name == plus and ours == CATALOGUE[plus]
    assert ours.jones == k.jones and ours.determinant == k.determinant
    assert ours.alexander in (k.alexander, tuple(-c for c in k.alexander))
    mirror = invariants(_mirrored(code))
    assert mirror.name == (name + "-" if k.chiral else name) == mirror_name(plus)
    assert mirror.jones == tuple(sorted((-e, c) for e, c in k.jones))
    assert (mirror.jones == ours.jones) == (not k.chiral)  # chirality as KnotInfo's symmetry type says


@pytest.mark.parametrize("name", PRIMES_UP_TO_7)
def test_knotinfos_pd_codes_read_as_spherogram_reads_them(name: str) -> None:
    """Independent check of the PD reading and of the chirality: spherogram's knot Floer homology of
    KnotInfo's PD code gives the table's Alexander polynomial, and its tau is -signature / 2 with
    KnotInfo's signature (every table knot is alternating); KnotInfo's positive knots are drawn with
only + crossings, so their ``+`` entry is the positive knot."""
    pytest.importorskip("spherogram")
    from tests.test_knots import _spherogram_alexander_and_tau

    k = KNOTINFO[name]
    alexander, tau = _spherogram_alexander_and_tau(list(k.pd))
    assert alexander == CATALOGUE[name + ("+" if k.chiral else "")].alexander
    assert tau == -k.signature // 2
    if name in ("3_1", "5_1", "5_2", "7_1", "7_2", "7_3", "7_4", "7_5"):  # KnotInfo: positive knots
        assert tau > 0 and set(gauss_code_from_pd(k.pd).signs) == {1}  # KnotInfo's diagram: all +


def _connected_sum(a: str, b: str) -> GaussCode:
    """A closed diagram of ``a # b``: a state tying ``a`` (ends in one face) followed by one tying ``b``."""
    p, q = minimal_states(a)[0], minimal_states(b)[0]
    joined = PData.from_crossings(_shifted(p, 0) + _shifted(q, len(p.visits)))
    events = [None] * len(joined.visits)
    signs = []
    for c, (o, u, s) in enumerate(joined.crossings()):
        events[o - 1], events[u - 1] = (c, True), (c, False)
        signs.append(s)
    return GaussCode(tuple(events), tuple(signs))  # type: ignore[arg-type]


@pytest.mark.parametrize("composite", ["3_1+#3_1+", "3_1+#3_1-", "3_1+#4_1", "3_1-#3_1-", "3_1-#4_1"])
def test_composite_entries_are_the_invariants_of_a_connected_sum_diagram(composite: str) -> None:
    a, b = composite.split("#")
    assert invariants(_connected_sum(a, b)) == CATALOGUE[composite]
    assert invariants(_connected_sum(b, a)) == CATALOGUE[composite]


@pytest.mark.parametrize("knot_type", TABLE)
def test_every_table_knot_gets_goal_states_whose_both_closures_are_it(knot_type: str) -> None:
    states = minimal_states(knot_type)
    assert states and list(states) == sorted(states, key=lambda p: p.key)
    assert {p.cross for p in states} == {crossing_number(knot_type)}
    for p in states:
        k = identify(p)
        assert k.under.name == k.over.name == knot_type, p.key
    # the mirror image's states are the mirror's
    assert sorted(p.mirror().key for p in states) == [p.key for p in minimal_states(mirror_name(knot_type))]
    # a knot goal by its KnotInfo name holds both chiralities' states
    goal = knot_goal(knotinfo_name(knot_type)) if "#" not in knot_type else knot_goal(knot_type)
    assert {p.key for p in states} <= goal.keys and goal.crossings == crossing_number(knot_type)


def test_goal_state_counts_up_to_6_crossings_are_those_the_enumeration_found() -> None:
    """The cut diagrams give every state the enumeration found at the crossing number (counts of
    docs/DESIGN.md section 9.4 and the tests of test_knots.py: 2, 8, 24 and 48)."""
    counts = Counter({t: len(minimal_states(t)) for t in TABLE})
    assert counts["3_1+"] == counts["3_1-"] == 2 and counts["4_1"] == 8
    assert counts["3_1+#3_1+"] == counts["3_1-#3_1-"] == 24 and counts["3_1+#3_1-"] == 48
    assert states_tying("overhand") == sorted(
        [p for c in (3,) for p in minimal_states(f"{c}_1+") + minimal_states(f"{c}_1-")], key=lambda p: p.key
    )


# One of the two 5-crossing states of 5_2+ the enumeration finds and no cut of a diagram gives (and its
# over/under swap): its ends lie in different faces (log 2026-12-06)
FIVE_TWO_UNCUT = (
    '[[1,"O",7,"+"],[2,"U",6,"+"],[3,"O",8,"+"],[4,"O",10,"+"],[5,"U",9,"+"],[6,"O",2,"+"],[7,"U",1,"+"],'
    '[8,"U",3,"+"],[9,"O",5,"+"],[10,"U",4,"+"]]'
)


def test_a_state_with_its_ends_in_two_faces_may_tie_the_knot_yet_is_no_cut() -> None:
    from twisted.diagram import diagram
    from twisted.topology import parse_p_data

    p = parse_p_data(FIVE_TWO_UNCUT)
    k = identify(p)
    assert k.under.name == k.over.name == "5_2+" and p.cross == 5
    head_face, tail_face = diagram(p).end_faces()
    assert head_face != tail_face
    assert p not in minimal_states("5_2+") and all(
        diagram(q).end_faces()[0] == diagram(q).end_faces()[1] for q in minimal_states("5_2+")
    )


@pytest.mark.parametrize("name", ["8_1", "8_19", "5_1#3_1", "4_1#4_1"])
def test_a_knot_beyond_the_table_is_refused_saying_so(name: str) -> None:
    with pytest.raises(KnotNameError, match="beyond the table .*valid names: the table: 0_1, 3_1\\+"):
        resolve_knot(name)


@pytest.mark.parametrize(
    ("name", "message"), [("8_1", "is beyond the table"), ("bowline", "unknown knot name 'bowline'")]
)
def test_plan_refuses_an_unknown_knot_or_one_beyond_the_table_with_exit_2(
    tmp_path: Path, name: str, message: str
) -> None:
    result = runner.invoke(app, ["--db", f"sqlite:///{tmp_path / 'k.db'}", "plan", "--knot", name])
    out = " ".join(result.output.split())
    assert result.exit_code == 2 and message in out, out
    assert "7_7-" in out and "3_1+#4_1" in out and "granny" in out  # what exists
    assert not (tmp_path / "k.db").exists()


def test_a_7_crossing_knot_goal_is_made_but_the_model_encodes_at_most_6() -> None:
    goal = knot_goal("7_1")
    assert goal.crossings == 7 and len(goal.states) == 4
    with pytest.raises(PlanInputError, match="7 crossings; the model encodes at most 6"):
        make_goal(knot="7_1")


def test_a_knot_goal_at_its_crossing_number_enumerates_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    """Before: a 5-crossing knot goal enumerated all 130,304 states of 5 crossings (and plan kept them in
    the store). Now its states are cut from the diagram; only a count above the crossing number
    enumerates, and only that is kept."""
    import twisted.knots.states
    import twisted.moves
    from twisted.store.knots import kept_crossings

    def no_enumeration(*args: object, **kwargs: object) -> None:
        raise AssertionError("enumerated")

    monkeypatch.setattr(twisted.knots.states, "states_by_type", no_enumeration)
    monkeypatch.setattr(twisted.moves, "enumerate_states", no_enumeration)
    twisted.knots.states._diagram_states.cache_clear()
    twisted.knots.states.minimal_states.cache_clear()
    for name in ("5_1", "5_2", "6_2", "7_7", "granny", "3_1#4_1"):
        assert knot_goal(name).states
    assert kept_crossings("5_2") is None and kept_crossings("5_1", 5) is None
    assert kept_crossings("overhand", 5) == 5  # above its crossing number: enumerated, kept
