"""The scripted Cross move curve (twisted.proposals) and the planner's use of it (``--cross-move``);
the node choice for an R1 step by the room its segment leaves for the curl (``--r1-room``).

The rope configurations are made by the simulator from the straight rope with seeded curves, so each
test sees the same ropes every time.
"""

from __future__ import annotations

from collections import Counter
from functools import cache
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from twisted.goals import PlanInputError, check_goal
from twisted.moves import Move, plans, successors
from twisted.planner import Node, PlannerOptions, SearchTree, Twisted, planner_options
from twisted.planner.search import N_LINKS as SEARCH_N_LINKS
from twisted.planner.search import R1_ROOM_FLOOR
from twisted.proposals import across_curve, cross_move_curve, segment_bounds
from twisted.sim import N_LINKS, Curve, RopeSim, sample_curve
from twisted.topology import PData, top


@cache
def rope_with_crossings(n: int) -> tuple[bytes, bytes]:
    """A simulated rope configuration (state, link points) with exactly ``n`` crossings: seeded across
    curves from the straight rope, each continuing from the last result that kept its crossings."""
    sim = RopeSim()
    rng = np.random.default_rng(11)
    sim.reset()
    state, cross = sim.state(), 0
    for _ in range(400):
        sim.set_state(state)
        if not sim.apply(across_curve(rng, sim.link_points())).ok:
            continue
        reached = sim.p_data().cross
        if reached == n:
            return sim.state().tobytes(), sim.link_points().tobytes()
        if cross <= reached < n:
            state, cross = sim.state(), reached
    raise AssertionError(f"no rope with {n} crossings in 400 curves")


def _rope(n: int) -> tuple[np.ndarray, np.ndarray]:
    state, points = rope_with_crossings(n)
    return np.frombuffer(state, dtype=np.float64).copy(), np.frombuffer(points, dtype=np.float64).reshape(
        -1, 3
    )


def _cross_moves(p: PData) -> list[tuple[PData, Move]]:
    return [(s.state, s.move) for s in successors(p) if s.move.kind == "Cross"]


def _at(points: np.ndarray, s: float) -> np.ndarray:
    i = min(int(s), len(points) - 2)
    return points[i] + (s - i) * (points[i + 1] - points[i])


def test_segment_bounds_are_the_crossing_visits_in_walking_order() -> None:
    _, points = _rope(2)
    p = top(points)
    bounds = segment_bounds(points)
    assert len(bounds) == 2 * p.cross + 2
    assert bounds[0] == 0.0 and bounds[-1] == N_LINKS and np.all(np.diff(bounds) > 0)
    # the two visits of each crossing lie at one point of the table
    for visit in p.visits:
        a, b = _at(points, bounds[visit.position]), _at(points, bounds[visit.partner])
        assert np.allclose(a[:2], b[:2], atol=1e-9), visit


def test_a_cross_move_curve_carries_the_tip_over_or_the_crossed_segment_over_the_tip() -> None:
    _, points = _rope(2)
    p = top(points)
    bounds = segment_bounds(points)
    rng = np.random.default_rng(0)
    moves = _cross_moves(p)
    assert {m.over for _, m in moves} == {"O", "U"} and {m.segment for _, m in moves} == {0, 2 * p.cross}
    for _, move in moves:
        head = move.segment == 0
        tip = points[0] if head else points[-1]
        for _ in range(10):
            curve = cross_move_curve(rng, points, move)
            centre = 0.5 * (points[curve.link, :2] + points[curve.link + 1, :2])
            target = centre + np.array([curve.x_m, curve.y_m])
            assert 0.03 <= curve.z_max_m <= 0.07  # lifted: over the strand it crosses, never pushing it
            if move.over == "O":
                assert curve.link in ((0, 1) if head else (N_LINKS - 1, N_LINKS - 2))
            else:
                # a link of segment b, put down beyond the tip, on the far side from where it was
                lo, hi = bounds[move.other_segment], bounds[move.other_segment + 1]
                assert int(lo) <= curve.link <= int(hi)
                assert np.dot(target - tip[:2], tip[:2] - centre) > 0


def test_a_move_that_is_not_a_cross_of_this_rope_is_refused() -> None:
    _, points = _rope(1)
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="not a Cross move"):
        cross_move_curve(rng, points, Move("R1", 0, side="L", sign="+", over="O"))
    with pytest.raises(ValueError, match="does not fit a rope with 1 crossings"):
        cross_move_curve(rng, points, Move("Cross", 6, sign="+", over="O", other_segment=1, other_side="L"))


def test_cross_move_curves_make_their_move_in_the_simulator_more_often_than_random_curves() -> None:
    """From a 1-crossing rope, 6 scripted and 6 uniform random curves toward each of its 12 Cross moves
    (over many seeded ropes: 8 % to 40 % of the scripted curves make their move at one crossing, 0 % to
    13 % at two; about 1 % of the random ones)."""
    state, points = _rope(1)
    p = top(points)
    sim = RopeSim()
    rng = np.random.default_rng(3)
    hits = {"scripted": 0, "random": 0}
    moves = _cross_moves(p)
    for reached, move in moves:
        for name in hits:
            for _ in range(6):
                curve = cross_move_curve(rng, points, move) if name == "scripted" else sample_curve(rng)
                sim.set_state(state)
                if sim.apply(curve).ok and sim.p_data() == reached:
                    hits[name] += 1
    assert len(moves) == 12
    assert hits["scripted"] >= 5 and hits["scripted"] >= 3 * max(1, hits["random"]), hits


# ---- the planner --------------------------------------------------------------------------------


class _CountingSampler:
    """The planner's sampler protocol, counting the curves asked of it."""

    name = "counting"

    def __init__(self) -> None:
        self.asked = 0

    def sample(
        self, node: Any, next_state: PData, move: Any, n: int, rng: np.random.Generator
    ) -> list[Curve]:
        self.asked += n
        return [sample_curve(rng) for _ in range(n)]


def _search(planner: str, share: float, n: int = 1) -> tuple[Twisted, _CountingSampler]:
    state, points = _rope(n)
    p = top(points)
    tree = SearchTree()
    tree.add(Node(0, None, state, points, p, None, 0, 0))
    goal = check_goal(_cross_moves(p)[0][0].to_json())
    sampler = _CountingSampler()
    options = PlannerOptions(planner=planner, k=3, cross_move=share, r1_room=0.0, seed=1)
    search = Twisted(
        goal, tree, options, pool=None, high_level=lambda s: plans(s, goal, 100), sampler=sampler
    )  # type: ignore[arg-type]
    return search, sampler


@pytest.mark.parametrize(
    ("planner", "share", "scripted"),
    [("twisted", 0.67, 2), ("twisted", 1.0, 3), ("twisted", 0.0, 0), ("sac", 1.0, 0)],
)
def test_a_step_toward_a_cross_move_takes_its_share_of_scripted_curves(
    planner: str, share: float, scripted: int
) -> None:
    search, sampler = _search(planner, share)
    node = search.tree.nodes[0]
    reached, move = _cross_moves(node.p_data)[0]
    curves, made = search.step_curves(node, reached, move)
    assert len(curves) == 3 and made == scripted and sampler.asked == 3 - scripted
    # a step toward any other move takes every curve from the sampler
    r1 = next(s for s in successors(node.p_data) if s.move.kind == "R1")
    curves, made = search.step_curves(node, r1.state, r1.move)
    assert len(curves) == 3 and made == 0 and sampler.asked == 6 - scripted


def test_the_cross_move_share_is_checked_and_runs_stored_before_it_had_none() -> None:
    with pytest.raises(PlanInputError, match=r"cross_move must lie in \[0, 1\], got 1.5"):
        planner_options({"cross_move": 1.5})
    stored = PlannerOptions(cross_move=0.5).to_dict()
    assert PlannerOptions.from_dict(stored).cross_move == 0.5
    del stored["cross_move"]
    assert PlannerOptions.from_dict(stored).cross_move == 0.0


# ---- R1 room: the node choice for a curl ----------------------------------------------------------


def test_the_r1_room_weight_is_the_squared_share_of_the_room_asked_for() -> None:
    search, _ = _search("twisted", 0.0)
    search = Twisted(
        search.goal, search.tree, PlannerOptions(r1_room=8.0), pool=None, high_level=search.high_level
    )  # type: ignore[arg-type]
    node = search.tree.nodes[0]
    bounds = segment_bounds(node.points)
    for segment in range(len(bounds) - 1):
        length = bounds[segment + 1] - bounds[segment]
        expected = max(R1_ROOM_FLOOR, min(1.0, length / 8.0) ** 2)
        assert search.r1_room_weight(node, segment) == pytest.approx(expected)


def test_an_r1_step_goes_to_the_nodes_with_room_for_the_curl() -> None:
    """Two nodes of one state: the plan's R1 segment spans 2 links in one and 8 in the other."""
    search, _ = _search("twisted", 0.0)
    node = search.tree.nodes[0]
    search.tree.add(Node(1, 0, node.q, node.points, node.p_data, None, 0, 0))
    r1 = next(s for s in successors(node.p_data) if s.move.kind == "R1" and s.move.segment == 1)
    bounds = np.array([0.0, 5.0, 7.0, 15.0, 21.0])
    search._bounds = {0: bounds, 1: np.array([0.0, 5.0, 13.0, 15.0, 21.0])}
    counts = Counter(
        search.select_configuration(node.p_data.key, r1.state, r1.move).index for _ in range(3000)
    )
    assert counts[0] / 3000 == pytest.approx(0.5, abs=0.03)  # off: uniform
    search.options = PlannerOptions(r1_room=8.0)
    counts = Counter(
        search.select_configuration(node.p_data.key, r1.state, r1.move).index for _ in range(3000)
    )
    share = (2 / 8) ** 2 / ((2 / 8) ** 2 + 1.0)
    assert counts[0] / 3000 == pytest.approx(share, abs=0.02), counts
    # a Cross step is not weighted by room
    cross = _cross_moves(node.p_data)[0]
    counts = Counter(
        search.select_configuration(node.p_data.key, cross[0], cross[1]).index for _ in range(3000)
    )
    assert counts[0] / 3000 == pytest.approx(0.5, abs=0.03), counts


def test_plans_and_states_go_where_some_node_has_room_for_the_curl() -> None:
    """A state whose plans start with an R1 curl on segment 1 (2 links in its one node) or a Cross
    move: the curl's plan, and the state for it, weigh (2/8)**2; a second node with room lifts both."""
    search, _ = _search("twisted", 0.0)
    node = search.tree.nodes[0]
    key = node.p_data.key
    r1 = next(s for s in successors(node.p_data) if s.move.kind == "R1" and s.move.segment == 1)
    cross = _cross_moves(node.p_data)[0]
    curl_plan = SimpleNamespace(states=[node.p_data, r1.state], moves=[r1.move])
    cross_plan = SimpleNamespace(states=[node.p_data, cross[0]], moves=[cross[1]])
    search.plans = {key: [curl_plan, cross_plan]}
    search._bounds = {0: np.array([0.0, 5.0, 7.0, 15.0, 21.0])}
    picks = Counter(search.select_plan(key)[0] for _ in range(3000))
    assert picks[0] / 3000 == pytest.approx(0.5, abs=0.03)  # off: uniform
    search.options = PlannerOptions(r1_room=8.0)
    assert search.plan_rooms(key) == pytest.approx([(2 / 8) ** 2, 1.0])
    picks = Counter(search.select_plan(key)[0] for _ in range(3000))
    assert picks[0] / 3000 == pytest.approx((2 / 8) ** 2 / ((2 / 8) ** 2 + 1.0), abs=0.02), picks
    search.plans = {key: [curl_plan]}  # the state's weight is its best plan's room
    search._plan_rooms.clear()
    assert search.plan_rooms(key) == pytest.approx([(2 / 8) ** 2])
    search.tree.add(Node(1, 0, node.q, node.points, node.p_data, None, 0, 0))
    search._bounds[1] = np.array([0.0, 5.0, 13.0, 15.0, 21.0])
    assert search.plan_rooms(key) == [1.0]  # the cache follows the state's nodes


def test_a_state_whose_nodes_leave_no_room_for_its_curls_is_chosen_less() -> None:
    search, _ = _search("twisted", 0.0)
    node = search.tree.nodes[0]
    r1 = next(s for s in successors(node.p_data) if s.move.kind == "R1" and s.move.segment == 1)
    cross = _cross_moves(r1.state)[0]
    search.tree.add(Node(1, 0, node.q, node.points, r1.state, None, 0, 0))
    a, b = node.p_data, r1.state
    search.plans = {
        a.key: [SimpleNamespace(states=[a, r1.state], moves=[r1.move])],
        b.key: [SimpleNamespace(states=[b, cross[0]], moves=[cross[1]])],
    }
    search._bounds = {0: np.array([0.0, 5.0, 7.0, 15.0, 21.0])}  # segment 1 of a: 2 links
    weights = {a.key: 1.0 + a.cross, b.key: 1.0 + b.cross}
    for room, r1_room in ((1.0, 0.0), ((2 / 8) ** 2, 8.0)):
        search.options = PlannerOptions(r1_room=r1_room)
        picks = Counter(search.select_topological_state() for _ in range(3000))
        share = weights[a.key] * room / (weights[a.key] * room + weights[b.key])
        assert picks[a.key] / 3000 == pytest.approx(share, abs=0.025), (r1_room, picks)


def test_r1_room_is_checked_and_runs_stored_before_it_choose_without_it() -> None:
    with pytest.raises(PlanInputError, match=r"r1_room must be a number of links in \[0, 21\], got -1"):
        planner_options({"r1_room": -1.0})
    stored = PlannerOptions(r1_room=8.0).to_dict()
    del stored["r1_room"]
    assert PlannerOptions.from_dict(stored).r1_room == 0.0
    assert SEARCH_N_LINKS == N_LINKS  # the planner's copy of the rope's link count
