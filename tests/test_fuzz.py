"""Fuzzing the inputs (issue 15): exit 0 or 2, never a traceback, and the store unchanged on 2.

Three targets: the P-data parser, goal files for `problems import`, and every numeric option of every
command. Hypothesis is derandomized (the same examples on every run); ``TWISTED_FUZZ_EXAMPLES`` scales
the number of examples up for a longer hunt (the default keeps the whole file to a few seconds).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sqlite3
from collections.abc import Iterator
from decimal import Decimal
from pathlib import Path
from typing import Any

import pytest
import typer
import typer.main
import typer.testing
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from cli.main import app
from twisted.store import open_store
from twisted.topology import PData, PDataError, parse_p_data

SCALE = float(os.environ.get("TWISTED_FUZZ_EXAMPLES", "1"))
runner = CliRunner()


def _fuzz(examples: int) -> Any:
    return settings(
        max_examples=max(1, int(examples * SCALE)),
        deadline=None,
        derandomize=True,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    )


# --- P-data parser ---------------------------------------------------------------------------------------

scalars = st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.floats() | st.text(max_size=5)
json_values = st.recursive(
    scalars | st.sampled_from("OU+-x"),
    lambda inner: st.lists(inner, max_size=6),
    max_leaves=30,
)
visit = st.tuples(
    st.integers(-2, 8),
    st.sampled_from(["O", "U", "X", 1]),
    st.integers(-2, 8),
    st.sampled_from(["+", "-", "*"]),
)
p_data_like = st.lists(visit.map(list), max_size=8)
texts = st.one_of(
    st.text(max_size=40),
    json_values.map(json.dumps),
    p_data_like.map(json.dumps),
    st.integers(1, 5000).map(lambda n: "[" * n + "]" * n),
    st.integers(1, 5000).map(lambda n: "[" * n),
)


@_fuzz(600)
@given(value=st.one_of(texts, json_values, p_data_like))
def test_p_data_parser_accepts_or_says_why(value: Any) -> None:
    try:
        p = parse_p_data(value)
    except PDataError as exc:
        assert 0 < len(str(exc)) < 400, "a message names the problem and quotes a little of the input"
        return
    assert isinstance(p, PData) and parse_p_data(p.key) == p


# --- goal files for `problems import` -----------------------------------------------------------------------

goal_entries = st.one_of(
    p_data_like,
    st.sampled_from(["overhand", "figure-eight@4", "knot:overhand@3", "nonsense@2", "5_1@99", "", "[1"]),
    json_values,
)
goal_files = st.one_of(
    st.text(max_size=60),
    st.lists(goal_entries, max_size=4).map(json.dumps),
    st.dictionaries(st.text(max_size=70), st.lists(goal_entries, max_size=3), max_size=3).map(json.dumps),
    st.integers(1, 4000).map(lambda n: '{"a": ' + "[" * n + "]" * n + "}"),
)


def _digest(path: Path) -> str:
    conn = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)
    try:
        return hashlib.sha256("\n".join(conn.iterdump()).encode()).hexdigest()
    finally:
        conn.close()


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An empty store at the current schema (copied for every example)."""
    path = tmp_path_factory.mktemp("fuzz") / "template.db"
    open_store(f"sqlite:///{path}").close()
    return path


@_fuzz(60)
@given(text=goal_files, name=st.sampled_from([None, "set", "x" * 70]))
@example(text='{"deep": ' + "[" * 3000 + "]" * 3000 + "}", name=None)
@example(text='{"x": ["' + "y" * 100_000 + '"]}', name=None)
def test_goal_files_are_imported_or_refused_untouched(
    template: Path, tmp_path: Path, text: str, name: str | None
) -> None:
    db = tmp_path / "goals.db"
    shutil.copyfile(template, db)
    before = _digest(db)
    goals = tmp_path / "goals.json"
    goals.write_text(text)
    named = ["--name", name] if name else []
    result = runner.invoke(app, ["--db", f"sqlite:///{db}", "problems", "import", str(goals), *named])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert result.exit_code in (0, 2), result.output
    if result.exit_code == 2:
        assert _digest(db) == before, "a refused file changed the store"


# --- every numeric option ---------------------------------------------------------------------------------

# what the commands need besides the option under test (values that pass, so the option decides)
REQUIRED: dict[str, list[str]] = {
    "eval": ["--set", "easy"],
    "sensitivity run": ["--set", "easy"],
    "plan": ["--goal", '[[1,"O",2,"+"],[2,"U",1,"+"]]'],
    "collect": ["--hours", "0.01"],
    "moves enumerate": [],
    "replay": [],
}


def _numeric_options() -> list[tuple[str, str, bool, type]]:
    """(command path, option or argument name, is an argument, int or float) of every numeric parameter."""
    found: list[tuple[str, str, bool, type]] = []

    def walk(command: Any, path: list[str]) -> None:
        if getattr(command, "commands", None):
            for name, sub in command.commands.items():
                walk(sub, [*path, name])
            return
        for param in command.params:
            annotation = getattr(getattr(param, "type_descriptor", None), "annotation", None)
            if annotation in (int, float):
                is_argument = not param.opts or not param.opts[0].startswith("-")
                name = param.opts[0] if not is_argument else param.name
                found.append((" ".join(path), name, is_argument, annotation))

    walk(typer.main.get_command(app), [])
    return found


NUMERIC = _numeric_options()
COMMAND = typer.main.get_command(app)
numbers = st.one_of(
    st.integers(-(2**70), 2**70).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["nan", "-inf", "inf", "1e308", "-1e308", "1e-320", "-0", "0", "1", "", "0x10", "1_0"]),
    st.text(max_size=6),
)


def stub_commands(monkeypatch: pytest.MonkeyPatch) -> None:
    """Commands stop where they would open the store or start long work; reaching it counts as exit 0
    (shared with test_fuzz_cli)."""
    import twisted.knots
    import twisted.moves
    import twisted.store

    def opened(*args: Any, **kwargs: Any) -> Any:
        raise typer.Exit(0)

    monkeypatch.setattr(twisted.store, "open_store", opened)
    # the command tree is built once instead of at every invocation (most of an invocation's time)
    monkeypatch.setattr(typer.testing, "_get_command", lambda _app, _built=COMMAND: _built)
    monkeypatch.setattr(twisted.knots, "states_tying", lambda *a, **k: [])
    monkeypatch.setattr(twisted.moves, "enumerate_states", lambda *a, **k: {})


@pytest.fixture
def stubbed(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    stub_commands(monkeypatch)
    yield


@pytest.mark.parametrize("command,option,is_argument,kind", NUMERIC, ids=[f"{c} {o}" for c, o, *_ in NUMERIC])
def test_every_numeric_option_is_accepted_or_refused_before_the_store(
    stubbed: None, tmp_path: Path, command: str, option: str, is_argument: bool, kind: type
) -> None:
    db = tmp_path / "never.db"

    @_fuzz(12)
    @given(value=numbers)
    @example(value="nan")
    @example(value="inf")
    @example(value="1e308")
    @example(value=str(2**64))
    @example(value="-1")
    def check(value: str) -> None:
        given_value = [value] if is_argument else [option, value]
        args = ["--db", f"sqlite:///{db}", *command.split(), *REQUIRED.get(command, []), *given_value]
        result = runner.invoke(app, args)
        assert result.exception is None or isinstance(result.exception, SystemExit), (
            f"{command} {option} {value!r}: {result.exception!r}\n{result.output[-1500:]}"
        )
        # a --timeout so short that it runs out during the set-up (its timer fires after 1 ms, before the
        # store is opened on a loaded machine) ends the command with exit 3 and nothing written: no crash
        ran_out = option == "--timeout" and "ran out during the set-up" in result.output
        allowed = (0, 2, 3) if ran_out else (0, 2)
        assert result.exit_code in allowed, f"{command} {option} {value!r}: {result.output[-1500:]}"
        assert not db.exists(), "nothing is written before the store is opened"
        if result.exit_code == 0 and value.strip():
            # what got past the checks is a finite number (an integer option: within 64 bits)
            number = Decimal(value.strip().replace("_", ""))
            assert number.is_finite(), f"{option} took {value!r}"
            assert kind is float or abs(number) < 2**63, f"{option} took {value!r}"

    check()
