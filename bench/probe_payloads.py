"""The trials of issue 62 items 1, 4, 7, 8 and 9 (payloads, names, URLs, goal files), for ``bench/probe.py``.

Each trial runs the CLI in a child process under a memory limit (``RLIMIT_AS``, 2 GiB by default,
``PROBE_MEMORY_GB`` to change it) and a timeout, and reports its exit code, its peak memory (the
child's maximum resident set, from ``wait4``), whether it printed a traceback or a raw terminal escape,
and whether the store changed. :data:`TRIALS` lists ``(item, name, expected, run, ok)`` as
``bench/probe_store.py`` does; ``bench/probe.py`` runs them with the others, or alone:

    python bench/probe.py --db PATH/TO/twisted.db --only 62.1,62.4,62.7,62.8,62.9

Run it with an older checkout on ``PYTHONPATH`` to see the "before".
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import resource
import shutil
import sqlite3
import subprocess
import sys
import threading
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path

ONE = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
LIMIT_BYTES = int(float(os.environ.get("PROBE_MEMORY_GB", "2")) * (1 << 30))
ESCAPES = ("\x1b", "\x07")


def run_limited(db: Path | None, *args: str, cwd: Path, env: dict[str, str] | None = None) -> str:
    """The CLI under the memory limit and a 300 s timeout, in words: "exit N, peak M MB[, TRACEBACK]
    [, RAW ESCAPE]: output"."""

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (LIMIT_BYTES, LIMIT_BYTES))

    command = [sys.executable, "-m", "cli.main", *(["--db", f"sqlite:///{db}"] if db else []), *args]
    proc = subprocess.Popen(
        command,
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        env={**os.environ, "COLUMNS": "1000", **(env or {})},
        preexec_fn=limit,
    )
    timer = threading.Timer(300, proc.kill)
    timer.start()
    assert proc.stdout is not None
    raw = proc.stdout.read().decode(errors="replace")
    _, status, usage = os.wait4(proc.pid, 0)
    timer.cancel()
    code = proc.returncode = os.waitstatus_to_exitcode(status)
    text = " ".join(raw.split())
    marks = ", TRACEBACK" if "Traceback (most recent call last)" in raw else ""
    marks += ", RAW ESCAPE" if any(e in raw for e in ESCAPES) else ""
    peak = usage.ru_maxrss / 1024
    shown = text[-170:] if "TRACEBACK" in marks else text[:170]
    shown = shown.replace("\x1b", "<ESC>").replace("\x07", "<BEL>")
    return f"exit {code}, peak {peak:.0f} MB{marks}: {shown}"


def _digest(db: Path) -> str:
    return hashlib.sha256(db.read_bytes()).hexdigest()


def _unchanged(db: Path, before: str, out: str) -> str:
    """``out`` of :func:`run_limited` with ", store CHANGED" after its exit code when the store changed."""
    head, _, tail = out.partition(": ")
    return out if _digest(db) == before else f"{head}, store CHANGED: {tail}"


def _sql(db: Path, statement: str, *params: object) -> None:
    conn = sqlite3.connect(db)
    conn.execute(statement, params)
    conn.commit()
    conn.close()


def exit2(text: str) -> bool:
    return text.startswith("exit 2,") and not any(w in text for w in ("CHANGED", "TRACEBACK", "RAW ESCAPE"))


def exit2_bounded(text: str) -> bool:
    """Refused by a check, not by running into the memory limit (bad_alloc / MemoryError)."""
    return exit2(text) and not any(w in text for w in ("bad_alloc", "MemoryError", "out of memory"))


def exit0_escaped(text: str) -> bool:
    return text.startswith("exit 0,") and "RAW ESCAPE" not in text and "TRACEBACK" not in text


# ---- items 1 and 9: compressed and oversized tensor payloads -----------------------------------------------


def _torch_bytes(obj: object) -> bytes:
    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def deflated(payload: bytes) -> bytes:
    """A torch zip with every member deflated (torch.save stores them as they are)."""
    src = zipfile.ZipFile(io.BytesIO(payload))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as archive:
        for info in src.infolist():
            archive.writestr(info.filename, src.read(info.filename))
    return out.getvalue()


def _sac_run_with_buffer(db: Path, buffer: bytes) -> int:
    """A SAC run (interrupted, small settings) whose checkpoint has a real policy and ``buffer``."""
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    from twisted.rl import SacConfig
    from twisted.rl.sac import _new_model, _policy_bytes, make_env

    config = SacConfig(total_steps=40, max_curves=3, learning_starts=10, batch_size=8, net_arch=(16, 16))
    env = make_env(config)
    policy = _policy_bytes(_new_model(config, DummyVecEnv([lambda: Monitor(env)])))
    conn = sqlite3.connect(db)
    cur = conn.execute(
        "insert into rl_runs (status, seed, parameters, total_steps, steps_done, episodes, elapsed_s, "
        "metrics, started_at, updated_at) values ('interrupted', 0, ?, 40, 20, 2, 1.0, '{}', "
        "'2026-01-01', '2026-01-01')",
        (json.dumps(config.to_dict()),),
    )
    run_id = int(cur.lastrowid or 0)
    conn.execute(
        "insert into rl_checkpoints (rl_run_id, steps, episodes, elapsed_s, final, policy, replay_buffer, "
        "size_bytes, created_at) values (?, 20, 2, 1.0, 0, ?, ?, 1, '2026-01-01')",
        (run_id, policy, buffer),
    )
    conn.commit()
    conn.close()
    return run_id


def replay_buffer(kind: str) -> Callable[[Path, Path], str]:
    """Item 1: ``rl train --resume`` of a run whose replay buffer holds 300M elements where a dict goes,
    deflated inside the zlib (``bomb``, the issue's 1.4 KB row) or a zero-stride view of one byte
    (``view``)."""

    def run(db: Path, work: Path) -> str:
        import torch

        n = 300_000_000
        if kind == "bomb":
            observations = torch.zeros(n, dtype=torch.uint8)
        else:
            observations = torch.zeros(1, dtype=torch.uint8).expand(n)
        arrays = {"observations": observations}
        state = {"format": "twisted-sac-buffer/1", "pos": 0, "full": False, "arrays": arrays}
        payload = _torch_bytes(state)
        buffer = zlib.compress(deflated(payload) if kind == "bomb" else payload, 9)
        del observations, arrays, state, payload
        run_id = _sac_run_with_buffer(db, buffer)
        before = _digest(db)
        out = run_limited(db, "rl", "train", "--resume", str(run_id), "--threads", "1", cwd=work)
        return _unchanged(db, before, out.replace(": ", f" [row {len(buffer):,} bytes]: ", 1))

    return run


def _deflated_model_bytes() -> bytes:
    """Item 9's row: the shipped model's config with a 200M-byte tensor, deflated (~195 KB)."""
    import torch

    from twisted.model.registry import load_default_model

    model = load_default_model()
    blob = {
        "format_version": 1,
        "config": model.net.config.to_dict(),
        "state_dict": {"pad": torch.zeros(200_000_000, dtype=torch.uint8)},
        "metadata": {},
    }
    return deflated(_torch_bytes(blob))


def model_bomb(command: str) -> Callable[[Path, Path], str]:
    def run(db: Path, work: Path) -> str:
        weights = _deflated_model_bytes()
        if command == "plan":
            _sql(
                db,
                "insert into models (name, data_size, metrics, config, size_bytes, weights, created_at) "
                "values ('bomb', 0, '{}', '{}', ?, ?, '2026-01-01 00:00:00')",
                len(weights),
                weights,
            )
            args = ["plan", "--goal", ONE, "--workers", "1", "--timeout", "60"]
        else:
            (work / "bomb.pt").write_bytes(weights)
            args = ["models", "--import", "bomb.pt"]
        before = _digest(db)
        out = run_limited(db, *args, cwd=work)
        return _unchanged(db, before, out.replace(": ", f" [row {len(weights):,} bytes]: ", 1))

    return run


# ---- item 7: names from file names and from the store ------------------------------------------------------


def import_escaped_file_name(db: Path, work: Path) -> str:
    from twisted.model.registry import default_model_path

    name = "\x1b[41mEVIL\x1b[0m.pt"
    shutil.copyfile(default_model_path(), work / name)
    before = _digest(db)
    return _unchanged(db, before, run_limited(db, "models", "--import", name, cwd=work))


HOSTILE = "x\x1b[2J\x1b]52;c;ZXZpbA==\x07y"


def listed_escaped(*command: str) -> Callable[[Path, Path], str]:
    def run(db: Path, work: Path) -> str:
        (work / "one.json").write_text(json.dumps([json.loads(ONE)]))
        run_limited(db, "problems", "import", "one.json", "--name", "probe-escapes", cwd=work)
        _sql(db, "update problem_sets set name = ? where name = 'probe-escapes'", HOSTILE)
        _sql(db, "update models set name = ? where id = (select max(id) from models)", HOSTILE)
        return run_limited(db, *command, cwd=work)

    return run


# ---- item 8: a read-only URL -------------------------------------------------------------------------------


def readonly_url(db: Path, work: Path) -> str:
    (work / "sub").mkdir()
    (work / "one.json").write_text(json.dumps([json.loads(ONE)]))
    before = _digest(db)
    env = {"TWISTED_DB": f"sqlite:///../{db.name}?mode=ro"}
    out = run_limited(None, "problems", "import", "../one.json", "--name", "zz2", cwd=work / "sub", env=env)
    return _unchanged(db, before, out)


# ---- item 4: improve's evaluation-set guard ----------------------------------------------------------------


def improve_guard(goalsets: str | None) -> Callable[[Path, Path], str]:
    """``improve --train-set mytrain`` (goal 0 of the committed final-u4.json) from a folder without
    goalsets/; ``goalsets``: a --goalsets folder (``BAD-UTF8``, ``DIR-NAMED-JSON``: made here)."""

    def run(db: Path, work: Path) -> str:
        from twisted.experiments.problems import parse_goal_file

        repo = Path(__file__).resolve().parents[1]
        final = parse_goal_file((repo / "goalsets" / "final-u4.json").read_text())
        (work / "mytrain.json").write_text(json.dumps([next(iter(final.values()))[0].spec]))
        (work / "mytune.json").write_text(json.dumps([json.loads(ONE)]))
        for name in ("mytrain", "mytune"):
            run_limited(db, "problems", "import", f"{name}.json", "--name", name, cwd=work)
        extra: list[str] = []
        if goalsets == "BAD-UTF8":
            (work / "sets").mkdir()
            (work / "sets" / "final-bad.json").write_bytes(b"\xff\xfe{")
            extra = ["--goalsets", "sets"]
        elif goalsets == "DIR-NAMED-JSON":
            (work / "sets" / "final-x.json").mkdir(parents=True)
            extra = ["--goalsets", "sets"]
        elif goalsets is not None:
            extra = ["--goalsets", goalsets]
        before = _digest(db)
        args = ["improve", "--tune-set", "mytune", "--train-set", "mytrain", "--goals", "1"]
        args += ["--generations", "1", "--hours", "0.01", *extra]
        return _unchanged(db, before, run_limited(db, *args, cwd=work))

    return run


TRIALS: list[tuple[str, str, str, Callable[[Path, Path], str], Callable[[str], bool]]] = [
    ("62.1", "rl train --resume, 300M deflated", "exit 2, bounded", replay_buffer("bomb"), exit2_bounded),
    ("62.1", "rl train --resume, 1 byte as 300M", "exit 2, bounded", replay_buffer("view"), exit2_bounded),
    ("62.9", "plan, deflated model weights", "exit 2, bounded", model_bomb("plan"), exit2_bounded),
    ("62.9", "models --import, deflated weights", "exit 2, bounded", model_bomb("import"), exit2_bounded),
    ("62.7", "models --import ESC[41mEVIL.pt (no --name)", "exit 2", import_escaped_file_name, exit2),
    ("62.7", "models, a stored name with escapes", "exit 0 escaped", listed_escaped("models"), exit0_escaped),
    (
        "62.7",
        "problems list, a stored name with escapes",
        "exit 0, escaped",
        listed_escaped("problems", "list"),
        exit0_escaped,
    ),
    ("62.8", "TWISTED_DB=...?mode=ro problems import", "exit 2, store intact", readonly_url, exit2),
    ("62.4", "improve, final goal, no goalsets/ in cwd", "exit 2", improve_guard(None), exit2),
    ("62.4", "improve --goalsets /nonexistent/dir", "exit 2", improve_guard("/nonexistent/dir"), exit2),
    ("62.4", "improve, final-*.json not UTF-8", "exit 2 naming it", improve_guard("BAD-UTF8"), exit2),
    ("62.4", "improve, a folder named final-x.json", "exit 2, named", improve_guard("DIR-NAMED-JSON"), exit2),
]
