"""Untie and retie: plans both ways in the plan cache, and searches from a stored rope to any goal."""

from __future__ import annotations

from sqlalchemy import select

from twisted.moves import plans, plans_both_ways
from twisted.store import open_store
from twisted.store.plans import BOTH_WAYS_SUFFIX, PlanQuery, cached_plans
from twisted.topology import EMPTY, parse_p_data

OVERHAND = parse_p_data(
    '[[1,"O",4,"+"],[2,"U",5,"+"],[3,"O",6,"+"],[4,"U",1,"+"],[5,"O",2,"+"],[6,"U",3,"+"]]'
)
CURL = parse_p_data('[[1,"U",2,"+"],[2,"O",1,"+"]]')


def test_both_ways_answers_are_cached_apart_from_adding_only_ones(sqlite_url: str) -> None:
    """An adding-only query keeps its key (the goal's), so answers stored before removing moves
    existed stay valid; the both-ways answer to the same (start, goal) sits beside it."""
    with open_store(sqlite_url) as store:
        adding = cached_plans(store, EMPTY, OVERHAND, 10)
        both = cached_plans(store, EMPTY, OVERHAND, 10, both_ways=True)
        untie = cached_plans(store, OVERHAND, EMPTY, 10, both_ways=True)
        assert adding == plans(EMPTY, OVERHAND, 10)
        assert both == plans_both_ways(EMPTY, [OVERHAND], 10)
        assert untie == plans_both_ways(OVERHAND, [EMPTY], 10) and untie
        assert all(m.remove for m in untie[0].moves)
        assert cached_plans(store, OVERHAND, EMPTY, 10) == []  # adding moves never untie
        with store.session() as session:
            keys = sorted((q.start_key, q.goal_key) for q in session.scalars(select(PlanQuery)))
        assert keys == sorted(
            [
                ("[]", OVERHAND.key),
                ("[]", OVERHAND.key + BOTH_WAYS_SUFFIX),
                (OVERHAND.key, "[]" + BOTH_WAYS_SUFFIX),
                (OVERHAND.key, "[]"),
            ]
        )
    with open_store(sqlite_url) as store:  # a hit reads the stored removing moves back
        assert cached_plans(store, OVERHAND, EMPTY, 10, both_ways=True) == untie
