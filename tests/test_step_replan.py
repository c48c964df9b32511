"""Closed loop one step at a time (docs/DESIGN.md section 15.4): which states a step replan aims at, when
the world's rope is pulled instead (it ties the goal's knot; a summand to cinch; an untied dead end), and
the replan mode as stored (revision 0017_episode_replan) and asked for on the command line."""

from __future__ import annotations

from pathlib import Path

import pytest
from alembic import command
from sqlalchemy import create_engine, text
from typer.testing import CliRunner

from cli.main import app
from twisted.experiments.episodes import CINCH_FIRST, UNTANGLE, ModelPlanner, ties_goal
from twisted.goals import knot_goal, state_goal
from twisted.moves import successor_states
from twisted.planner import planner_options
from twisted.store import open_store
from twisted.store.db import alembic_config
from twisted.topology import parse_p_data

STRAIGHT = parse_p_data("[]")
CURL = parse_p_data('[[1,"O",2,"+"],[2,"U",1,"+"]]')
# an overhand with three crossings more: both closures are the right-handed trefoil
TREFOIL_OF_6 = parse_p_data(
    '[[1,"U",8,"+"],[2,"O",9,"+"],[3,"U",6,"-"],[4,"U",11,"+"],[5,"O",12,"+"],[6,"O",3,"-"],'
    '[7,"O",10,"-"],[8,"O",1,"+"],[9,"U",2,"+"],[10,"U",7,"-"],[11,"O",4,"+"],[12,"U",5,"+"]]'
)
# two curls of opposite sign on one rope: two crossings, untied
TWO_CURLS = parse_p_data('[[1,"O",2,"+"],[2,"U",1,"+"],[3,"O",4,"-"],[4,"U",3,"-"]]')
runner = CliRunner()


def test_a_rope_that_ties_the_goals_knot_with_more_crossings_is_pulled() -> None:
    overhand = knot_goal("overhand")
    assert TREFOIL_OF_6 not in overhand and TREFOIL_OF_6.cross == 6
    assert ties_goal(overhand, TREFOIL_OF_6)
    assert all(ties_goal(overhand, p) for p in overhand.states)
    assert not ties_goal(overhand, CURL) and not ties_goal(knot_goal("figure-eight"), TREFOIL_OF_6)
    # a state goal asks for that diagram, not for what it ties
    assert not ties_goal(state_goal(CURL), TWO_CURLS) and ties_goal(state_goal(CURL), CURL)


@pytest.fixture
def store(tmp_path: Path):  # type: ignore[no-untyped-def]
    with open_store(f"sqlite:///{tmp_path / 'twisted.db'}") as opened:
        yield opened


def test_a_step_aims_at_the_next_states_of_the_plans_most_plans_go_through_first(store) -> None:  # type: ignore[no-untyped-def]
    goal = knot_goal("overhand")
    planner = ModelPlanner(store, goal, planner_options({}), None)
    try:
        plans = planner.plans(STRAIGHT)
        targets = planner.next_states(STRAIGHT)
    finally:
        planner.close()
    through = {p.key: sum(1 for plan in plans if plan.states[1].key == p.key) for p in targets}
    assert [p.key for p in targets] == sorted(through, key=lambda key: (-through[key], key))
    one_move = {p.key for p in successor_states(STRAIGHT)}
    assert {p.key for p in targets} == {plan.states[1].key for plan in plans} and set(through) <= one_move


def test_an_untied_dead_end_is_untangled_and_a_summand_cinched_once_per_state_and_episode(store) -> None:  # type: ignore[no-untyped-def]
    overhand = ModelPlanner(store, knot_goal("overhand"), planner_options({}), None, episode_run_id=1)
    granny = ModelPlanner(store, knot_goal("granny"), planner_options({}), None, episode_run_id=1)
    no_cinch = ModelPlanner(store, knot_goal("granny"), planner_options({"cinch": False}), None)
    try:
        # no adding move leads from two curls of opposite sign to a trefoil state: pull them out
        assert not overhand.plans(TWO_CURLS)
        assert overhand._cinch_reason(TWO_CURLS) == UNTANGLE
        assert overhand._cinch_reason(TWO_CURLS) is None  # once per state and episode
        overhand.episode_run_id = 2
        assert overhand._cinch_reason(TWO_CURLS) == UNTANGLE
        # a state with a plan, or one that ties a knot, is left to the step searches
        assert overhand.plans(CURL) and overhand._cinch_reason(CURL) is None
        assert overhand._cinch_reason(TREFOIL_OF_6) is None
        trefoil = knot_goal("overhand").states[0]
        assert granny._cinch_reason(trefoil) == CINCH_FIRST
        assert granny._cinch_reason(trefoil) is None
        assert no_cinch._cinch_reason(trefoil) is None
    finally:
        for planner in (overhand, granny, no_cinch):
            planner.close()


def test_closed_loop_episodes_stored_before_the_replan_mode_replanned_by_search(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'old.db'}"
    engine = create_engine(url)
    with engine.begin() as conn:
        command.upgrade(alembic_config(conn), "0016_episodes")
        for run_id, closed in ((1, 1), (2, 0)):
            conn.execute(
                text(
                    "INSERT INTO runs (id, kind, parameters, status, started_at, tried, kept, rejected, "
                    "wall_seconds, sim_seconds) VALUES (:id, 'episode', '{}', 'finished', '2026-12-06', "
                    "0, 0, 0, 2, 0)"
                ),
                {"id": run_id},
            )
            conn.execute(
                text(
                    "INSERT INTO episodes (run_id, goal_knot, level, level_ranges, world_seed, physics, "
                    "closed_loop, timeout_s, max_actions, outcome, actions, replans, planning_s, elapsed_s) "
                    "VALUES (:id, 'overhand', 'moderate', '{}', 1, '{}', :closed, 180, 30, 'tied', "
                    "5, 1, 1, 2)"
                ),
                {"id": run_id, "closed": closed},
            )
    engine.dispose()
    with open_store(url) as store, store.engine.connect() as conn:
        modes = dict(conn.execute(text("SELECT run_id, replan FROM episodes ORDER BY run_id")).all())
    assert modes == {1: "search", 2: None}


@pytest.mark.parametrize("command_args", [["execute", "1", "--closed-loop"], ["tie", "--knot", "overhand"]])
def test_a_replan_mode_that_does_not_exist_is_refused_before_anything_is_written(
    tmp_path: Path, command_args: list[str]
) -> None:
    new = tmp_path / "new.db"
    result = runner.invoke(app, ["--db", f"sqlite:///{new}", *command_args, "--replan", "sideways"])
    assert result.exit_code == 2 and "--replan" in result.output, result.output
    assert not new.exists()


def test_a_search_for_one_action_keeps_only_curves_from_the_start_that_change_its_state(
    tmp_path: Path,
) -> None:
    import json

    from sqlalchemy import select

    from twisted.store.search_tree import SearchNode

    db = f"sqlite:///{tmp_path / 'twisted.db'}"
    two_curls = '[[1,"O",2,"+"],[2,"U",1,"+"],[3,"O",4,"+"],[4,"U",3,"+"]]'
    args = ["--db", db, "plan", "--goal", two_curls, "--planner", "random-low", "--workers", "1"]
    result = runner.invoke(app, [*args, "--one-action", "--max-iterations", "40", "--json"])
    assert result.exit_code in (0, 3), result.output
    run_id = int(json.loads(result.output)["run_id"])
    with open_store(db) as store, store.session() as session:
        nodes = session.execute(
            select(SearchNode.id, SearchNode.seq, SearchNode.parent_id, SearchNode.cross).where(
                SearchNode.run_id == run_id
            )
        ).all()
        query = text("SELECT parameters FROM runs WHERE id = :id")
        parameters = session.execute(query, {"id": run_id}).scalar()
    (root,) = [n for n in nodes if n.seq == 0]
    assert len(nodes) > 1  # forty iterations of random curves toward two curls reach some crossing
    assert all(n.parent_id == root.id and n.cross > 0 for n in nodes if n.seq > 0)
    assert json.loads(parameters)["one_action"] is True


def test_a_step_replan_with_no_time_left_is_out_of_time_not_lost(store) -> None:  # type: ignore[no-untyped-def]
    from twisted.experiments.episodes import OUT_OF_TIME
    from twisted.sim import RopeSim

    sim = RopeSim()
    sim.reset()
    planner = ModelPlanner(store, knot_goal("overhand"), planner_options({}), None)
    try:
        replanned = planner.replan_step(sim.link_points(), seed=1, timeout_s=0.0)
    finally:
        planner.close()
    assert replanned.reason == OUT_OF_TIME and replanned.plan is None and replanned.run_id is None
