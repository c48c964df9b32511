"""The commands and files the README and the docs name exist.

Every `twisted ...` line of a fenced code block (its indented continuation lines included) is matched
against the CLI itself: the command words must name a command, and every `--option` written after them
must be one of that command's options (or a global one). Every repository path a page names
(`twisted/...`, `bench/...`, `tests/...`) must exist. An option renamed or a module moved fails here,
not on a reader's machine. The experiment log (docs/log/) describes the code of its day and is left out
of both checks.
"""

from __future__ import annotations

import re
from pathlib import Path

import click
import pytest
import typer

from cli.main import app

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
CURRENT = [p for p in PAGES if "log" not in p.relative_to(REPO).parts]  # the log keeps its day's commands


def command_lines(text: str) -> list[str]:
    """The `twisted ...` command lines of the fenced code blocks of a markdown text, each joined with its
    indented or backslash-continued lines, comments dropped."""
    lines: list[str] = []
    for block in re.findall(r"^```[a-z]*\n(.*?)^```", text, flags=re.S | re.M):
        current: str | None = None
        for raw in block.splitlines():
            line = raw.split(" #", 1)[0].rstrip()
            indented = raw[:1].isspace() and line.strip()[:1] in ("[", "-")  # a usage block's next line
            continued = current is not None and (indented or current.endswith("\\"))
            if continued and line.strip():
                current = current.rstrip("\\").rstrip() + " " + line.strip()  # type: ignore[union-attr]
                continue
            if current is not None:
                lines.append(current)
                current = None
            for part in re.split(r"&&|;", line):
                if part.strip().startswith("twisted "):
                    if current is not None:
                        lines.append(current)
                    current = part.strip()
        if current is not None:
            lines.append(current)
    return lines


def _options(command: click.Command) -> set[str]:
    return {opt for param in command.params for opt in (*param.opts, *param.secondary_opts)}


def _resolve(words: list[str]) -> tuple[click.Command, list[str], list[str]]:
    """The command the words name, the words that named it, the words after it."""
    root = typer.main.get_command(app)
    command: click.Command = root
    named: list[str] = []
    rest = list(words)
    while hasattr(command, "get_command") and rest:  # a group (the root is a Typer group of its own)
        word = rest[0]
        if word.startswith("-"):  # a global option before the command, with its value
            rest = rest[2:] if word in ("--db", "--log-file") else rest[1:]
            continue
        sub = command.get_command(click.Context(command), word)  # type: ignore[attr-defined]
        if sub is None:
            break
        command, named, rest = sub, [*named, word], rest[1:]
    return command, named, rest


def test_command_lines_are_found_with_their_continuations() -> None:
    text = (
        "```\ntwisted plan --goal G [--k 3]\n             [--tighten]   # a comment --nope\n```\n"
        "```bash\npip install x && twisted plan --knot overhand \\\n    --timeout 3\ntwisted stats\n```\n"
    )
    assert command_lines(text) == [
        "twisted plan --goal G [--k 3] [--tighten]",
        "twisted plan --knot overhand --timeout 3",
        "twisted stats",
    ]


GLOBAL = {"--db", "--log-file", "--verbose", "--version", "--help"}


@pytest.mark.parametrize("page", CURRENT, ids=[str(p.relative_to(REPO)) for p in CURRENT])
def test_the_commands_a_page_shows_exist_with_their_options(page: Path) -> None:
    problems = []
    for line in command_lines(page.read_text()):
        words = re.findall(r"[^\s\[\]|]+", line)[1:]
        command, named, rest = _resolve(words)
        if not named:
            problems.append(f"{line!r}: no such command")
            continue
        known = _options(command) | GLOBAL
        for word in rest:
            for option in word.split("=", 1)[0].split("/"):  # --flag/--no-flag: both
                if option.startswith("--") and option not in known:
                    problems.append(f"{line!r}: `twisted {' '.join(named)}` has no option {option}")
    assert not problems, "\n".join(problems)


# Paths a page names on purpose although they are gone: where code used to be (DESIGN section 1.3).
HISTORY = {"twisted/sim/tighten.py"}
PATH = re.compile(r"(?<![\w/.-])((?:twisted|cli|bench|tests|scripts|migrations|docs|goalsets)/[\w./-]*[\w/])")


def repository_paths(text: str) -> set[str]:
    """The repository paths a text names (placeholders in capitals, like goalsets/SET.json, and ids
    such as twisted/RopeKnot-v0 left out)."""
    return {m.rstrip("/") for m in PATH.findall(text) if m == m.lower()}


def test_repository_paths_are_found() -> None:
    text = "`twisted/planner/search.py`, bench/x.py; twisted/RopeKnot-v0, goalsets/SET.json; a/twisted/b.py"
    assert repository_paths(text) == {"twisted/planner/search.py", "bench/x.py"}


@pytest.mark.parametrize("page", CURRENT, ids=[str(p.relative_to(REPO)) for p in CURRENT])
def test_the_files_a_page_names_exist(page: Path) -> None:
    missing = sorted(p for p in repository_paths(page.read_text()) - HISTORY if not (REPO / p).exists())
    assert not missing, f"{page.relative_to(REPO)} names files that are not in the repository: {missing}"


def test_every_benchmark_script_has_a_row_on_the_benchmarks_page() -> None:
    page = (REPO / "docs" / "benchmarks.md").read_text()
    rows = set(re.findall(r"^\| `([a-z0-9_]+\.py)` \|", page, flags=re.M))
    scripts = {p.name for p in (REPO / "bench").glob("*.py")}
    assert scripts - rows == set(), "bench scripts without a row on docs/benchmarks.md"
    assert rows - scripts == set(), "rows of docs/benchmarks.md naming no script in bench/"
