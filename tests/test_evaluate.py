"""Experiments: problem sets from a synthetic database, goal import errors, resumable eval, report,
discretisation."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select
from typer.testing import CliRunner

from cli.main import app
from twisted.experiments.discretise import round_curve, run_discretisation
from twisted.experiments.problems import (
    EvalInputError,
    make_problem_sets_in_store,
    parse_goal_file,
    rank_by_frequency,
    split_thirds,
)
from twisted.experiments.report import load_results, success_curve, success_until, write_report
from twisted.experiments.runner import EvalOptions, run_eval
from twisted.goals import state_goal
from twisted.moves import enumerate_states, successors
from twisted.planner import PlannerOptions
from twisted.store import open_store
from twisted.store.experiments import EvalResult, EvalRun, ProblemRecord, load_problem_set, save_problem_set
from twisted.store.models import Configuration, Run, TopologicalState, Transition, array_to_blob
from twisted.store.queries import get_or_create_state, start_run
from twisted.topology import EMPTY, PData, parse_p_data

ONE = parse_p_data([[1, "O", 2, "+"], [2, "U", 1, "+"]])
ONE_UNDER = parse_p_data([[1, "U", 2, "+"], [2, "O", 1, "+"]])
STATES_3 = enumerate_states(3)[3]


def _add_transition(
    session, run_id: int, from_config: Configuration, p_data: PData, curve=(0, 0.01, 0.1, 0.1)
):
    """A kept transition into ``p_data`` with made-up arrays (enough for frequency counting)."""
    state = get_or_create_state(session, p_data)
    config = Configuration(
        run_id=run_id,
        state_id=state.id,
        cross=p_data.cross,
        q=array_to_blob(np.zeros(93)),
        points=array_to_blob(np.zeros((22, 3))),
    )
    session.add(config)
    session.flush()
    link, z, x, y = curve
    session.add(
        Transition(
            run_id=run_id,
            from_configuration_id=from_config.id,
            to_configuration_id=config.id,
            link=link,
            z_max_m=z,
            x_m=x,
            y_m=y,
            from_state_id=from_config.state_id,
            to_state_id=state.id,
            from_cross=from_config.cross,
            to_cross=p_data.cross,
        )
    )
    return config


@pytest.fixture
def synthetic(db_url: str):
    """12 visited 3-crossing states with frequencies 1..12, plus a 2-crossing state visited 50 times."""
    visited = STATES_3[::40][:12]
    with open_store(db_url) as store:
        with store.session(write=True) as session:
            run_id = start_run(session, "collect", {}).id
            root_state = get_or_create_state(session, EMPTY)
            root = Configuration(
                run_id=run_id,
                state_id=root_state.id,
                cross=0,
                q=array_to_blob(np.zeros(93)),
                points=array_to_blob(np.zeros((22, 3))),
            )
            session.add(root)
            session.flush()
            for i, p in enumerate(visited):
                for _ in range(i + 1):
                    _add_transition(session, run_id, root, p)
            two = enumerate_states(2)[2][0]
            for _ in range(50):
                _add_transition(session, run_id, root, two)
        yield store, {p.key: i + 1 for i, p in enumerate(visited)}


def test_split_thirds_ranks_by_frequency_then_key() -> None:
    freqs = {"a": 5, "b": 9, "c": 1, "d": 9, "e": 3, "f": 7, "g": 2}
    assert rank_by_frequency(freqs) == ["b", "d", "f", "a", "e", "g", "c"]
    easy, medium, hard = split_thirds(freqs)
    assert (easy, medium, hard) == (["b", "d", "f"], ["a", "e"], ["g", "c"])


def test_problem_sets_cut_thirds_and_replay_from_seed(synthetic, tmp_path: Path) -> None:
    store, freq = synthetic
    ranked = sorted(freq, key=lambda k: -freq[k])  # distinct frequencies: no ties
    thirds = {"easy": set(ranked[:4]), "medium": set(ranked[4:8]), "hard": set(ranked[8:])}
    records = {r.name: r for r in make_problem_sets_in_store(store, per_set=2, seed=7)}
    assert set(records) == {"easy", "medium", "hard", "unseen-3", "4", "5"}
    for name, third in thirds.items():
        goals = records[name].problems
        assert len(goals) == 2 and {p.p_data.key for p in goals} <= third
        assert all(p.frequency == freq[p.p_data.key] and p.tag == name for p in goals)
        assert [p.frequency for p in goals] == sorted((p.frequency for p in goals), reverse=True)
    all3 = {p.key for p in STATES_3}
    unseen = records["unseen-3"].problems
    assert len(unseen) == 2
    assert all(p.p_data.key in all3 and p.p_data.key not in freq and p.frequency == 0 for p in unseen)
    four = records["4"].problems
    assert len(four) == 2 and all(p.p_data.cross == 4 and p.tag == "4-unseen" for p in four)
    # 5: none visited here, so states one move beyond the 4-crossing goals
    five = records["5"].problems
    assert len(five) == 2 and all(p.p_data.cross == 5 and p.tag == "5-unseen" for p in five)
    beyond = {s.state for g in four for s in successors(g.p_data)}
    assert all(p.p_data in beyond for p in five)

    def keys(prefix: str) -> dict[str, list[str]]:
        with store.session() as session:
            return {
                n: [p.p_data.key for p in load_problem_set(session, prefix + n).problems]
                for n in ("easy", "medium", "hard", "unseen-3", "4", "5")
            }

    # same seed, same sets; other seeds draw others
    make_problem_sets_in_store(store, per_set=2, seed=7, prefix="again-")
    assert keys("again-") == keys("")
    for seed in (1, 2):
        make_problem_sets_in_store(store, per_set=2, seed=seed, prefix=f"s{seed}-")
    assert keys("s1-") != keys("") or keys("s2-") != keys("")

    with pytest.raises(EvalInputError, match="exists"):
        make_problem_sets_in_store(store, per_set=2, seed=7)
    make_problem_sets_in_store(store, per_set=3, seed=7, replace=True, sets=["easy"])
    with store.session() as session:
        assert len(load_problem_set(session, "easy").problems) == 3


def test_problem_sets_need_three_crossing_data(sqlite_url: str) -> None:
    with open_store(sqlite_url) as store, pytest.raises(EvalInputError, match="collect data first"):
        make_problem_sets_in_store(store)


def test_goal_file_errors_name_the_entry() -> None:
    good = ONE.to_list()
    bad = [[1, "O", 2, "+"], [2, "U", 1, "-"]]  # signs differ
    with pytest.raises(EvalInputError, match=r"set 'mine-b' entry 1: .*signs differ"):
        parse_goal_file(json.dumps({"a": [good], "b": [good, bad]}), "mine")
    with pytest.raises(EvalInputError, match="entry 0: the empty rope"):
        parse_goal_file("[[]]", "x")
    with pytest.raises(EvalInputError, match="entry 1: same goal as entry 0"):
        parse_goal_file(json.dumps([good, good]), "x")
    with pytest.raises(EvalInputError, match="needs a set name"):
        parse_goal_file(json.dumps([good]))
    with pytest.raises(EvalInputError, match="not valid JSON"):
        parse_goal_file("[[1,", "x")
    with pytest.raises(EvalInputError, match=r"set 'x' entry 0: .*knot"):
        parse_goal_file(json.dumps(["granny-knot"]), "x")
    assert parse_goal_file(json.dumps({"a": [good]})) == {"a": [state_goal(ONE)]}


def test_import_cli_reports_bad_entry_and_stores_nothing(db_url: str, tmp_path: Path) -> None:
    runner = CliRunner()
    bad_file = tmp_path / "goals.json"
    bad_file.write_text(json.dumps({"ok": [ONE.to_list()], "broken": [ONE.to_list(), [[1, "O", 3, "+"]]]}))
    result = runner.invoke(app, ["--db", db_url, "problems", "import", str(bad_file), "--name", "g"])
    assert result.exit_code == 2
    assert "set 'g-broken' entry 1: P-data has 1 visits" in " ".join(
        result.output.split()
    )  # rich wraps lines
    listed = runner.invoke(app, ["--db", db_url, "problems", "list"])
    assert listed.exit_code == 0 and "g-ok" not in listed.output  # the good set was not stored either
    good_file = tmp_path / "good.json"
    good_file.write_text(json.dumps([ONE.to_list(), ONE_UNDER.to_list()]))
    result = runner.invoke(app, ["--db", db_url, "problems", "import", str(good_file), "--name", "g"])
    assert result.exit_code == 0, result.output
    listed = runner.invoke(app, ["--db", db_url, "problems", "list", "--show", "g"])
    assert ONE.key in listed.output and ONE_UNDER.key in listed.output


def _two_goal_set(store) -> None:
    with store.session(write=True) as session:
        problems = [ProblemRecord(None, i, p, 0, "imported") for i, p in enumerate((ONE, ONE_UNDER))]
        save_problem_set(session, "ones", problems, source="imported")


def _finished_result(
    eval_run: EvalRun,
    problem: ProblemRecord,
    planner: str,
    seed: int,
    time_to_solve_s: float | None,
    sim_calls: int,
    friction_scale: float = 1.0,
) -> EvalResult:
    """A finished result of ``eval_run`` on ``problem``: solved when it has a time to solve."""
    solved = time_to_solve_s is not None
    return EvalResult(
        eval_run_id=eval_run.id,
        set_id=eval_run.set_id,
        problem_id=problem.id,
        planner=planner,
        goal_key=problem.p_data.key,
        seed=seed,
        timeout_s=eval_run.timeout_s,
        friction_scale=friction_scale,
        status="solved" if solved else "timeout",
        solved=solved,
        time_to_solve_s=time_to_solve_s,
        sim_calls=sim_calls,
    )


def test_interrupted_eval_resumes_without_repeating_goals(db_url: str) -> None:
    with open_store(db_url) as store:
        _two_goal_set(store)

        def interrupt(outcome, summary) -> None:
            raise KeyboardInterrupt  # what Ctrl-C raises in the parent, after the first goal is stored

        request = EvalOptions("ones", "random-low", timeout_s=1.5, seeds=[0], parallel=1, workers=1)
        with pytest.raises(KeyboardInterrupt):
            run_eval(store, db_url, request, on_outcome=interrupt)
        with store.session() as session:
            first = session.scalars(select(EvalResult)).all()
            runs = session.scalars(select(EvalRun)).all()
        assert len(first) == 1 and first[0].status in ("solved", "timeout")
        assert first[0].plan_run_id is not None and first[0].sim_calls is not None
        assert [r.status for r in runs] == ["interrupted"]

        summary = run_eval(store, db_url, request)
        assert summary.already_done == 1
        assert [o.goal_key for o in summary.outcomes] == [ONE_UNDER.key]  # only the missing goal ran
        with store.session() as session:
            rows = session.scalars(select(EvalResult).order_by(EvalResult.id)).all()
            plan_runs = session.scalars(select(Run).where(Run.kind == "plan")).all()
        assert len(rows) == 2 and {r.goal_key for r in rows} == {ONE.key, ONE_UNDER.key}
        assert (rows[0].id, rows[0].eval_run_id, rows[0].ended_at) == (
            first[0].id,
            first[0].eval_run_id,
            first[0].ended_at,
        )
        assert len(plan_runs) == 2  # one planner run per goal, none repeated

        # a third invocation has nothing left to do
        assert run_eval(store, db_url, request).outcomes == []
        with store.session() as session:
            for r in load_results(session):
                # the goal node's simulation, read from the planner's tree, for solved goals only
                assert (r.sim_calls_to_solve is not None) == r.solved
                assert r.sim_calls_to_solve is None or 1 <= r.sim_calls_to_solve <= r.sim_calls


@pytest.mark.slow
def test_sigint_mid_goal_checkpoints_and_resumes_the_same_planner_run(
    sqlite_url: str, tmp_path: Path
) -> None:
    with open_store(sqlite_url) as store:
        with store.session(write=True) as session:
            # a 4-crossing goal: random-low does not solve it within the 3 s before the Ctrl-C, even on
            # an idle machine (a 3-crossing goal sometimes was)
            goal = enumerate_states(4)[4][0]
            save_problem_set(
                session, "hard1", [ProblemRecord(None, 0, goal, 0, "imported")], source="imported"
            )
    cmd = [
        sys.executable,
        "-m",
        "cli.main",
        "--db",
        sqlite_url,
        "eval",
        "--set",
        "hard1",
        "--planner",
        "random-low",
    ]
    cmd += ["--timeout", "12", "--parallel", "1"]
    proc = subprocess.Popen(
        cmd,
        cwd=tmp_path,
        start_new_session=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        # a shell's background job (e.g. CI started with `&`) inherits SIGINT ignored, and Python keeps
        # ignoring it: give the child the default disposition so that Ctrl-C reaches it as in a terminal
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + 60
        row = None
        with open_store(sqlite_url) as store:
            while time.monotonic() < deadline:
                with store.session() as session:
                    row = session.scalar(select(EvalResult))
                if row is not None and row.plan_run_id is not None:
                    break
                time.sleep(0.3)
            assert row is not None and row.plan_run_id is not None
            time.sleep(3.0)  # let the planner save a checkpoint or two
            os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group
            proc.wait(timeout=60)
            assert proc.returncode == 130, proc.stderr.read().decode()
            with store.session() as session:
                row = session.scalar(select(EvalResult))
                run_status = session.scalar(select(EvalRun.status))
            assert row.status == "interrupted" and run_status == "interrupted"
            plan_run, elapsed = row.plan_run_id, row.elapsed_s
            request = EvalOptions("hard1", "random-low", timeout_s=12.0, parallel=1)
            summary = run_eval(store, sqlite_url, request)
            # it fails to solve in the remaining time or solves it; either way the same planner run continued
            with store.session() as session:
                row = session.scalar(select(EvalResult))
                plans = session.scalars(select(Run).where(Run.kind == "plan")).all()
        assert [o.status for o in summary.outcomes] == [row.status] and row.status in ("solved", "timeout")
        assert row.plan_run_id == plan_run and len(plans) == 1
        assert elapsed is not None and row.elapsed_s >= elapsed  # search time carried over, not restarted
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


def test_report_curves_and_table(db_url: str, tmp_path: Path) -> None:
    assert success_curve([1.0, None, 3.0, 2.0], [0.5, 1.0, 2.5, 10.0]).tolist() == [0.0, 0.25, 0.5, 0.75]
    # beside longer runs, a series of 120 s runs ends at 120 s, with a goal solved just before it counted
    times, fractions = success_until([1.0, None, 119.8], np.linspace(0.0, 900.0, 400), 120.0)
    assert times[-1] == 120.0 and times.max() == 120.0 and fractions[-1] == 2 / 3
    with open_store(db_url) as store:
        _two_goal_set(store)
        with store.session(write=True) as session:
            record = load_problem_set(session, "ones")
            eval_run = EvalRun(
                set_id=record.id,
                planner="x",
                timeout_s=10.0,
                friction_scale=1.0,
                seeds=[0],
                workers=1,
                parallel=1,
            )
            session.add(eval_run)
            session.flush()
            outcomes = {  # (planner, friction) -> time to solve of each goal (None: timed out)
                ("twisted", 1.0): [2.0, 4.0],
                ("random-low", 1.0): [None, 8.0],
                ("twisted", 0.95): [3.0, None],
                ("twisted", 1.05): [None, None],
            }
            for (planner, friction), times in outcomes.items():
                for p, t in zip(record.problems, times, strict=True):
                    session.add(_finished_result(eval_run, p, planner, 0, t, 100, friction))
        files = write_report(store, tmp_path / "rep")
    text = files.markdown.read_text()
    assert "| ones | twisted | 1 | 10 | 2 | 2 | 100% | 3.0 | 100 |" in text
    assert "| ones | random-low | 1 | 10 | 2 | 1 | 50% | 8.0 | 100 |" in text
    assert "| ones | twisted | 1.05 | 10 | 2 | 0 | 0% | - | 100 |" in text
    assert [p.name for p in files.plots] == ["success_ones.png"]
    assert [p.name for p in files.sensitivity] == ["friction_ones_twisted_10s.png"]
    for p in files.plots + files.sensitivity:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 5000


def test_discretisation_control_is_unchanged_and_rounding_is_measured(db_url: str, tmp_path: Path) -> None:
    from twisted.sim import RopeSim, sample_curve

    sim = RopeSim()
    rng = np.random.default_rng(3)
    with open_store(db_url) as store:
        with store.session(write=True) as session:
            run_id = start_run(session, "collect", {}).id
            root_state = get_or_create_state(session, EMPTY)
            root = Configuration(
                run_id=run_id,
                state_id=root_state.id,
                cross=0,
                q=array_to_blob(sim.state()),
                points=array_to_blob(sim.link_points()),
            )
            session.add(root)
            session.flush()
            q0 = sim.state()
            stored = 0
            while stored < 4:
                curve = sample_curve(rng)
                sim.set_state(q0)
                if not sim.apply(curve).ok:
                    continue
                _add_transition(
                    session, run_id, root, sim.p_data(), (curve.link, curve.z_max_m, curve.x_m, curve.y_m)
                )
                stored += 1
        summary = run_discretisation(store, n=4, from_cross=None, to_cross=None, workers=1)
        by_variant = {v.variant: v for v in summary.variants}
        assert by_variant["control"].transitions == 4 and by_variant["control"].changed == 0  # deterministic
        assert by_variant["rounded"].transitions == 4
        # a record that does not match what the simulator does is counted as changed
        with store.session(write=True) as session:
            t = session.scalars(select(Transition).order_by(Transition.id)).first()
            current = session.get(TopologicalState, t.to_state_id).key
            t.to_state_id = get_or_create_state(session, ONE_UNDER if current == ONE.key else ONE).id
        again = run_discretisation(store, n=4, from_cross=None, to_cross=None, workers=1)
        assert {v.variant: v.changed for v in again.variants}["control"] == 1
        text = write_report(store, tmp_path / "rep").markdown.read_text()
        assert f"| {again.run_id} | 4 | any -> any | control | 1 | 1 | 25.0% | 0 |" in text
    with pytest.raises(EvalInputError, match="no stored transitions"):
        with open_store(db_url) as store:
            run_discretisation(store, n=4, from_cross=5, to_cross=6)


def test_round_curve_steps() -> None:
    from twisted.sim import Curve

    c = round_curve(Curve(4, 0.0314159, -0.2371, 0.4449))
    assert (c.link, c.z_max_m, c.x_m, c.y_m) == (
        4,
        pytest.approx(0.031),
        pytest.approx(-0.24),
        pytest.approx(0.44),
    )


def test_eval_runs_each_set_given_and_checks_them_all_before_running_any(sqlite_url: str) -> None:
    one = enumerate_states(1)[1][0]
    with open_store(sqlite_url) as store, store.session(write=True) as session:
        for name in ("a", "b"):
            save_problem_set(session, name, [ProblemRecord(None, 0, one, 0, "imported")], source="imported")
    args = ["--planner", "random-low", "--timeout", "2", "--parallel", "1"]
    runner = CliRunner()
    # a set that does not exist, given second: refused before the first set runs
    bad = runner.invoke(app, ["--db", sqlite_url, "eval", "--set", "a", "--set", "nope", *args])
    assert bad.exit_code == 2 and "nope" in bad.output, bad.output
    with open_store(sqlite_url) as store, store.session() as session:
        assert session.scalar(select(EvalRun)) is None
    good = runner.invoke(app, ["--db", sqlite_url, "eval", "--set", "a", "--set", "b", "--set", "a", *args])
    assert good.exit_code == 0, good.output
    with open_store(sqlite_url) as store, store.session() as session:
        runs = list(session.scalars(select(EvalRun)))
        results = list(session.scalars(select(EvalResult)))
    assert len(runs) == 2 and len(results) == 2  # one run per set; a set given twice runs once
    assert {r.set_id for r in results} == {r.set_id for r in runs} and len({r.set_id for r in runs}) == 2


def test_results_under_one_label_must_share_the_planner_options(sqlite_url: str) -> None:
    """Finished results count as done for a later evaluation under the same label, so one with another
    K (or model) is refused instead of silently reusing them; under its own label it runs with its K."""
    one = enumerate_states(1)[1][0]
    with open_store(sqlite_url) as store, store.session(write=True) as session:
        save_problem_set(session, "a", [ProblemRecord(None, 0, one, 0, "imported")], source="imported")
    args = ["--db", sqlite_url, "eval", "--set", "a", "--planner", "random-low", "--timeout", "5"]
    args += ["--parallel", "1"]
    runner = CliRunner()
    first = runner.invoke(app, [*args, "--label", "x"])
    assert first.exit_code == 0, first.output
    refused = runner.invoke(app, [*args, "--label", "x", "--k", "2"])
    assert refused.exit_code == 2, refused.output
    message = " ".join(refused.output.split())  # the console wraps long lines
    assert "--label x:" in message and "k 3 (now 2)" in message  # the defaults are stored as values
    with open_store(sqlite_url) as store, store.session() as session:
        assert len(list(session.scalars(select(EvalRun)))) == 1  # refused before a run was stored
    again = runner.invoke(app, [*args, "--label", "x"])  # the same options: finished results reused
    assert again.exit_code == 0 and "1 finished before" in " ".join(again.output.split()), again.output
    variant = ["--k", "2", "--p-expand", "0.5", "--k-expand", "3", "--retry-weight", "1"]
    other = runner.invoke(app, [*args, "--label", "x-k2", *variant])
    assert other.exit_code == 0, other.output
    with open_store(sqlite_url) as store, store.session() as session:
        run = session.scalars(select(EvalRun).order_by(EvalRun.id.desc())).first()
        assert run is not None and run.planner == "x-k2"
        assert (run.parameters["k"], run.parameters["p_expand"], run.parameters["k_expand"]) == (2, 0.5, 3)
        result = session.scalars(select(EvalResult).where(EvalResult.planner == "x-k2")).one()
        plan_run = session.get(Run, result.plan_run_id)
        assert plan_run is not None
        assert (plan_run.parameters["k"], plan_run.parameters["p_expand"]) == (2, 0.5)
        assert plan_run.parameters["retry_weight"] == 1.0

    # results stored before --cross-move existed ran without scripted curves: they count as 0, so
    # an evaluation that asks for 0 reuses them and one with today's default does not
    with open_store(sqlite_url) as store, store.session(write=True) as session:
        for run in session.scalars(select(EvalRun).where(EvalRun.planner == "x")):
            assert run.parameters["cross_move"] == PlannerOptions().cross_move
            run.parameters = {k: v for k, v in run.parameters.items() if k != "cross_move"}
    before = runner.invoke(app, [*args, "--label", "x", "--cross-move", "0"])
    assert before.exit_code == 0 and "1 finished before" in " ".join(before.output.split()), before.output
    scripted = runner.invoke(app, [*args, "--label", "x"])
    message = " ".join(scripted.output.split())
    assert scripted.exit_code == 2 and f"cross_move 0.0 (now {PlannerOptions().cross_move})" in message

    # results stored before the defaults were stored as values (the option left out) are not reused
    # by an evaluation with today's defaults, whose values may differ from those of their day
    with open_store(sqlite_url) as store, store.session(write=True) as session:
        for run in session.scalars(select(EvalRun).where(EvalRun.planner == "x")):
            run.parameters = {k: v for k, v in run.parameters.items() if k != "retry_weight"}
    old = runner.invoke(app, [*args, "--label", "x", "--cross-move", "0"])
    assert old.exit_code == 2, old.output
    shown = f"retry_weight unrecorded (the default of its day) (now {PlannerOptions().retry_weight})"
    assert shown in " ".join(old.output.split())

    # results made with an option since removed (--state-prior 50) are not reused by any new evaluation;
    # those that stored its neutral value (0) are
    x_k2 = [*args, "--label", "x-k2", *variant]
    with open_store(sqlite_url) as store, store.session(write=True) as session:
        for run in session.scalars(select(EvalRun).where(EvalRun.planner == "x-k2")):
            run.parameters = {**run.parameters, "state_prior": 0.0}
    assert runner.invoke(app, x_k2).exit_code == 0
    with open_store(sqlite_url) as store, store.session(write=True) as session:
        for run in session.scalars(select(EvalRun).where(EvalRun.planner == "x-k2")):
            run.parameters = {**run.parameters, "state_prior": 50.0}
    removed = runner.invoke(app, x_k2)
    assert removed.exit_code == 2 and "state_prior 50.0 (--state-prior was removed" in " ".join(
        removed.output.split()
    ), removed.output


def test_eval_takes_the_pull_test_and_a_knot_set_requires_it(sqlite_url: str) -> None:
    """``eval --tighten`` reaches the planner runs and is an option the label keeps; a set whose goals
    count only when the rope pulls tight (``problems make --set catalogue`` / ``knots``) is refused
    without it, before anything is stored."""
    from twisted.goals import knot_goal

    overhand = knot_goal("overhand")
    with open_store(sqlite_url) as store, store.session(write=True) as session:
        knots = [ProblemRecord(None, 0, overhand.representative, 0, "knots", spec=overhand.spec)]
        save_problem_set(session, "knots", knots, source="made", parameters={"pull_test": "required"})
    args = ["--db", sqlite_url, "eval", "--set", "knots", "--planner", "random-low", "--timeout", "3"]
    args += ["--parallel", "1", "--label", "t"]
    runner = CliRunner()
    refused = runner.invoke(app, args)
    assert refused.exit_code == 2 and "add --tighten" in " ".join(refused.output.split()), refused.output
    with open_store(sqlite_url) as store, store.session() as session:
        assert session.scalar(select(EvalRun)) is None  # refused before anything was stored
    pulled = runner.invoke(app, [*args, "--tighten"])
    assert pulled.exit_code == 0, pulled.output
    with open_store(sqlite_url) as store, store.session() as session:
        run = session.scalars(select(EvalRun)).one()
        assert run.parameters["tighten"] is True
        result = session.scalars(select(EvalResult)).one()
        plan_run = session.get(Run, result.plan_run_id)
        assert plan_run is not None and plan_run.parameters["tighten"] is True
