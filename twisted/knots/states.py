"""The rope states that tie a named knot: enumerated up to 5 crossings, composites built at 6.

:func:`states_tying` lists them (reachable by moves, both closures the knot); :func:`least_crossings`
is a goal's default crossing count; :func:`rotations` cuts a closed diagram at each edge.
``twisted.moves`` is imported inside the functions that use it.
"""

from __future__ import annotations

from functools import lru_cache

from twisted.diagram import diagram
from twisted.knots.catalogue import crossing_number, resolve_knot
from twisted.knots.rope import identify
from twisted.topology import PData, PDataError

__all__ = [
    "MAX_BUILT_CROSSINGS",
    "MAX_ENUMERATED_CROSSINGS",
    "least_crossings",
    "prime_states_by_type",
    "primed_states",
    "rotations",
    "states_by_type",
    "states_tying",
]


# Enumerating every state stops here (5 crossings: 130,304 states, ~30 s); 6 would be millions.
MAX_ENUMERATED_CROSSINGS = 5
# Composite knots are built up to this many crossings (see _composite_states).
MAX_BUILT_CROSSINGS = 6


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
        heads = [p for p in states_by_type(crossing_number(order[0])).get(order[0], ()) if _ends_together(p)]
        tails = [p for p in states_by_type(crossing_number(order[1])).get(order[1], ()) if _ends_together(p)]
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
            found.extend(states_by_type(crossings).get(t, ()))
    return sorted(found, key=lambda p: p.key)
