"""The planner (Algorithm 1): finds and replays a plan, resumes after SIGKILL, rejects bad input.

Simulation is real everywhere (in-process ``SimPool(1)`` or worker processes); seeds are fixed so
every run here is the same run each time.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sqlalchemy import func, select, text
from typer.testing import CliRunner

from cli.main import app
from twisted.goals import PlanInputError, check_goal
from twisted.moves import plans
from twisted.planner import (
    Node,
    PlannerOptions,
    RandomCurves,
    Search,
    SearchTree,
    planner_options,
    replay,
    resume_search,
    start_search,
    straight_rope,
)
from twisted.runtime import StopSignals
from twisted.sim.pool import SimPool
from twisted.store import open_store
from twisted.store.models import Run
from twisted.store.search_tree import SearchCheckpoint, SearchNode, SearchRunRow, load_run
from twisted.topology import EMPTY, PData, parse_p_data

ONE_CROSSING = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
# a 3-crossing goal that random curves do not reach in seconds (for the kill / resume cycle)
THREE_CROSSINGS = '[[1,"O",4,"+"],[2,"U",5,"+"],[3,"O",6,"+"],[4,"U",1,"+"],[5,"O",2,"+"],[6,"U",3,"+"]]'

# seven curls one after the other: a valid rope, but more crossings than the model encodes
SEVEN_CURLS = json.dumps([[p, "O" if p % 2 else "U", p + 1 if p % 2 else p - 1, "+"] for p in range(1, 15)])

runner = CliRunner()


def _db(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'plan.db'}"


def _plan(db: str, *args: str) -> tuple[int, str]:
    result = runner.invoke(app, ["--db", db, "plan", *args])
    return result.exit_code, result.output


# --- the whole loop -----------------------------------------------------------------------------------


def test_random_low_finds_a_one_crossing_plan_and_it_replays(db_url: str) -> None:
    db = db_url
    code, out = _plan(
        db, "--goal", ONE_CROSSING, "--planner", "random-low", "--workers", "1", "--timeout", "120", "--json"
    )
    assert code == 0, out
    result = json.loads(out)
    assert result["solved"] and result["outcome"] == "solved"
    assert result["plan"][-1]["state"] == json.loads(ONE_CROSSING)
    assert result["sim_calls"] > 0 and result["search_time_s"] > 0
    # every simulator call is counted under the source of its curve
    assert sum(result["sim_calls_by_source"].values()) == result["sim_calls"]
    assert set(result["sim_calls_by_source"]) <= {"follow_plan", "random_expand"}
    for steps in result["plan_steps_by_move"].values():
        assert 0 <= steps["reached"] <= steps["tried"]
    # the stored path is the printed one, and replaying it in a fresh simulator ends in the goal
    with open_store(db) as store:
        replayed = replay(store, result["run_id"])
        assert replayed.reached_goal
        assert all(step.matches for step in replayed.steps)
        assert [step.curve.link for step in replayed.steps] == [row["link"] for row in result["plan"]]
    # the view search_plan_steps lists the same plan, step 0 being the initial configuration
    with open_store(db) as store, store.engine.connect() as conn:
        rows = conn.execute(
            text("SELECT step, link, state FROM search_plan_steps WHERE run_id = :r ORDER BY step"),
            {"r": result["run_id"]},
        ).all()
    assert [r.step for r in rows] == list(range(len(result["plan"]) + 1))
    assert rows[0].link is None and rows[0].state == "[]"
    printed = [(step["link"], step["state"]) for step in result["plan"]]
    assert [(r.link, json.loads(r.state)) for r in rows[1:]] == printed
    replayed_cli = runner.invoke(app, ["--db", db, "replay", str(result["run_id"]), "--json"])
    assert replayed_cli.exit_code == 0, replayed_cli.output
    assert json.loads(replayed_cli.output)["reached_goal"] is True


def test_tree_keeps_only_results_that_do_not_lose_crossings_nor_overshoot(tmp_path: Path) -> None:
    goal = check_goal(ONE_CROSSING)
    options = PlannerOptions(planner="random-low", seed=3, k=4, p_expand=0.5, k_expand=8)
    with open_store(_db(tmp_path)) as store, SimPool(1) as pool:
        search = start_search(store, goal, options, pool)
        result = search.run(max_iterations=6)
        tree = search.tree
        for node in tree.nodes[1:]:
            parent = tree.nodes[node.parent]
            assert parent.p_data.cross <= node.p_data.cross <= goal.cross
            assert node.sim_call <= result.sim_calls and node.iteration <= result.iterations
        with store.session() as session:
            stored = session.scalar(select(func.count()).select_from(SearchNode))
        assert stored == len(tree) == result.nodes
    # the counts per source add up to the calls and to the nodes below the root
    by_source = result.stats["calls"]
    assert set(by_source) == {"follow_plan", "random_expand"}  # p_expand 0.5 over 6 iterations
    assert sum(calls for calls, _ in by_source.values()) == result.sim_calls
    assert sum(kept for _, kept in by_source.values()) == len(tree) - 1
    # one follow_plan step per iteration that selected a plan from the root, more when it hit
    tried = sum(t for t, _ in result.steps_by_move().values())
    reached = sum(r for _, r in result.steps_by_move().values())
    assert result.iterations <= tried and reached <= tried
    assert tried * options.k == result.calls_by_source()["follow_plan"]



def test_a_search_logs_its_start_checkpoints_and_end(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    options = PlannerOptions(planner="random-low", seed=3, k=4, p_expand=0.5, k_expand=8)
    caplog.set_level(logging.DEBUG, logger="twisted.planner.runs")
    with open_store(_db(tmp_path)) as store, SimPool(1) as pool:
        search = start_search(store, check_goal(THREE_CROSSINGS), options, pool)
        search.run(max_iterations=2)
        resume_search(store, search.run_id, pool).run(max_iterations=3)  # type: ignore[arg-type]
    lines = [r.getMessage() for r in caplog.records if r.name == "twisted.planner.runs"]
    assert lines[0].startswith("run 1: new search from the straight rope for goal [[1,")
    assert "planner random-low, heuristic crs, model none, seed 3" in lines[0]
    assert any(line.startswith("run 1: checkpoint at iteration 2") for line in lines)
    assert any(line.startswith("run 1 stopped at its iteration limit") for line in lines)
    assert any(line.startswith("run 1: resumed at iteration 2") for line in lines)
    assert "iterations" in lines[-1] and "simulator calls" in lines[-1]


def test_a_resumed_run_keeps_its_options() -> None:
    stored = PlannerOptions(planner="random-low", seed=4).to_dict()
    assert planner_options({"seed": 4, "k": None}, stored=stored) == PlannerOptions.from_dict(stored)
    with pytest.raises(PlanInputError, match=r"drop or fix: --seed 5 \(run has 4\)"):
        planner_options({"seed": 5}, stored=stored)
    with pytest.raises(PlanInputError, match="heuristic must be one of"):
        planner_options({"heuristic": "bogus"})

# --- selection heuristics --------------------------------------------------------------------------------


def _search_with_states(states: list[str], heuristic: str, goal: str, **options: Any) -> Search:
    """A search whose tree holds one node per state (no simulation is needed to select)."""
    q, points, p0 = straight_rope()
    tree = SearchTree()
    for i, state in enumerate(states):
        p = parse_p_data(state)
        tree.add(Node(i, None if i == 0 else 0, q, points, p, None, 0, 0))
    g = check_goal(goal)
    # every node has the straight rope's points whatever its state: no room for a curl can be read
    options.setdefault("r1_room", 0.0)
    options = PlannerOptions(heuristic=heuristic, seed=7, **options)
    return Search(g, tree, options, pool=None, high_level=lambda s: plans(s, g, 100))  # type: ignore[arg-type]


STATES_0_1_2 = ["[]", ONE_CROSSING, '[[1,"O",4,"+"],[2,"O",3,"+"],[3,"U",2,"+"],[4,"U",1,"+"]]']
GOAL_3 = '[[1,"O",6,"+"],[2,"O",5,"+"],[3,"O",4,"+"],[4,"U",3,"+"],[5,"U",2,"+"],[6,"U",1,"+"]]'


# (each selection on its own, rnd / crs / ucb, the retry weight and the R1 room: tests/test_strategies.py)


def test_the_search_asks_its_parts_with_its_own_generator() -> None:
    """Two searches with one seed make the same choices; the choices are those of the parts."""
    a = _search_with_states(STATES_0_1_2, "crs", GOAL_3)
    b = _search_with_states(STATES_0_1_2, "crs", GOAL_3)
    picks = [a.select_topological_state() for _ in range(30)]
    assert picks == [b.select_topological_state() for _ in range(30)]
    assert set(picks) <= set(a.candidate_states) and len(set(picks)) == 3
    s = picks[0]
    index, plan = a.select_plan(s)
    assert plan is a.plans[s][index]
    assert a.select_configuration(s, plan.states[1], plan.moves[0]).p_data.key == s


def test_states_off_every_plan_are_not_candidates() -> None:
    # a 1-crossing state of the wrong sign is not a sub-state of this goal: no plan leads on from it
    wrong = '[[1,"O",2,"-"],[2,"U",1,"-"]]'
    search = _search_with_states(["[]", wrong], "crs", GOAL_3)
    assert search.candidate_states == [EMPTY.key]


def test_follow_plan_counts_each_node_and_next_state_it_asks_for(tmp_path: Path) -> None:
    options = PlannerOptions(planner="random-low", seed=0)
    with open_store(_db(tmp_path)) as store, SimPool(1, 1.0) as pool:
        search = start_search(store, check_goal(ONE_CROSSING), options, pool)
        result = search.run(max_iterations=5)
    pairs = result.stats["pair"]
    steps = sum(tried for tried, _ in result.steps_by_move().values())
    assert pairs and sum(tried for tried, _ in pairs.values()) == steps
    assert sum(tried for tried, _ in result.stats["step"].values()) == steps
    assert all(key.split("|")[1] == parse_p_data(ONE_CROSSING).key for key in pairs)


def test_runs_stored_before_the_retry_weight_resume_with_the_uniform_choice() -> None:
    stored = PlannerOptions(seed=3).to_dict()
    del stored["retry_weight"]
    assert PlannerOptions.from_dict(stored).retry_weight == 1.0
    assert PlannerOptions().retry_weight < 1.0
    with pytest.raises(PlanInputError, match=r"retry_weight must lie in \(0, 1\], got 0"):
        planner_options({"retry_weight": 0.0})


def test_no_same_state_keeps_only_curves_that_change_the_state_and_the_cinch(tmp_path: Path) -> None:
    """--no-same-state (DESIGN 8): a curve whose rope stays in its parent's state does not enter T; the
    same search with the default keeps such curves (from the straight rope most random curves do). A
    cinch's rope keeps its state by design and enters T either way."""
    from types import SimpleNamespace

    from twisted.planner.tree import CINCH

    goal = check_goal(ONE_CROSSING)
    same: dict[bool, int] = {}
    with open_store(_db(tmp_path)) as store, SimPool(1) as pool:
        for keep in (True, False):
            options = PlannerOptions(planner="random-low", seed=0, same_state=keep)
            search = start_search(store, goal, options, pool)
            search.run(max_iterations=40)
            nodes = search.tree.nodes
            assert len(nodes) > 1
            same[keep] = sum(n.p_data == nodes[n.parent].p_data for n in nodes[1:])
            assert store_options(store, search) == options.to_dict()
    assert same[True] > 0 and same[False] == 0, same
    root = search.tree.nodes[0]
    stays = SimpleNamespace(ok=True, p_data=root.p_data, state=root.q, points=root.points)
    assert search.add_to_tree(root, "a curve", stays, 0) is None
    cinched = search.add_to_tree(root, CINCH, stays, 0)
    assert cinched is not None and cinched.p_data == root.p_data


def store_options(store: Any, search: Search) -> dict[str, Any]:
    """The options the search's run stored (a resume reads them back)."""
    with store.session() as session:
        return PlannerOptions.from_dict(session.get(Run, search.run_id).parameters).to_dict()


def test_a_run_stored_with_a_removed_option_is_refused_unless_it_had_no_effect(tmp_path: Path) -> None:
    """--state-prior was removed: a run searched with it (n0 > 0) cannot continue as another search;
    one that stored the value without effect (0, the default of its day) resumes as before."""
    goal = check_goal(ONE_CROSSING)
    options = PlannerOptions(planner="random-low", seed=2, k=2, p_expand=0.0)
    with open_store(_db(tmp_path)) as store, SimPool(1) as pool:
        runs = []
        for prior in (50.0, 0.0):
            search = start_search(store, goal, options, pool)
            search.run(max_iterations=1)
            with store.session(write=True) as session:
                row = session.get(Run, search.run_id)
                assert row is not None
                row.parameters = {**row.parameters, "state_prior": prior}
            runs.append(search.run_id)
        with pytest.raises(PlanInputError, match=rf"run {runs[0]} cannot be continued: .*state_prior 50.0"):
            resume_search(store, runs[0], pool)
        info = load_run(store, runs[0], with_nodes=False)
        assert info is not None and info.holder is None  # refused before its lease was taken
        assert resume_search(store, runs[1], pool).run(max_iterations=2).iterations == 2
    code, out = _plan(_db(tmp_path), "--resume", str(runs[0]), "--workers", "1")
    assert code == 2 and "--state-prior was removed" in " ".join(out.split()), out


# --- persistence: checkpoint, resume, determinism ----------------------------------------------------------


def _tree_signature(store, run_id: int) -> list[tuple]:  # type: ignore[no-untyped-def]
    info = load_run(store, run_id)
    assert info is not None
    return [(n.seq, n.parent_seq, n.p_data.key, n.curve, n.iteration, n.sim_call) for n in info.nodes]


def test_stop_and_resume_gives_the_same_tree_as_one_run(db_url: str) -> None:
    """On SQLite and PostgreSQL: the RNG state, statistics and tree survive the store bit for bit."""
    goal = check_goal(THREE_CROSSINGS)
    options = PlannerOptions(planner="random-low", seed=11, k=3, p_expand=0.3, k_expand=5)
    with open_store(db_url) as store, SimPool(1) as pool:
        whole = start_search(store, goal, options, pool)
        assert whole.run(max_iterations=6).status == "stopped"
        first = start_search(store, goal, options, pool)
        half = first.run(max_iterations=3)
        assert half.status == "stopped" and half.iterations == 3
        resumed = resume_search(store, first.run_id, pool)
        assert resumed.iteration == 3 and resumed.elapsed_before_s == pytest.approx(half.elapsed_s)
        rest = resumed.run(max_iterations=6)
        assert rest.run_id == first.run_id and rest.iterations == 6
        assert rest.sim_calls == whole.sim_calls
        # the move and call counts survive the store like the selection statistics
        whole_result = load_run(store, whole.run_id, with_nodes=False)
        assert whole_result is not None and whole_result.checkpoint is not None
        assert rest.stats == whole_result.checkpoint.stats
        assert sum(rest.calls_by_source().values()) == rest.sim_calls
        assert rest.elapsed_s > half.elapsed_s
        a, b = _tree_signature(store, whole.run_id), _tree_signature(store, first.run_id)
        assert a == b
        with store.session() as session:
            row = session.get(SearchRunRow, first.run_id)
            assert row is not None and row.outcome == "stopped"


class _StopOnCall(RandomCurves):
    """Random curves that raise a stop request on their ``n``-th call: the pool wait right after it
    is cut short, inside an iteration, as a Ctrl-C would do."""

    def __init__(self, stop: StopSignals, n: int) -> None:
        self.stop, self.n, self.calls = stop, n, 0
        self.search: Search | None = None
        self.stopped_in = 0  # the iteration the stop request came in

    def sample(self, *args: Any, **kwargs: Any) -> list[Any]:
        self.calls += 1
        if self.calls == self.n:
            self.stop.signum = signal.SIGTERM
            self.stopped_in = self.search.iteration if self.search is not None else 0
        return super().sample(*args, **kwargs)


def test_a_stop_mid_iteration_is_rolled_back_so_the_search_continues_identically(tmp_path: Path) -> None:
    goal = check_goal(THREE_CROSSINGS)
    options = PlannerOptions(planner="random-low", seed=5, k=3, p_expand=0.3, k_expand=5)
    with open_store(_db(tmp_path)) as store, SimPool(1) as pool:
        whole = start_search(store, goal, options, pool)
        whole.run(max_iterations=7)
        stop = StopSignals()
        sampler = _StopOnCall(stop, 5)
        cut = start_search(store, goal, options, pool, sampler=sampler, stop=stop)
        sampler.search = cut
        first = cut.run()
        # the iteration the stop came in was dropped (a plan step that succeeds samples again, so
        # the 5th sample may fall in an earlier iteration than the 5th)
        assert first.status == "interrupted" and sampler.stopped_in >= 2
        assert first.iterations == sampler.stopped_in - 1
        assert len(cut.tree) == first.nodes == cut._saved
        stop.signum = None
        second = cut.run(max_iterations=7)
        assert second.elapsed_s > first.elapsed_s
        assert _tree_signature(store, whole.run_id) == _tree_signature(store, cut.run_id)
        assert second.sim_calls == whole.sim_calls


def _wait_for_checkpoint(db_path: Path, min_iteration: int, proc: subprocess.Popen, limit_s: float) -> None:
    import sqlite3

    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
        if db_path.exists():
            try:
                with sqlite3.connect(db_path, timeout=5) as conn:
                    row = conn.execute("SELECT MAX(iteration) FROM search_checkpoints").fetchone()
                if row and row[0] is not None and row[0] >= min_iteration:
                    return
            except sqlite3.OperationalError:
                pass  # tables not created yet
        time.sleep(0.2)
    raise AssertionError(f"no checkpoint at iteration >= {min_iteration} within {limit_s} s")


def _checkpoint_elapsed_s(db_path: Path) -> float:
    import sqlite3

    with sqlite3.connect(db_path, timeout=5) as conn:
        return float(conn.execute("SELECT MAX(elapsed_s) FROM search_checkpoints").fetchone()[0])


def _twisted(*args: str) -> list[str]:
    return [sys.executable, "-c", "from cli.main import run; run()", *args]


@pytest.mark.slow
def test_sigkill_then_resume_keeps_run_id_time_and_rows(tmp_path: Path) -> None:
    db_path = tmp_path / "plan.db"
    db = f"sqlite:///{db_path}"
    common = ["--planner", "random-low", "--workers", "2", "--checkpoint-every", "0.3", "--json"]
    proc = subprocess.Popen(
        _twisted("--db", db, "plan", "--goal", THREE_CROSSINGS, "--timeout", "120", *common),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        _wait_for_checkpoint(db_path, 3, proc, 90)
        time.sleep(0.5)
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
    with open_store(db) as store, store.session() as session:
        (run_id,) = session.scalars(select(SearchRunRow.run_id)).all()
        checkpoint = session.get(SearchCheckpoint, run_id)
        assert checkpoint is not None
        killed_elapsed_s, killed_iteration = checkpoint.elapsed_s, checkpoint.iteration
        # nodes and checkpoint are written together: nothing beyond the checkpoint survives the kill
        assert session.scalar(select(func.count()).select_from(SearchNode)) == checkpoint.nodes
        assert session.scalar(select(func.max(SearchNode.iteration))) <= killed_iteration

    out = subprocess.run(
        _twisted("--db", db, "plan", "--resume", "--timeout", str(killed_elapsed_s + 3.0), *common),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 3, out.stderr
    result = json.loads(out.stdout)
    assert result["run_id"] == run_id and result["outcome"] == "timeout"
    assert result["search_time_s"] >= killed_elapsed_s + 3.0 - 1e-6
    assert result["iterations"] > killed_iteration
    with open_store(db) as store, store.session() as session:
        assert session.scalar(select(func.count()).select_from(SearchRunRow)) == 1
        seqs = session.scalars(select(SearchNode.seq).order_by(SearchNode.seq)).all()
        assert seqs == list(range(len(seqs))), "every node once, in creation order"
        assert len(seqs) == result["nodes"]


@pytest.mark.slow
def test_sigterm_saves_a_checkpoint_and_exits_143(tmp_path: Path) -> None:
    db_path = tmp_path / "plan.db"
    db = f"sqlite:///{db_path}"
    proc = subprocess.Popen(
        _twisted("--db", db, "plan", "--goal", THREE_CROSSINGS, "--planner", "random-low", "--workers", "2",
                 "--timeout", "120", "--checkpoint-every", "30"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        _wait_for_checkpoint(db_path, 0, proc, 60)
        first_elapsed_s = _checkpoint_elapsed_s(db_path)
        # a live run cannot be resumed by a second process
        code, out = _plan(db, "--resume", "1", "--timeout", "5")
        assert code == 2 and "still being searched" in out
        assert _plan(db, "--resume", "--timeout", "5")[0] == 2  # no resumable (non-live) run
        time.sleep(2.0)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "--resume" in err
    with open_store(db) as store:
        run_id = store.session().__enter__().scalar(select(SearchRunRow.run_id))
        info = load_run(store, run_id)
        assert info is not None and info.outcome == "interrupted" and info.status == "interrupted"
        assert info.checkpoint is not None and info.checkpoint.iteration > 0
        # --checkpoint-every 30: only the SIGTERM handler can have written the search time since then
        # (>= 2 s of sleep; the unfinished last iteration is rolled back, so allow one iteration less)
        assert info.checkpoint.elapsed_s >= first_elapsed_s + 1.0
        assert len(info.nodes) == info.checkpoint.nodes


# --- bad input ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "goal",
    [
        "not json",
        '[[1,"O",2,"+"]]',  # one visit
        '[[1,"O",2,"+"],[2,"O",1,"+"]]',  # both over
        '[[1,"O",2,"+"],[2,"U",1,"-"]]',  # signs differ
        "[]",  # the straight rope already
        SEVEN_CURLS,
    ],
)
def test_bad_goals_exit_2(tmp_path: Path, goal: str) -> None:
    code, out = _plan(_db(tmp_path), "--goal", goal, "--planner", "random-low", "--timeout", "1")
    assert code == 2, out
    assert "goal" in out.lower()


def test_a_goal_at_the_crossing_limit_is_taken_and_encoded_and_one_beyond_is_refused() -> None:
    from twisted.model.encoding import encode_p_data
    from twisted.rope import MAX_CROSSINGS

    def loops(n: int) -> PData:
        return PData.from_crossings([(2 * k + 1, 2 * k + 2, 1) for k in range(n)])

    assert np.isfinite(encode_p_data(check_goal(loops(MAX_CROSSINGS)))).all()
    with pytest.raises(PlanInputError, match=f"the inverse model encodes at most {MAX_CROSSINGS}"):
        check_goal(loops(MAX_CROSSINGS + 1))


def test_bad_run_ids_and_missing_model_exit_2(tmp_path: Path) -> None:
    db = _db(tmp_path)
    assert _plan(db, "--resume", "42", "--timeout", "1")[0] == 2
    assert _plan(db, "--resume", "--timeout", "1")[0] == 2  # nothing to resume
    assert _plan(db, "--timeout", "1")[0] == 2  # no goal
    assert runner.invoke(app, ["--db", db, "replay", "42"]).exit_code == 2
    code, out = _plan(db, "--goal", ONE_CROSSING, "--model", "999", "--timeout", "1")
    assert code == 2 and "model" in out.lower()
    with open_store(db) as store:
        with store.session() as session:
            assert session.scalar(select(func.count()).select_from(SearchRunRow)) == 0


def test_resume_refuses_changed_search_options(tmp_path: Path) -> None:
    db = _db(tmp_path)
    code, out = _plan(db, "--goal", THREE_CROSSINGS, "--planner", "random-low", "--workers", "1",
                      "--max-iterations", "1", "--k", "2", "--p-expand", "0", "--json")
    assert code == 3, out
    run_id = json.loads(out)["run_id"]
    code, out = _plan(db, "--resume", str(run_id), "--heuristic", "ucb", "--timeout", "5")
    assert code == 2 and "heuristic" in out
    code, out = _plan(db, "--resume", str(run_id), "--goal", ONE_CROSSING, "--timeout", "5")
    assert code == 2 and "goal" in out


def test_unknown_heuristic_or_planner_exit_2(tmp_path: Path) -> None:
    db = _db(tmp_path)
    code, out = _plan(db, "--goal", ONE_CROSSING, "--heuristic", "greedy", "--timeout", "1")
    assert code == 2 and "heuristic" in out
    code, out = _plan(db, "--goal", ONE_CROSSING, "--planner", "magic", "--timeout", "1")
    assert code == 2 and "planner" in out


def test_start_config_is_the_root_of_the_tree(tmp_path: Path) -> None:
    from twisted.sim import Curve, RopeSim
    from twisted.sim.pool import simulate
    from twisted.store.queries import add_configuration

    db = _db(tmp_path)
    sim = RopeSim()
    sim.reset()
    moved = simulate(sim, sim.state(), Curve(3, 0.02, 0.1, 0.2))
    assert moved.ok and moved.state is not None and moved.p_data is not None
    with open_store(db) as store:
        with store.session(write=True) as session:
            config_id = add_configuration(
                session, run_id=None, p_data=moved.p_data, q=moved.state, points=moved.points
            ).id
    assert _plan(db, "--goal", ONE_CROSSING, "--start-config", str(config_id + 1), "--timeout", "1",
                 "--planner", "random-low")[0] == 2
    code, out = _plan(db, "--goal", ONE_CROSSING, "--start-config", str(config_id), "--planner", "random-low",
                      "--workers", "1", "--max-iterations", "1", "--p-expand", "0", "--json")
    assert code in (0, 3), out
    with open_store(db) as store:
        info = load_run(store, json.loads(out)["run_id"])
        assert info is not None and info.start_configuration_id == config_id
        assert np.array_equal(info.nodes[0].q, moved.state)


# --- one call runs a search ------------------------------------------------------------------------------


def test_run_search_opens_nothing_for_a_bad_goal_and_its_result_serialises_itself(tmp_path: Path) -> None:
    """run_search is every caller's one call: a bad goal is refused before the store is opened (so no
    database is created), and a search's result is its own JSON (what `plan --json` prints)."""
    from twisted.planner import SearchProgress, SearchRequest, run_search

    url = _db(tmp_path)
    opened: list[bool] = []

    def opener(*, create: bool) -> Any:
        opened.append(create)
        return open_store(url) if create else None

    with pytest.raises(PlanInputError, match="--goal"):
        run_search(opener, SearchRequest(goal="[[1,", workers=1))
    assert opened == [] and not (tmp_path / "plan.db").exists()
    progress = SearchProgress()
    options = {"planner": "random-low", "seed": 0}
    request = SearchRequest(goal=ONE_CROSSING, options=options, workers=1, timeout_s=600, timed_setup=False)
    result = run_search(opener, request, progress=progress)
    assert opened == [True] and result.solved and progress.search is not None
    payload = json.loads(json.dumps(result.to_dict()))
    assert payload["run_id"] == result.run_id == progress.search.run_id and payload["outcome"] == "solved"
    assert payload["reached_state"] == parse_p_data(ONE_CROSSING).to_list() == payload["plan"][-1]["state"]
    assert payload["sim_calls"] == sum(payload["sim_calls_by_source"].values())


def test_run_search_reuses_the_workers_and_model_it_is_given_and_leaves_them_running(tmp_path: Path) -> None:
    """Issue 64's replans: searches in a row given one SearchResources start the workers and load the
    model once; run_search leaves them running (the owner closes them), and starts its own without."""
    from twisted.planner import SearchProgress, SearchRequest, SearchResources, run_search

    options = {"planner": "twisted", "seed": 0}
    request = SearchRequest(goal=ONE_CROSSING, options=options, workers=1, timeout_s=600, timed_setup=False)
    pools, samplers = [], []
    with open_store(_db(tmp_path)) as store, SearchResources() as resources:
        for seed in (0, 1):
            progress = SearchProgress()
            asked = dataclasses.replace(request, options={**options, "seed": seed})
            assert run_search(store, asked, progress=progress, resources=resources).solved
            assert progress.search is not None
            pools.append(progress.search.pool)
            samplers.append(progress.search.sampler)
        # the second search ran on the first one's workers: they were left running
        assert pools[0] is pools[1] is resources.pool(1, 1.0) and samplers[0] is samplers[1]
        alone = SearchProgress()
        assert run_search(store, request, progress=alone).solved and alone.search is not None
        assert alone.search.pool is not pools[0]
