"""What a command writes (issue 37, items 2, 7, 10, 14; docs/security.md).

No command writes over the database it has open or its -wal/-shm files (by any path to them: relative,
a symbolic or a hard link), nor over any existing file without --force, nor into a folder that does not
exist, nor onto a kernel file system. Names (sets, labels, models) hold no control characters, and
names that differ never share a picture file.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.main import app
from twisted.experiments.report import _safe
from twisted.model.registry import default_model_path
from twisted.runtime import name_problem, output_folder_problem, output_problem, store_files
from twisted.store import open_store

runner = CliRunner()
ONE = '[[1,"O",2,"+"],[2,"U",1,"+"]]'


def said(result: object) -> str:
    """The output with rich's line breaks folded."""
    return " ".join(result.output.split())  # type: ignore[attr-defined]


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def store_with_model(tmp_path: Path) -> Path:
    db = tmp_path / "twisted.db"
    result = runner.invoke(app, ["--db", f"sqlite:///{db}", "models", "--import", str(default_model_path())])
    assert result.exit_code == 0, result.output
    assert not Path(f"{db}-wal").exists()  # the command closed the store (no connection left to the GC)
    return db


# ---- the rule, in twisted.runtime ----------------------------------------------------------------------


def test_output_problem_protects_the_store_by_every_path(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    db = tmp_path / "s.db"
    db.write_bytes(b"x")
    (tmp_path / "link.db").symlink_to(db)
    os.link(db, tmp_path / "hard.db")
    protected = store_files(db)
    monkeypatch.chdir(tmp_path)
    for path in (
        "s.db",
        str(db),
        "link.db",
        "hard.db",
        "./sub/../s.db",
        "s.db-wal",
        "s.db-shm",
        "s.db-journal",
    ):
        if path.startswith("./sub"):
            (tmp_path / "sub").mkdir(exist_ok=True)
        problem = output_problem(path, protected=protected, force=True)
        assert problem is not None and "database" in problem, path
    assert output_problem("s.db", protected=protected, append=True) is not None  # a log never goes there


def test_output_problem_existing_missing_kernel_folder(tmp_path: Path) -> None:
    existing = tmp_path / "old.pt"
    existing.write_text("keep")
    assert "--force" in (output_problem(existing) or "")
    assert output_problem(existing, force=True) is None
    assert output_problem(existing, append=True) is None  # a log is added to
    assert "does not exist" in (output_problem(tmp_path / "no" / "such" / "m.pt") or "")
    assert "kernel" in (output_problem("/proc/self/x") or "")
    assert "kernel" in (output_problem("/dev/null", force=True) or "")
    assert "directory" in (output_problem(tmp_path) or "")
    assert output_problem(tmp_path / "new.pt") is None
    assert not (tmp_path / "no").exists()
    # a report folder: made one level deep, one holding a report only with --force
    assert output_folder_problem(tmp_path / "rep", marker="report.md") is None
    assert "does not exist" in (output_folder_problem(tmp_path / "a" / "b", marker="report.md") or "")
    assert "not a folder" in (output_folder_problem(existing, marker="report.md") or "")
    (tmp_path / "rep").mkdir()
    (tmp_path / "rep" / "report.md").write_text("old")
    assert "--force" in (output_folder_problem(tmp_path / "rep", marker="report.md") or "")
    assert output_folder_problem(tmp_path / "rep", marker="report.md", force=True) is None


# ---- item 2: models --export, --log-file ---------------------------------------------------------------


def test_models_export_never_writes_over_the_open_store(
    store_with_model: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    db = store_with_model
    (tmp_path / "link.db").symlink_to(db.name)
    (tmp_path / "twisted.db-wal").write_bytes(b"")
    before = sha(db)
    monkeypatch.chdir(tmp_path)
    for target in ("twisted.db", str(db), "link.db", "twisted.db-wal", "../" + tmp_path.name + "/twisted.db"):
        for db_arg in (f"sqlite:///{db}", "sqlite:///twisted.db"):
            result = runner.invoke(app, ["--db", db_arg, "--force", "models", "--export", target])
            assert result.exit_code == 2, (target, result.output)
            assert "database this command has open" in " ".join(result.output.split())
    assert sha(db) == before
    assert (tmp_path / "twisted.db-wal").read_bytes() == b""


def test_models_export_asks_for_force_and_an_existing_folder(store_with_model: Path, tmp_path: Path) -> None:
    url = f"sqlite:///{store_with_model}"
    out = tmp_path / "m.pt"
    out.write_bytes(b"keep me")
    result = runner.invoke(app, ["--db", url, "models", "--export", str(out)])
    assert result.exit_code == 2 and "--force" in said(result) and out.read_bytes() == b"keep me"
    result = runner.invoke(app, ["--db", url, "models", "--export", str(out), "--force"])
    assert result.exit_code == 0, result.output
    assert out.stat().st_size > 1000
    result = runner.invoke(app, ["--db", url, "models", "--export", str(tmp_path / "missing" / "m.pt")])
    assert result.exit_code == 2 and "does not exist" in said(result)
    assert not (tmp_path / "missing").exists()


def test_log_file_is_never_the_store(store_with_model: Path, tmp_path: Path) -> None:
    db = store_with_model
    before = sha(db)
    for args in (
        ["--db", f"sqlite:///{db}", "--log-file", str(db), "models"],
        ["--log-file", str(db), "models", "--db", f"sqlite:///{db}"],  # --db after the command wins
        ["--db", f"sqlite:///{db}", "models", "--log-file", f"{db}-shm"],
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        assert "database" in said(result)
    assert sha(db) == before
    log = tmp_path / "run.log"
    log.write_text("earlier\n")
    result = runner.invoke(app, ["--db", f"sqlite:///{db}", "--log-file", str(log), "models"])
    assert result.exit_code == 0 and log.read_text().startswith("earlier\n")  # a log is added to


# ---- item 7: report --out, render --out ----------------------------------------------------------------


def test_report_out_refuses_files_proc_and_an_earlier_report(store_with_model: Path, tmp_path: Path) -> None:
    url = f"sqlite:///{store_with_model}"
    afile = tmp_path / "afile"
    afile.write_text("keep")
    for target, words in (
        (str(afile), "not a folder"),
        ("/proc/x", "kernel"),
        (str(tmp_path / "a" / "b"), "exist"),
    ):
        result = runner.invoke(app, ["--db", url, "report", "--out", target])
        assert result.exit_code == 2 and words in " ".join(result.output.split()), result.output
    assert afile.read_text() == "keep"
    folder = tmp_path / "rep"
    assert runner.invoke(app, ["--db", url, "report", "--out", str(folder)]).exit_code == 0
    again = runner.invoke(app, ["--db", url, "report", "--out", str(folder)])
    assert again.exit_code == 2 and "--force" in said(again)
    assert runner.invoke(app, ["--db", url, "report", "--out", str(folder), "--force"]).exit_code == 0


def test_render_out_creates_no_folders(tmp_path: Path) -> None:
    target = tmp_path / "new" / "deeper" / "goal.png"
    result = runner.invoke(app, ["render", "--goal", ONE, "--out", str(target), "--no-gl"])
    assert result.exit_code == 2 and "does not exist" in said(result)
    assert not (tmp_path / "new").exists()


# ---- item 10: names ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "bad", ["a\x1b[31mb", "a\nb", "tab\there", "  ", "", " lead", "zero\u200bwidth", "x" * 65]
)
def test_names_with_control_characters_or_blanks_are_refused(tmp_path: Path, bad: str) -> None:
    assert name_problem(bad) is not None
    db = tmp_path / "s.db"
    open_store(f"sqlite:///{db}").close()
    goals = tmp_path / "g.json"
    goals.write_text(json.dumps([json.loads(ONE)]))
    for args in (
        ["problems", "import", str(goals), "--name", bad],
        ["eval", "--set", "x", "--label", bad],
        ["models", "--import", str(default_model_path()), "--name", bad],
    ):
        result = runner.invoke(app, ["--db", f"sqlite:///{db}", *args])
        assert result.exit_code == 2, (args, result.output)
        assert "\x1b[31m" not in result.output, "the escape is not echoed raw to the terminal"
    # a key of a goal file becomes a set name: the same rule
    goals.write_text(json.dumps({bad or "": [json.loads(ONE)]}))
    result = runner.invoke(app, ["--db", f"sqlite:///{db}", "problems", "import", str(goals)])
    assert result.exit_code == 2, result.output


def test_names_that_differ_never_share_a_picture() -> None:
    names = ["a/b", "a_b", "a b", "a\\b", "easy", "..", ".hidden", "é"]
    files = [_safe(n) for n in names]
    assert len(set(files)) == len(names)
    assert _safe("easy") == "easy" and _safe("s1-easy_2.0") == "s1-easy_2.0"  # plain names stay as they are
    assert all(f and not f.startswith(".") and "/" not in f and "\\" not in f for f in files)


def test_a_prefix_ending_in_a_dash_gets_no_second_one(tmp_path: Path) -> None:
    db = tmp_path / "s.db"
    goals = tmp_path / "g.json"
    goals.write_text(json.dumps({"one": [json.loads(ONE)]}))
    result = runner.invoke(app, ["--db", f"sqlite:///{db}", "problems", "import", str(goals), "--name", "t-"])
    assert result.exit_code == 0, result.output
    assert "t-one" in said(result) and "t--one" not in said(result)


# ---- item 14: the small ones ---------------------------------------------------------------------------


def test_nan_is_called_not_finite_rather_than_out_of_range(tmp_path: Path) -> None:
    result = runner.invoke(app, ["--db", f"sqlite:///{tmp_path / 'n.db'}", "train", "--lr", "nan"])
    assert result.exit_code == 2 and "not a finite number" in said(result) and ">=" not in said(result)


def test_an_empty_goal_object_is_refused(tmp_path: Path) -> None:
    db = tmp_path / "s.db"
    open_store(f"sqlite:///{db}").close()
    goals = tmp_path / "g.json"
    goals.write_text("{}")
    result = runner.invoke(app, ["--db", f"sqlite:///{db}", "problems", "import", str(goals)])
    assert result.exit_code == 2 and "empty" in said(result)


def test_a_missing_psycopg_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    from twisted.store import StoreError

    monkeypatch.setitem(sys.modules, "psycopg", None)  # as if it were not installed
    with pytest.raises(StoreError, match=r"twisted-knots\[distributed\]"):
        open_store("postgresql+psycopg://user@127.0.0.1:1/none")


def test_a_failed_training_run_keeps_no_checkpoint(tmp_path: Path) -> None:
    from twisted.model.config import TrainConfig
    from twisted.store.training import Checkpoint, TrainingRun, mark_training_failed

    with open_store(f"sqlite:///{tmp_path / 't.db'}") as store:
        with store.session(write=True) as session:
            run = TrainingRun(seed=0, parameters=TrainConfig().to_dict(), max_transition_id=0, metrics={})
            session.add(run)
            session.flush()
            session.add(
                Checkpoint(training_run_id=run.id, epoch=1, batch_index=0, elapsed_s=1.0, payload=b"nan")
            )
            run_id = run.id
        mark_training_failed(store, run_id, "validation loss is nan")
        with store.session() as session:
            assert session.get(TrainingRun, run_id).status == "failed"
            assert session.query(Checkpoint).filter(Checkpoint.training_run_id == run_id).count() == 0


def test_file_names_too_long_for_the_file_system_are_refused(tmp_path: Path) -> None:
    assert "too long" in (output_problem(tmp_path / ("x" * 300)) or "")
    assert "too long" in (output_problem("/".join(["d" * 200] * 30)) or "")
    result = runner.invoke(app, ["--log-file", "x" * 5000, "knots", "list"])
    assert result.exit_code == 2 and "too long" in said(result)


def test_an_error_quoting_a_terminal_escape_shows_it_escaped(tmp_path: Path) -> None:
    """Found by test_fuzz_cli: `sensitivity plot --out ESC[31m...` echoed the escape raw."""
    out = tmp_path / "\x1b[31mred\x1b[0m"
    out.write_text("a file, not a folder")
    db = f"sqlite:///{tmp_path / 'store.db'}"
    result = runner.invoke(app, ["--db", db, "sensitivity", "plot", "--out", str(out)])
    assert result.exit_code == 2
    assert "\x1b" not in said(result)
    assert "\\x1b[31mred" in said(result)


def test_names_from_file_names_are_checked_and_names_from_the_store_print_escaped(
    store_with_model: Path, tmp_path: Path
) -> None:
    """Issue 62, item 7: `models --import` takes the file's name only when --name would accept it, and
    every name read back from the store (planted there by hand) prints with its escapes visible."""
    import sqlite3

    evil = tmp_path / "\x1b[41mEVIL\x1b[0m.pt"
    evil.write_bytes(default_model_path().read_bytes())
    fresh = tmp_path / "fresh.db"
    result = runner.invoke(app, ["--db", f"sqlite:///{fresh}", "models", "--import", str(evil)])
    assert result.exit_code == 2 and "give --name" in said(result), said(result)
    assert "\x1b" not in result.output and not fresh.exists()

    db = f"sqlite:///{store_with_model}"
    goals = tmp_path / "one.json"
    goals.write_text(json.dumps([json.loads(ONE)]))
    imported = runner.invoke(app, ["--db", db, "problems", "import", str(goals), "--name", "plain"])
    assert imported.exit_code == 0, imported.output
    hostile = "x\x1b[2J\x1b]52;c;ZXZpbA==\x07[red]y\nz\u200b"
    conn = sqlite3.connect(store_with_model)
    conn.execute("update problem_sets set name = ?", (hostile,))
    conn.execute("update problems set tag = ?", (hostile,))
    conn.execute("update models set name = ?", (hostile,))
    conn.commit()
    conn.close()
    for args in (["models"], ["problems", "list"], ["problems", "list", "--show", hostile]):
        result = runner.invoke(app, ["--db", db, *args], env={"COLUMNS": "300"})
        assert result.exit_code == 0, result.output
        assert not {"\x1b", "\x07", "\u200b"} & set(result.output), (args, result.output)
        assert "x\\x1b[2J\\x1b]52;c;ZXZpbA==\\x07[red]y\\nz\\u200b" in result.output, (args, result.output)
