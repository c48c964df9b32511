"""Issue 37 (trust), the store and the input parsers: items 3, 5, 6, 8, 9 and 11.

Each test reproduces one finding (what it did before is in its docstring). Permissions are real: the
tests run as root in CI, and root writes anything, so the commands that must meet a read-only file run
in a child process that has given up root's right to override file permissions
(:func:`_as_plain_user`); run as another user, plain ``chmod`` is enough and nothing is given up.
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import os
import shutil
import sqlite3
import stat
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sqlalchemy import text
from typer.testing import CliRunner

from cli.main import app
from twisted.store import StoreError, open_store
from twisted.topology import PDataError, parse_p_data

REPO = Path(__file__).resolve().parents[1]
ONE_CROSSING = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
HUGE = "9" * 5000  # beyond Python's 4,300-digit limit on reading integers
BIG = "123456789012345678901234567890"  # beyond 64 bits, within that limit

runner = CliRunner()


def _cli(*args: str, env: dict[str, str] | None = None) -> tuple[int, str]:
    """Run the CLI in this process; a traceback fails the test (only exits are allowed)."""
    result = runner.invoke(app, list(args), env=env)
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        f"{[a[:40] for a in args[:4]]}... raised {result.exception!r}\n{result.output[-2000:]}"
    )
    return result.exit_code, " ".join(result.output.split())


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# --- running as a plain user --------------------------------------------------------------------------------

PR_CAPBSET_DROP = 24  # prctl(2)
CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH = 1, 2


def _drop_file_override() -> None:
    """In the child before exec: take the two capabilities that let root ignore file permissions out of
    its bounding set, so that the program it runs meets permissions as any user does."""
    libc = ctypes.CDLL(None, use_errno=True)
    for cap in (CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH):
        if libc.prctl(PR_CAPBSET_DROP, cap, 0, 0, 0) != 0:
            os._exit(97)


def _as_plain_user(args: list[str], cwd: Path, **kwargs: Any) -> subprocess.CompletedProcess[str]:
    """``args`` in a child process that file permissions bind (root gives up its override first)."""
    preexec = _drop_file_override if os.geteuid() == 0 else None
    done = subprocess.run(
        args, cwd=cwd, capture_output=True, text=True, preexec_fn=preexec, timeout=600, **kwargs
    )
    if done.returncode == 97:
        pytest.skip("cannot give up root's file-permission override here (prctl refused)")
    return done


def _twisted(db: Path, *args: str, cwd: Path) -> tuple[int, str]:
    """The CLI in a child process as a plain user; a traceback on stderr fails the test."""
    command = [sys.executable, "-m", "cli.main", "--db", f"sqlite:///{db}", *args]
    done = _as_plain_user(command, cwd=cwd, env={**os.environ, "COLUMNS": "1000"})  # no line breaks
    assert "Traceback" not in done.stderr, done.stderr[-3000:]
    return done.returncode, " ".join((done.stdout + done.stderr).split())


@pytest.fixture(scope="module")
def store_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store with a solved planner run (run 1), an imported goal set and a model: what the reading
    commands read."""
    folder = tmp_path_factory.mktemp("store")
    path = folder / "twisted.db"
    url = f"sqlite:///{path}"
    plan = ["plan", "--goal", ONE_CROSSING, "--planner", "random-low", "--workers", "1", "--seed", "0"]
    code, out = _cli("--db", url, *plan, "--max-iterations", "40", "--json")
    assert code == 0, out
    goals = folder / "goals.json"
    goals.write_text(json.dumps([json.loads(ONE_CROSSING)]))
    assert _cli("--db", url, "problems", "import", str(goals), "--name", "one")[0] == 0
    from twisted.model.registry import default_model_path

    assert _cli("--db", url, "models", "--import", str(default_model_path()), "--name", "shipped")[0] == 0
    with open_store(url) as store, store.engine.connect() as conn:
        conn.exec_driver_sql("PRAGMA wal_checkpoint(TRUNCATE)")
    for companion in ("-wal", "-shm"):
        Path(f"{path}{companion}").unlink(missing_ok=True)
    return path


@pytest.fixture
def store_copy(store_file: Path, tmp_path: Path) -> Iterator[Path]:
    """A copy of the store in its own folder (folder and file made writable again at the end)."""
    folder = tmp_path / "copy"
    folder.mkdir()
    path = folder / "twisted.db"
    shutil.copy(store_file, path)
    yield path
    folder.chmod(0o755)
    for p in folder.iterdir():
        p.chmod(0o644)


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# --- 11. commands that only read open the store read-only ---------------------------------------------------


READING_COMMANDS = [
    ["models"],
    ["models", "--json"],
    ["models", "--export", "OUT/model.pt"],
    ["problems", "list"],
    ["problems", "list", "--show", "one"],
    ["report", "--out", "OUT/report"],
    ["render", "--run", "1", "--out", "OUT/run.png", "--no-gl"],
    ["render", "--goal", ONE_CROSSING, "--out", "OUT/goal.png"],
    ["replay", "1"],
    ["rl", "list"],
    ["stats"],
    ["db"],
]


@pytest.mark.parametrize("command", READING_COMMANDS, ids=" ".join)
def test_a_read_only_store_can_be_inspected(store_copy: Path, tmp_path: Path, command: list[str]) -> None:
    """Before: models, problems list, report, render and replay refused a read-only database ("is not
    writable ... SQLite keeps its write-ahead log beside the file", exit 2) while stats and db read it.
    The file is read-only and so is its folder: nothing can be written beside it either."""
    out = tmp_path / "out"
    out.mkdir()
    before = _digest(store_copy)
    store_copy.chmod(0o444)
    store_copy.parent.chmod(0o555)
    code, output = _twisted(store_copy, *[a.replace("OUT", str(out)) for a in command], cwd=out)
    assert code == 0, output
    assert _files(store_copy.parent) == ["twisted.db"], "no -wal / -shm beside it"
    assert _digest(store_copy) == before


def test_a_writing_command_still_refuses_a_read_only_store(store_copy: Path, tmp_path: Path) -> None:
    goals = tmp_path / "g.json"
    goals.write_text(json.dumps([json.loads(ONE_CROSSING)]))
    store_copy.chmod(0o444)
    code, output = _twisted(store_copy, "problems", "import", str(goals), "--name", "two", cwd=tmp_path)
    assert code == 2 and "not writable" in output, output


def test_a_read_only_url_is_honoured_or_refused(
    store_copy: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 62, item 8. Before: `TWISTED_DB='sqlite:///../p.db?mode=ro' problems import` printed an
    SQLAlchemy warning (the driver drops the option), exit 0, and the set was written."""
    goals = tmp_path / "g.json"
    goals.write_text(json.dumps([json.loads(ONE_CROSSING)]))
    before = _digest(store_copy)
    monkeypatch.chdir(store_copy.parent)  # a relative path, as in the report
    env = {"TWISTED_DB": "sqlite:///../copy/twisted.db?mode=ro"}
    code, output = _cli("problems", "import", str(goals), "--name", "zz2", env=env)
    assert code == 2 and "read-only (mode=ro)" in output and "nothing was written" in output, output
    assert _digest(store_copy) == before
    code, output = _cli("problems", "list", "--json", env=env)  # a reading command reads it
    assert code == 0 and "zz2" not in output, output
    for url, said in (
        ("sqlite:///../copy/twisted.db?mode=rw", "mode=rw is not understood"),
        ("sqlite:///../copy/twisted.db?mode=ro&cache=shared", "option cache is not understood"),
        ("sqlite:///../copy/new.db?mode=ro", "does not exist"),
    ):
        code, output = _cli("--db", url, "problems", "list")
        assert code == 2 and said in output, (url, output)
    assert _digest(store_copy) == before and not (store_copy.parent / "new.db").exists()


def test_a_reading_command_on_a_new_database_still_creates_it(tmp_path: Path) -> None:
    """Read-only opening applies to an existing store; `twisted models` on a new --db makes it as before."""
    code, out = _cli("--db", f"sqlite:///{tmp_path / 'new.db'}", "models", "--json")
    assert code == 0 and json.loads(out) == [], out


# --- 3. a read-only -shm / -wal beside a writable store -----------------------------------------------------


def test_read_only_companions_left_by_a_reader_are_refused_with_the_reason(
    store_copy: Path, tmp_path: Path
) -> None:
    """Before: after a plain SQLite reader of a read-only copy (which leaves -wal and -shm read-only beside
    it), every writing command ended in "OperationalError: attempt to write a readonly database"
    (exit 1, traceback), even once the database itself was writable again."""
    store_copy.chmod(0o444)
    reader = (
        "import sqlite3, sys; sqlite3.connect(sys.argv[1]).execute('SELECT count(*) FROM runs').fetchall()"
    )
    done = _as_plain_user([sys.executable, "-c", reader, str(store_copy)], cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    shm = Path(f"{store_copy}-shm")
    assert shm.exists() and not shm.stat().st_mode & stat.S_IWUSR, "the reader left a read-only -shm"
    store_copy.chmod(0o644)
    before = _digest(store_copy)
    goals = tmp_path / "g.json"
    goals.write_text(json.dumps([json.loads(ONE_CROSSING)]))
    code, output = _twisted(store_copy, "problems", "import", str(goals), "--name", "two", cwd=tmp_path)
    assert code == 2, output
    assert "twisted.db-shm" in output and "read-only" in output and "chmod u+w" in output, output
    assert _digest(store_copy) == before
    assert _twisted(store_copy, "stats", cwd=tmp_path)[0] == 0, "reading still works"
    for companion in store_copy.parent.glob("twisted.db-*"):
        companion.chmod(0o644)  # what the message says to do
    code, output = _twisted(store_copy, "problems", "import", str(goals), "--name", "two", cwd=tmp_path)
    assert code == 0, output


# --- 9. pages overwritten in place --------------------------------------------------------------------------


def _overwrite_pages(path: Path, table: str) -> list[int]:
    """Overwrite (0xFF) two pages of ``table`` in place, as a stray write would; returns their numbers."""
    conn = sqlite3.connect(path)
    try:
        page_size = conn.execute("PRAGMA page_size").fetchone()[0]
        pages = [
            row[0] for row in conn.execute("SELECT pageno FROM dbstat WHERE name = ? ORDER BY 1", (table,))
        ]
    finally:
        conn.close()
    chosen = pages[:2] if len(pages) >= 2 else [pages[0], pages[0] + 1]
    with path.open("r+b") as fh:
        for page in chosen:
            fh.seek((page - 1) * page_size)
            fh.write(b"\xff" * page_size)
    return chosen


@pytest.mark.parametrize(
    "command",
    [
        ["problems", "import", "GOALS", "--name", "two"],
        ["collect", "--hours", "0.01", "--workers", "1", "--seed", "1"],
        ["train", "--epochs", "1", "--threads", "1"],
        [
            "plan",
            "--goal",
            ONE_CROSSING,
            "--planner",
            "random-low",
            "--workers",
            "1",
            "--max-iterations",
            "1",
        ],
    ],
    ids=lambda c: c[0],
)
def test_damaged_pages_are_found_before_anything_is_written(
    store_copy: Path, tmp_path: Path, command: list[str]
) -> None:
    """Before: with two pages overwritten by 0xFF, collect ended in "database disk image is malformed"
    (exit 1, traceback) after it had added a run, and problems import wrote into the damaged file (exit 0).
    Now every writing command runs SQLite's quick_check first and exits 2 naming the damage."""
    pages = _overwrite_pages(store_copy, "search_nodes")
    before = _digest(store_copy)
    goals = tmp_path / "g.json"
    goals.write_text(json.dumps([json.loads(ONE_CROSSING)]))
    args = [a.replace("GOALS", str(goals)) for a in command]
    code, out = _cli("--db", f"sqlite:///{store_copy}", *args)
    assert code == 2, out
    assert "is damaged" in out and f"Page {pages[0]}" in out and "quick_check" in out, out
    assert _digest(store_copy) == before
    code, out = _cli("--db", f"sqlite:///{store_copy}", "stats")
    assert code == 0, "reading commands do not pay for the check (nor refuse what they can read)"


def test_the_check_passes_a_sound_store(store_copy: Path) -> None:
    with open_store(f"sqlite:///{store_copy}", verify=True) as store, store.session() as session:
        assert session.execute(text("SELECT count(*) FROM runs")).scalar() == 1
    _overwrite_pages(store_copy, "runs")
    with pytest.raises(StoreError, match="is damaged"):
        open_store(f"sqlite:///{store_copy}", verify=True)
    open_store(f"sqlite:///{store_copy}", readonly=True).close()  # a reader does not check


# --- 8. file names the file system or SQLite cannot take ----------------------------------------------------


@pytest.mark.parametrize(
    "command", [["stats"], ["models"], ["problems", "list"], ["collect", "--hours", "0.01"]]
)
def test_a_file_name_over_255_bytes_is_refused_without_being_echoed_whole(
    tmp_path: Path, command: list[str]
) -> None:
    """Before: "OSError: [Errno 36] File name too long" with a traceback that printed the name whole."""
    name = "a" * 300 + ".db"
    code, out = _cli("--db", f"sqlite:///{tmp_path / name}", *command)
    assert code == 2 and "255" in out and "shorter --db" in out, out[:500]
    assert "a" * 150 not in out.replace(" ", ""), "the name is shortened in the message"
    assert _files(tmp_path) == []


def test_a_path_over_4095_bytes_is_refused(tmp_path: Path) -> None:
    deep = "/".join(["b" * 200] * 25)
    code, out = _cli("--db", f"sqlite:///{tmp_path / deep}.db", "stats")
    assert code == 2 and "4095" in out and "b" * 150 not in out.replace(" ", ""), out[:500]


@pytest.mark.parametrize("command", [["stats"], ["models"], ["problems", "list"], ["report", "--out", "r"]])
def test_a_file_name_that_is_not_utf8_is_refused(tmp_path: Path, command: list[str]) -> None:
    """Before: "UnicodeEncodeError: 'utf-8' codec can't encode character '\\udcff'" (traceback), through
    --db and through TWISTED_DB alike (a name read from the command line keeps such bytes as surrogates)."""
    bad = os.fsdecode(b"bad\xff.db")
    code, out = _cli("--db", f"sqlite:///{tmp_path / bad}", *command)
    assert code == 2 and "not valid UTF-8" in out and "0xff" in out, out
    code, out = _cli(*command, env={"TWISTED_DB": f"sqlite:///{tmp_path / bad}"})
    assert code == 2 and "not valid UTF-8" in out, out
    assert _files(tmp_path) == []


def test_a_log_file_gets_a_bad_name_escaped(tmp_path: Path) -> None:
    bad = os.fsdecode(b"bad\xfe.db")
    log = tmp_path / "log.txt"
    code, out = _cli("--db", f"sqlite:///{tmp_path / bad}", "--log-file", str(log), "--verbose", "stats")
    assert code == 2 and "Logging error" not in out, out
    assert "exit 2" in log.read_text()


# --- 5. integers beyond 64 bits (and beyond 4,300 digits) in P-data -----------------------------------------


@pytest.mark.parametrize("digits", [HUGE, BIG, "-" + BIG], ids=["5000-digits", "30-digits", "negative"])
def test_parse_p_data_refuses_integers_beyond_64_bits(digits: str) -> None:
    """Before: json.loads raised "ValueError: Exceeds the limit (4300 digits) for integer string
    conversion" out of every parser (a traceback in the CLI)."""
    with pytest.raises(PDataError, match="beyond 64 bits"):
        parse_p_data(f'[[{digits},"O",2,"+"],[2,"U",1,"+"]]')
    with pytest.raises(PDataError, match="beyond 64 bits"):
        parse_p_data([[int(digits) if len(digits) < 4000 else 10**5000, "O", 2, "+"], [2, "U", 1, "+"]])
    with pytest.raises(PDataError, match="outside 1..2"):  # 64 bits: refused as any bad partner is
        parse_p_data(f'[[1,"O",{2**63 - 1},"+"],[2,"U",1,"+"]]')


@pytest.mark.parametrize("digits", [HUGE, BIG])
@pytest.mark.parametrize(
    "command",
    [
        ["moves", "successors", "--state", "STATE"],
        ["knots", "identify", "STATE"],
        ["plan", "--goal", "STATE", "--planner", "random-low"],
        ["render", "--goal", "STATE"],
        ["rl", "train", "--goal", "STATE", "--steps", "5"],
    ],
    ids=lambda c: c[0] if isinstance(c, list) else None,
)
def test_every_command_refuses_a_huge_integer_in_p_data(
    tmp_path: Path, digits: str, command: list[str]
) -> None:
    state = f'[[{digits},"O",2,"+"],[2,"U",1,"+"]]'
    db = tmp_path / "x.db"
    code, out = _cli("--db", f"sqlite:///{db}", *[state if a == "STATE" else a for a in command])
    assert code == 2 and "64 bits" in out, out[:600]
    assert len(out) < 3000, "the integer is not echoed whole"
    assert not db.exists(), "refused before the store is opened"


@pytest.mark.parametrize(
    "content",
    [
        f'[[[{HUGE},"O",2,"+"],[2,"U",1,"+"]]]',
        f'{{"a": [[[1,"O",2,"+"],[2,"U",{BIG},"+"]]]}}',
        f'["overhand@{HUGE}"]',
        f'["knot:3_1@{BIG}"]',
    ],
    ids=["p-data-5000", "p-data-30", "knot-5000", "knot-30"],
)
def test_a_goal_file_with_a_huge_integer_is_refused(tmp_path: Path, content: str) -> None:
    goals = tmp_path / "g.json"
    goals.write_text(content)
    code, out = _cli(
        "--db", f"sqlite:///{tmp_path / 'x.db'}", "problems", "import", str(goals), "--name", "s"
    )
    assert code == 2 and "g.json" in out and ("64 bits" in out or "crossings" in out), out[:600]
    assert len(out) < 3000


# --- 6. goal files that are not UTF-8 -----------------------------------------------------------------------

GOALS = json.dumps({"s": [json.loads(ONE_CROSSING)]})


@pytest.mark.parametrize(
    ("content", "said"),
    [
        (GOALS.encode("utf-16"), "UTF-16"),
        (GOALS.encode("utf-16-be"), "NUL characters"),
        (GOALS.encode("utf-32"), "UTF-32"),
        (GOALS.replace("s", "é").encode("latin-1"), "byte 0xe9"),
        (np.random.default_rng(37).integers(0, 256, 400, dtype=np.uint8).tobytes(), "not UTF-8"),
        (b"\x00" * 64, "NUL characters"),
    ],
    ids=["utf-16-bom", "utf-16-no-bom", "utf-32", "latin-1", "random-bytes", "nul-bytes"],
)
def test_a_goal_file_that_is_not_utf8_is_refused(tmp_path: Path, content: bytes, said: str) -> None:
    """Before: "UnicodeDecodeError: 'utf-8' codec can't decode byte 0xff in position 0" (traceback)."""
    goals = tmp_path / "goals.json"
    goals.write_bytes(content)
    db = tmp_path / "x.db"
    code, out = _cli("--db", f"sqlite:///{db}", "problems", "import", str(goals))
    assert code == 2 and "goals.json" in out and said in out and "UTF-8" in out, out
    assert not db.exists(), "refused before the store is opened"


def test_a_utf8_goal_file_with_a_byte_order_mark_is_read(tmp_path: Path) -> None:
    goals = tmp_path / "goals.json"
    goals.write_bytes(GOALS.encode("utf-8-sig"))
    code, out = _cli("--db", f"sqlite:///{tmp_path / 'x.db'}", "problems", "import", str(goals))
    assert code == 0, out
