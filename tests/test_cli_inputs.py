"""Issue 16: the CLI checks every input before it opens or writes anything; global options.

Each bad option of plan, collect, train and eval is tried twice: where no database exists (none may be
created, nor any other file) and on an existing database (its content must not change). Then
``--version``, ``--db`` after the command, ``--json`` on the listing commands and ``--log-file``.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from cli.main import app
from tests.test_hardening import _digest

ONE_CROSSING = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
runner = CliRunner()


def _cli(*args: str, **kwargs: Any) -> tuple[int, str]:
    """Run the CLI in this process; a traceback fails the test (only exits are allowed)."""
    result = runner.invoke(app, list(args), **kwargs)
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        f"{args[:4]}... raised {result.exception!r}\n{result.output[-2000:]}"
    )
    return result.exit_code, " ".join(result.output.replace("│", " ").split())


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A database holding one problem set ``s`` (one goal): what the existing-database cases start from."""
    folder = tmp_path_factory.mktemp("template")
    goals = folder / "goals.json"
    goals.write_text(json.dumps([json.loads(ONE_CROSSING)]))
    code, out = _cli(
        "--db", f"sqlite:///{folder / 'db.sqlite'}", "problems", "import", str(goals), "--name", "s"
    )
    assert code == 0, out
    return folder / "db.sqlite"


# (arguments after the command name, what the message must contain; for the existing database when it
# differs there: a second text)
BAD: dict[str, list[tuple[list[str], str] | tuple[list[str], str, str]]] = {
    "plan": [
        (["--goal", ONE_CROSSING, "--heuristic", "bogus"], "'--heuristic'"),
        (["--goal", ONE_CROSSING, "--planner", "bogus"], "'--planner'"),
        (["--goal", ONE_CROSSING, "--k", "0"], "'--k'"),
        (["--goal", ONE_CROSSING, "--p-expand", "1.5"], "'--p-expand'"),
        (["--goal", ONE_CROSSING, "--k-expand", "0"], "'--k-expand'"),
        (["--goal", ONE_CROSSING, "--retry-weight", "0"], "'--retry-weight'"),
        (["--goal", ONE_CROSSING, "--cross-move", "1.5"], "'--cross-move'"),
        (["--goal", ONE_CROSSING, "--cross-move", "nan"], "'--cross-move'"),
        (["--goal", ONE_CROSSING, "--r1-room", "22"], "'--r1-room'"),
        (["--goal", ONE_CROSSING, "--plan-limit", "0"], "'--plan-limit'"),
        (["--goal", ONE_CROSSING, "--picture", "knot.txt"], "--picture knot.txt"),
        (["--goal", ONE_CROSSING, "--seed", "-1"], "'--seed'"),
        (["--goal", ONE_CROSSING, "--timeout", "nan"], "'--timeout'"),
        (["--goal", ONE_CROSSING, "--workers", "0"], "--workers 0"),
        (["--goal", '[[1,"O"]]'], "--goal"),
        (["--goal", "[]"], "--goal"),
        (["--knot", "no-such-knot"], "--knot"),
        (["--crossings", "3"], "--knot"),
        (["7"], "--resume 7"),
        (["--resume", "7"], "--resume 7"),
        (["--resume", "--start-config", "1"], "--start-config"),
        (["--goal", ONE_CROSSING, "--model", "99", "--workers", "1"], "--model 99"),
        (["--goal", ONE_CROSSING, "--log-file", "/no/such/folder/plan.log"], "'--log-file'"),
        (["--goal", ONE_CROSSING, "--db", "sqlite://"], "in-memory"),
    ],
    "collect": [
        (["--hours", "0"], "--hours"),
        (["--hours", "inf"], "'--hours'"),
        (["--hours", "1", "--workers", "100000"], "--workers 100000"),
        (["--hours", "1", "--seed", "-1"], "'--seed'"),
        (["--hours", "1", "--batch-size", "0"], "--batch-size"),
        (["--hours", "1", "--max-cross", "0"], "--max-cross"),
        (["--hours", "1", "--cross-bias", "nan"], "'--cross-bias'"),
        (["--hours", "1", "--across-share", "2"], "--across-share"),
        (["--hours", "1", "--friction-scale", "0"], "--friction-scale"),
        (["--hours", "1", "--max-kept", "0"], "--max-kept"),
        (["--hours", "1", "--log-file", "/no/such/folder/c.log"], "'--log-file'"),
    ],
    "train": [
        (["--link-head", "bogus"], "'--link-head'"),
        (["--device", "tpu"], "'--device'"),
        (["--device", "cuda:x"], "'--device'"),
        (["--from", "collect,elsewhere"], "'--from'"),
        (["--epochs", "0"], "'--epochs'"),
        (["--lr", "inf"], "'--lr'"),
        (["--seed", "-1"], "'--seed'"),
        (["--val-fraction", "0.95"], "'--val-fraction'"),
        (["--batch-size", "0"], "'--batch-size'"),
        (["--hidden", "4"], "'--hidden'"),
        (["--threads", "0"], "'--threads'"),
        (["--checkpoint-every", "0"], "'--checkpoint-every'"),
        ([], "does not exist", "collect first"),  # nothing collected: nothing to train on
        (["--resume"], "does not exist", "--resume"),
    ],
    "eval": [
        (["--set", "s", "--planner", "bogus"], "'--planner'"),
        (["--set", "s", "--heuristic", "bogus"], "'--heuristic'"),
        (["--set", "s", "--seeds", "x"], "'--seeds'"),
        (["--set", "s", "--seeds", "5-1"], "'--seeds'"),
        (["--set", "s", "--seeds", "-1"], "'--seeds'"),
        (["--set", "s", "--seeds", ""], "'--seeds'"),
        (["--set", "s", "--seeds", "2", "3"], "unexpected argument '3'", "several seeds go in one argument"),
        (["--set", "s", "--timeout", "-1"], "'--timeout'"),
        (["--set", "s", "--friction-scale", "0"], "'--friction-scale'"),
        (["--set", "s", "--workers", "0"], "'--workers'"),
        (["--set", "s", "--k", "0"], "'--k'"),
        (["--set", "s", "--p-expand", "1.5"], "'--p-expand'"),
        (["--set", "s", "--k-expand", "0"], "'--k-expand'"),
        (["--set", "s", "--retry-weight", "1.5"], "'--retry-weight'"),
        (["--set", "s", "--retry-weight", "nan"], "'--retry-weight'"),
        (["--set", "s", "--cross-move", "-0.5"], "'--cross-move'"),
        (["--set", "s", "--r1-room", "nan"], "'--r1-room'"),
        (["--set", "s", "--parallel", "100000"], "--parallel 100000"),
        (["--set", "nope", "--planner", "random-low"], "--set nope", "no problem set 'nope'"),
        (["--set", "s", "--model", "99"], "--set s", "no model 99"),
        (["--set", "s", "--planner", "random-low", "--label", "x" * 40], "--set s", "--label"),
    ],
}
CASES = [(command, *case) for command, cases in BAD.items() for case in cases]


def _case_id(case: tuple[Any, ...]) -> str:
    return f"{case[0]} {' '.join(case[1])}"[:60]


@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_a_bad_input_creates_no_database(tmp_path: Path, case: tuple[Any, ...]) -> None:
    command, args, expected = case[0], case[1], case[2]
    code, out = _cli("--db", f"sqlite:///{tmp_path / 'x.db'}", command, *args)
    assert code == 2, out
    assert expected in out, out
    assert list(tmp_path.iterdir()) == [], "nothing may be created for bad input"


@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_a_bad_input_writes_nothing_into_an_existing_database(
    tmp_path: Path, template: Path, case: tuple[Any, ...]
) -> None:
    command, args, expected = case[0], case[1], case[-1]
    path = tmp_path / "x.db"
    shutil.copy(template, path)
    before = _digest(path)
    code, out = _cli("--db", f"sqlite:///{path}", command, *args)
    assert code == 2, out
    assert expected in out, out
    assert _digest(path) == before
    assert {p.name for p in tmp_path.iterdir()} <= {"x.db", "x.db-wal", "x.db-shm"}


# --- global options ---------------------------------------------------------------------------------------


def test_version_is_the_one_pyproject_declares() -> None:
    """--version prints the version of this checkout's pyproject.toml (an install from another checkout,
    or a stale one, prints another), not the installed metadata read back the way --version reads it."""
    import tomllib

    declared = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
    code, out = _cli("--version")
    assert code == 0 and out == f"twisted {declared['project']['version']}"


def test_db_after_the_command_wins(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    before, after, env = (f"sqlite:///{tmp_path / name}" for name in ("before.db", "after.db", "env.db"))
    code, out = _cli("--db", before, "problems", "list", "--db", after, "--json")
    assert code == 0 and json.loads(out) == [], out
    assert [p.name for p in tmp_path.iterdir()] == ["after.db"]
    code, out = _cli("problems", "list", "--json", env={"TWISTED_DB": env})
    assert code == 0 and (tmp_path / "env.db").exists()
    code, out = _cli("problems", "list", "--db", before, env={"TWISTED_DB": env})
    assert code == 0 and (tmp_path / "before.db").exists()


def test_plan_takes_db_after_the_command(tmp_path: Path) -> None:
    """`twisted plan --db X --goal G` (before: "No such option: --db")."""
    path = tmp_path / "p.db"
    args = ["plan", "--db", f"sqlite:///{path}", "--goal", ONE_CROSSING, "--planner", "random-low"]
    code, out = _cli(
        *args, "--workers", "1", "--max-iterations", "1", "--k", "1", "--p-expand", "0", "--json"
    )
    assert code in (0, 3), out
    assert json.loads(out)["run_id"] == 1 and path.exists()


@pytest.mark.parametrize(
    "command",
    [
        ["problems", "list"],
        ["models"],
        ["stats"],
        ["db"],
        ["rl", "list"],
        ["knots", "list", "--max-crossings", "3", "--limit", "1"],
    ],
    ids=" ".join,
)
def test_every_listing_prints_json(tmp_path: Path, template: Path, command: list[str]) -> None:
    path = tmp_path / "x.db"
    shutil.copy(template, path)
    result = runner.invoke(app, ["--db", f"sqlite:///{path}", *command, "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert isinstance(data, (list, dict)), data
    if command[0] == "problems":
        assert [s["name"] for s in data] == ["s"]


def test_the_log_file_gets_the_start_and_the_end(tmp_path: Path) -> None:
    log = tmp_path / "logs" / "twisted.log"
    log.parent.mkdir()
    for _ in range(2):  # appends
        code, out = _cli("knots", "identify", ONE_CROSSING, "--log-file", str(log))
        assert code == 0, out
    lines = log.read_text().splitlines()
    assert len(lines) == 4, lines
    assert "knots identify started" in lines[0] and "p_data=" in lines[0]
    assert "knots identify ended: exit 0" in lines[1]
    assert lines[0][:4].isdigit(), "timestamped"
    code, out = _cli("--log-file", str(log.parent), "knots", "identify", ONE_CROSSING)
    assert code == 2 and "'--log-file'" in out and "directory" in out


def test_the_console_shows_warnings_only_unless_verbose(tmp_path: Path) -> None:
    code, out = _cli("knots", "identify", ONE_CROSSING)
    assert code == 0 and "started" not in out
    code, out = _cli("--verbose", "knots", "identify", ONE_CROSSING)
    assert code == 0 and "knots identify started" in out


def test_train_logs_its_parameters_and_each_epoch(tmp_path: Path) -> None:
    from tests.test_train import fill_store

    url = f"sqlite:///{tmp_path / 't.db'}"
    fill_store(url, 40)
    log = tmp_path / "train.log"
    args = ["--epochs", "2", "--hidden", "16", "--batch-size", "64", "--threads", "1", "--log-file", str(log)]
    code, out = _cli("--db", url, "train", *args)
    assert code == 0, out
    text = log.read_text()
    assert "training run 1 started on cpu" in text and "'epochs': 2" in text
    assert "epoch 1/2" in text and "epoch 2/2" in text
    assert "training run 1 finished after 2 epochs" in text and "model 1 stored" in text


def test_help_reads_as_prose_flags_take_no_placeholder_and_plan_groups_its_options() -> None:
    """Typer keeps the line breaks of a docstring's later paragraphs (sentences cut mid-line) and shows
    `<bool>` for every flag; plan's 30 options sat in one list."""
    import typer

    from cli.app import readable_help

    root = typer.main.get_command(app)
    readable_help(root)  # as every run of the CLI does
    plan = root.get_command(None, "plan")  # type: ignore[attr-defined]
    code, out = _cli("plan", "--help")
    assert code == 0 and "<bool>" not in out and "…" not in out
    assert all("\n" not in paragraph for paragraph in plan.help.split("\n\n"))
    panels = ("Goal", "Start or resume", "Budget and workers", "Output", "Search options", "Global options")
    for panel in panels:
        assert f" {panel} " in out, panel
