"""Issue 62 items 5, 6 and 10: runs and checkpoints read back from the store are checked at the boundary.

Each case plants one hostile value with ``sqlite3`` into a copy of a small real store (a solved plan run,
a stopped plan run, a stopped untie run), runs the command that reads it, and checks: exit 2 with a
message naming the table, the row and the field, no traceback, no run changed state and nothing in the
store changed. Before the fix each ended in a traceback (exit 1), most left the run ``running`` with a
dead pid, ``iteration = -5`` deleted every node of the run, and the broken end configurations of item 6
created a run (5 floats: a ValueError in the search; NaN, 1e300, zeros: a search of one node until
``--timeout``). ``bench/probe.py`` replays the same cases as a table.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from cli.main import app
from twisted.planner.options import PlannerOptions, specs
from twisted.store.boundary import MAX_JSON_BYTES, MAX_JSON_DEPTH, StoredJSONError, parse_json, shown

ONE = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
REPO = Path(__file__).resolve().parents[1]
DEEP = "[" * 200_000 + "]" * 200_000
SOLVED, STOPPED, UNTIE = 1, 2, 3  # the runs of the store (see the fixture)

runner = CliRunner()


def _cli(db: Path, *args: str) -> tuple[int, str]:
    result = runner.invoke(app, ["--db", f"sqlite:///{db}", *args])
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        f"{args[:3]} raised {result.exception!r}\n{result.output[-2000:]}"
    )
    return result.exit_code, " ".join(result.output.split())


@pytest.fixture(scope="module")
def runs_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Run 1: a solved plan (one crossing); run 2: a plan stopped before its first iteration; run 3: an
    untie of run 1 stopped the same way (random curves: no model is loaded)."""
    db = tmp_path_factory.mktemp("runs") / "runs.db"
    plan = ["plan", "--goal", ONE, "--planner", "random-low", "--workers", "1", "--seed", "0"]
    assert _cli(db, *plan, "--max-iterations", "40")[0] == 0
    assert _cli(db, *plan, "--max-iterations", "0")[0] == 3
    untie = ["untie", "1", "--planner", "random-low", "--workers", "1", "--max-iterations", "0"]
    assert _cli(db, *untie)[0] == 3
    return db


def _snapshot(db: Path) -> tuple[str, list[tuple[Any, ...]]]:
    """The store's content (a digest of its SQL dump) and each run's status, pid and outcome."""
    conn = sqlite3.connect(db)
    try:
        digest = hashlib.sha256("\n".join(conn.iterdump()).encode()).hexdigest()
        runs = conn.execute(
            "select r.id, r.status, r.pid, s.outcome from runs r join search_runs s on s.run_id = r.id"
        ).fetchall()
    finally:
        conn.close()
    return digest, runs


Plant = Callable[[sqlite3.Connection], Any]


def _params(run: int, **change: Any) -> Plant:
    def plant(conn: sqlite3.Connection) -> None:
        (text,) = conn.execute("select parameters from runs where id = ?", (run,)).fetchone()
        stored = json.loads(text)
        conn.execute("update runs set parameters = ? where id = ?", (json.dumps({**stored, **change}), run))

    return plant


def _raw(run: int, text: str) -> Plant:
    return lambda conn: conn.execute("update runs set parameters = ? where id = ?", (text, run))


def _cp(run: int, column: str, value: Any) -> Plant:
    statement = f"update search_checkpoints set {column} = ? where run_id = ?"
    return lambda conn: conn.execute(statement, (value, run))


def _end_q(run: int, q: np.ndarray) -> Plant:
    return _goal_node(run, "q", q.tobytes())


GOAL_NODE = "(select goal_node_id from search_runs where run_id = ?)"


def _goal_node(run: int, column: str, value: Any) -> Plant:
    statement = f"update search_nodes set {column} = ? where id = {GOAL_NODE}"
    return lambda conn: conn.execute(statement, (value, run))


def _goal_state_key(run: int, key: str) -> Plant:
    node_state = f"(select state_id from search_nodes where id = {GOAL_NODE})"
    statement = f"update topological_states set key = ? where id = {node_state}"
    return lambda conn: conn.execute(statement, (key, run))


def _configuration(q: np.ndarray) -> Plant:
    """Configuration 1: the straight rope of run 1's root with ``q`` in its place (``--start-config 1``)."""
    statement = (
        "insert into configurations (id, state_id, cross, q, points, created_at) "
        "select 1, state_id, cross, ?, points, '2026-12-06' from search_nodes where run_id = ? and seq = 0"
    )
    return lambda conn: conn.execute(statement, (q.tobytes(), SOLVED))


PLAN_ONE = ["plan", "--goal", ONE, "--planner", "random-low", "--workers", "1"]
RESUME = ["plan", "--resume", str(STOPPED), "--workers", "1", "--max-iterations", "2"]
UNTIE_IT = ["untie", str(SOLVED), "--planner", "random-low", "--workers", "1", "--timeout", "60"]
UNTIE_RESUME = ["untie", str(UNTIE), "--resume", "--workers", "1", "--max-iterations", "1"]
REPLAY = ["replay", str(SOLVED)]
RENDER = ["render", "--run", str(SOLVED), "--out", "OUT", "--no-gl"]
MT19937 = json.dumps(np.random.MT19937(1).state, default=lambda a: a.tolist())

def _case(name: str, plant: Plant, command: list[str], said: str) -> Any:
    return pytest.param(plant, command, said, id=name)


PARAMS_2, CP_2 = "runs, row 2, parameters", "search_checkpoints, row 2"
CASES = [
    # item 5: a run's parameters, each through its option's declaration
    _case("k=-1", _params(STOPPED, k=-1), RESUME, f"{PARAMS_2}.k: must lie in [1, 1000], got -1"),
    _case("seed=-5", _params(STOPPED, seed=-5), RESUME, f"{PARAMS_2}.seed: must lie in"),
    _case("heuristic=x", _params(STOPPED, heuristic="x"), RESUME, "parameters.heuristic: must be one of"),
    _case("p_expand=x", _params(STOPPED, p_expand="x"), RESUME, "p_expand: must be a number, got 'x'"),
    _case("k=true", _params(STOPPED, k=True), RESUME, "parameters.k: must be an integer, got True"),
    _case("cinch=1", _params(STOPPED, cinch=1), RESUME, "parameters.cinch: must be true or false"),
    _case("model_id=x", _params(STOPPED, model_id="x"), RESUME, "model_id: must be an integer"),
    _case(
        "removal_curves=evil",
        _params(UNTIE, removal_curves="evil"),
        UNTIE_RESUME,
        "runs, row 3, parameters.removal_curves: must be one of model, random, got 'evil'",
    ),
    _case("parameters a string", _raw(STOPPED, '"abc"'), RESUME, f"{PARAMS_2}: must be a JSON object"),
    _case("parameters a list", _raw(STOPPED, "[1, 2]"), RESUME, "must be a JSON object, got list"),
    _case("not json: plan --resume", _raw(STOPPED, "not json"), RESUME, f"{PARAMS_2}: not JSON"),
    _case("not json: untie", _raw(SOLVED, "not json"), UNTIE_IT, "runs, row 1, parameters: not JSON"),
    _case("not json: replay", _raw(SOLVED, "not json"), REPLAY, "runs, row 1, parameters: not JSON"),
    _case("not json: render", _raw(SOLVED, "not json"), RENDER, "runs, row 1, parameters: not JSON"),
    _case("deep: plan --resume", _raw(STOPPED, DEEP), RESUME, f"{PARAMS_2}: JSON nested 200,000"),
    _case("deep: untie", _raw(SOLVED, DEEP), UNTIE_IT, "row 1, parameters: JSON nested 200,000"),
    _case("deep: replay", _raw(SOLVED, DEEP), REPLAY, "row 1, parameters: JSON nested 200,000"),
    _case("deep: render", _raw(SOLVED, DEEP), RENDER, "row 1, parameters: JSON nested 200,000"),
    # item 5: a checkpoint
    _case("rng MT19937", _cp(STOPPED, "rng_state", MT19937), RESUME, f"{CP_2}, rng_state: not a PCG64"),
    _case("rng deep", _cp(STOPPED, "rng_state", DEEP), RESUME, f"{CP_2}, rng_state: JSON nested"),
    _case("iteration=-5", _cp(STOPPED, "iteration", -5), RESUME, f"{CP_2}, iteration: must be a"),
    _case("elapsed_s=-1", _cp(STOPPED, "elapsed_s", -1.0), RESUME, f"{CP_2}, elapsed_s: must be"),
    _case("stats=garbage", _cp(STOPPED, "stats", "garbage"), RESUME, f"{CP_2}, stats: not JSON"),
    _case("stats a list", _cp(STOPPED, "stats", "[1]"), RESUME, f"{CP_2}, stats: must be a JSON"),
    _case(
        "stats entry",
        _cp(STOPPED, "stats", json.dumps({"state": {"[]": "x"}})),
        RESUME,
        f"{CP_2}, stats.state['[]']: must be [count, reward]",
    ),
    # item 6: the end configuration an untie starts from
    _case("q of 5 floats", _end_q(SOLVED, np.zeros(5)), UNTIE_IT, "q: holds 5 floats; a state of the rope"),
    _case("q all NaN", _end_q(SOLVED, np.full(93, np.nan)), UNTIE_IT, "q: must be finite floats, got 93"),
    _case("q all 1e300", _end_q(SOLVED, np.full(93, 1e300)), UNTIE_IT, "the simulator refuses it: rope left"),
    _case("q all zeros", _end_q(SOLVED, np.zeros(93)), UNTIE_IT, "q: the simulator refuses it"),
    _case(
        "start configuration NaN",
        _configuration(np.full(93, np.nan)),
        [*PLAN_ONE, "--start-config", "1", "--max-iterations", "2"],
        "configurations, row 1, q: must be finite floats",
    ),
    # the nodes of a run's plan (replay, render and untie read them)
    _case("points of 5 floats", _goal_node(SOLVED, "points", bytes(40)), REPLAY, "points: must be float64"),
    _case("curve link 99", _goal_node(SOLVED, "link", 99), REPLAY, "link: must be a link 0..20, got 99"),
    _case("curve x_m text", _goal_node(SOLVED, "x_m", "far"), RENDER, "x_m: must be a finite number"),
    _case("state key", _goal_state_key(SOLVED, "not p-data"), UNTIE_IT, "topological_states, row"),
    # item 10: untie --resume continues untie runs only
    _case(
        "untie --resume of a plan run",
        lambda conn: None,
        ["untie", str(STOPPED), "--resume", "--workers", "1"],
        "run 2 is not an untie run",
    ),
]


@pytest.mark.parametrize(("plant", "command", "said"), CASES)
def test_a_hostile_stored_value_is_refused_with_exit_2(
    runs_db: Path, tmp_path: Path, plant: Plant, command: list[str], said: str
) -> None:
    db = tmp_path / "copy.db"
    shutil.copyfile(runs_db, db)
    conn = sqlite3.connect(db)
    plant(conn)
    conn.commit()
    conn.close()
    before = _snapshot(db)
    code, out = _cli(db, *[str(tmp_path / "run.png") if a == "OUT" else a for a in command])
    assert code == 2 and said in out, out[-1500:]
    assert _snapshot(db) == before, "no run changed state, nothing was written"
    assert not (tmp_path / "run.png").exists()


def test_an_untie_run_still_resumes(runs_db: Path, tmp_path: Path) -> None:
    """The checks pass the runs the commands write: the stopped untie run continues (and solves)."""
    db = tmp_path / "copy.db"
    shutil.copyfile(runs_db, db)
    code, out = _cli(db, "untie", str(UNTIE), "--resume", "--workers", "1", "--max-iterations", "20")
    assert code == 0 and f"run {UNTIE}: solved" in out, out[-1500:]
    code, out = _cli(db, "plan", "--resume", str(STOPPED), "--workers", "1", "--max-iterations", "40")
    assert code == 0 and f"run {STOPPED}: solved" in out, out[-1500:]


def test_parse_json_bounds_depth_and_size_in_linear_time() -> None:
    assert parse_json('{"a": [[1, "[[[["], {"b": "]]"}]}') == {"a": [[1, "[[[["], {"b": "]]"}]}
    nested = "[" * MAX_JSON_DEPTH + "]" * MAX_JSON_DEPTH
    assert parse_json(nested) == parse_json(nested)  # the limit itself is read
    with pytest.raises(StoredJSONError, match="nested 33 levels deep"):
        parse_json("[" + nested + "]")
    with pytest.raises(StoredJSONError, match="nested 1,000,000 levels"):
        parse_json("{" * 1_000_000)  # not even JSON: refused for its depth before the parser recurses
    with pytest.raises(StoredJSONError, match=f"more than the {MAX_JSON_BYTES:,} read back"):
        parse_json(b" " * (MAX_JSON_BYTES + 1))


@pytest.mark.parametrize(
    ("name", "value", "said"),
    [
        ("k", "3", "must be an integer, got '3'"),
        ("k", 3.0, "must be an integer, got 3.0"),
        pytest.param("k", 10**400, "must lie in [1, 1000]", id="k-10**400"),
        ("p_expand", float("nan"), "must lie in [0, 1], got nan"),
        ("p_expand", None, "must be a number, got None"),
        ("tighten", "yes", "must be true or false, got 'yes'"),
        ("heuristic", ["crs"], "must be one of rnd, crs, ucb, got ['crs']"),
        pytest.param("planner", "x" * 10_000, "must be one of", id="planner-x*10000"),
    ],
)
def test_an_option_declaration_checks_the_type_as_well(name: str, value: Any, said: str) -> None:
    """The declaration's check is what the command line and the store's values both pass."""
    spec = next(s for s in specs() if s.name == name)
    problem = spec.check(value)
    assert problem is not None and said in problem and len(problem) < 200, problem
    assert spec.check(getattr(PlannerOptions(), name)) is None


# --- item 11: a Ctrl-C that lands as a run solves ----------------------------------------------------------


@pytest.mark.parametrize("picture", [False, True], ids=["while-exiting", "while-drawing-the-picture"])
def test_a_ctrl_c_after_the_run_is_solved_and_stored_leaves_exit_0(
    runs_db: Path, tmp_path: Path, picture: bool
) -> None:
    """Before: the signal, sent as the result was printed, killed the process (exit -2, 130 in a shell)
    during the interpreter's shutdown with no word, or during the picture ended it with 130, while the
    run was stored solved (130 says "resume it", and a resume is refused: it is solved). Now a solved
    run's command exits 0; an interrupt that cut something short (the picture) says so in one line."""
    db = tmp_path / "copy.db"
    shutil.copyfile(runs_db, db)
    png = tmp_path / "end.png"
    command = [sys.executable, "-m", "cli.main", "--db", f"sqlite:///{db}", "plan", "--goal", ONE]
    command += ["--planner", "random-low", "--workers", "1", "--seed", "0", "--max-iterations", "40"]
    command += ["--picture", str(png)] if picture else []
    child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
    assert child.stdout is not None
    for line in child.stdout:
        if "solved" in line:
            break
    time.sleep(0.0 if picture else 0.3)
    child.send_signal(signal.SIGINT)
    out, err = child.communicate(timeout=120)
    assert child.returncode == 0, (child.returncode, err[-2000:])
    assert "Traceback" not in err
    conn = sqlite3.connect(db)
    (outcome,) = conn.execute("select outcome from search_runs order by run_id desc limit 1").fetchone()
    conn.close()
    assert outcome == "solved"
    if picture and not png.exists():
        assert "was solved and stored: that stands (exit 0)" in " ".join(err.split())


def test_a_huge_stored_value_is_quoted_cut_whatever_its_type() -> None:
    """Before: a dict of over 600 items raised TypeError (sliced like a list) inside an error message."""
    for value in ("x" * 10_000, b"x" * 10_000, list(range(10_000)), {i: i for i in range(10_000)}):
        text = shown(value)
        assert len(text) <= 60 and "..." in text
    assert shown({"k": 1}) == "{'k': 1}"
