"""`--planner sac`: the SAC+HER policy replaces the inverse model inside the same planner (and eval)."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("gymnasium", reason="the rl extra (gymnasium) is not installed")
pytest.importorskip("stable_baselines3", reason="the rl extra (stable-baselines3) is not installed")

from typer.testing import CliRunner  # noqa: E402

from cli.main import app  # noqa: E402
from twisted.rl import SacConfig, train_sac  # noqa: E402
from twisted.store import open_store  # noqa: E402
from twisted.store.search_tree import load_run  # noqa: E402

ONE = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
runner = CliRunner()


def test_sac_planner_needs_a_policy_then_plans_with_it(sqlite_url: str) -> None:
    # the set-up counts toward --timeout, and loading stable-baselines3 on a busy machine can take more
    # than a second: a short timeout could end the set-up (exit 3) before the missing policy is found
    code = runner.invoke(
        app, ["--db", sqlite_url, "plan", "--goal", ONE, "--planner", "sac", "--timeout", "120"]
    )
    assert code.exit_code == 2 and "twisted rl train" in code.output

    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with open_store(sqlite_url) as store:
            tiny = SacConfig(
                total_steps=30,
                seed=1,
                max_curves=3,
                learning_starts=10,
                batch_size=8,
                net_arch=(16, 16),
                log_every=30,
                checkpoint_every=30,
            )
            policy_id = train_sac(store, tiny).checkpoint_id
    finally:
        torch.set_num_threads(threads)
    args = ["--db", sqlite_url, "plan", "--goal", ONE, "--planner", "sac", "--workers", "1"]
    result = runner.invoke(app, [*args, "--max-iterations", "3", "--json"])
    assert result.exit_code in (0, 3), result.output
    run_id = json.loads(result.output)["run_id"]
    with open_store(sqlite_url) as store:
        info = load_run(store, run_id)
        assert info is not None
        assert info.parameters["planner"] == "sac" and info.parameters["model_id"] == policy_id
        # the policy proposed the curves: the tree grew beyond the root
        assert len(info.nodes) > 1
    # a resumed sac run reloads the policy it started with
    if result.exit_code == 3:
        again = runner.invoke(
            app, ["--db", sqlite_url, "plan", "--resume", str(run_id), "--max-iterations", "4"]
        )
        assert again.exit_code in (0, 3), again.output
    # (a long timeout, as above: on a busy machine the set-up can outlast a second before the model is read)
    bad = runner.invoke(app, [*args, "--model", "99", "--timeout", "120"])
    assert bad.exit_code == 2 and "99" in bad.output
