"""The kinematic drag prediction (twisted.drag): where a curve leaves the rope, without the simulator.

Ropes come from tests/test_cross_move.py's seeded simulator runs, so every test sees the same ones.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.test_cross_move import _cross_moves, _rope
from twisted.drag import DragPool, drag, predicted_states
from twisted.rope import LINK_SPACING_M, N_LINKS
from twisted.sim import Curve, RopeSim, sample_curve
from twisted.topology import top


def _curves(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.array([sample_curve(rng).to_array() for _ in range(n)])


def test_a_curve_that_does_not_move_its_link_leaves_the_rope_and_its_state_as_they_were() -> None:
    _, points = _rope(2)
    still = np.array([[link, 0.05, 0.0, 0.0] for link in range(N_LINKS)])
    xy, high = drag(points, still)
    assert np.allclose(xy, points[None, :, :2]) and high.max() > 0.0  # lifted, put back in place
    assert predicted_states(points, still) == [top(points)] * N_LINKS


def test_the_rope_follows_the_carried_link_without_stretching() -> None:
    _, points = _rope(1)
    curves = _curves(np.random.default_rng(0), 200)
    xy, _ = drag(points, curves)
    lengths = np.hypot(*np.moveaxis(np.diff(xy, axis=1), -1, 0))
    assert lengths.max() <= LINK_SPACING_M + 1e-9
    moved = np.hypot(*np.moveaxis(xy - points[None, :, :2], -1, 0))
    for m, (link, _, x, y) in enumerate(curves):  # the grasped link went where the curve said
        assert moved[m, int(link)] == pytest.approx(np.hypot(x, y))


def test_where_it_predicts_a_cross_move_the_simulator_makes_it_more_often_than_for_random_curves() -> None:
    """From the 1-crossing rope, 4,000 seeded uniform curves: those predicted to make one of the rope's
    Cross moves are simulated, and as many of the others. A predicted curve counts when it made its
    predicted state, another one when it made any of the Cross moves (when written: 20 of 34 against
    0 of 34)."""
    state, points = _rope(1)
    targets = {reached for reached, _ in _cross_moves(top(points))}
    curves = _curves(np.random.default_rng(5), 4000)
    predicted = predicted_states(points, curves)
    chosen = [m for m, p in enumerate(predicted) if p in targets]
    others = [m for m, p in enumerate(predicted) if p not in targets][: len(chosen)]
    sim = RopeSim()
    hits = {"predicted": 0, "others": 0}
    for name, group in (("predicted", chosen), ("others", others)):
        for m in group:
            sim.set_state(state)
            made = sim.p_data() if sim.apply(Curve.from_array(curves[m])).ok else None
            hits[name] += made == predicted[m] if name == "predicted" else made in targets
    assert len(chosen) >= 20
    assert hits["predicted"] >= max(10, 3 * hits["others"]), hits


def test_a_pool_names_the_curves_predicted_to_reach_a_state_and_is_the_same_for_a_seed() -> None:
    _, points = _rope(1)
    pool = DragPool(points, 2000, np.random.default_rng(7))
    assert np.array_equal(pool.curves, DragPool(points, 2000, np.random.default_rng(7)).curves)
    found = {reached: pool.reaching(reached) for reached, _ in _cross_moves(top(points))}
    target, reaching = max(found.items(), key=lambda item: len(item[1]))
    assert reaching == pool.reaching(target)  # the second time from the cache
    assert reaching and predicted_states(points, pool.curves[reaching]) == [target] * len(reaching)
    others = [m for m in range(2000) if m not in reaching][:50]
    assert target not in predicted_states(points, pool.curves[others])
    assert pool.curve(reaching[0]) == Curve.from_array(pool.curves[reaching[0]])
