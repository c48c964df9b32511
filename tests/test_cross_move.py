"""The scripted Cross move curve (twisted.proposals), and the planner options that use it and the R1 room
(``--cross-move``, ``--r1-room``).

The rope configurations are made by the simulator from the straight rope with seeded curves, so each
test sees the same ropes every time.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from twisted.goals import PlanInputError
from twisted.moves import Move, successors
from twisted.planner import PlannerOptions, planner_options
from twisted.planner.options import N_LINKS as PLANNER_N_LINKS
from twisted.proposals import across_curve, cross_fit, cross_move_curve, segment_bounds
from twisted.sim import N_LINKS, RopeSim, sample_curve
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


def test_the_sign_fit_of_a_cross_move_and_of_its_other_sign_share_the_segment() -> None:
    """Every aimed point of the crossed segment gives one sign to a straight carry of the tip: the fits
    of a Cross move and of the same move with the other sign add up to 1 (the other side it arrives from).
    Where no point fits, the scripted curve is still drawn (aimed at any point of the segment)."""
    for n in (1, 2):
        _, points = _rope(n)
        moves = [move for _, move in _cross_moves(top(points))]
        assert moves
        twins = 0
        for move in moves:
            fit = cross_fit(points, move)
            assert 0.0 <= fit <= 1.0 and cross_fit(points, move, segment_bounds(points)) == fit
            where = (move.segment, move.other_segment, move.over)
            for twin in moves:  # the same crossing arriving from the other side, where the state allows both
                if (twin.segment, twin.other_segment, twin.over) == where and twin.sign != move.sign:
                    twins += 1
                    assert fit + cross_fit(points, twin) == pytest.approx(1.0)
        assert twins >= 4
        unfit = next(m for m in moves if cross_fit(points, m) == 0.0)
        assert isinstance(cross_move_curve(np.random.default_rng(0), points, unfit).link, int)


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


# ---- the planner's options for them ------------------------------------------------------------------
# (the parts that use them, ScriptedCross, StepCurves and R1Room, are tested in tests/test_strategies.py)


def test_the_cross_move_share_and_r1_room_are_checked_and_old_runs_resume_without_them() -> None:
    with pytest.raises(
        PlanInputError, match=r"cross_move must be a share of the K curves in \[0, 1\], got 1.5"
    ):
        planner_options({"cross_move": 1.5})
    with pytest.raises(PlanInputError, match=r"r1_room must be a number of links in \[0, 21\], got -1"):
        planner_options({"r1_room": -1.0})
    stored = PlannerOptions(cross_move=0.5, r1_room=4.0).to_dict()
    assert PlannerOptions.from_dict(stored).cross_move == 0.5
    del stored["cross_move"], stored["r1_room"]
    assert (
        PlannerOptions.from_dict(stored).cross_move == 0.0 and PlannerOptions.from_dict(stored).r1_room == 0.0
    )
    assert PLANNER_N_LINKS == N_LINKS  # the planner's copy of the rope's link count
