"""The planner's confidence weight (DESIGN 8): plan and node choice within a state weighted by the
inverse model's confidence in the step, ``c ** b``.

Selection is checked on hand-made trees with a sampler whose confidence is set per node and next
state; the model's confidence on the shipped model; a stop and resume with the real model and
simulator gives the tree of one uninterrupted run.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np
import pytest

from twisted.goals import check_goal
from twisted.model.registry import load_default_model
from twisted.model.sampler import ModelCurves
from twisted.moves import plans
from twisted.planner import (
    Node,
    PlannerOptions,
    RandomCurves,
    SearchTree,
    Twisted,
    pair_key,
    resume_search,
    start_search,
    straight_rope,
)
from twisted.sim.pool import SimPool
from twisted.store import open_store
from twisted.store.search import load_run
from twisted.topology import EMPTY, parse_p_data

ONE_CROSSING = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
GOAL_3 = '[[1,"O",6,"+"],[2,"O",5,"+"],[3,"O",4,"+"],[4,"U",3,"+"],[5,"U",2,"+"],[6,"U",1,"+"]]'
THREE_CROSSINGS = '[[1,"O",4,"+"],[2,"U",5,"+"],[3,"O",6,"+"],[4,"U",1,"+"],[5,"O",2,"+"],[6,"U",3,"+"]]'


class _Confident(RandomCurves):
    """Random curves with a confidence per (node index, next state key); 0.1 where none is set."""

    def __init__(self, table: dict[tuple[int, str], float]) -> None:
        self.table = table
        self.asked: list[int] = []

    def confidence(self, requests: list[tuple[Any, Any, Any]]) -> np.ndarray:
        self.asked.append(len(requests))
        return np.array([self.table.get((node.index, nxt.key), 0.1) for node, nxt, _ in requests])


def _search(states: list[str], goal: str, sampler: Any, **options: Any) -> Twisted:
    """A search whose tree holds one node per state (no simulation is needed to select)."""
    q, points, _ = straight_rope()
    tree = SearchTree()
    for i, state in enumerate(states):
        tree.add(Node(i, None if i == 0 else 0, q, points, parse_p_data(state), None, 0, 0))
    g = check_goal(goal)
    return Twisted(
        g,
        tree,
        PlannerOptions(seed=7, **options),
        pool=None,  # type: ignore[arg-type]
        high_level=lambda s: plans(s, g, 100),
        sampler=sampler,
    )


def test_nodes_are_drawn_in_proportion_to_the_confidence_to_the_weight_times_the_retry_weight() -> None:
    one = parse_p_data(ONE_CROSSING)
    sampler = _Confident({(0, one.key): 0.6, (1, one.key): 0.2})
    search = _search(["[]", "[]"], ONE_CROSSING, sampler, confidence_weight=2.0)
    assert search.uses_confidence
    assert np.allclose(search.node_weights(EMPTY.key, one, None), [0.36, 0.04])
    counts = Counter(search.select_configuration(EMPTY.key, one).index for _ in range(4000))
    assert counts[0] / 4000 == pytest.approx(0.9, abs=0.02), counts
    # node 0 was asked once already: 0.1 * 0.36 against 0.04
    search.stats["pair"][pair_key(0, one.key)] = [1.0, 0.0]
    counts = Counter(search.select_configuration(EMPTY.key, one).index for _ in range(4000))
    assert counts[0] / 4000 == pytest.approx(0.036 / 0.076, abs=0.025), counts
    # each (node, next state) pair was asked of the sampler once, in one batch
    assert sampler.asked == [2]


def test_plans_are_drawn_with_the_summed_weight_of_their_first_step() -> None:
    sampler = _Confident({})
    search = _search(["[]", "[]"], THREE_CROSSINGS, sampler, confidence_weight=1.0)
    candidates = search.plans[EMPTY.key]
    firsts = sorted({plan.states[1].key for plan in candidates})
    assert len(firsts) >= 2, "the straight rope has several first steps toward this goal"
    favoured = firsts[0]
    sampler.table = {(0, favoured): 0.9, (1, favoured): 0.5}
    per_plan = np.array([1.4 if plan.states[1].key == favoured else 0.2 for plan in candidates])
    expected = per_plan[[plan.states[1].key == favoured for plan in candidates]].sum() / per_plan.sum()
    draws = [search.select_plan(EMPTY.key)[1].states[1].key for _ in range(3000)]
    assert draws.count(favoured) / 3000 == pytest.approx(expected, abs=0.03)
    # every first step of the state was scored in one batch, for both nodes
    assert sampler.asked == [2 * len(firsts)]


def test_without_a_confidence_the_weight_changes_nothing() -> None:
    one = parse_p_data(ONE_CROSSING)
    plain = _search(["[]", "[]", "[]"], GOAL_3, RandomCurves(), confidence_weight=0.0)
    weighted = _search(["[]", "[]", "[]"], GOAL_3, RandomCurves(), confidence_weight=3.0)
    assert not weighted.uses_confidence
    for search in (plain, weighted):
        search.stats["pair"][pair_key(1, one.key)] = [1.0, 0.0]
    picks = [
        [(s.select_plan(EMPTY.key)[0], s.select_configuration(EMPTY.key, one).index) for _ in range(40)]
        for s in (plain, weighted)
    ]
    assert picks[0] == picks[1]
    # and a sampler with a confidence but weight 0 is not asked
    sampler = _Confident({})
    off = _search(["[]", "[]"], GOAL_3, sampler, confidence_weight=0.0)
    off.select_plan(EMPTY.key)
    off.select_configuration(EMPTY.key, one)
    assert not off.uses_confidence and sampler.asked == []


def test_a_rollback_forgets_the_confidence_of_the_discarded_nodes() -> None:
    one = parse_p_data(ONE_CROSSING)
    sampler = _Confident({(0, one.key): 0.6, (1, one.key): 0.2, (2, one.key): 0.9})
    search = _search(["[]", "[]", "[]"], ONE_CROSSING, sampler, confidence_weight=2.0)
    search.node_weights(EMPTY.key, one, None)
    search._rollback(2)
    # a new node 2 in the same state is a different rope: its confidence is asked again
    sampler.table[(2, one.key)] = 0.3
    root = search.tree.nodes[0]
    search.tree.add(Node(2, 0, root.q, root.points, EMPTY, None, 0, 0))
    assert np.allclose(search.node_weights(EMPTY.key, one, None), [0.36, 0.04, 0.09])


def test_the_model_confidence_is_the_largest_link_probability_row_by_row() -> None:
    model = load_default_model()
    _, points, _ = straight_rope()
    curled = points.copy()
    curled[:, 1] += 0.05 * np.sin(np.linspace(0.0, 3.0, len(points)))
    one, three = parse_p_data(ONE_CROSSING), parse_p_data(THREE_CROSSINGS)
    requests = [(EMPTY, one, None), (EMPTY, one, None), (EMPTY, three, None)]
    batch = model.link_confidence(np.stack([points, curled, points]), requests)
    single = [
        model.link_probabilities(p, nxt, p_data=now, move=move).max()
        for p, (now, nxt, move) in zip([points, curled, points], requests, strict=True)
    ]
    assert np.allclose(batch, single, atol=1e-5)
    assert np.all((batch >= 1.0 / 21.0 - 1e-6) & (batch <= 1.0))
    assert batch[0] != pytest.approx(batch[2]), "the request changes the confidence"
    q, _, _ = straight_rope()
    nodes = [Node(i, None, q, p, EMPTY, None, 0, 0) for i, p in enumerate([points, curled, points])]
    sampled = ModelCurves(model).confidence([(n, r[1], r[2]) for n, r in zip(nodes, requests, strict=True)])
    assert np.allclose(sampled, batch)
    assert ModelCurves(model).confidence([]).shape == (0,)


def test_a_stopped_run_with_the_confidence_weight_resumes_to_the_tree_of_one_run(tmp_path: Any) -> None:
    goal = check_goal(THREE_CROSSINGS)
    options = PlannerOptions(seed=11, k=2, p_expand=0.2, k_expand=4, confidence_weight=2.0)
    sampler = ModelCurves(load_default_model())
    with open_store(f"sqlite:///{tmp_path / 'c.db'}") as store, SimPool(1) as pool:
        whole = start_search(store, goal, options, pool, sampler=sampler)
        assert whole.uses_confidence
        whole.run(max_iterations=6)
        first = start_search(store, goal, options, pool, sampler=sampler)
        first.run(max_iterations=3)
        # a fresh sampler, as a new process has: nothing of the confidence is carried over
        rest = resume_search(store, first.run_id, pool, sampler=ModelCurves(load_default_model()))  # type: ignore[arg-type]
        assert rest.options.confidence_weight == 2.0
        rest.run(max_iterations=6)

        def signature(run_id: int) -> list[tuple[Any, ...]]:
            info = load_run(store, run_id)
            assert info is not None
            return [(n.seq, n.parent_seq, n.p_data.key, n.curve) for n in info.nodes]

        assert signature(whole.run_id) == signature(first.run_id)  # type: ignore[arg-type]
        assert rest.sim_calls == whole.sim_calls


def test_runs_stored_before_the_confidence_weight_resume_without_it() -> None:
    stored = PlannerOptions(seed=3, confidence_weight=2.0).to_dict()
    assert PlannerOptions.from_dict(stored).confidence_weight == 2.0
    del stored["confidence_weight"]
    assert PlannerOptions.from_dict(stored).confidence_weight == 0.0
    with pytest.raises(ValueError, match=r"confidence_weight must lie in \[0, 10\], got -1"):
        PlannerOptions(confidence_weight=-1.0).validate()
