"""The move prior (``--move-prior``, DESIGN 8): plans weighted by the step success of their move classes,
learned from the stored searches of other goals and from the run itself.

The searches here are real (in-process ``SimPool(1)``, random-low curves, fixed seeds); the selection
tests need no simulation.
"""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sqlalchemy.orm.attributes import flag_modified
from typer.testing import CliRunner

from cli.main import app
from twisted.goals import check_goal, state_goal
from twisted.moves import MOVE_CLASSES, move_class, move_key, plans, successors
from twisted.planner import (
    Node,
    PlannerOptions,
    SearchTree,
    Twisted,
    resume_search,
    start_search,
    straight_rope,
)
from twisted.planner.search import MOVE_PRIOR_TRIES, RUN_PRIOR_TRIES
from twisted.sim.pool import SimPool
from twisted.store import open_store
from twisted.store.search import SearchCheckpoint, move_counts
from twisted.topology import EMPTY, parse_p_data

ONE_CROSSING = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
TWO_CROSSINGS = '[[1,"O",4,"+"],[2,"O",3,"+"],[3,"U",2,"+"],[4,"U",1,"+"]]'
GOAL_3 = '[[1,"O",6,"+"],[2,"O",5,"+"],[3,"O",4,"+"],[4,"U",3,"+"],[5,"U",2,"+"],[6,"U",1,"+"]]'
# a 3-crossing goal with seven plans from the straight rope, of six different sequences of move classes
MIXED_3 = '[[1,"O",6,"+"],[2,"O",5,"-"],[3,"O",4,"+"],[4,"U",3,"+"],[5,"U",2,"-"],[6,"U",1,"+"]]'


def _search(states: list[str], goal: str, **options: Any) -> Twisted:
    """A search whose tree holds one node per state (selection needs no simulation)."""
    q, points, _ = straight_rope()
    tree = SearchTree()
    for i, state in enumerate(states):
        tree.add(Node(i, None if i == 0 else 0, q, points, parse_p_data(state), None, 0, 0))
    g = check_goal(goal)
    opts = PlannerOptions(heuristic="crs", seed=7, **options)
    return Twisted(g, tree, opts, pool=None, high_level=lambda s: plans(s, g, 100))  # type: ignore[arg-type]


def test_move_classes_follow_the_segments_of_the_state_a_move_starts_from() -> None:
    seen = set()
    for state in ("[]", ONE_CROSSING, TWO_CROSSINGS):
        p = parse_p_data(state)
        ends = (0, 2 * p.cross)
        for successor in successors(p):
            move, name = successor.move, move_class(successor.move, p)
            seen.add(name)
            assert name in MOVE_CLASSES and name.split()[0] == move.kind
            if move.kind == "Cross":
                assert move.segment in ends, "Cross lays an end's tip"
                assert (name == "Cross end") == (move.other_segment in ends)
            elif move.kind == "R1":
                assert (name == "R1 end") == (move.segment in ends)
            assert move_key(move, p) == f"{p.cross}|{name}"
    assert seen == set(MOVE_CLASSES), "every class occurs from these states"


def test_without_the_move_prior_plans_are_drawn_as_the_paper_does() -> None:
    plain = _search(["[]"], GOAL_3)
    weighted = _search(["[]"], GOAL_3, move_prior=0.0)
    weighted.stats["prior"] = {"0|R1 end": [100.0, 1.0]}
    assert [plain.select_plan(EMPTY.key)[0] for _ in range(40)] == [
        weighted.select_plan(EMPTY.key)[0] for _ in range(40)
    ]
    assert plain.stats["prior"] == {} and "move_class" in plain.stats


def test_plans_are_drawn_by_the_inverse_of_the_tries_they_are_expected_to_take() -> None:
    search = _search(["[]"], MIXED_3, move_prior=1.0)
    # from one crossing a Cross of the tip over the other end is made to succeed ten times as often as a
    # curl on the inner segment
    search.stats["prior"] = {"1|Cross end": [1000.0, 300.0], "1|R1 inner": [1000.0, 30.0]}
    all_plans = search.plans[EMPTY.key]
    rates = search.move_rates()
    weights = search.plan_weights(EMPTY.key, rates)
    for plan, w in zip(all_plans, weights, strict=True):
        keys = [move_key(move, start) for start, move in zip(plan.states, plan.moves, strict=False)]
        assert w == pytest.approx(1.0 / sum(1.0 / rates[search._class_keys[key]] for key in keys))
    # the estimate from earlier searches is shrunk toward its level's rate by MOVE_PRIOR_TRIES pseudo-steps
    level = (330.0 + 1.0) / (2000.0 + 2.0)
    prior = (300.0 + MOVE_PRIOR_TRIES * level) / (1000.0 + MOVE_PRIOR_TRIES)
    assert rates[search._class_keys["1|Cross end"]] == pytest.approx(prior)
    draws = Counter(search.select_plan(EMPTY.key)[0] for _ in range(8000))
    shares = np.array([draws[i] for i in range(len(all_plans))]) / 8000
    assert np.allclose(shares, weights / weights.sum(), atol=0.02)
    # the run's own steps weigh against that estimate as if it were RUN_PRIOR_TRIES of them
    search.stats["move_class"]["1|Cross end"] = [300.0, 0.0]
    level = (330.0 + 1.0) / (2300.0 + 2.0)
    prior = (300.0 + MOVE_PRIOR_TRIES * level) / (1000.0 + MOVE_PRIOR_TRIES)
    after = search.move_rates()
    assert after[search._class_keys["1|Cross end"]] == pytest.approx(RUN_PRIOR_TRIES * prior / 330.0)
    # a class that failed 300 times here (once expected to succeed 30 % of the time) now draws less
    # often than the curl, which it beat tenfold elsewhere
    assert after[search._class_keys["1|Cross end"]] < after[search._class_keys["1|R1 inner"]]


def test_crs_keeps_its_level_shares_and_prefers_the_state_whose_plans_use_the_better_moves() -> None:
    goal = check_goal(MIXED_3)
    # two 2-crossing states on the way: from one the last move is a curl on an inner segment, from the
    # other a Cross of the tip over the other end
    last: dict[str, str] = {}
    for plan in plans(EMPTY, goal, 100):
        if plan.states[-2].cross == 2:
            last.setdefault(move_key(plan.moves[-1], plan.states[-2]), plan.states[-2].key)
    curl, cross = last["2|R1 inner"], last["2|Cross end"]
    search = _search(["[]", ONE_CROSSING], MIXED_3, move_prior=1.0)
    search.stats["prior"] = {"2|Cross end": [1000.0, 200.0], "2|R1 inner": [1000.0, 10.0]}
    keys = [EMPTY.key, parse_p_data(ONE_CROSSING).key]
    # one state per level: the move prior leaves the crs shares as they are
    assert np.allclose(search.plan_ratios(keys), 1.0)
    node = search.tree.nodes[0]
    for key in (curl, cross):
        search.tree.add(Node(len(search.tree), 0, node.q, node.points, parse_p_data(key), None, 0, 0))
        search._reached(parse_p_data(key))
    keys += [curl, cross]
    assert search.candidate_states == keys
    rates = search.move_rates()

    def expected(key: str) -> float:  # success of a plan drawn by its weights
        w = search.plan_weights(key, rates)
        return float((w * w).sum() / w.sum())

    ratios = search.plan_ratios(keys)
    level = (expected(curl) + expected(cross)) / 2
    assert ratios[:2] == pytest.approx([1.0, 1.0])
    assert ratios[2:] == pytest.approx([expected(curl) / level, expected(cross) / level])
    assert ratios[3] > 1.5 > 0.5 > ratios[2]
    draws = Counter(search.select_topological_state() for _ in range(6000))
    weights = np.array([1.0, 2.0, 3.0 * ratios[2], 3.0 * ratios[3]])
    shares = np.array([draws[k] for k in keys]) / 6000
    assert np.allclose(shares, weights / weights.sum(), atol=0.03), shares


# --- the prior from the store -----------------------------------------------------------------------------


def _run(store: Any, pool: Any, goal: str, iterations: int, **options: Any) -> Twisted:
    search = start_search(store, check_goal(goal), PlannerOptions(planner="random-low", **options), pool)
    search.run(max_iterations=iterations)
    return search


def _summed(*tables: dict[str, list[float]]) -> dict[str, list[float]]:
    out: dict[str, list[float]] = {}
    for table in tables:
        for key, (tried, hit) in table.items():
            entry = out.setdefault(key, [0.0, 0.0])
            entry[0] += tried
            entry[1] += hit
    return out


def test_a_new_search_learns_from_the_stored_searches_of_other_goals(tmp_path: Path) -> None:
    with open_store(f"sqlite:///{tmp_path / 'prior.db'}") as store, SimPool(1, 1.0) as pool:
        first = _run(store, pool, TWO_CROSSINGS, 12, seed=0)
        same_goal = _run(store, pool, GOAL_3, 12, seed=1)
        assert first.stats["move_class"] and same_goal.stats["move_class"]
        # the "move_class" table counts every plan step once, by the class of the move the plan named
        steps = sum(tried for tried, _ in first.stats["step"].values())
        assert sum(tried for tried, _ in first.stats["move_class"].values()) == steps

        search = _run(store, pool, GOAL_3, 0, seed=2, move_prior=1.0)
        # only the other goal's search counts: not the earlier one of this goal
        assert search.stats["prior"] == first.stats["move_class"]
        counts, runs = move_counts(store, state_goal(check_goal(GOAL_3)), "random-low", None)
        assert counts == first.stats["move_class"] and runs == 1
        # another planner's (or model's) searches are not this one's evidence
        assert move_counts(store, state_goal(check_goal(GOAL_3)), "twisted", None) == ({}, 0)
        everything = _summed(first.stats["move_class"], same_goal.stats["move_class"])
        assert move_counts(store, state_goal(check_goal(ONE_CROSSING)), "random-low", None)[0] == everything

        # a run stored before checkpoints kept the "move_class" table: rebuilt from its pair table and nodes
        with store.session() as session, session.begin():
            row = session.get(SearchCheckpoint, first.run_id)
            assert row is not None
            row.stats = {k: v for k, v in row.stats.items() if k != "move_class"}
            flag_modified(row, "stats")
        rebuilt, _ = move_counts(store, state_goal(check_goal(GOAL_3)), "random-low", None)
        assert rebuilt == first.stats["move_class"]

        # the prior is fixed when the run starts: a resume reads it from the checkpoint
        search.run(max_iterations=4)
        _run(store, pool, ONE_CROSSING, 6, seed=3)
        resumed = resume_search(store, search.run_id, pool)
        assert resumed.stats["prior"] == first.stats["move_class"]
        assert resumed.options.move_prior == 1.0


def test_a_search_with_the_move_prior_replays_from_its_seed(tmp_path: Path) -> None:
    trees = []
    for name in ("a", "b"):
        with open_store(f"sqlite:///{tmp_path / f'{name}.db'}") as store, SimPool(1, 1.0) as pool:
            _run(store, pool, TWO_CROSSINGS, 10, seed=0)
            search = _run(store, pool, GOAL_3, 15, seed=5, move_prior=2.0)
            trees.append([(n.parent, n.p_data.key, n.curve) for n in search.tree.nodes])
            assert not math.isnan(sum(w.sum() for w in map(search.plan_weights, search.candidate_states)))
    assert trees[0] == trees[1] and len(trees[0]) > 1


@pytest.mark.parametrize("value", ["-1", "nan", "101"])
def test_a_bad_move_prior_is_refused_before_anything_is_opened(tmp_path: Path, value: str) -> None:
    db = tmp_path / "never.db"
    for command in (["plan", "--goal", ONE_CROSSING], ["eval", "--set", "s"]):
        result = CliRunner().invoke(app, ["--db", f"sqlite:///{db}", *command, "--move-prior", value])
        assert result.exit_code == 2, result.output
        assert "--move-prior" in result.output
    assert not db.exists()
