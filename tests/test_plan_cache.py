"""The plan cache in the store (tables plan_queries / plans) and the `twisted moves` commands."""

from __future__ import annotations

import json

import pytest
from sqlalchemy import func, select, update
from typer.testing import CliRunner

from cli.main import app
from twisted.moves import MOVES_VERSION, Plan, plans
from twisted.store import open_store
from twisted.store.plans import PlanQuery, PlanRow, cached_plans, get_plans
from twisted.topology import EMPTY, parse_p_data

OVERHAND = parse_p_data(
    '[[1,"O",4,"+"],[2,"U",5,"+"],[3,"O",6,"+"],[4,"U",1,"+"],[5,"O",2,"+"],[6,"U",3,"+"]]'
)
CURL = parse_p_data('[[1,"U",2,"+"],[2,"O",1,"+"]]')  # the first state of every overhand plan
MINUS_CURL = parse_p_data('[[1,"O",2,"-"],[2,"U",1,"-"]]')
MIXED = parse_p_data('[[1,"O",2,"+"],[2,"U",1,"+"],[3,"U",6,"+"],[4,"U",5,"-"],[5,"O",4,"-"],[6,"O",3,"+"]]')


def test_miss_computes_and_stores_then_hits(db_url: str) -> None:
    with open_store(db_url) as store:
        first = cached_plans(store, EMPTY, OVERHAND, 10)
        assert first == plans(EMPTY, OVERHAND, 10)
        with store.session() as session:
            query = session.scalars(select(PlanQuery)).one()
            assert (query.start_key, query.goal_key, query.n_plans, query.complete) == (
                "[]",
                OVERHAND.key,
                4,
                True,
            )
            assert query.moves_version == MOVES_VERSION
            rows = session.scalars(select(PlanRow).order_by(PlanRow.plan_index)).all()
            assert [r.plan_index for r in rows] == [0, 1, 2, 3]
            assert [r.to_plan() for r in rows] == first
            # mark the stored copy: a hit must return what the database holds
            session.execute(update(PlanRow).where(PlanRow.plan_index == 0).values(length=99, moves=[]))
    # a new connection (another command, another run) reads the marked row back
    with open_store(db_url) as store:
        again = cached_plans(store, EMPTY, OVERHAND, 10)
        assert again[0].moves == [] and again[1:] == first[1:]
        with store.session() as session:
            assert session.scalar(select(func.count()).select_from(PlanQuery)) == 1


def test_unreachable_goal_is_cached_as_complete_and_empty(db_url: str) -> None:
    two_plus = parse_p_data('[[1,"O",2,"+"],[2,"U",1,"+"],[3,"O",4,"+"],[4,"U",3,"+"]]')
    with open_store(db_url) as store:
        assert cached_plans(store, MINUS_CURL, two_plus, 5) == []
        with store.session() as session:
            assert get_plans(session, MINUS_CURL, two_plus, 1000) == []  # known empty, not "unknown"
            query = session.scalars(select(PlanQuery)).one()
            assert (query.n_plans, query.complete) == (0, True)


def test_limits_smaller_answer_from_cache_larger_recompute(db_url: str) -> None:
    everything = plans(EMPTY, MIXED, 1000)
    assert len(everything) == 8
    with open_store(db_url) as store:
        assert cached_plans(store, EMPTY, MIXED, 3) == everything[:3]
        with store.session() as session:
            assert get_plans(session, EMPTY, MIXED, 2) == everything[:2]
            assert get_plans(session, EMPTY, MIXED, 4) is None  # 3 stored, more may exist
        assert cached_plans(store, EMPTY, MIXED, 20) == everything
        with store.session() as session:
            query = session.scalars(select(PlanQuery)).one()
            assert (query.plan_limit, query.n_plans, query.complete) == (20, 8, True)
            assert session.scalar(select(func.count()).select_from(PlanRow)) == 8
            assert get_plans(session, EMPTY, MIXED, 500) == everything


def test_plans_from_intermediate_states_are_separate_entries(db_url: str) -> None:
    with open_store(db_url) as store:
        from_root = cached_plans(store, EMPTY, OVERHAND, 10)
        from_curl = cached_plans(store, CURL, OVERHAND, 10)
        assert from_curl and all(p.states[0] == CURL for p in from_curl)
        assert [p.states[1:] for p in from_root if p.states[1] == CURL] == [p.states for p in from_curl]
        with store.session() as session:
            assert session.scalar(select(func.count()).select_from(PlanQuery)) == 2


def test_older_moves_version_is_recomputed(db_url: str) -> None:
    with open_store(db_url) as store:
        cached_plans(store, EMPTY, OVERHAND, 10)
        with store.session() as session:
            session.execute(update(PlanRow).values(moves=[]))
            session.execute(update(PlanQuery).values(moves_version=MOVES_VERSION - 1))
        assert cached_plans(store, EMPTY, OVERHAND, 10) == plans(EMPTY, OVERHAND, 10)
        with store.session() as session:
            assert session.scalars(select(PlanQuery.moves_version)).one() == MOVES_VERSION


def test_with_a_session_the_caller_commits(sqlite_url: str) -> None:
    with open_store(sqlite_url) as store:
        with store.session() as session:
            found = cached_plans(session, EMPTY, OVERHAND, 10)
            assert get_plans(session, EMPTY, OVERHAND, 10) == found
            session.rollback()
        with store.session() as session:
            assert get_plans(session, EMPTY, OVERHAND, 10) is None


def test_limit_must_be_positive(sqlite_url: str) -> None:
    with open_store(sqlite_url) as store, pytest.raises(ValueError, match="limit"):
        cached_plans(store, EMPTY, OVERHAND, 0)


# --------------------------------------------------------------------------------------------
# CLI

runner = CliRunner()


def test_cli_successors_and_distinct() -> None:
    result = runner.invoke(app, ["moves", "successors", "--state", "[]"])
    assert result.exit_code == 0, result.output
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert len(lines) == 12
    assert {line["move"]["kind"] for line in lines} == {"R1", "R2"}
    assert lines[2] == {
        "move": {"kind": "R1", "segment": 0, "side": "R", "over": "O", "sign": "+"},
        "state": [[1, "O", 2, "+"], [2, "U", 1, "+"]],
    }
    distinct = runner.invoke(app, ["moves", "successors", "--state", CURL.key, "--distinct"])
    assert distinct.exit_code == 0
    assert len(distinct.stdout.splitlines()) == 52


def test_cli_enumerate_is_stable_and_counts() -> None:
    result = runner.invoke(app, ["moves", "enumerate", "--max-crosses", "2"])
    assert result.exit_code == 0, result.output
    states = [parse_p_data(line) for line in result.stdout.splitlines()]
    assert [p.cross for p in states].count(1) == 4 and [p.cross for p in states].count(2) == 40
    assert states[0] == EMPTY
    assert states == sorted(states, key=lambda p: (p.cross, p.key))
    assert runner.invoke(app, ["moves", "enumerate", "--max-crosses", "2"]).stdout == result.stdout


def test_cli_plan_uses_the_cache(tmp_path) -> None:  # type: ignore[no-untyped-def]
    url = f"sqlite:///{tmp_path / 'plans.db'}"
    args = ["--db", url, "moves", "plan", "--goal", OVERHAND.key, "--limit", "3"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    got = [Plan.from_dict(json.loads(line)) for line in result.stdout.splitlines()]
    assert got == plans(EMPTY, OVERHAND, 3)
    with open_store(url) as store, store.session() as session:
        assert session.scalars(select(PlanQuery.goal_key)).one() == OVERHAND.key
    from_curl = runner.invoke(
        app, ["--db", url, "moves", "plan", "--start", CURL.key, "--goal", OVERHAND.key]
    )
    assert from_curl.exit_code == 0
    assert all(json.loads(line)["states"][0] == CURL.to_list() for line in from_curl.stdout.splitlines())


def _err(result) -> str:  # type: ignore[no-untyped-def]
    """stderr with rich's line wrapping undone."""
    return " ".join(result.stderr.split())


def test_cli_plan_errors(tmp_path) -> None:  # type: ignore[no-untyped-def]
    url = f"sqlite:///{tmp_path / 'plans.db'}"
    bad = runner.invoke(app, ["--db", url, "moves", "plan", "--goal", '[[1,"O",2]]'])
    assert bad.exit_code == 2
    assert "--goal" in _err(bad) and '[position, "O"|"U", partner, "+"|"-"]' in _err(bad)
    virtual = '[[1,"O",3,"+"],[2,"O",4,"+"],[3,"U",1,"+"],[4,"U",2,"+"]]'
    undrawable = runner.invoke(app, ["--db", url, "moves", "plan", "--goal", virtual])
    assert undrawable.exit_code == 2 and "cannot be drawn" in _err(undrawable)
    two_plus = '[[1,"O",2,"+"],[2,"U",1,"+"],[3,"O",4,"+"],[4,"U",3,"+"]]'
    unreachable = runner.invoke(
        app, ["--db", url, "moves", "plan", "--start", MINUS_CURL.key, "--goal", two_plus]
    )
    assert unreachable.exit_code == 3 and "cannot be reached" in _err(unreachable)
    bad_state = runner.invoke(app, ["moves", "successors", "--state", "[[1,2]]"])
    assert bad_state.exit_code == 2 and "--state" in _err(bad_state)
