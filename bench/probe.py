"""Replay the hostile trials of issue 37 ("Trust") on copies of a real store; print trial / expected / got.

    python bench/probe.py --db PATH/TO/twisted.db [--only 1,2,4] [--work DIR]

Every trial copies the store (``--db``: a SQLite file with collected transitions and a trained model,
e.g. after ``twisted collect`` and ``twisted train``), does one hostile thing to it or with it, runs the
CLI (``python -m cli.main``, as installed, or from ``PYTHONPATH``: run it once with an older checkout on
``PYTHONPATH`` to see the "before") and reports what happened: the exit code, whether a traceback was
printed, whether a planted pickle ran (it creates a marker file when unpickled) and what the trial
checks besides. Nothing outside ``--work`` (default: a temporary folder) is written.

The trials of items 3, 5, 6, 8, 9 and 11 (the other half of the issue) come from
``bench/probe_store.py`` in the same form; items 12 and 13 need a Ray cluster and are tested there.
Items ``62.5``, ``62.6``, ``62.10`` and ``62.11`` are issue 62's runs and checkpoints read back from the
store (bad parameters, checkpoints and end configurations, ``untie --resume`` of a plan run, a Ctrl-C as
a run solves): they add three small runs to the copy (random curves, no model) and plant into them.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import math
import os
import pickle
import shutil
import sqlite3
import struct
import subprocess
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ONE = '[[1,"O",2,"+"],[2,"U",1,"+"]]'


class Planted:
    """Unpickling this creates the file ``path`` (the stand-in for any code a pickle can run)."""

    def __init__(self, path: Path) -> None:
        self.path = str(path)

    def __reduce__(self) -> tuple[Any, ...]:
        return (open, (self.path, "w"))


def torch_bomb(path: Path) -> bytes:
    import torch

    buf = io.BytesIO()
    torch.save({"net": Planted(path)}, buf)
    return buf.getvalue()


@dataclass
class Outcome:
    code: int
    traceback: bool
    text: str  # stdout + stderr, whitespace folded


@dataclass
class Trial:
    item: str
    name: str
    expected: str
    run: Callable[[Path, Path], str]  # (copy of the store, work folder) -> what happened, in words
    ok: Callable[[str], bool] | None = None  # from that text: did it go as expected


def cli(db: Path | None, *args: str, cwd: Path, timeout: float = 300) -> Outcome:
    command = [sys.executable, "-m", "cli.main"]
    if db is not None:
        command += ["--db", f"sqlite:///{db}"]
    env = {**os.environ, "COLUMNS": "200"}
    done = subprocess.run(
        [*command, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env
    )
    text = " ".join((done.stdout + " " + done.stderr).split())
    return Outcome(done.returncode, "Traceback (most recent call last)" in done.stderr, text)


def digest(db: Path) -> str:
    conn = sqlite3.connect(f"{db.resolve().as_uri()}?mode=ro", uri=True)
    try:
        return hashlib.sha256("\n".join(conn.iterdump()).encode()).hexdigest()[:12]
    except sqlite3.DatabaseError as exc:
        return f"unreadable ({exc})"
    finally:
        conn.close()


def said(out: Outcome, extra: str = "") -> str:
    tail = out.text[-300:] if out.traceback else out.text
    return f"exit {out.code}{', TRACEBACK' if out.traceback else ''}{extra}: {tail}"


def exit2_clean(text: str) -> bool:
    return text.startswith("exit 2:") and "RAN CODE" not in text and "CHANGED" not in text


# ---- item 1: payloads from the store ---------------------------------------------------------------------


def _sql(db: Path, statement: str, *params: Any) -> None:
    conn = sqlite3.connect(db)
    conn.execute(statement, params)
    conn.commit()
    conn.close()


def planted_checkpoint(db: Path, work: Path) -> str:
    marker = work / "ran-train"
    conn = sqlite3.connect(db)
    run = conn.execute("select id from training_runs order by id desc limit 1").fetchone()
    if run is None:
        return "the store has no training run: train one first"
    conn.execute("update training_runs set status='interrupted' where id=?", run)
    conn.execute(
        "insert into checkpoints (training_run_id, epoch, batch_index, elapsed_s, payload, created_at) "
        "values (?, 0, 1, 1.0, ?, '2026-01-01 00:00:00')",
        (run[0], torch_bomb(marker)),
    )
    conn.commit()
    conn.close()
    before = digest(db)
    out = cli(db, "train", "--resume", "--threads", "1", cwd=work)
    return said(out, _ran(marker) + _changed(db, before))


def planted_weights(db: Path, work: Path) -> str:
    marker = work / "ran-model"
    _sql(
        db,
        "insert into models (name, data_size, metrics, config, size_bytes, weights, created_at) "
        "values ('planted', 0, '{}', '{}', 1, ?, '2026-01-01 00:00:00')",
        torch_bomb(marker),
    )
    before = digest(db)
    out = cli(db, "plan", "--goal", ONE, "--workers", "1", "--timeout", "60", cwd=work)
    return said(out, _ran(marker) + _changed(db, before))


def _sac_run(db: Path) -> int:
    parameters = {
        "total_steps": 40,
        "max_curves": 3,
        "learning_starts": 10,
        "batch_size": 8,
        "net_arch": [16, 16],
    }
    conn = sqlite3.connect(db)
    cur = conn.execute(
        "insert into rl_runs (status, seed, parameters, total_steps, steps_done, episodes, elapsed_s, "
        "metrics, started_at, updated_at) "
        "values ('interrupted', 0, ?, 40, 20, 2, 1.0, '{}', '2026-01-01', '2026-01-01')",
        (json.dumps(parameters),),
    )
    conn.commit()
    conn.close()
    return int(cur.lastrowid or 0)


def _sac_checkpoint(db: Path, run_id: int, policy: bytes, buffer: bytes | None) -> int:
    conn = sqlite3.connect(db)
    cur = conn.execute(
        "insert into rl_checkpoints (rl_run_id, steps, episodes, elapsed_s, final, policy, replay_buffer, "
        "size_bytes, created_at) values (?, 20, 2, 1.0, 0, ?, ?, 1, '2026-01-01')",
        (run_id, policy, buffer),
    )
    conn.commit()
    conn.close()
    return int(cur.lastrowid or 0)


def planted_sac_policy_plan(db: Path, work: Path) -> str:
    marker = work / "ran-sac"
    run_id = _sac_run(db)
    policy_id = _sac_checkpoint(db, run_id, torch_bomb(marker), None)
    before = digest(db)
    out = cli(
        db, "plan", "--goal", ONE, "--planner", "sac", "--model", str(policy_id), "--workers", "1", cwd=work
    )
    return said(out, _ran(marker) + _changed(db, before))


def planted_sac_policy_resume(db: Path, work: Path) -> str:
    marker = work / "ran-sac-resume"
    run_id = _sac_run(db)
    _sac_checkpoint(db, run_id, pickle.dumps(Planted(marker)), None)
    before = digest(db)
    out = cli(db, "rl", "train", "--resume", str(run_id), cwd=work)
    return said(out, _ran(marker) + _changed(db, before))


def _ran(marker: Path) -> str:
    return ", RAN CODE (the marker file was created)" if marker.exists() else ""


def _changed(db: Path, before: str) -> str:
    return "" if digest(db) == before else ", store CHANGED"


# ---- item 2: no command writes over the database, its -wal/-shm, or an existing file ----------------------


def export_onto(target: str) -> Callable[[Path, Path], str]:
    def trial(db: Path, work: Path) -> str:
        local = work / "twisted.db"
        shutil.move(db, local)
        (work / "link.db").symlink_to("twisted.db")
        (work / "twisted.db-wal").write_bytes(b"")
        (work / "existing.pt").write_bytes(b"keep me")
        before = hashlib.sha256(local.read_bytes()).hexdigest()
        watched = work / target
        kept = watched.read_bytes() if watched.is_file() else None
        args = [*target.split(), "models"] if target.startswith("--") else ["models", "--export", target]
        out = cli(Path("twisted.db"), *args, cwd=work)
        changed = hashlib.sha256(local.read_bytes()).hexdigest() != before
        overwritten = kept is not None and watched.is_file() and watched.read_bytes() != kept
        return said(
            out,
            (", the database file CHANGED" if changed else "") + (", file CHANGED" if overwritten else ""),
        )

    return trial


# ---- item 4: imported models are checked; a run that dies is marked failed --------------------------------


def _broken_model(work: Path, kind: str) -> Path:
    import torch

    from twisted.model.registry import load_default_model

    model = load_default_model()
    with torch.no_grad():
        for p in model.net.parameters():
            p.fill_(1e30 if kind == "huge" else float("nan"))
    path = work / f"{kind}.pt"
    path.write_bytes(model.to_bytes())
    return path


def import_broken(kind: str) -> Callable[[Path, Path], str]:
    def trial(db: Path, work: Path) -> str:
        path = _broken_model(work, kind)
        before = digest(db)
        out = cli(db, "models", "--import", str(path), cwd=work)
        return said(out, _changed(db, before))

    return trial


def plan_with_huge_model(db: Path, work: Path) -> str:
    path = _broken_model(work, "huge")
    _sql(
        db,
        "insert into models (name, data_size, metrics, config, size_bytes, weights, created_at) "
        "values ('huge', 0, '{}', '{}', 1, ?, '2026-01-01 00:00:00')",
        path.read_bytes(),
    )
    out = cli(db, "plan", "--goal", ONE, "--workers", "1", "--timeout", "60", cwd=work)
    conn = sqlite3.connect(db)
    left = conn.execute("select count(*) from runs where kind='plan' and status='running'").fetchone()[0]
    conn.close()
    return said(out, f", {left} plan run(s) left 'running'" if left else "")


# ---- item 7: output paths ----------------------------------------------------------------------------------


def report_onto(target: str) -> Callable[[Path, Path], str]:
    def trial(db: Path, work: Path) -> str:
        (work / "afile").write_text("keep me")
        return said(cli(db, "report", "--out", target, cwd=work))

    return trial


def render_into_missing(db: Path, work: Path) -> str:
    out = cli(db, "render", "--goal", ONE, "--out", "new/deeper/goal.png", "--no-gl", cwd=work)
    made = (work / "new").exists()
    return said(out, ", folders CREATED" if made else "")


def export_into_missing(db: Path, work: Path) -> str:
    return said(cli(db, "models", "--export", "missing/dir/m.pt", cwd=work))


# ---- item 10: labels and set names -------------------------------------------------------------------------


def import_set(name: str) -> Callable[[Path, Path], str]:
    def trial(db: Path, work: Path) -> str:
        goals = work / "goals.json"
        goals.write_text(json.dumps({"x": [json.loads(ONE)]}))
        before = digest(db)
        out = cli(db, "problems", "import", str(goals), "--name", name, cwd=work)
        return said(out, _changed(db, before) if out.code == 2 else "")

    return trial


def eval_label(label: str) -> Callable[[Path, Path], str]:
    def trial(db: Path, work: Path) -> str:
        goals = work / "goals.json"
        goals.write_text(json.dumps([json.loads(ONE)]))
        cli(db, "problems", "import", str(goals), "--name", "probe-set", cwd=work)
        before = digest(db)
        out = cli(db, "eval", "--set", "probe-set", "--label", label, "--timeout", "1", cwd=work)
        return said(out, _changed(db, before) if out.code == 2 else "")

    return trial


def pictures_of_similar_names(db: Path, work: Path) -> str:
    """Sets ``a/b`` and ``a_b`` (where the names are accepted) must not share a picture file."""
    goals = work / "goals.json"
    goals.write_text(json.dumps({"x": [json.loads(ONE)]}))
    names = []
    for name in ("a/b", "a_b"):
        out = cli(db, "problems", "import", str(goals), "--name", name, cwd=work)
        names.append(f"{name}: exit {out.code}")
    return "; ".join(names)


def plan_run_that_dies(db: Path, work: Path) -> str:
    """A search that dies of an exception (its stored states of the wrong length) is marked failed."""
    args = ["plan", "--goal", ONE, "--planner", "random-low", "--max-iterations", "1", "--workers", "1"]
    first = cli(db, *args, "--json", cwd=work)
    try:
        run_id = json.loads(first.text[first.text.index("{") :])["run_id"]
    except ValueError:
        return f"could not start a run: {said(first)}"
    _sql(db, "update search_nodes set q = ? where run_id = ?", bytes(40), run_id)
    out = cli(db, "plan", "--resume", str(run_id), "--workers", "1", cwd=work)
    conn = sqlite3.connect(db)
    status = conn.execute("select status from runs where id = ?", (run_id,)).fetchone()[0]
    conn.close()
    return f"run {status}; " + said(out)


def cosmetic(args: list[str], setup: str | None = None) -> Callable[[Path, Path], str]:
    def trial(db: Path, work: Path) -> str:
        if setup is not None:
            (work / "goals.json").write_text(setup)
        return said(cli(db, *args, cwd=work))

    return trial


TRIALS: list[Trial] = [
    Trial("1", "train --resume, planted checkpoint", "exit 2, no code", planted_checkpoint, exit2_clean),
    Trial("1", "plan, planted model weights", "exit 2, no code", planted_weights, exit2_clean),
    Trial("1", "plan --planner sac, planted policy", "exit 2, no code", planted_sac_policy_plan, exit2_clean),
    Trial(
        "1", "rl train --resume, pickled policy", "exit 2, no code", planted_sac_policy_resume, exit2_clean
    ),
    Trial(
        "2",
        "models --export twisted.db (the open db)",
        "exit 2, db intact",
        export_onto("twisted.db"),
        exit2_clean,
    ),
    Trial(
        "2",
        "models --export link.db (symlink to it)",
        "exit 2, db intact",
        export_onto("link.db"),
        exit2_clean,
    ),
    Trial("2", "models --export twisted.db-wal", "exit 2", export_onto("twisted.db-wal"), exit2_clean),
    Trial(
        "2",
        "models --export existing.pt (no --force)",
        "exit 2, file kept",
        export_onto("existing.pt"),
        lambda t: t.startswith("exit 2:") and "CHANGED" not in t,
    ),
    Trial(
        "2", "--log-file twisted.db", "exit 2, db intact", export_onto("--log-file twisted.db"), exit2_clean
    ),
    Trial("4", "models --import weights 1e30", "exit 2, nothing stored", import_broken("huge"), exit2_clean),
    Trial("4", "models --import NaN weights", "exit 2, nothing stored", import_broken("nan"), exit2_clean),
    Trial(
        "4",
        "plan with a 1e30 model in the store",
        "exit 2, no run left running",
        plan_with_huge_model,
        lambda t: t.startswith("exit 2:") and "running" not in t.split(":")[0],
    ),
    Trial(
        "4",
        "plan --resume, a search that dies",
        "run marked failed",
        plan_run_that_dies,
        lambda t: t.startswith("run failed"),
    ),
    Trial("7", "report --out onto an existing file", "exit 2", report_onto("afile"), exit2_clean),
    Trial("7", "report --out /proc/x", "exit 2", report_onto("/proc/x"), exit2_clean),
    Trial("7", "models --export into a missing folder", "exit 2", export_into_missing, exit2_clean),
    Trial(
        "7",
        "render --out into missing folders",
        "exit 2, nothing created",
        render_into_missing,
        lambda t: t.startswith("exit 2:") and "CREATED" not in t,
    ),
    Trial("10", "problems import --name 'a\\x1b[31mb'", "exit 2", import_set("a\x1b[31mb"), exit2_clean),
    Trial("10", "problems import --name 'a\\nb'", "exit 2", import_set("a\nb"), exit2_clean),
    Trial("10", "problems import --name '  '", "exit 2", import_set("  "), exit2_clean),
    Trial("10", "eval --label 'x\\x07y'", "exit 2", eval_label("x\x07y"), exit2_clean),
    Trial(
        "14",
        "train --lr nan",
        "exit 2, 'not a finite number'",
        cosmetic(["train", "--lr", "nan"]),
        lambda t: t.startswith("exit 2:") and "not a finite number" in t,
    ),
    Trial(
        "14",
        "problems import {}",
        "exit 2",
        cosmetic(["problems", "import", "goals.json"], "{}"),
        exit2_clean,
    ),
    Trial(
        "14",
        "problems import --name t- (object)",
        "set t-one",
        cosmetic(
            ["problems", "import", "goals.json", "--name", "t-"], json.dumps({"one": [json.loads(ONE)]})
        ),
        lambda t: "t-one" in t and "t--one" not in t,
    ),
    Trial("10", "sets a/b and a_b", "distinct pictures (or one refused)", pictures_of_similar_names, None),
]


# ---- issue 62 items 5, 6, 10, 11: runs and checkpoints read back from the store -------------------------

_RUNS_STORES: dict[Path, Path] = {}  # the store given -> a copy of it with the three runs below (made once)


def _runs_store(db: Path, work: Path) -> tuple[int, int, int]:
    """Give ``db`` (a copy of the probed store) a solved plan run, a plan run stopped before its first
    iteration and an untie of the first stopped the same way (random curves, no model); their ids."""
    prepared = _RUNS_STORES.get(work.parent)
    if prepared is None:
        prepared = work.parent / "runs-store.db"
        shutil.copyfile(db, prepared)
        plan = ["plan", "--goal", ONE, "--planner", "random-low", "--workers", "1", "--seed", "0"]
        cli(prepared, *plan, "--max-iterations", "40", cwd=work.parent)
        solved = str(_newest_run(prepared))
        cli(prepared, *plan, "--max-iterations", "0", cwd=work.parent)
        untie = ["untie", solved, "--planner", "random-low", "--workers", "1", "--max-iterations", "0"]
        cli(prepared, *untie, cwd=work.parent)
        _RUNS_STORES[work.parent] = prepared
    shutil.copyfile(prepared, db)
    newest = _newest_run(db)
    return newest - 2, newest - 1, newest


def _newest_run(db: Path) -> int:
    conn = sqlite3.connect(db)
    row = conn.execute("select max(run_id) from search_runs").fetchone()
    conn.close()
    return int(row[0] or 0)


def _run_states(db: Path) -> dict[int, str]:
    """Each planner run's ``runs.status`` / ``search_runs.outcome``."""
    conn = sqlite3.connect(db)
    rows = conn.execute(
        "select r.id, r.status || '/' || s.outcome from runs r join search_runs s on s.run_id = r.id"
    ).fetchall()
    conn.close()
    return dict(rows)


def stored_run_value(plant: str, command: str) -> Callable[[Path, Path], str]:
    """Plant a hostile value (``plant``: SQL with {solved}, {stopped}, {untie} for the run ids) and run
    ``command`` (the same placeholders); report the exit, a traceback, and whether a run changed state or
    the store changed."""

    def trial(db: Path, work: Path) -> str:
        solved, stopped, untie = _runs_store(db, work)
        ids = {"solved": solved, "stopped": stopped, "untie": untie}
        conn = sqlite3.connect(db)
        conn.execute(plant.format(**ids), ("[" * 200_000 + "]" * 200_000,) if "?" in plant else ())
        conn.commit()
        conn.close()
        before, states = digest(db), _run_states(db)
        out = cli(db, *command.format(**ids).split(), cwd=work, timeout=120)
        moved = [
            f"run {i} {states.get(i, 'new')} -> {state}"
            for i, state in _run_states(db).items()
            if states.get(i) != state
        ]
        return said(out, "".join(f", {m}" for m in moved) + _changed(db, before))

    return trial


def ctrl_c_as_it_solves(db: Path, work: Path) -> str:
    """SIGINT sent as `plan` prints its solved result (what ended in exit 130 / -2 with no word)."""
    import signal
    import time

    command = [sys.executable, "-m", "cli.main", "--db", f"sqlite:///{db}", "plan", "--goal", ONE]
    command += ["--planner", "random-low", "--workers", "1", "--seed", "0", "--max-iterations", "40"]
    child = subprocess.Popen(command, cwd=work, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert child.stdout is not None
    for line in child.stdout:
        if "solved" in line:
            break
    time.sleep(0.3)
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=120)
    solved = _run_states(db)[_newest_run(db)] == "finished/solved"
    return f"exit {child.returncode}, run stored solved: {bool(solved)}: {' '.join(err.split())[:150]}"


RESUME = "plan --resume {stopped} --workers 1 --max-iterations 2"
UNTIE = "untie {solved} --workers 1 --timeout 60"
PARAMETER = "update runs set parameters = json_set(parameters, '$.{name}', {value}) where id = {{stopped}}"
CHECKPOINT = "update search_checkpoints set {column} = {value} where run_id = {{stopped}}"
END_Q = (
    "update search_nodes set q = X'{blob}' "
    "where id = (select goal_node_id from search_runs where run_id = {{solved}})"
)
MT19937 = {"bit_generator": "MT19937", "state": {"key": [0] * 624, "pos": 624}}
MT19937_TEXT = json.dumps(MT19937).replace("{", "{{").replace("}", "}}")  # read by str.format once more


def _q(*values: float) -> str:
    return struct.pack(f"<{len(values)}d", *values).hex()


RUN_TRIALS = [
    *(
        Trial("62.5", f"plan --resume, {name} = {value}", "exit 2, run unchanged",
              stored_run_value(PARAMETER.format(name=name, value=value), RESUME), exit2_clean)
        for name, value in (("k", "-1"), ("seed", "-5"), ("heuristic", "'x'"), ("p_expand", "'x'"),
                            ("removal_curves", "'evil'"))
    ),
    *(
        Trial("62.5", f"plan --resume, {name}", "exit 2, run unchanged", stored_run_value(plant, RESUME),
              exit2_clean)
        for name, plant in (
            ("rng_state MT19937", CHECKPOINT.format(column="rng_state", value=f"'{MT19937_TEXT}'")),
            ("iteration -5", CHECKPOINT.format(column="iteration", value="-5")),
            ("stats 'garbage'", CHECKPOINT.format(column="stats", value="'garbage'")),
            ("parameters a string", "update runs set parameters = '\"abc\"' where id = {stopped}"),
            ("parameters a list", "update runs set parameters = '[1, 2]' where id = {stopped}"),
        )
    ),
    *(
        Trial("62.5", f"{command.split()[0]}, parameters {what}", "exit 2, run unchanged",
              stored_run_value(plant, command), exit2_clean)
        for what, plant in (
            ("'not json'", "update runs set parameters = 'not json' where id = {solved}"),
            ("200k levels deep", "update runs set parameters = ? where id = {solved}"),
        )
        for command in (
            UNTIE,
            "replay {solved}",
            "render --run {solved} --out r.png --no-gl",
        )
    ),
    *(
        Trial("62.6", f"untie, end q {name}", "exit 2, no run created",
              stored_run_value(END_Q.format(blob=blob), UNTIE), exit2_clean)
        for name, blob in (
            ("of 5 floats", _q(*[0.0] * 5)),
            ("all NaN", _q(*[math.nan] * 93)),
            ("all 1e300", _q(*[1e300] * 93)),
            ("all zeros", _q(*[0.0] * 93)),
        )
    ),
    Trial("62.10", "untie --resume of a plan run", "exit 2, run unchanged",
          stored_run_value("select 1", "untie {stopped} --resume --workers 1"), exit2_clean),
    Trial("62.11", "Ctrl-C as plan prints its solved run", "exit 0, run solved", ctrl_c_as_it_solves,
          lambda t: t.startswith("exit 0, run stored solved: True")),
]
TRIALS += RUN_TRIALS


def _store_trials() -> list[Trial]:
    """The trials of issue 37's items 3, 5, 6, 8, 9 and 11 (``bench/probe_store.py``, the other half of
    the issue) and of issue 62's items 1, 4, 7, 8 and 9 (``bench/probe_payloads.py``: run under a memory
    limit, with each command's peak memory)."""
    import importlib

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    trials = []
    try:
        for name in ("probe_store", "probe_payloads"):
            try:
                trials += [Trial(*trial) for trial in importlib.import_module(name).TRIALS]
            except ImportError:
                continue
    finally:
        sys.path.pop(0)
    return trials


TRIALS += _store_trials()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--db", type=Path, required=True, help="a SQLite store to copy for each trial")
    parser.add_argument("--only", default="", help="comma-separated item numbers (default: all)")
    parser.add_argument("--work", type=Path, default=None, help="folder for the copies (default: temporary)")
    args = parser.parse_args()
    if not args.db.is_file():
        parser.error(f"--db {args.db}: no such file")
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    root = Path(tempfile.mkdtemp(prefix="probe-")) if args.work is None else args.work
    rows = []
    for i, trial in enumerate(t for t in TRIALS if not only or t.item in only):
        work = root / f"trial-{i:02d}"
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir(parents=True)
        db = work / "store.db"
        shutil.copyfile(args.db, db)
        try:
            got = trial.run(db, work)
        except subprocess.TimeoutExpired:
            got = "TIMED OUT"
        verdict = "" if trial.ok is None else ("ok" if trial.ok(got) else "NOT OK")
        rows.append((trial.item, trial.name, trial.expected, got, verdict))
        print(
            f"{trial.item:>3} | {trial.name:44s} | {trial.expected:30s} | {verdict:6s} | {got[:150]}",
            flush=True,
        )
    failed = sum(1 for *_, v in rows if v == "NOT OK")
    print(f"\n{len(rows)} trials, {failed} not as expected (work folder {root})")


if __name__ == "__main__":
    main()
