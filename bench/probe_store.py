"""The trials of issue 37 items 3, 5, 6, 8, 9 and 11 (the store and the parsers), for ``bench/probe.py``.

:data:`TRIALS` lists ``(item, name, expected, run, ok)``: ``run(db, work)`` gets a copy of the store and
a work folder and returns what happened in words ("exit 2: ..."), ``ok`` says from that text whether it
went as expected. ``bench/probe.py`` wraps them in its ``Trial``; alone,

    python bench/probe_store.py --db PATH/TO/twisted.db

runs them and prints the same table. Root ignores file permissions: the trials that need a read-only
file run the CLI with root's override given up (``prctl``), as ``tests/test_trust_store.py`` does.
"""

from __future__ import annotations

import argparse
import ctypes
import hashlib
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

ONE = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
HUGE = "9" * 5000


def _plain_user() -> None:
    libc = ctypes.CDLL(None, use_errno=True)
    for cap in (1, 2):  # CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH out of the bounding set
        libc.prctl(24, cap, 0, 0, 0)


def _run(db: Path | str | None, *args: str, cwd: Path, plain: bool = False) -> str:
    command = [
        sys.executable,
        "-m",
        "cli.main",
        *(["--db", f"sqlite:///{db}"] if db is not None else []),
        *args,
    ]
    done = subprocess.run(
        command,
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "COLUMNS": "1000"},
        preexec_fn=_plain_user if plain and os.geteuid() == 0 else None,
    )
    text = " ".join((done.stdout + " " + done.stderr).split())
    traceback = ", TRACEBACK" if "Traceback (most recent call last)" in done.stderr else ""
    return f"exit {done.returncode}{traceback}: {text[-170:] if traceback else text[:170]}"


def _sha(db: Path) -> str:
    return hashlib.sha256(db.read_bytes()).hexdigest()


def _unchanged(db: Path, before: str) -> str:
    return "" if _sha(db) == before else " (STORE CHANGED)"


def _goals(work: Path, content: bytes | str) -> Path:
    path = work / "goals.json"
    path.write_bytes(content.encode() if isinstance(content, str) else content)
    return path


def readonly_store(*command: str) -> Callable[[Path, Path], str]:
    """Item 11: a reading command on a read-only file in a read-only folder."""

    def run(db: Path, work: Path) -> str:
        out = work / "out"
        out.mkdir()
        conn = sqlite3.connect(db)
        solved = conn.execute("SELECT min(run_id) FROM search_runs WHERE outcome = 'solved'").fetchone()[0]
        conn.close()
        if "SOLVED" in command and solved is None:
            return "the store has no solved planner run: plan one first"
        command_here = [a.replace("OUT", str(out)).replace("SOLVED", str(solved)) for a in command]
        before = _sha(db)
        db.chmod(0o444)
        work.chmod(0o555)
        try:
            got = _run(db, *command_here, cwd=out, plain=True)
            left = sorted(p.name for p in work.iterdir() if p.name.startswith(db.name + "-"))
        finally:
            work.chmod(0o755)
            db.chmod(0o644)
        return got + _unchanged(db, before) + (f" (LEFT {left})" if left else "")

    return run


def readonly_companions(db: Path, work: Path) -> str:
    """Item 3: a reader of a read-only copy leaves -wal/-shm read-only; then a writing command."""
    db.chmod(0o444)
    reader = "import sqlite3, sys; sqlite3.connect(sys.argv[1]).execute('SELECT 1 FROM runs').fetchall()"
    subprocess.run([sys.executable, "-c", reader, str(db)], preexec_fn=_plain_user, check=True)
    db.chmod(0o644)
    before = _sha(db)
    got = _run(db, "problems", "import", str(_goals(work, f"[{ONE}]")), "--name", "p3", cwd=work, plain=True)
    return got + _unchanged(db, before)


def damaged(*command: str) -> Callable[[Path, Path], str]:
    """Item 9: two pages of a big table overwritten with 0xFF in place, then a writing command."""

    def run(db: Path, work: Path) -> str:
        conn = sqlite3.connect(db)
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        size = conn.execute("PRAGMA page_size").fetchone()[0]
        table = (
            "configurations" if conn.execute("SELECT count(*) FROM configurations").fetchone()[0] else "runs"
        )
        pages = [r[0] for r in conn.execute("SELECT pageno FROM dbstat WHERE name = ? ORDER BY 1", (table,))]
        conn.close()
        with db.open("r+b") as fh:
            for page in pages[len(pages) // 2 :][:2] or pages[:1]:
                fh.seek((page - 1) * size)
                fh.write(b"\xff" * size)
        before = _sha(db)
        args = [a.replace("GOALS", str(_goals(work, f"[{ONE}]"))) for a in command]
        return _run(db, *args, cwd=work) + _unchanged(db, before)

    return run


def bad_name(name: str, *command: str) -> Callable[[Path, Path], str]:
    """Item 8: --db names a file the file system or SQLite cannot take."""

    def run(db: Path, work: Path) -> str:
        got = _run(f"{work}/{name}", *command, cwd=work)
        return got + (" (NAME ECHOED WHOLE)" if name[:200] in got.replace(" ", "") else "")

    return run


def with_state(*command: str) -> Callable[[Path, Path], str]:
    """Item 5: a P-data state with an integer of 5,000 digits."""

    def run(db: Path, work: Path) -> str:
        state = f'[[{HUGE},"O",2,"+"],[2,"U",1,"+"]]'
        return _run(db, *[state if a == "STATE" else a for a in command], cwd=work)

    return run


def goal_file(content: bytes | str) -> Callable[[Path, Path], str]:
    """Items 5 and 6: `problems import` of a goal file."""

    def run(db: Path, work: Path) -> str:
        before = _sha(db)
        return _run(
            db, "problems", "import", str(_goals(work, content)), "--name", "p", cwd=work
        ) + _unchanged(db, before)

    return run


def exit2(text: str) -> bool:
    return text.startswith("exit 2:") and "CHANGED" not in text and "ECHOED" not in text


def exit0(text: str) -> bool:
    return text.startswith("exit 0:") and "CHANGED" not in text and "LEFT" not in text


GOALS = '{"s": [' + ONE + "]}"
TRIALS: list[tuple[str, str, str, Callable[[Path, Path], str], Callable[[str], bool]]] = [
    ("3", "problems import, read-only -wal/-shm", "exit 2, store intact", readonly_companions, exit2),
    (
        "5",
        "moves successors --state <5,000 digits>",
        "exit 2",
        with_state("moves", "successors", "--state", "STATE"),
        exit2,
    ),
    ("5", "plan --goal <5,000 digits>", "exit 2", with_state("plan", "--goal", "STATE"), exit2),
    ("5", "knots identify <5,000 digits>", "exit 2", with_state("knots", "identify", "STATE"), exit2),
    (
        "5",
        "problems import, 5,000-digit position",
        "exit 2",
        goal_file(f'[[[{HUGE},"O",2,"+"],[2,"U",1,"+"]]]'),
        exit2,
    ),
    ("5", "problems import, overhand@<5,000 digits>", "exit 2", goal_file(f'["overhand@{HUGE}"]'), exit2),
    ("6", "problems import, UTF-16 goal file", "exit 2", goal_file(GOALS.encode("utf-16")), exit2),
    ("6", "problems import, binary goal file", "exit 2", goal_file(bytes(range(256)) * 4), exit2),
    (
        "6",
        "problems import, Latin-1 goal file",
        "exit 2",
        goal_file(GOALS.replace("s", "\xe9").encode("latin-1")),
        exit2,
    ),
    (
        "8",
        "--db <300-byte name> stats",
        "exit 2, name shortened",
        bad_name("a" * 300 + ".db", "stats"),
        exit2,
    ),
    (
        "8",
        "--db <300-byte name> collect",
        "exit 2, name shortened",
        bad_name("a" * 300 + ".db", "collect", "--hours", "0.01"),
        exit2,
    ),
    ("8", "--db <not UTF-8> models", "exit 2", bad_name(os.fsdecode(b"bad\xff.db"), "models"), exit2),
    (
        "9",
        "problems import, 2 pages of 0xFF",
        "exit 2, store intact",
        damaged("problems", "import", "GOALS", "--name", "p9"),
        exit2,
    ),
    (
        "9",
        "collect, 2 pages of 0xFF",
        "exit 2, store intact",
        damaged("collect", "--hours", "0.01", "--workers", "1"),
        exit2,
    ),
    (
        "9",
        "train, 2 pages of 0xFF",
        "exit 2, store intact",
        damaged("train", "--epochs", "1", "--threads", "1"),
        exit2,
    ),
    ("11", "models, read-only store", "exit 0, nothing written", readonly_store("models"), exit0),
    (
        "11",
        "problems list, read-only store",
        "exit 0, nothing written",
        readonly_store("problems", "list"),
        exit0,
    ),
    (
        "11",
        "report, read-only store",
        "exit 0, nothing written",
        readonly_store("report", "--out", "OUT/report"),
        exit0,
    ),
    (
        "11",
        "render --goal, read-only store",
        "exit 0, nothing written",
        readonly_store("render", "--goal", ONE, "--out", "OUT/g.png"),
        exit0,
    ),
    (
        "11",
        "replay SOLVED, read-only store",
        "exit 0, nothing written",
        readonly_store("replay", "SOLVED"),
        exit0,
    ),
]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--db", type=Path, required=True, help="a store (SQLite file) to copy for each trial")
    args = parser.parse_args()
    root = Path(tempfile.mkdtemp(prefix="probe-store-"))
    master = root / "master.db"  # upgraded once, so that no trial's digest changes by a migration
    shutil.copyfile(args.db, master)
    from twisted.store import open_store

    open_store(f"sqlite:///{master}").close()
    conn = sqlite3.connect(master)
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")  # every row in the file that is copied
    conn.close()
    failed = 0
    for i, (item, name, expected, run, ok) in enumerate(TRIALS):
        work = root / f"trial-{i:02d}"
        work.mkdir()
        db = work / "store.db"
        shutil.copyfile(master, db)
        got = run(db, work)
        verdict = "ok" if ok(got) else "NOT OK"
        failed += verdict != "ok"
        print(f"{item:>3} | {name:42s} | {expected:34s} | {verdict:6s} | {got[:150]}", flush=True)
    print(f"\n{len(TRIALS)} trials, {failed} not as expected (work folder {root})")


if __name__ == "__main__":
    main()
