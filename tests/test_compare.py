"""`twisted compare A B`: two eval labels paired run by run (twisted.experiments.compare)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.main import app
from tests.test_evaluate import _finished_result, _two_goal_set
from tests.test_hardening import _digest
from twisted.experiments.compare import compare_labels, pair_runs, ratio_intervals
from twisted.experiments.problems import EvalInputError
from twisted.experiments.report import ResultRow
from twisted.store import open_store
from twisted.store.experiments import EvalRun, load_problem_set

# (set, goal, seed) -> calls of A and of B; None: timed out after that many calls
RUNS: dict[tuple[str, str, int], tuple[tuple[int, bool], tuple[int, bool]]] = {
    ("s4", "g1", 0): ((100, True), (400, True)),
    ("s4", "g1", 1): ((300, True), (200, True)),
    ("s4", "g2", 0): ((500, True), (9000, False)),
    ("s4", "g2", 1): ((8000, False), (600, True)),
    ("s5", "g3", 0): ((50, True), (1000, True)),
}


def _row(set_name: str, goal: str, seed: int, label: str, calls: int, solved: bool) -> ResultRow:
    return ResultRow(
        set_name,
        label,
        goal,
        seed,
        300.0,
        1.0,
        solved,
        calls / 100 if solved else None,
        calls + 7,  # every call of the run: a few after the goal node's
        0,
        "t",
        calls if solved else None,
    )


def _rows() -> list[ResultRow]:
    rows = []
    for (set_name, goal, seed), ((ca, sa), (cb, sb)) in RUNS.items():
        rows.append(_row(set_name, goal, seed, "A", ca, sa))
        rows.append(_row(set_name, goal, seed, "B", cb, sb))
    rows.append(_row("s4", "g9", 0, "A", 70, True))  # no partner under B: counted, not compared
    rows.append(_row("s6", "g9", 0, "B", 70, True))  # a set only B ran
    return rows


def test_figures_per_set_and_over_all() -> None:
    s4, s5, both = compare_labels(_rows(), "A", "B")
    assert (s4.scope, s5.scope, both.scope) == ("s4", "s5", "all")
    assert (s4.a.runs, s4.a.solved, s4.b.solved, s4.only_a, s4.only_b) == (4, 3, 3, 1, 0)
    assert s4.a.calls_to_solve == pytest.approx((100 + 300 + 500) / 3)  # the goal node's call
    assert s4.a.all_calls == 100 + 300 + 500 + 8000 + 4 * 7  # every call, the unsolved run's too
    assert s4.a.median_time_s == 3.0
    # runs both solved: (100, 400) and (300, 200)
    assert (s4.both_solved, s4.calls_both_a, s4.calls_both_b) == (2, 200.0, 300.0)
    assert s4.calls_both_ratio == pytest.approx(2 / 3)
    assert s4.median_ratio == pytest.approx((0.25 + 1.5) / 2) and s4.a_fewer == 1
    assert s4.all_calls_ratio == pytest.approx((8928 / 3) / ((400 + 200 + 9000 + 600 + 28) / 3))
    assert (s5.both_solved, s5.a_fewer, s5.median_ratio) == (1, 1, 0.05)
    assert (both.a.runs, both.a.solved, both.b.solved, both.both_solved) == (5, 4, 4, 3)
    assert (both.only_a, both.only_b) == (1, 1)
    assert both.a.all_calls == s4.a.all_calls + s5.a.all_calls
    assert json.loads(json.dumps(both.to_dict()))["a"]["all_calls_per_solved"] == both.a.all_calls / 4


def test_the_intervals_resample_whole_goals() -> None:
    s4, s5, both = compare_labels(_rows(), "A", "B")
    assert s5.calls_both_interval is None and s5.all_calls_interval is None, "one goal: no interval"
    for c in (s4, both):
        assert c.calls_both_interval is not None and c.all_calls_interval is not None
        for (low, high), ratio in (
            (c.calls_both_interval, c.calls_both_ratio),
            (c.all_calls_interval, c.all_calls_ratio),
        ):
            assert ratio is not None and low <= ratio <= high
    # s4: g1's two runs both solved (A 400 calls, B 600), g2 has none both solved; a draw of g2 alone
    # leaves the ratio undefined, every other draw gives 400 / 600
    assert s4.calls_both_interval == pytest.approx((2 / 3, 2 / 3))
    # the draws come from a seeded generator: the same interval at every call
    ra, rb = pair_runs(_rows(), "A", "B")
    assert ratio_intervals(ra, rb) == ratio_intervals(ra, rb)
    # goals whose ratios agree give an interval of that ratio alone
    rows = [
        _row("s", g, seed, label, calls * (2 if label == "B" else 1), True)
        for g, calls in (("g1", 100), ("g2", 1000))
        for seed in (0, 1)
        for label in ("A", "B")
    ]
    ra, rb = pair_runs(rows, "A", "B")
    agreed, _ = ratio_intervals(ra, rb)
    assert agreed == pytest.approx((0.5, 0.5))
    assert json.loads(json.dumps(s4.to_dict()))["calls_both_interval"] == pytest.approx([2 / 3, 2 / 3])


def test_seeds_choose_the_runs() -> None:
    (s4, s5, both) = compare_labels(_rows(), "A", "B", seeds=[0])
    assert (s4.a.runs, s5.a.runs, both.a.runs, both.both_solved) == (2, 1, 3, 2)
    (only,) = compare_labels([r for r in _rows() if r.set_name == "s5"], "A", "B")
    assert only.scope == "s5"  # one set and no other runs: no "all" row
    s5, rest = compare_labels([r for r in _rows() if r.set_name in ("s5", "s6")], "A", "B")
    assert (s5.scope, rest.scope, rest.only_b, rest.a.runs) == ("s5", "all", 1, 1)


def test_refusals() -> None:
    with pytest.raises(EvalInputError, match="two different labels"):
        compare_labels(_rows(), "A", "A")
    with pytest.raises(
        EvalInputError, match=r"label 'C' has no finished results \(labels with results: A, B\)"
    ):
        compare_labels(_rows(), "A", "C")
    with pytest.raises(EvalInputError, match="'B' has no finished results with these seeds"):
        compare_labels([r for r in _rows() if r.planner == "A" or r.seed == 1], "A", "B", seeds=[0])
    with pytest.raises(EvalInputError, match="share no run"):
        compare_labels([r for r in _rows() if (r.planner == "A") == (r.seed == 0)], "A", "B")


def _store_results(url: str) -> None:
    """Set ``ones`` (two goals), labels ``new`` and ``old``, seeds 0-1."""
    with open_store(url) as store:
        _two_goal_set(store)
        with store.session(write=True) as session:
            record = load_problem_set(session, "ones")
            calls = {"new": [(100, True), (200, True), (300, True), (50, False)], "old": [(400, True)] * 4}
            for label, outcomes in calls.items():
                run = EvalRun(
                    set_id=record.id, planner=label, timeout_s=10.0, friction_scale=1.0, seeds=[0, 1],
                    workers=1, parallel=1,
                )  # fmt: skip
                session.add(run)
                session.flush()
                pairs = [(p, seed) for p in record.problems for seed in (0, 1)]
                for (p, seed), (n, solved) in zip(pairs, outcomes, strict=True):
                    session.add(_finished_result(run, p, label, seed, 1.0 if solved else None, n))


def test_cli_prints_the_comparison(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'e.db'}"
    _store_results(url)
    runner = CliRunner()
    result = runner.invoke(app, ["--db", url, "compare", "new", "old", "--json"])
    assert result.exit_code == 0, result.output
    (c,) = json.loads(result.output)
    assert (c["a"]["solved"], c["b"]["solved"], c["both_solved"], c["a_fewer"]) == (3, 4, 3, 3)
    assert c["all_calls_ratio"] == pytest.approx((650 / 3) / 400)
    result = runner.invoke(app, ["--db", url, "compare", "new", "old", "--seeds", "1", "--set", "ones"])
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.replace("│", " ").split())
    assert "ones: new against old" in text and "solved 1 2" in text
    assert "all calls per solved goal 250 400 0.62" in text  # seed 1: 200 solved + 50 unsolved, over 1


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["new", "new"], "A and B are both 'new'"),
        (["new", "nope"], "label 'nope' has no finished results"),
        (["new", "old", "--set", "nope"], "--set nope: no such problem set"),
        (["new", "old", "--seeds", "x"], "'--seeds'"),
    ],
)
def test_cli_refuses_bad_input_and_writes_nothing(tmp_path: Path, args: list[str], message: str) -> None:
    path = tmp_path / "e.db"
    _store_results(f"sqlite:///{path}")
    before = _digest(path)
    result = CliRunner().invoke(app, ["--db", f"sqlite:///{path}", "compare", *args])
    assert result.exit_code == 2 and message in " ".join(result.output.split()), result.output
    assert _digest(path) == before
    missing = tmp_path / "none.db"
    result = CliRunner().invoke(app, ["--db", f"sqlite:///{missing}", "compare", *args])
    assert result.exit_code == 2 and not missing.exists(), result.output
