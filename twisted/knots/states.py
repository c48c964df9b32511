"""The rope states that tie a named knot: made from its diagrams at its crossing number, enumerated above.

:func:`minimal_states` cuts KnotInfo's diagram of a table knot open on each edge (composites: the
summands' cut diagrams joined); :func:`states_tying` lists a knot name's states (reachable by moves,
both closures the knot) at a crossing count; :func:`least_crossings` is a goal's default crossing
count; :func:`rotations` cuts a closed diagram at each edge. The enumeration (:func:`states_by_type`)
remains for counts above a knot's crossing number and for the uniform goal sets.
``twisted.moves`` is imported inside the functions that use it.
"""

from __future__ import annotations

from functools import lru_cache

from twisted.knots.catalogue import CATALOGUE, crossing_number, knotinfo_name, resolve_knot
from twisted.knots.gauss import GaussCode, gauss_code_from_pd
from twisted.knots.identify_rope import identify
from twisted.knots.knotinfo import KNOTINFO, MAX_TABLE_CROSSINGS
from twisted.topology import EMPTY, PData, PDataError

__all__ = [
    "MAX_BUILT_CROSSINGS",
    "MAX_ENUMERATED_CROSSINGS",
    "least_crossings",
    "minimal_states",
    "prime_states_by_type",
    "primed_states",
    "rotations",
    "states_by_type",
    "states_tying",
]


# Enumerating every state stops here (5 crossings: 130,304 states, ~30 s); 6 would be millions.
MAX_ENUMERATED_CROSSINGS = 5
# Knot goals are made from diagrams up to the table's largest crossing number (see minimal_states).
MAX_BUILT_CROSSINGS = MAX_TABLE_CROSSINGS


# Sets handed in from elsewhere (the store's cache, twisted.store.knots): crossings -> type -> states
_PRIMED: dict[int, dict[str, tuple[PData, ...]]] = {}


@lru_cache(maxsize=16)
def _enumerated_by_type(crossings: int) -> dict[str, tuple[PData, ...]]:
    from twisted.moves import enumerate_states

    out: dict[str, list[PData]] = {}
    for p in enumerate_states(crossings)[crossings]:
        out.setdefault(identify(p).name, []).append(p)
    return {name: tuple(states) for name, states in out.items()}


def states_by_type(crossings: int) -> dict[str, tuple[PData, ...]]:
    """Every state of ``crossings`` crossings by what it ties (``RopeKnot.name``: a knot, ``"knotoid"``,
    ``"unknown"``), each list sorted by key: the sets :func:`prime_states_by_type` was given, else the
    enumeration (5 crossings: 130,304 states, a minute or more; cached per process)."""
    if crossings in _PRIMED:
        return _PRIMED[crossings]
    return _enumerated_by_type(crossings)


def primed_states(crossings: int) -> tuple[PData, ...] | None:
    """Every state of ``crossings`` crossings sorted by key when its sets were primed, else None."""
    if crossings not in _PRIMED:
        return None
    return tuple(sorted((p for states in _PRIMED[crossings].values() for p in states), key=lambda p: p.key))


def prime_states_by_type(crossings: int, by_type: dict[str, tuple[PData, ...]]) -> None:
    """Hand in the sets of :func:`states_by_type` computed before (the store keeps them: a 5-crossing
    knot's set-up is paid once per database, not once per process)."""
    _PRIMED[crossings] = dict(by_type)


def _shifted(p: PData, offset: int) -> list[tuple[int, int, int]]:
    return [(o + offset, u + offset, s) for o, u, s in p.crossings()]


def rotations(p: PData) -> list[PData]:
    """The open diagrams made by cutting the closure of ``p`` at each of its edges, in both directions.

    Meant for a state whose ends lie in one face: its closing arc then crosses nothing, the closed
    diagram has the same crossings, and cutting it at another edge gives a state with the same two
    closures (a rotation of the visit sequence; the reverse walks it tail to head). States that
    cannot be drawn are skipped.
    """
    return _drawable(_cuts(p))


def _cuts(p: PData, into: dict[str, PData] | None = None) -> dict[str, PData]:
    """The rotations of ``p``'s visit sequence, both ways, by key (added to ``into``), none drawn yet."""
    m = len(p.visits)
    out: dict[str, PData] = {} if into is None else into
    for r in range(max(m, 1)):
        q = PData.from_crossings([((o - 1 - r) % m + 1, (u - 1 - r) % m + 1, s) for o, u, s in p.crossings()])
        for candidate in (q, q.reverse()):
            out.setdefault(candidate.key, candidate)
    return out


def _drawable(candidates: dict[str, PData]) -> list[PData]:
    """The candidates a rope can have (:func:`twisted.moves.parse_state`: its diagram can be drawn)."""
    from twisted.moves import parse_state

    out = []
    for key in sorted(candidates):
        try:
            out.append(parse_state(candidates[key]))
        except PDataError:
            continue
    return out


def _cut(code: GaussCode) -> PData:
    """The open rope of a closed diagram cut just before its first event (walked from there)."""
    position: dict[tuple[int, bool], int] = {event: i + 1 for i, event in enumerate(code.events)}
    return PData.from_crossings(
        (position[(c, True)], position[(c, False)], s) for c, s in enumerate(code.signs)
    )


def _swapped(p: PData) -> PData:
    """Every O/U swapped, signs kept: the diagram reflected in the plane, then through it (the same knot)."""
    return PData.from_crossings((u, o, s) for o, u, s in p.crossings())


@lru_cache(maxsize=64)
def _diagram_states(knotinfo_name: str) -> dict[str, tuple[PData, ...]]:
    """The states cut from KnotInfo's diagram of a prime knot, by what they tie (``RopeKnot.name``).

    The diagram is KnotInfo's PD code; with it come its mirror image (every sign flipped) and, for each,
    the diagram reflected in the plane and through it (every O/U swapped, signs kept: the same knot, the
    shadow mirrored). Each is cut open on every edge, walked both ways (:func:`rotations`). A cut on an
    edge leaves both ends in the face the edge borders, for every choice of the outer face, so its
    closing arc crosses nothing and both closures are the diagram's knot; :func:`identify` checks it.
    """
    base = _cut(gauss_code_from_pd(KNOTINFO[knotinfo_name].pd))
    candidates: dict[str, PData] = {}
    for variant in (base, _swapped(base), base.mirror(), _swapped(base).mirror()):
        _cuts(variant, candidates)
    out: dict[str, list[PData]] = {}
    for q in _drawable(candidates):
        out.setdefault(identify(q).name, []).append(q)
    return {name: tuple(states) for name, states in out.items()}


@lru_cache(maxsize=64)
def minimal_states(knot_type: str) -> tuple[PData, ...]:
    """The states that tie table type ``knot_type`` at its crossing number, made from its diagrams.

    A prime knot: the cuts of KnotInfo's diagram (:func:`_diagram_states`). A composite: a state tying
    the first summand followed by one tying the second, every cut of that closed diagram, kept when both
    closures are the composite (:func:`_composite_states`). Nothing is enumerated. Sorted by key.
    """
    if knot_type not in CATALOGUE:
        raise ValueError(f"{knot_type!r} is not a table knot type")
    if knot_type == "0_1":
        return (EMPTY,)
    if "#" in knot_type:
        return _composite_states(knot_type)
    return _diagram_states(knotinfo_name(knot_type)).get(knot_type, ())


def _composite_states(knot_type: str) -> tuple[PData, ...]:
    """States that tie the composite ``knot_type`` at its crossing number, built from its summands.

    A minimal diagram of a connected sum of alternating knots is visibly composite (Menasco 1984): one
    summand's diagram, then the other's. So: a rope that ties the first summand (a cut diagram: its ends
    in one face) followed by a rope that ties the second, every cut of that closed diagram
    (:func:`rotations`), and only the states whose two closures are both ``knot_type`` are kept.
    """
    first, second = knot_type.split("#")
    candidates: dict[str, PData] = {}
    # the second summand's states before the first's: the same closed diagrams cut elsewhere
    for a in minimal_states(first):
        for b in minimal_states(second):
            _cuts(PData.from_crossings(_shifted(a, 0) + _shifted(b, len(a.visits))), candidates)
    return tuple(q for q in _drawable(candidates) if identify(q).name == knot_type)


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
    square, 7 for ``7_1`` or ``3_1#4_1``). At a type's crossing number the states are made from its
    diagrams (:func:`minimal_states`, nothing enumerated); below it no state ties the knot. Above it
    every state is enumerated, up to ``max_crossings`` (at most :data:`MAX_ENUMERATED_CROSSINGS`: 5
    crossings take tens of seconds, cached per count). Sorted by key.
    """
    types = resolve_knot(name)
    if crossings is None:
        crossings = least_crossings(name)
    if crossings < 0:
        raise ValueError(f"crossings must be >= 0, got {crossings}")
    found: list[PData] = []
    for t in sorted(types):
        least = crossing_number(t)
        if crossings == least:
            found.extend(minimal_states(t))
        elif crossings < least:
            continue  # a knot needs its crossing number (bench/bench_knots.py checks it up to 5)
        elif crossings > min(max_crossings, MAX_ENUMERATED_CROSSINGS):
            raise ValueError(
                f"{name}: states of {crossings} crossings (more than its crossing number {least}) would have "
                f"to be enumerated; at most {min(max_crossings, MAX_ENUMERATED_CROSSINGS)} are"
            )
        else:
            found.extend(states_by_type(crossings).get(t, ()))
    return sorted(found, key=lambda p: p.key)
