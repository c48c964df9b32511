"""Closed loop pulls the world's rope as soon as it ties the goal's knot, whatever its crossings
(docs/DESIGN.md section 15.4, ``twisted.experiments.episodes.ties_goal``)."""

from __future__ import annotations

from twisted.experiments.episodes import ties_goal
from twisted.goals import knot_goal, state_goal
from twisted.topology import parse_p_data

CURL = parse_p_data('[[1,"O",2,"+"],[2,"U",1,"+"]]')
# an overhand with three crossings more: both closures are the right-handed trefoil
TREFOIL_OF_6 = parse_p_data(
    '[[1,"U",8,"+"],[2,"O",9,"+"],[3,"U",6,"-"],[4,"U",11,"+"],[5,"O",12,"+"],[6,"O",3,"-"],'
    '[7,"O",10,"-"],[8,"O",1,"+"],[9,"U",2,"+"],[10,"U",7,"-"],[11,"O",4,"+"],[12,"U",5,"+"]]'
)
# two curls of opposite sign on one rope: two crossings, untied
TWO_CURLS = parse_p_data('[[1,"O",2,"+"],[2,"U",1,"+"],[3,"O",4,"-"],[4,"U",3,"-"]]')


def test_a_rope_that_ties_the_goals_knot_with_more_crossings_is_pulled() -> None:
    overhand = knot_goal("overhand")
    assert TREFOIL_OF_6 not in overhand and TREFOIL_OF_6.cross == 6
    assert ties_goal(overhand, TREFOIL_OF_6)
    assert all(ties_goal(overhand, p) for p in overhand.states)
    assert not ties_goal(overhand, CURL) and not ties_goal(knot_goal("figure-eight"), TREFOIL_OF_6)
    # a state goal asks for that diagram, not for what it ties
    assert not ties_goal(state_goal(CURL), TWO_CURLS) and ties_goal(state_goal(CURL), CURL)
