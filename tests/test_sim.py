"""The MuJoCo rope: model, link points, determinism, a designed crossing, friction, rejection, pool."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twisted.sim import (
    CURVE_HIGH,
    CURVE_LOW,
    N_LINKS,
    N_POINTS,
    Curve,
    CurveOutcome,
    RopeSim,
    SimPool,
    sample_curve,
    simulate,
)
from twisted.sim.mjcf import RopeParams
from twisted.sim.simulator import LINK_RADIUS_M, MIN_LIFT_M, RELEASE_HEIGHT_M
from twisted.topology import EMPTY, parse_p_data

# Two hand-designed curves: pull the middle link sideways (a V with both arms ending near y=0),
# then carry the head high over the other arm. Neighbouring values give the same result, so the
# test does not hang on a knife edge of the physics.
MAKE_V = Curve(link=10, z_max_m=0.02, x_m=0.0, y_m=0.3)
HEAD_OVER_ARM = Curve(link=0, z_max_m=0.06, x_m=0.5, y_m=0.25)


@pytest.fixture(scope="module")
def sim() -> RopeSim:
    return RopeSim()


@pytest.fixture(scope="module")
def v_state(sim: RopeSim) -> np.ndarray:
    sim.reset()
    assert sim.apply(MAKE_V).ok
    return sim.state()


def test_model_builds_and_straight_rope_has_no_crossings(sim: RopeSim) -> None:
    sim.reset()
    assert (sim.model.nq, sim.model.nv) == (47, 46)
    assert sim.state().shape == (93,) and sim.state().dtype == np.float64
    assert sim.p_data() == EMPTY
    # the gripper can never touch the rope: it has no geom
    assert sim.model.body_geomnum[sim.model.body("gripper").id] == 0


def test_link_points_run_head_to_tail_along_the_rope(sim: RopeSim) -> None:
    sim.reset()
    pts = sim.link_points()
    assert pts.shape == (N_POINTS, 3) == (22, 3)
    np.testing.assert_allclose(pts[:, 0], np.linspace(-0.42, 0.42, N_POINTS), atol=1e-6)
    np.testing.assert_allclose(pts[:, 1], 0.0, atol=1e-6)
    np.testing.assert_allclose(pts[:, 2], LINK_RADIUS_M, atol=5e-4)  # resting on the table
    assert np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)) == pytest.approx(0.84, abs=1e-3)
    # the head (point 0) is the tip of link 0: carrying link 0 sideways moves it, not the tail
    assert sim.apply(Curve(0, 0.02, 0.0, 0.2)).ok
    moved = sim.link_points() - pts
    assert moved[0, 1] > 0.15
    assert np.linalg.norm(moved[-1]) < 0.25 * np.linalg.norm(moved[0])
    link0 = sim.data.body("link_0").xpos
    assert np.linalg.norm(link0 - (sim.link_points()[0] + sim.link_points()[1]) / 2) < 1e-9


def test_state_round_trip_and_shape_error(sim: RopeSim, v_state: np.ndarray) -> None:
    sim.set_state(v_state)
    assert sim.state().tobytes() == v_state.tobytes()
    with pytest.raises(ValueError, match="93 floats"):
        sim.set_state(np.zeros(47))


def test_apply_is_deterministic_across_instances(sim: RopeSim, v_state: np.ndarray) -> None:
    curve = Curve(link=5, z_max_m=0.05, x_m=0.1, y_m=-0.3)
    sim.set_state(v_state)
    first = sim.apply(curve)
    after_first = sim.state()
    # dirty the solver's warm start and the gripper with another action, then repeat
    sim.apply(Curve(17, 0.07, -0.2, 0.2))
    sim.set_state(v_state)
    second = sim.apply(curve)
    assert first.ok and first == second
    assert sim.state().tobytes() == after_first.tobytes()
    other = RopeSim()
    other.set_state(v_state)
    assert other.apply(curve) == first
    assert other.state().tobytes() == after_first.tobytes()


def test_head_carried_over_the_rope_makes_one_crossing(sim: RopeSim, v_state: np.ndarray) -> None:
    sim.set_state(v_state)
    assert sim.p_data() == EMPTY
    outcome = sim.apply(HEAD_OVER_ARM)
    assert outcome.ok, outcome.reason
    # head passes over the other arm; the sign follows from the directions (see topology tests)
    assert sim.p_data() == parse_p_data([[1, "O", 2, "+"], [2, "U", 1, "+"]])
    # settled: nothing moves faster than a few cm/s, the upper strand lies on the lower one
    assert np.abs(sim.data.qvel[:3]).max() < 0.05
    z = sim.link_points()[:, 2]
    assert z.max() == pytest.approx(3 * LINK_RADIUS_M, abs=0.004)
    assert sim.data.contact.dist[: sim.data.ncon].min() > -LINK_RADIUS_M / 2


def test_gripper_path_lifts_carries_and_lowers(sim: RopeSim) -> None:
    sim.reset()
    start = sim.data.body("link_4").xpos.copy()
    for z_max in (0.0, 0.05):
        path = sim.gripper_path(Curve(4, z_max, 0.3, -0.2))
        np.testing.assert_allclose(path[-1, :2], start[:2] + [0.3, -0.2], atol=1e-12)
        assert path[-1, 2] == pytest.approx(RELEASE_HEIGHT_M)
        assert np.linalg.norm(path[0] - start) < 1e-3  # starts where the link lies
        # z_max = 0 still lifts the link off the table by MIN_LIFT_M (above the straight line down)
        assert path[:, 2].max() >= start[2] + z_max + MIN_LIFT_M - 1e-4
        speed = np.linalg.norm(np.diff(path, axis=0), axis=1) / sim.model.opt.timestep
        assert 0.2 < np.mean(speed) < 0.4 and speed.max() < 0.8  # about 0.3 m/s, smooth


def test_gripper_path_can_be_slowed_to_a_least_duration(sim: RopeSim) -> None:
    sim.reset()
    curve = Curve(4, 0.03, 0.3, -0.2)
    plain = sim.gripper_path(curve)
    np.testing.assert_array_equal(sim.gripper_path(curve, min_duration_s=0.1), plain)  # shorter: no change
    slow = sim.gripper_path(curve, min_duration_s=3.0)
    assert len(slow) == round(3.0 / sim.model.opt.timestep) > len(plain)
    np.testing.assert_allclose(slow[-1], plain[-1], atol=1e-12)  # the same line to the same target
    assert slow[:, 2].max() == pytest.approx(plain[:, 2].max(), abs=1e-4)


def test_a_curve_reports_its_settling_steps_and_a_looser_rest_settles_sooner(sim: RopeSim) -> None:
    curve = Curve(4, 0.03, 0.3, -0.2)
    sim.reset()
    out = sim.apply(curve)
    assert out.ok and 0 < out.settle_steps < out.steps
    assert out.steps - out.settle_steps <= len(sim.gripper_path(curve))  # the rest is the carry
    loose = RopeSim()
    loose.settle_speed_m_s = 10 * sim.settle_speed_m_s
    loose.reset()
    quick = loose.apply(curve)
    assert quick.ok and quick.steps - quick.settle_steps == out.steps - out.settle_steps
    assert 2 * loose.window_steps <= quick.settle_steps < out.settle_steps


def test_a_watch_sees_the_release_and_every_settling_window_and_changes_nothing(sim: RopeSim) -> None:
    curve = Curve(4, 0.03, 0.3, -0.2)
    sim.reset()
    plain = sim.apply(curve)
    after = sim.state()
    seen: list[int] = []

    def record(points: np.ndarray, steps: int) -> None:
        assert points.shape == (N_LINKS + 1, 3)
        seen.append(steps)

    sim.reset()
    watched = sim.apply(curve, record)
    np.testing.assert_array_equal(sim.state(), after)
    assert watched == plain
    carry = plain.steps - plain.settle_steps
    assert seen == [carry + k * sim.window_steps for k in range(len(seen))]
    assert seen[-1] == plain.steps  # the last window is the one the rope came to rest in


def test_grasp_welds_exactly_one_link(sim: RopeSim) -> None:
    sim.reset()
    sim.grasp(7)
    # the grasp welds come first; the second hand's (two-hand curves, tests/test_pin.py) after them
    assert sim.data.eq_active.tolist() == [int(i == 7) for i in range(N_LINKS)] + [0] * N_LINKS
    np.testing.assert_array_equal(sim.data.mocap_pos[0], sim.data.body("link_7").xpos)
    sim.grasp(3)
    assert sim.data.eq_active.tolist() == [int(i == 3) for i in range(N_LINKS)] + [0] * N_LINKS
    sim.release()
    assert not sim.data.eq_active.any()


def test_friction_scale_scales_every_geom_friction() -> None:
    base = RopeSim().model.geom_friction
    assert np.all(base[:, 0] > 0)
    np.testing.assert_allclose(RopeSim(friction_scale=1.05).model.geom_friction, 1.05 * base)
    np.testing.assert_allclose(RopeSim(friction_scale=0.95).model.geom_friction, 0.95 * base)
    with pytest.raises(ValueError, match="friction_scale"):
        RopeSim(friction_scale=0.0)


def test_invalid_start_states_are_rejected(sim: RopeSim) -> None:
    sim.reset()
    q = sim.state()
    q[5] = np.nan
    sim.set_state(q)
    outcome = sim.apply(Curve(3, 0.03, 0.1, 0.1))
    assert not outcome.ok and "NaN" in (outcome.reason or "")
    sim.reset()
    q = sim.state()
    q[0] = 2.0  # middle link 2 m from the origin
    sim.set_state(q)
    outcome = sim.apply(Curve(3, 0.03, 0.1, 0.1))
    assert not outcome.ok and "workspace" in (outcome.reason or "")


def test_wild_curves_are_rejected_not_kept(
    sim: RopeSim, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)  # MuJoCo appends its divergence warning to ./MUJOCO_LOG.TXT
    sim.reset()
    outcome = sim.apply(Curve(0, 0.07, 5.0, -5.0))
    assert outcome == CurveOutcome(False, outcome.reason, 0)
    assert "outside the workspace" in (outcome.reason or "")
    # lifted 0.5 m: the rope leaves the workspace in the air and is stopped there, mid-path
    sim.reset()
    curve = Curve(0, 0.5, 0.0, 0.0)
    n_path = len(sim.gripper_path(curve))
    outcome = sim.apply(curve)
    assert not outcome.ok and "flew up" in (outcome.reason or "")
    assert 0 < outcome.steps < n_path
    # a rope thrown at 1e6 m/s trips MuJoCo's divergence guard, which resets the data and goes on:
    # that must not pass as a result
    sim.reset()
    q = sim.state()
    q[sim.model.nq] = 1e6  # x velocity of the middle link
    sim.set_state(q)
    outcome = sim.apply(Curve(20, 0.0, 0.0, 0.0))
    assert not outcome.ok and "diverged" in (outcome.reason or "")


def test_curve_array_round_trip_and_validation() -> None:
    c = Curve(7, 0.03, -0.2, 0.4)
    assert Curve.from_array(c.to_array()) == c
    assert c.to_array().dtype == np.float64
    with pytest.raises(ValueError, match="0..20"):
        Curve(21, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="finite"):
        Curve(1, float("nan"), 0.0, 0.0)
    assert Curve(1, 0.5, -3.0, 0.1).clipped() == Curve(1, 0.07, -0.5, 0.1)
    rng = np.random.default_rng(3)
    arr = np.array([sample_curve(rng).to_array() for _ in range(500)])
    assert np.all(arr >= CURVE_LOW) and np.all(arr <= CURVE_HIGH)
    assert set(arr[:, 0].astype(int)) == set(range(N_LINKS))


def test_pool_matches_in_process_simulate(v_state: np.ndarray) -> None:
    rng = np.random.default_rng(11)
    jobs = [(v_state, sample_curve(rng)) for _ in range(5)] + [(v_state, Curve(0, 0.07, 5.0, 5.0))]
    local = [simulate(RopeSim(), s, c) for s, c in jobs]
    with SimPool(workers=2) as pool:
        remote = pool.run(jobs)
    with SimPool(workers=0) as pool:
        inline = pool.run(jobs)
    for a, b, c in zip(local, remote, inline, strict=True):
        for r in (b, c):
            assert (r.ok, r.reason, r.steps, r.p_data) == (a.ok, a.reason, a.steps, a.p_data)
            if a.ok:
                assert a.state is not None and r.state is not None
                assert r.state.tobytes() == a.state.tobytes()
                assert a.points is not None and r.points is not None
                np.testing.assert_array_equal(r.points, a.points)
    assert not local[-1].ok and local[-1].state is None


@pytest.mark.parametrize(("radius_m", "z_m", "deep"), [(0.011, 0.0005, False), (0.011, -0.0003, True)])
def test_how_deep_a_rope_may_sink_is_in_its_own_radius(radius_m: float, z_m: float, deep: bool) -> None:
    """A world's thicker rope sunk 10.5 mm into the table is within its 11 mm radius (the planner's
    10 mm bound would reject it); 11.3 mm is past it."""
    sim = RopeSim(params=RopeParams(link_radius_m=radius_m))
    q = sim.state()
    q[2] = z_m  # the middle link's free joint: the straight rope's centreline height
    sim.set_state(q)
    reason = sim.invalid_reason()
    assert (reason is not None and reason.startswith("deep penetration")) is deep, reason


def test_the_planners_rope_keeps_its_bound_of_one_radius() -> None:
    sim = RopeSim()
    q = sim.state()
    q[2] = LINK_RADIUS_M - 0.0105  # 10.5 mm into the table: deeper than the 10 mm radius
    sim.set_state(q)
    assert sim.invalid_reason() == "deep penetration (0.0105 m > 0.01 m)"
