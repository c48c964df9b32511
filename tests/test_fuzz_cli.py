"""The standing guard of issue 37: hostile values into every command's options and every file importer.

Each example must end in exit 0, 2 or 3 with no traceback, and a command that refuses its input
(exit 2) must leave the store exactly as it was (a digest of its SQL dump). Two targets:

- the argument parser: every command of the CLI, with up to three of its options set to hostile text
  (control characters, terminal escapes, paths of the store itself and of /proc, huge and non-finite
  numbers, very long strings). The store is replaced by a stub that ends the command where it would
  be opened (exit 0), as in ``tests/test_fuzz.py``, so that no long job starts;
- the file importers on a real store: ``models --import`` (random bytes, truncated and re-pickled
  torch files, dicts of the wrong shape, crafted pickles) and ``problems import`` (binary, UTF-16,
  BOMs, JSON of every shape).

Hypothesis is derandomised (the same examples every run); ``TWISTED_FUZZ_EXAMPLES`` scales the counts.
"""

from __future__ import annotations

import io
import json
import pickle
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import torch
import typer
import typer.main
import typer.testing
from hypothesis import example, given
from hypothesis import strategies as st
from typer.testing import CliRunner

from cli.main import app
from tests.test_fuzz import _digest, _fuzz, stub_commands
from twisted.model.registry import default_model_path
from twisted.store import open_store

runner = CliRunner()
ONE = '[[1,"O",2,"+"],[2,"U",1,"+"]]'


def _clean_exit(result: Any, allowed: tuple[int, ...], what: str) -> None:
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        f"{what}: {result.exception!r}\n{result.output[-1500:]}"
    )
    assert result.exit_code in allowed, f"{what}: exit {result.exit_code}\n{result.output[-1500:]}"
    assert "Traceback (most recent call last)" not in result.output, f"{what}: {result.output[-1500:]}"


# ---- the argument parser: every command, hostile option values ----------------------------------------

HOSTILE = [
    "",
    " ",
    "-",
    "--",
    "\x1b[31mred\x1b[0m",
    "a\nb",
    "a\x00b",
    "\u202eevil",
    "/proc/self/mem",
    "/dev/null",
    "store.db",
    "store.db-wal",
    "../",
    "x" * 5000,
    "nan",
    "-inf",
    "1e308",
    str(2**64),
    "-1",
    "0",
    "é",
    "sqlite:///:memory:",
    "{}",
    "[]",
    ONE,
    "[[1,2]]",
]
hostile = st.one_of(st.sampled_from(HOSTILE), st.text(max_size=12))
SKIPPED = {"browse"}  # serves a web page until stopped


def _commands() -> list[tuple[str, list[tuple[str, bool]]]]:
    """(command path, [(option, is a flag)]) of every command but those in SKIPPED."""
    found: list[tuple[str, list[tuple[str, bool]]]] = []

    def walk(command: Any, path: list[str]) -> None:
        if getattr(command, "commands", None):
            for name, sub in sorted(command.commands.items()):
                walk(sub, [*path, name])
            return
        if path and path[0] in SKIPPED:
            return
        options = [
            (param.opts[0], bool(getattr(param, "is_flag", False)))
            for param in command.params
            if param.opts and param.opts[0].startswith("--") and param.opts[0] not in ("--help",)
        ]
        found.append((" ".join(path), options))

    walk(typer.main.get_command(app), [])
    return found


COMMANDS = _commands()


@pytest.fixture
def stubbed(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Iterator[None]:
    """The store is never opened (reaching it counts as exit 0); the work folder is a temporary one."""
    stub_commands(monkeypatch)
    monkeypatch.chdir(tmp_path)
    yield


@_fuzz(300)
@given(data=st.data())
def test_every_command_takes_hostile_option_values_without_a_traceback(stubbed: None, data: Any) -> None:
    db = Path("store.db")
    command, options = data.draw(st.sampled_from(COMMANDS), label="command")
    chosen = (
        data.draw(st.lists(st.sampled_from(options), max_size=3, unique=True), label="options")
        if options
        else []
    )
    args = ["--db", f"sqlite:///{db}", *command.split()]
    for option, is_flag in chosen:
        args += [option] if is_flag else [option, data.draw(hostile, label=option)]
    result = runner.invoke(app, args)
    _clean_exit(result, (0, 2, 3), " ".join(repr(a) for a in args))
    assert not db.exists(), "nothing is written before the store is opened"
    if result.exit_code == 2:
        assert "\x1b[31m" not in result.output, "an escape given is not echoed raw to the terminal"


# ---- the file importers, on a real store ----------------------------------------------------------------


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An empty store at the current schema (copied for every example)."""
    path = tmp_path_factory.mktemp("fuzz_cli") / "template.db"
    open_store(f"sqlite:///{path}").close()
    return path


def _import(template: Path, tmp_path: Path, args: list[str], allowed: tuple[int, ...]) -> Any:
    db = tmp_path / "store.db"
    shutil.copyfile(template, db)
    before = _digest(db)
    result = runner.invoke(app, ["--db", f"sqlite:///{db}", *args])
    _clean_exit(result, allowed, " ".join(args))
    if result.exit_code == 2:
        assert _digest(db) == before, "a refused file changed the store"
    return result


SHIPPED = default_model_path().read_bytes()


def _torch_bytes(obj: Any) -> bytes:
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def _shipped_with(change: str) -> bytes:
    blob = torch.load(io.BytesIO(SHIPPED), weights_only=True)
    if change == "no-config":
        del blob["config"]
    elif change == "config-garbage":
        blob["config"] = {"hidden": -3, "layers": "many"}
    elif change == "config-huge":
        blob["config"] = {**blob["config"], "hidden": 10**9}
    elif change == "shape":
        name = next(iter(blob["state_dict"]))
        blob["state_dict"][name] = torch.zeros(1)
    elif change == "inf":
        for value in blob["state_dict"].values():
            if value.is_floating_point():
                value.fill_(float("inf"))
    elif change == "metadata":
        blob["metadata"] = {"metrics": {"val_loss": float("nan")}, "sampling": {"oversample": -1}}
    elif change == "version":
        blob["format_version"] = 99
    return _torch_bytes(blob)


class _Opens:
    def __reduce__(self) -> tuple[Any, ...]:
        return (open, ("fuzz-ran-code", "w"))


model_files = st.one_of(
    st.binary(max_size=300),
    st.integers(0, len(SHIPPED) - 1).map(lambda n: SHIPPED[:n]),
    st.sampled_from(
        ["no-config", "config-garbage", "config-huge", "shape", "inf", "metadata", "version", "same"]
    ).map(_shipped_with),
    st.sampled_from([[], {}, None, 3, "text", {"config": 1, "state_dict": 2}]).map(_torch_bytes),
    st.just(pickle.dumps(_Opens())),
    st.just(_torch_bytes({"config": _Opens()})),
)


@_fuzz(40)
@given(content=model_files)
@example(content=SHIPPED)
def test_model_files_are_imported_or_refused_untouched(
    template: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, content: bytes
) -> None:
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "model.pt"
    path.write_bytes(content)
    result = _import(template, tmp_path, ["models", "--import", str(path)], (0, 2))
    assert not (tmp_path / "fuzz-ran-code").exists(), "a model file ran code"
    if content == SHIPPED:
        assert result.exit_code == 0, result.output


goal_texts = st.one_of(
    st.lists(st.sampled_from([json.loads(ONE), "overhand@3", [], [[1, "O"]], 7]), max_size=3).map(json.dumps),
    st.dictionaries(st.text(max_size=8), st.just([json.loads(ONE)]), max_size=2).map(json.dumps),
)
encodings = st.sampled_from(["utf-8", "utf-8-sig", "utf-16", "utf-16-le", "latin-1"])
goal_files = st.one_of(
    st.binary(max_size=200),
    st.tuples(goal_texts, encodings).map(lambda t: t[0].encode(t[1], errors="replace")),
)


def _goal_files_decoded() -> bool:
    """Whether ``problems import`` reads goal files that are not UTF-8 (issue 37 item 6, the other half)."""
    from twisted.experiments import problems

    return hasattr(problems, "decode_goal_file")


@pytest.mark.xfail(
    not _goal_files_decoded(), reason="goal files that are not UTF-8: issue 37 item 6", strict=True
)
@_fuzz(60)
@given(content=goal_files)
@example(content=b"\xff\xfe" + json.dumps([json.loads(ONE)]).encode("utf-16-le"))
@example(content=bytes(range(256)))
def test_goal_files_of_any_bytes_are_imported_or_refused_untouched(
    template: Path, tmp_path: Path, content: bytes
) -> None:
    path = tmp_path / "goals.json"
    path.write_bytes(content)
    _import(template, tmp_path, ["problems", "import", str(path), "--name", "fz"], (0, 2))
