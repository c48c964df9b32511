"""SAC+HER: a short training run into the store, Ctrl-C and resume, the planner's policy sampler."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("gymnasium", reason="the rl extra (gymnasium) is not installed")
pytest.importorskip("stable_baselines3", reason="the rl extra (stable-baselines3) is not installed")

from sqlalchemy import func, select  # noqa: E402

from twisted.model.registry import ModelError  # noqa: E402
from twisted.planner import Node  # noqa: E402
from twisted.rl import PolicyError, SacConfig, load_policy_sampler, train_sac  # noqa: E402
from twisted.sim import CURVE_HIGH, CURVE_LOW, RopeSim  # noqa: E402
from twisted.store import open_store  # noqa: E402
from twisted.store.rl import RlCheckpoint, RlRun, RlSuccess, list_checkpoints, success_table  # noqa: E402
from twisted.topology import parse_p_data  # noqa: E402

ONE = '[[1,"O",2,"+"],[2,"U",1,"+"]]'

SMALL = SacConfig(
    total_steps=240,
    seed=3,
    max_curves=4,
    learning_starts=60,
    batch_size=32,
    net_arch=(64, 64),
    log_every=60,
    checkpoint_every=120,
)


@pytest.fixture(autouse=True)
def _one_thread() -> None:
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def test_short_run_is_interrupted_resumed_and_its_policy_samples_valid_curves(sqlite_url: str) -> None:
    store = open_store(sqlite_url)
    seen: list[int] = []

    def interrupt_at_180(p) -> None:
        seen.append(p.steps)
        if p.steps == 180:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train_sac(store, SMALL, progress=interrupt_at_180)
    assert seen == [60, 120, 180]
    with store.session() as session:
        run = session.scalars(select(RlRun)).one()
        assert (run.status, run.steps_done) == ("interrupted", 180)
        checkpoints = list_checkpoints(session, run.id)
        # the periodic checkpoint at 120 and the Ctrl-C one at 180; only the newest keeps the buffer
        assert [c.steps for c in checkpoints] == [180, 120]
        assert [c.has_replay_buffer for c in checkpoints] == [True, False]

    # a process killed after its checkpoint had logged one more interval: the resume runs it again
    with store.session(write=True) as session:
        session.add(RlSuccess(rl_run_id=run.id, steps=200, goal_cross=1, episodes=9, successes=9))
    resumed: list[int] = []
    outcome = train_sac(store, resume_run_id=run.id, progress=lambda p: resumed.append(p.steps))
    assert outcome.status == "finished" and outcome.run_id == run.id
    assert outcome.steps == SMALL.total_steps and resumed == [240]
    with store.session() as session:
        run = session.get(RlRun, run.id)
        assert run.status == "finished" and run.steps_done == 240 and run.episodes == outcome.episodes
        table = success_table(session, run.id)
        final = session.get(RlCheckpoint, outcome.checkpoint_id)
        assert final.final and final.steps == 240
    # one row per interval and goal crossing count; every episode counted once
    assert {steps for steps, *_ in table} == {60, 120, 180, 240}
    assert {cross for _, cross, *_ in table} <= {1, 2, 3}
    assert sum(episodes for _, _, episodes, _ in table) == outcome.episodes
    assert all(0 <= hits <= episodes for *_, episodes, hits in table)
    with pytest.raises(ValueError, match="has finished"):
        train_sac(store, resume_run_id=run.id)

    sampler, policy_id = load_policy_sampler(store, None)
    assert policy_id == outcome.checkpoint_id and sampler.name == "sac"
    sim = RopeSim()
    sim.reset()
    node = Node(0, None, sim.state(), sim.link_points(), sim.p_data(), None, 0, 0)
    goal = parse_p_data('[[1,"O",2,"+"],[2,"U",1,"+"]]')
    curves = sampler.sample(node, goal, None, 6, np.random.default_rng(0))
    assert len(curves) == 6
    for c in curves:
        assert 0 <= c.link <= 20
        assert np.all(c.to_array()[1:] >= CURVE_LOW[1:]) and np.all(c.to_array()[1:] <= CURVE_HIGH[1:])
    assert len({tuple(c.to_array()) for c in curves}) == 6  # stochastic beyond the first
    again = sampler.sample(node, goal, None, 6, np.random.default_rng(0))
    assert [c.to_array().tolist() for c in again] == [c.to_array().tolist() for c in curves]
    other = sampler.sample(node, goal, None, 2, np.random.default_rng(1))
    assert other[0] == curves[0]  # the first curve is the policy's deterministic action
    assert other[1] != curves[1]
    # an older checkpoint of the run loads by id too
    with store.session() as session:
        older = min(c.id for c in list_checkpoints(session, run.id))
    assert load_policy_sampler(store, older)[1] == older
    store.close()


def test_missing_policy_errors_name_what_to_do(sqlite_url: str) -> None:
    with open_store(sqlite_url) as store:
        with pytest.raises(PolicyError, match="twisted rl train"):
            load_policy_sampler(store, None)
        with pytest.raises(ModelError, match="no SAC policy 5"):
            load_policy_sampler(store, 5)
        with pytest.raises(ValueError, match="no SAC run 9"):
            train_sac(store, resume_run_id=9)
        with pytest.raises(ValueError, match="total_steps"):
            train_sac(store, SacConfig(total_steps=0))
        with store.session() as session:
            assert session.scalar(select(func.count()).select_from(RlRun)) == 0


def test_cli_train_list_and_bad_input(sqlite_url: str) -> None:
    from typer.testing import CliRunner

    from cli.main import app

    runner = CliRunner()
    empty = runner.invoke(app, ["--db", sqlite_url, "rl", "list"])
    assert empty.exit_code == 0 and "no SAC runs" in empty.output
    bad = runner.invoke(app, ["--db", sqlite_url, "rl", "train", "--goal", '[[1,"O",1,"+"]]', "--steps", "5"])
    assert bad.exit_code == 2 and "goal #0" in bad.output
    crossings = runner.invoke(app, ["--db", sqlite_url, "rl", "train", "--goal-crossings", "1,x"])
    assert crossings.exit_code == 2 and "--goal-crossings" in crossings.output
    args = ["--steps", "40", "--learning-starts", "20", "--batch-size", "16", "--log-every", "20"]
    ok = runner.invoke(app, ["--db", sqlite_url, "rl", "train", *args, "--max-curves", "2", "--goal", ONE])
    assert ok.exit_code == 0, ok.output
    text = " ".join(ok.output.split())  # rich wraps lines
    assert "run 1 finished: 40 steps" in text
    listed = runner.invoke(app, ["--db", sqlite_url, "rl", "list"])
    assert listed.exit_code == 0 and "40/40" in listed.output
    with open_store(sqlite_url) as store, store.session() as session:
        (final,) = [c for c in list_checkpoints(session) if c.final]
        assert session.get(RlRun, 1).parameters["goals"] == [ONE]
    assert f"--model {final.id}" in text
