"""Every value the code reads back from its own store, made hostile (issue 62, the general fix).

The cases come from the schema: every column of every table in ``twisted.store``'s metadata is either
read by one of the commands below (:data:`READS`, per command, as SQLite's authorizer saw them read on
the template store) or named in :data:`NOT_FUZZED` with the reason; a new column in neither fails
:func:`test_every_column_has_cases_or_a_reason`. For each column read, hostile values of its kind
(:data:`HOSTILE`: wrong type, empty, huge, nested deep, NaN/inf, control characters) are planted into
every row of a copy of a small real store (one short ``plan`` that solves, one that stops, a goal set,
the shipped model and a short SAC run, made once per module), and the commands that read the column run
in this process (Typer's runner). Each must end in exit 0, 2 or 3 with no traceback and no raw
terminal escape; a refusal (exit 2), and any run of a command that only reads, must leave the store
file byte-identical (sha256). The compression bombs (``models.weights``, ``rl_checkpoints.policy`` and
``.replay_buffer``) run in a child process under a 3 GiB address-space limit and must exit 2 within it.

To keep the run short, a scalar column (integer, float, text, time, flag) is read by its cheapest
reader only, with two values; JSON and blob columns by every reader, with every value of their kind,
except that the slow readers (:data:`SLOW`) get of the JSON values the parser refuses only "deep"; the
browse pages are fetched for the kinds the plugin's cells read (:data:`PLUGIN_KINDS`, and floats of a
column of seconds). Count and time (``pytest -q tests/test_fuzz_store.py``, 2026-12-06): 285 columns in
26 tables (the episodes' tables named in :data:`NOT_FUZZED`), 130 of them read by these commands; 286
(table, column, value, command) cases in process and 5 named refusals, 157 browse page fetches (297
column cases) and 3 bombs in child processes: 475 passed, no expected failures, in 2 min 20 s of wall
time on the 2-core development machine (1 min 32 s user + 45 s system CPU, the template store's set-up
included).
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import os
import resource
import shutil
import sqlite3
import subprocess
import sys
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from cli.main import app
from twisted.store import Base

runner = CliRunner()
ONE = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
MEMORY_LIMIT = 3 << 30

# ---- who reads what -----------------------------------------------------------------------------------

# The command lines (run 1: a solved plan; run 2: a stopped one; SAC run 1: interrupted), cheapest first.
COMMANDS: dict[str, list[str]] = {
    "models": ["models"],
    "problems list": ["problems", "list"],
    "replay": ["replay", "1"],
    "render --run": ["render", "--run", "1", "--out", "{tmp}/run.png", "--no-gl"],
    "rl train --resume": ["rl", "train", "--resume", "1", "--minutes", "0.001", "--threads", "1"],
    "plan --resume": ["plan", "--resume", "2", "--max-iterations", "1", "--workers", "1"],
    "untie": ["untie", "1", "--max-iterations", "1", "--workers", "1"],
    "plan": ["plan", "--goal", ONE, "--max-iterations", "1", "--workers", "1"],  # the newest model
}
WRITERS = {"rl train --resume", "plan --resume", "untie", "plan"}  # may write when they accept what they read

_ROPE = "rope_profile: id link_spacing_m n_links max_crossings"
_RUNS = (
    "runs: id kind parameters seed tried kept rejected wall_seconds sim_seconds host pid started_at ended_at "
    "message status"
)
_TREE = (
    "search_runs: run_id goal_state_id goal_cross goal_knot planner heuristic start_configuration_id outcome "
    "goal_node_id; search_nodes: id run_id seq parent_id state_id cross q points link z_max_m x_m y_m action "
    "iteration sim_call created_s; search_checkpoints: run_id iteration elapsed_s sim_calls nodes rng_state "
    "stats updated_at; topological_states: id key"
)
_MODELS = "models: id training_run_id name data_size metrics size_bytes created_at"
_MODEL = f"{_MODELS} config weights"
_PLANS = (
    "plan_queries: id start_key goal_key start_cross goal_cross plan_limit n_plans complete moves_version "
    "compute_s created_at"
)
# What each command reads (SQLite's authorizer on the template store; rows loaded whole count as read).
READS: dict[str, str] = {
    "models": f"{_ROPE}; {_MODELS}; improve_generations: id lineage generation parent_model_id model_id",
    "problems list": (
        f"{_ROPE}; problem_sets: id name source seed parameters created_at; problems: id set_id cross "
        "frequency; eval_results: id set_id"
    ),
    "replay": f"{_ROPE}; {_RUNS}; {_TREE}",
    "render --run": f"{_ROPE}; {_RUNS}; {_TREE}",
    "rl train --resume": (
        f"{_ROPE}; rl_runs: id seed parameters total_steps steps_done episodes elapsed_s metrics updated_at "
        "started_at ended_at message status; rl_checkpoints: id rl_run_id steps episodes elapsed_s final "
        "policy replay_buffer size_bytes created_at; rl_success: rl_run_id steps"
    ),
    "plan --resume": (
        f"{_ROPE}; {_RUNS}; {_TREE}; {_MODEL}; {_PLANS}; "
        "plans: id query_id start_key goal_key plan_index length states moves created_at"
    ),
    "untie": (
        f"{_ROPE}; {_RUNS}; {_TREE}; {_MODEL}; {_PLANS}; configurations: id; "
        "topological_states: p_data cross knot_type closure_under closure_over"
    ),
}

_OTHER = "read only by {}, which this module does not run (a gap: see docs/security.md)"
# Columns no command above reads, with the reason.
NOT_FUZZED: dict[str, str] = {
    "checkpoints": _OTHER.format("`train --resume`"),
    "training_runs": _OTHER.format("`train --resume` and `models`' lineage"),
    "collect_batches": _OTHER.format("`collect` (its own batch bookkeeping) and `stats`"),
    "collect_tries": _OTHER.format("`stats`"),
    "transitions": _OTHER.format("`train`, `collect --resume`, `discretise` and `stats`"),
    "configurations": _OTHER.format("`render --config`, `collect` and `train`") + "; `untie` reads ids",
    "discretisation_results": _OTHER.format("`discretise` (a rerun) and `report`"),
    "eval_results": _OTHER.format("`eval`, `report` and `compare`") + "; `problems list` counts ids",
    "eval_runs": _OTHER.format("`eval` (a rerun), `report` and `compare`"),
    "improve_generations": _OTHER.format("`improve` (a rerun) and `improve-status`") + "; `models` reads ids",
    "knot_state_sets": _OTHER.format("`plan --goal knot:...` (enumerated sets kept for reuse)"),
    "problems": _OTHER.format("`eval` and `improve`") + "; `problems list` reads counts only",
    "rl_success": _OTHER.format("`rl list`") + "; `rl train --resume` reads steps only",
    "rope_profile.created_at": "never read back (written for people)",
    "tightenings": _OTHER.format("`render --run --tightened` and `eval`'s tightening figures"),
    "episodes": _OTHER.format("`execute --resume`, `robustness`, `report` and browse's `episode` query"),
    "episode_steps": _OTHER.format("`execute --resume` and browse's `episode` query"),
}


def _reads() -> dict[str, list[str]]:
    """``table.column`` -> the commands reading it (in :data:`COMMANDS`' order)."""
    found: dict[str, list[str]] = {}
    for command, spec in READS.items():
        for part in spec.split(";"):
            table, _, columns = part.partition(":")
            for column in columns.split():
                found.setdefault(f"{table.strip()}.{column}", []).append(command)
    return found


def _schema() -> dict[str, str]:
    """``table.column`` -> its kind, for every column of the store's tables."""
    import twisted.store.episodes  # noqa: F401  (every area adds its tables to the metadata)
    import twisted.store.experiments  # noqa: F401
    import twisted.store.improve  # noqa: F401
    import twisted.store.knots  # noqa: F401
    import twisted.store.plans  # noqa: F401
    import twisted.store.rl  # noqa: F401
    import twisted.store.rope_profile  # noqa: F401
    import twisted.store.search_tree  # noqa: F401
    import twisted.store.training  # noqa: F401

    kinds = {"JSON": "json", "BLOB": "blob", "LARGEBINARY": "blob", "FLOAT": "float", "BOOLEAN": "bool"}
    kinds |= {"INTEGER": "int", "BIGINT": "int", "DATETIME": "time", "TEXT": "text", "VARCHAR": "text"}
    schema: dict[str, str] = {}
    for table in Base.metadata.tables.values():
        for column in table.columns:
            name = type(column.type).__name__.upper()
            kind = kinds.get(name) or kinds.get(str(column.type).split("(")[0].upper())
            assert kind, f"{table.name}.{column.name}: no hostile values for {column.type}"
            schema[f"{table.name}.{column.name}"] = kind
    return schema


SCHEMA = _schema()
READERS = _reads()

ESCAPES = "n\x1b[2J\x1b]52;c;ZXZpbA==\x07m"
# Hostile values by column kind (the first VALUES_USED of a scalar kind are used: see the docstring).
HOSTILE: dict[str, dict[str, Any]] = {
    "json": {
        "not-json": "not json {",
        "empty": "",
        "wrong-type": '"a string"',
        "deep": "[" * 100_000 + "]" * 100_000,
        "nan": '{"x": NaN, "y": -Infinity, "z": 1e999}',
        "huge": json.dumps({"x": "y" * (2 << 20)}),
    },
    "blob": {
        "empty": b"",
        "junk": b"\x00junk\xff",
        "wrong-type": "text, not bytes",
        "nan": np.full(3 * 41, np.nan).tobytes(),
        "huge": bytes(8 << 20),
    },
    "text": {"escapes": ESCAPES, "wrong-type": 7, "empty": "", "huge": "x" * (1 << 20)},
    "int": {"wrong-type": "x", "negative": -1, "huge": 2**63 - 1},
    "float": {"inf": float("inf"), "wrong-type": "x"},
    "time": {"garbage": "not a time", "wrong-type": 7},
    "bool": {"wrong-type": "x", "two": 2},
}
# how many of a kind's values a column of that kind gets (all, for JSON and blobs)
VALUES_USED = {"int": 1, "float": 2, "text": 2, "time": 1, "bool": 1}
DRAWN = {"search_nodes.points", "search_nodes.q"}


def _values(column: str) -> list[str]:
    """The names of the hostile values planted into ``column`` (SQLite keeps only integers in an
    INTEGER PRIMARY KEY: no text there)."""
    table, name = column.split(".")
    values = list(HOSTILE[SCHEMA[column]])
    primary = Base.metadata.tables[table].primary_key.columns
    if len(primary) == 1 and name in primary and SCHEMA[column] == "int":
        values.remove("wrong-type")
    return values


# The slowest readers (a search set up) get the JSON values that reach the reader's own checks, and of
# those the parser refuses only "deep": "not-json" and "empty" end on the same path (the engine's
# json_deserializer, twisted.store.cells), which the cheaper readers of each column still take.
SLOW = {"plan --resume", "untie", "rl train --resume"}
PARSE_REFUSED = ("not-json", "empty")


def _cases() -> list[tuple[str, str, str, str]]:
    cases = []
    for column, commands in sorted(READERS.items()):
        kind = SCHEMA[column]
        values = _values(column)
        if kind not in ("json", "blob"):
            values, commands = values[: VALUES_USED[kind]], commands[:1]
        elif column not in DRAWN:  # render --run reads the tree as replay does; it adds the drawing
            commands = [c for c in commands if c != "render --run"]
        for value in values:
            for command in commands:
                if not (kind == "json" and command in SLOW and value in PARSE_REFUSED):
                    cases.append((column, kind, value, command))
    return cases


CASES = _cases()


# Cases the code still mishandles, as strict xfails: (column, value, command, reason, "always"). Empty
# since 2026-12-06; a case found later goes here with its reason until it is fixed.
KNOWN: list[tuple[str, str, str, str, str]] = []


def _known(column: str, value: str, command: str) -> str | None:
    for case in KNOWN:
        if case[:3] == (column, value, command):
            return case[3]
    return None


def test_every_column_has_cases_or_a_reason() -> None:
    tables = {column.split(".")[0] for column in SCHEMA}
    unknown = [c for c in READERS if c not in SCHEMA]
    assert not unknown, f"read but not in the schema (renamed?): {unknown}"
    for column in SCHEMA:
        table = column.split(".")[0]
        skipped = NOT_FUZZED.get(column) or (NOT_FUZZED.get(table) if column not in READERS else None)
        assert (column in READERS) != bool(skipped), f"{column}: fuzz it (READS) or say why not (NOT_FUZZED)"
    assert set(k.split(".")[0] for k in NOT_FUZZED) <= tables, "NOT_FUZZED names a table that is gone"


# ---- the template store -------------------------------------------------------------------------------


def _cli(db: Path, *args: str) -> Any:
    return runner.invoke(app, ["--db", f"sqlite:///{db}", *args])


def _checkpointed(path: Path) -> None:
    with sqlite3.connect(path) as conn:
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    conn.close()
    for companion in ("-wal", "-shm"):
        Path(f"{path}{companion}").unlink(missing_ok=True)


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from twisted.model.registry import default_model_path

    folder = tmp_path_factory.mktemp("fuzz_store")
    db = folder / "twisted.db"
    plan = ["plan", "--planner", "random-low", "--workers", "1", "--seed", "0"]
    assert _cli(db, *plan, "--goal", ONE, "--max-iterations", "40").exit_code == 0  # run 1: solved
    assert _cli(db, *plan, "--goal", "knot:overhand@3", "--max-iterations", "1").exit_code == 3  # run 2
    (folder / "one.json").write_text(json.dumps([json.loads(ONE)]))
    assert _cli(db, "problems", "import", str(folder / "one.json"), "--name", "one").exit_code == 0
    assert _cli(db, "models", "--import", str(default_model_path()), "--name", "shipped").exit_code == 0
    sac = ["rl", "train", "--steps", "2000", "--learning-starts", "10", "--batch-size", "8", "--threads", "1"]
    sac += ["--checkpoint-every", "20", "--max-curves", "3", "--minutes", "0.02"]
    result = _cli(db, *sac)
    assert result.exit_code == 0 and "--resume 1" in result.output, result.output
    _checkpointed(db)
    return db


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _plant(db: Path, column: str, value: Any) -> None:
    """``value`` into ``column`` of every row, or of the first row where a unique key forbids that."""
    table, name = column.split(".")
    conn = sqlite3.connect(db)
    try:
        try:
            conn.execute(f'UPDATE {table} SET "{name}" = ?', (value,))
        except sqlite3.IntegrityError:
            first = f"(SELECT min(rowid) FROM {table})"
            conn.execute(f'UPDATE {table} SET "{name}" = ? WHERE rowid = {first}', (value,))
        conn.commit()
    finally:
        conn.close()


def _check(column: str, value: str, command: str, code: int, output: str, changed: bool) -> None:
    what = f"{column} = {value}, {command}: exit {code}"
    assert code in (0, 2, 3), f"{what}\n{output[-2000:]}"
    assert "Traceback (most recent call last)" not in output, f"{what}\n{output[-2000:]}"
    assert "\x1b[2J" not in output and "\x07" not in output, f"{what}: a raw escape\n{output[-500:]}"
    if code == 2 or command not in WRITERS:
        assert not changed, f"{what}: the store changed"


@pytest.mark.parametrize(
    "column,kind,value,command",
    [
        pytest.param(*case, marks=pytest.mark.xfail(reason=reason, strict=True))
        if (reason := _known(case[0], case[2], case[3]))
        else case
        for case in CASES
    ],
    ids=[f"{c}={v}-{m}" for c, _, v, m in CASES],
)
def test_a_hostile_stored_value_is_refused_or_harmless(
    template: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, column: str, kind: str, value: str,
    command: str,
) -> None:
    db = tmp_path / "twisted.db"
    shutil.copyfile(template, db)
    _plant(db, column, HOSTILE[kind][value])
    before = _sha(db)
    monkeypatch.chdir(tmp_path)
    args = [a.replace("{tmp}", str(tmp_path)) for a in COMMANDS[command]]
    result = _cli(db, *args)
    output = result.output
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        import traceback

        raised = "".join(traceback.format_exception(result.exception))
        output += f"Traceback (most recent call last)\n{raised}"
    _check(column, value, command, result.exit_code, output, _sha(db) != before)


NAMED = [
    ("runs.started_at", "not a time", "replay", "runs, row 1, started_at: not a time"),
    ("problem_sets.parameters", "not json {", "problems list", "problem_sets, a row, parameters: not JSON"),
    ("models.metrics", '"a string"', "models", "models, row 1, metrics: must be a JSON object"),
    ("plans.moves", '[{"kind": "R9", "segment": 0}]', "plan --resume", "moves: must be a list of moves"),
    ("plans.states", "[]", "plan --resume", "states: must be"),
]


@pytest.mark.parametrize("column,value,command,said", NAMED, ids=[n[0] for n in NAMED])
def test_a_refused_cell_is_named(
    template: Path, tmp_path: Path, column: str, value: str, command: str, said: str
) -> None:
    """A time or JSON cell SQLAlchemy cannot parse, or whose shape the reader refuses, is exit 2 naming
    the table and the column (it was a ValueError traceback, exit 1), the store unchanged."""
    db = tmp_path / "twisted.db"
    shutil.copyfile(template, db)
    _plant(db, column, value)
    before = _sha(db)
    result = _cli(db, *COMMANDS[command])
    assert result.exit_code == 2, result.output[-2000:]
    assert said in " ".join(result.output.split()), result.output[-2000:]
    assert _sha(db) == before


# ---- browse: every table's page, every column hostile -------------------------------------------------


# Datasette shows integers, times and flags as they come; the plugin's cells (twisted/browse/plugin.py)
# read JSON, blobs and text, and floats of a column of seconds: the pages of those kinds are fetched.
PLUGIN_KINDS = ("json", "blob", "text")


def _has_seconds(table: str) -> bool:
    columns = [c for c, kind in SCHEMA.items() if c.split(".")[0] == table and kind == "float"]
    return any(c.endswith(("_s", "_seconds")) for c in columns)


def _browse_cases() -> list[tuple[str, str, str]]:
    """One page fetch per (table, hostile value of each kind): the value planted into every column of
    that kind at once (Datasette and the plugin's cells read every column of the page)."""
    cases = []
    for table in sorted({c.split(".")[0] for c in SCHEMA}):
        kinds = sorted({kind for c, kind in SCHEMA.items() if c.split(".")[0] == table})
        for kind in [k for k in kinds if k in PLUGIN_KINDS or (k == "float" and _has_seconds(table))]:
            # Datasette shows numbers, times and flags as they are: one value of those kinds
            values = list(HOSTILE[kind])[: None if kind in ("json", "blob") else 1]
            values += ["huge"] if kind == "text" else []
            cases += [(table, kind, value) for value in values]
    return cases


BROWSE = _browse_cases()


@pytest.mark.parametrize("table,kind,value", BROWSE, ids=[f"{t}-{k}={v}" for t, k, v in BROWSE])
def test_a_browse_page_of_hostile_values_answers(
    template: Path, tmp_path: Path, table: str, kind: str, value: str
) -> None:
    pytest.importorskip("datasette")
    from twisted.browse.server import DATABASE, datasette_app

    db = tmp_path / "twisted.db"
    shutil.copyfile(template, db)
    for column, its_kind in SCHEMA.items():
        if column.split(".")[0] == table and its_kind == kind and value in _values(column):
            _plant(db, column, HOSTILE[kind][value])
    before = _sha(db)
    datasette = datasette_app(db, f"sqlite:///{db}")

    async def fetch() -> tuple[int, str]:
        response = await datasette.client.get(f"/{DATABASE}/{table}?_size=5")
        return response.status_code, response.text

    status, body = asyncio.run(fetch())
    assert status in (200, 400), f"{table} {kind}={value}: {status}\n{body[-2000:]}"
    assert "Traceback" not in body, body[-2000:]  # (escapes reach a browser, not a terminal)
    assert _sha(db) == before, "browse changed the store"


# ---- compression bombs, in a child process under a memory limit ---------------------------------------


def _limit() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def _torch_bytes(obj: Any) -> bytes:
    import io

    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def _bomb(column: str) -> bytes:
    """A small row that inflates to 300 MB (a torch zip whose members are deflated: probe_payloads)."""
    import torch

    from bench.probe_payloads import deflated

    zeros = torch.zeros(300_000_000, dtype=torch.uint8)
    if column == "models.weights":
        from twisted.model.registry import load_default_model

        config = load_default_model().net.config.to_dict()
        return deflated(_torch_bytes({"format_version": 1, "config": config, "state_dict": {"pad": zeros}}))
    if column == "rl_checkpoints.replay_buffer":
        state = {"format": "twisted-sac-buffer/1", "pos": 0, "full": False, "arrays": {"observations": zeros}}
        return zlib.compress(deflated(_torch_bytes(state)), 9)
    return deflated(_torch_bytes({"policy": zeros}))


BOMBS = [
    ("models.weights", "plan"),
    ("rl_checkpoints.replay_buffer", "rl train --resume"),
    ("rl_checkpoints.policy", "rl train --resume"),
]


@pytest.mark.parametrize("column,command", BOMBS, ids=[c for c, _ in BOMBS])
def test_a_compression_bomb_is_refused_within_the_memory_limit(
    template: Path, tmp_path: Path, column: str, command: str
) -> None:
    db = tmp_path / "twisted.db"
    shutil.copyfile(template, db)
    _plant(db, column, _bomb(column))
    before = _sha(db)
    args = [a.replace("{tmp}", str(tmp_path)) for a in COMMANDS[command]]
    proc = subprocess.Popen(
        [sys.executable, "-m", "cli.main", "--db", f"sqlite:///{db}", *args],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])},
        preexec_fn=_limit,
    )
    try:
        output = proc.communicate(timeout=300)[0].decode(errors="replace")
    finally:
        proc.kill()
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss << 10
    assert proc.returncode == 2, f"{column}, {command}: exit {proc.returncode}\n{output[-2000:]}"
    assert not any(w in output for w in ("MemoryError", "bad_alloc", "Traceback")), output[-2000:]
    assert peak < MEMORY_LIMIT, f"peak {peak >> 20} MB"
    assert _sha(db) == before
