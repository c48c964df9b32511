"""RopeKnotEnv: the Gymnasium contract, seeded replay, rewards, goal sources, failed curves."""

from __future__ import annotations

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="the rl extra (gymnasium) is not installed")

from gymnasium.utils.env_checker import check_env  # noqa: E402

from twisted.envs import (  # noqa: E402
    ENV_ID,
    GoalError,
    RopeKnotEnv,
    action_to_curve,
    curve_to_action,
    goal_pool,
)
from twisted.model.encoding import encode_p_data  # noqa: E402
from twisted.sim import CURVE_HIGH, CURVE_LOW, Curve, RopeSim  # noqa: E402
from twisted.topology import parse_p_data  # noqa: E402

ONE = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
ONE_MINUS = '[[1,"O",2,"-"],[2,"U",1,"-"]]'


def _rollout(env: RopeKnotEnv, actions: np.ndarray) -> list[tuple]:
    out = []
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        out.append((obs, reward, terminated, truncated, info["cross"], info["curve_failed"]))
        if terminated or truncated:
            break
    return out


def test_registered_and_passes_env_checker() -> None:
    env = gym.make(ENV_ID, max_curves=3)
    assert isinstance(env.unwrapped, RopeKnotEnv)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_reset_seed_replays_goal_observation_and_trajectory() -> None:
    env = RopeKnotEnv(max_curves=4)
    actions = np.random.default_rng(7).uniform(-1, 1, size=(4, 4)).astype(np.float32)
    runs = []
    for _ in range(2):
        obs, info = env.reset(seed=11)
        runs.append((env.goal, obs, _rollout(env, actions)))
    (g1, o1, t1), (g2, o2, t2) = runs
    assert g1 == g2
    for key in o1:
        np.testing.assert_array_equal(o1[key], o2[key])
    assert len(t1) == len(t2)
    for s1, s2 in zip(t1, t2, strict=True):
        for key in s1[0]:
            np.testing.assert_array_equal(s1[0][key], s2[0][key])
        assert s1[1:] == s2[1:]
    # different seeds draw different goals (over a few seeds at least one differs)
    goals = {env.reset(seed=s)[1]["goal_cross"] for s in range(12)}
    assert goals == {1, 2, 3}


def test_compute_reward_agrees_with_step_rewards_and_is_vectorised() -> None:
    env = RopeKnotEnv(goals=[ONE, ONE_MINUS], max_curves=6)
    rng = np.random.default_rng(3)
    achieved, desired, rewards = [], [], []
    for episode in range(3):
        env.reset(seed=episode)
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 4))
            assert reward == env.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)
            assert (reward == 0.0) == info["is_success"] == terminated
            achieved.append(obs["achieved_goal"])
            desired.append(obs["desired_goal"])
            rewards.append(reward)
            done = terminated or truncated
    batch = env.compute_reward(np.stack(achieved), np.stack(desired), [{}] * len(rewards))
    np.testing.assert_array_equal(batch, np.array(rewards, dtype=np.float32))
    # relabelled with its own achieved goal, every transition succeeds
    np.testing.assert_array_equal(env.compute_reward(np.stack(achieved), np.stack(achieved), None), 0.0)


def test_goal_reached_terminates_with_reward_zero() -> None:
    """Drive the rope with the curve that tied a 1-crossing state in the sim, as an action."""
    sim = RopeSim()
    rng = np.random.default_rng(0)
    for _ in range(200):  # find a random curve from the straight rope that makes one crossing
        sim.reset()
        curve = Curve(int(rng.integers(0, 21)), *rng.uniform(CURVE_LOW[1:], CURVE_HIGH[1:]))
        if sim.apply(curve).ok and sim.p_data().cross == 1:
            break
    else:
        pytest.fail("no random curve made a crossing")
    goal = sim.p_data()
    env = RopeKnotEnv(goals=[goal])
    env.reset(seed=0)
    action = curve_to_action(curve, env.sim.link_points())
    obs, reward, terminated, truncated, info = env.step(action)
    assert info["cross"] == 1 and env.p_data == goal
    assert (reward, terminated, truncated, info["is_success"]) == (0.0, True, False, True)
    np.testing.assert_array_equal(obs["achieved_goal"], encode_p_data(goal))


def test_truncates_after_max_curves_and_failed_curve_restores_the_state() -> None:
    env = RopeKnotEnv(goals=[ONE], max_curves=2)
    env.reset(seed=0)
    pull = np.array(
        [-1.0, 1.0, -1.0, 0.0], dtype=np.float32
    )  # head link, highest lift, 0.5 m away from the tail
    _, r1, term1, trunc1, info1 = env.step(pull)
    assert (r1, term1, trunc1, info1["curve_failed"]) == (-1.0, False, False, False)
    points, q = env.sim.link_points(), env.sim.state()
    # the head now lies about 0.9 m out: pulled 0.5 m further it would end outside the 1.2 m workspace
    _, r2, term2, trunc2, info2 = env.step(pull)
    assert info2["curve_failed"] and "workspace" in info2["reason"]
    assert (r2, term2, trunc2, info2["curves"]) == (-1.0, False, True, 2)
    np.testing.assert_array_equal(env.sim.state(), q)
    np.testing.assert_array_equal(env.sim.link_points(), points)


def test_action_curve_mapping_round_trips_in_the_canonical_frame() -> None:
    sim = RopeSim()
    rng = np.random.default_rng(1)
    sim.apply(Curve(5, 0.03, 0.2, 0.3))  # a turned rope: the canonical frame is not the world frame
    points = sim.link_points()
    for _ in range(20):
        a = rng.uniform(-0.6, 0.6, 4).astype(np.float32)
        curve = action_to_curve(a, points)
        assert 0 <= curve.link <= 20
        assert np.all(curve.to_array()[1:] >= CURVE_LOW[1:]) and np.all(
            curve.to_array()[1:] <= CURVE_HIGH[1:]
        )
        back = curve_to_action(curve, points)
        np.testing.assert_allclose(back[1:], a[1:], atol=1e-5)
        assert abs(back[0] - a[0]) <= 1.0 / 20 + 1e-6  # the link is rounded to the nearest of 21


def test_goal_sources_and_their_errors(sqlite_url: str) -> None:
    assert {p.cross for p in goal_pool()} == {1, 2, 3}
    assert len(goal_pool(goal_crossings=(1,))) == 4
    assert goal_pool([ONE]) == [parse_p_data(ONE)]
    with pytest.raises(GoalError, match="one goal source"):
        goal_pool([ONE], knot="trefoil")
    with pytest.raises(GoalError, match="no crossing"):
        goal_pool(["[]"])
    with pytest.raises(GoalError, match="goal #0"):
        goal_pool(['[[1,"O",1,"+"]]'])
    with pytest.raises(GoalError, match="no problem set 'nope'"):
        goal_pool(problem_set="nope", db_url=sqlite_url)

    from twisted.store import open_store
    from twisted.store.experiments import ProblemRecord, save_problem_set

    with open_store(sqlite_url) as store, store.session() as session:
        save_problem_set(
            session, "tiny", [ProblemRecord(None, 0, parse_p_data(ONE_MINUS), 0, "test")], source="test"
        )
    env = RopeKnotEnv(problem_set="tiny", db_url=sqlite_url)
    assert env.goals == [parse_p_data(ONE_MINUS)]
    env.reset(seed=0, options={"goal": ONE})
    assert env.goal == parse_p_data(ONE)


def test_friction_scale_reaches_the_simulator() -> None:
    env = RopeKnotEnv(goals=[ONE], friction_scale=1.05)
    assert env.friction_scale == pytest.approx(1.05)
    assert env.sim.model.geom_friction[:, 0].max() == pytest.approx(
        1.05 * RopeSim().model.geom_friction[:, 0].max()
    )
