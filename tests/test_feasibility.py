"""The learned feasibility of a plan step (twisted.model.feasibility) and how the planner weighs it
(twisted.planner.strategies.FeasibilityRoom)."""

from __future__ import annotations

import io
import json
import pickle
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import torch

from tests.test_model import random_rope
from tests.test_strategies import ONE, THREE, View, _shares, _view
from twisted.model.feasibility import (
    Feasibility,
    PairSamples,
    step_features,
    train_feasibility,
)
from twisted.moves import successors
from twisted.planner import PlannerOptions
from twisted.planner.strategies import FeasibilityRoom, R1Room, RetryWeightedNodes, default_parts
from twisted.store.payloads import UnsafePayloadError
from twisted.topology import parse_p_data


def _easy(points: np.ndarray) -> np.ndarray:
    """The rule the synthetic pairs follow: the head's first links are lifted (by :func:`_samples`)."""
    return points[:, 0, 2] > 0.04


def _samples(n: int = 2000, seed: int = 0) -> PairSamples:
    """Pairs whose success depends on the rope: a step from an easy rope (:func:`_easy`) reaches its
    state 40 % of the time, otherwise 2 %; runs of 20 pairs."""
    rng = np.random.default_rng(seed)
    one = parse_p_data(ONE)
    cross = next(s for s in successors(one) if s.move.kind == "Cross")
    points = np.stack([random_rope(int(s)) for s in rng.integers(0, 10**6, n)]).astype(np.float32)
    points[: n // 2, :3, 2] += 0.05
    easy = _easy(points)
    tried = np.full(n, 5.0)
    reached = rng.binomial(5, np.where(easy, 0.4, 0.02)).astype(float)
    steps = torch.stack([step_features(one, cross.state, cross.move)] * n)
    return PairSamples(points, steps, tried, reached, np.repeat(np.arange(n // 20), 20), ["Cross|1"] * n)


def test_training_learns_what_the_rope_allows_and_replays_from_its_seed() -> None:
    samples = _samples()
    model, figures = train_feasibility(samples, epochs=12, seed=3)
    again, figures_again = train_feasibility(samples, epochs=12, seed=3)
    assert figures["val_loss"] == figures_again["val_loss"]
    assert figures["val_loss"] < figures["baseline_val_loss"]
    (group,) = figures["groups"]
    assert group["group"] == "Cross|1" and group["auc"] > 0.7, group  # at most about 0.78 here
    assert figures["val_runs"] == 20 and figures["train_pairs"] + figures["val_pairs"] == len(samples)
    # the odds follow the rule, relative to the group's rate
    one = parse_p_data(ONE)
    cross = next(s for s in successors(one) if s.move.kind == "Cross")
    easy = samples.points[_easy(samples.points)][:50]
    hard = samples.points[~_easy(samples.points)][:50]
    ratio_easy = model.ratios(model.odds(easy, one, cross.state, cross.move), one, cross.move)
    ratio_hard = model.ratios(model.odds(hard, one, cross.state, cross.move), one, cross.move)
    assert np.median(ratio_easy) > 1.0 > np.median(ratio_hard)


def test_nothing_to_learn_from_is_an_error_that_says_so() -> None:
    empty = PairSamples(np.zeros((0, 22, 3)), torch.zeros(0, 0), np.zeros(0), np.zeros(0), np.zeros(0))
    with pytest.raises(ValueError, match="no pair statistics"):
        train_feasibility(empty)


def test_a_saved_model_loads_the_same_and_a_pickle_is_refused() -> None:
    model, _ = train_feasibility(_samples(200), epochs=2, seed=0)
    back = Feasibility.from_bytes(model.to_bytes())
    one = parse_p_data(ONE)
    cross = next(s for s in successors(one) if s.move.kind == "Cross")
    ropes = np.stack([random_rope(i) for i in range(4)])
    assert np.array_equal(
        back.odds(ropes, one, cross.state, cross.move), model.odds(ropes, one, cross.state, cross.move)
    )
    assert back.rates == model.rates

    class Evil:
        def __reduce__(self) -> Any:
            return (print, ("ran",))

    buffer = io.BytesIO()
    torch.save(
        {"in_dim": 1, "hidden": 1, "state_dict": {}, "rates": {}, "x": Evil()}, buffer, pickle_protocol=2
    )
    with pytest.raises(UnsafePayloadError):
        Feasibility.from_bytes(buffer.getvalue())
    with pytest.raises(UnsafePayloadError):
        Feasibility.from_bytes(pickle.dumps({"a": 1}))


class _Odds:
    """A stand-in for a trained model: the odds of node i are odds[i] (its geometry row holds i)."""

    def __init__(self, odds: list[float], rate: float) -> None:
        self.odds, self.rate, self.calls = odds, rate, 0

    def odds_of(self, geometry: torch.Tensor, *_: Any) -> np.ndarray:
        self.calls += 1
        return np.array([self.odds[int(row[0])] for row in geometry])

    def ratios(self, odds: np.ndarray, *_: Any) -> np.ndarray:
        return np.clip(odds / self.rate, 0.05, 5.0)


def _room_view(monkeypatch: pytest.MonkeyPatch) -> tuple[View, Any]:
    """Three nodes of the 1-crossing state; the features of node i are [i, ...]."""
    view = _view(["[]", ONE, ONE, ONE], goal=THREE)
    import twisted.model.feasibility as feasibility

    monkeypatch.setattr(
        feasibility,
        "geometry_features",
        lambda points: torch.arange(len(points), dtype=torch.float32)[:, None],
    )
    return view, next(s for s in successors(parse_p_data(ONE)) if s.move.kind == "Cross")


def test_nodes_are_drawn_by_their_odds_over_the_groups_rate_to_the_power(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    view, cross = _room_view(monkeypatch)
    # the features are computed for the new nodes [1, 2, 3] in one call: rows 0, 1, 2
    model = _Odds([0.3, 0.1, 0.0001], rate=0.1)
    room = FeasibilityRoom(model, power=2.0)
    key = parse_p_data(ONE).key
    indices = view.tree.by_state[key]
    assert room.node_weights(view, indices, cross.state, cross.move) == pytest.approx([9.0, 1.0, 0.05**2])
    room.node_weights(view, indices, cross.state, cross.move)
    assert model.calls == 1  # cached per (node, next state)
    nodes = RetryWeightedNodes(1.0, room)
    shares = _shares(lambda rng: nodes.select(view, key, cross.state, cross.move, rng).index, indices)
    w = np.array([9.0, 1.0, 0.0025])
    assert np.allclose(shares, w / w.sum(), atol=0.03), shares
    room.forget(2)  # an iteration rolled back: nodes from index 2 on are forgotten
    assert set(room._ratios) == {(1, cross.state.key)} and set(room._geometry) == {1}


def test_a_plan_weighs_the_best_node_for_its_first_step(monkeypatch: pytest.MonkeyPatch) -> None:
    view, cross = _room_view(monkeypatch)
    one = parse_p_data(ONE)
    r1 = next(s for s in successors(one) if s.move.kind == "R1")
    view.plans[one.key] = [
        SimpleNamespace(states=[one, cross.state], moves=[cross.move]),
        SimpleNamespace(states=[one, r1.state], moves=[r1.move]),
    ]
    room = FeasibilityRoom(_Odds([0.3, 0.1, 0.02], rate=0.1), power=1.0)
    assert room.plan_rooms(view, one.key) == pytest.approx([3.0, 3.0])


def test_the_options_choose_the_room(monkeypatch: pytest.MonkeyPatch) -> None:
    goal = _view([], goal=THREE).goal
    assert isinstance(default_parts(PlannerOptions(), goal).room, R1Room)
    stand_in = _Odds([0.1], rate=0.1)
    parts = default_parts(PlannerOptions(feasibility=1.0), goal, feasibility=stand_in)
    assert isinstance(parts.room, FeasibilityRoom) and parts.room.model is stand_in
    # the baselines draw random curves: no learned weighting for them
    assert isinstance(default_parts(PlannerOptions(feasibility=1.0, planner="random-low"), goal).room, R1Room)
    with pytest.raises(ValueError, match="feasibility must lie in"):
        PlannerOptions(feasibility=-1.0).validate()


def _cli(*args: str) -> tuple[int, str]:
    from typer.testing import CliRunner

    from cli.main import app

    result = CliRunner().invoke(app, list(args))
    return result.exit_code, result.output


def test_train_feasibility_learns_from_a_stored_search_and_writes_a_model(
    sqlite_url: str, tmp_path: Path
) -> None:
    code, out = _cli(
        "--db", sqlite_url, "plan", "--goal", THREE, "--planner", "random-low", "--workers", "1",
        "--max-iterations", "30", "--k", "2", "--p-expand", "0", "--seed", "2", "--json",
    )  # fmt: skip
    assert code in (0, 3), out
    target = tmp_path / "f.pt"
    code, out = _cli("--db", sqlite_url, "train-feasibility", "--out", str(target), "--epochs", "2", "--json")
    assert code == 0, out
    figures = json.loads(out)
    assert figures["pairs"] > 0 and figures["out"] == str(target)
    model = Feasibility.from_bytes(target.read_bytes())
    assert model.metadata["sources"] == ["--db"] and model.rates
    # the runs toward an evaluation set's goals are left out when asked: here the only run
    held = tmp_path / "final-x.json"
    goal = parse_p_data(THREE).to_list()
    held.write_text(
        json.dumps({"format": "twisted-goal-set/1", "name": "final-x", "seed": 1, "goals": [goal]})
    )
    assert _cli("--db", sqlite_url, "problems", "import", str(held))[0] == 0
    code, out = _cli(
        "--db", sqlite_url, "train-feasibility", "--out", str(tmp_path / "g.pt"), "--exclude-set", "final-x"
    )
    assert code == 2 and "no stored search" in out and not (tmp_path / "g.pt").exists()


def test_train_feasibility_refuses_bad_input_before_writing(sqlite_url: str, tmp_path: Path) -> None:
    from twisted.store import open_store

    open_store(sqlite_url).close()
    missing = tmp_path / "no" / "f.pt"
    code, out = _cli("--db", sqlite_url, "train-feasibility", "--out", str(missing))
    assert code == 2 and "--out" in out and not missing.parent.exists()
    code, out = _cli(
        "--db", sqlite_url, "train-feasibility", "--out", str(tmp_path / "f.pt"),
        "--from", f"sqlite:///{tmp_path / 'absent.db'}",
    )  # fmt: skip
    assert code == 2 and "--from" in out and not (tmp_path / "f.pt").exists()
    code, out = _cli("--db", sqlite_url, "plan", "--goal", ONE, "--feasibility", "-1", "--timeout", "1")
    assert code == 2 and "feasibility" in out
