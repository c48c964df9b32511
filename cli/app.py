"""The Typer application object and what every command shares (the --db option, errors, exit codes)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NoReturn

import typer
from rich.console import Console
from rich.markup import escape
from typer.core import TyperGroup

from twisted.runtime import cpu_cores

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_NOT_REACHED = 3

DEFAULT_DB = "sqlite:///twisted.db"

# Every integer the CLI takes ends up in a 64-bit column or a numpy generator; seeds in runs.seed (BIGINT).
MAX_INT = 2**63 - 1
MAX_SEED = MAX_INT
# An error message quotes at most this much of what was given (1 MB in must not bury the cause).
MAX_MESSAGE_CHARS = 2000


def _check_number(value: Any, param: Any, ctx: typer.Context) -> None:
    if isinstance(value, (list, tuple)):
        for item in value:
            _check_number(item, param, ctx)
    elif isinstance(value, float) and not math.isfinite(value):
        raise typer.BadParameter(f"{value} is not a finite number", ctx=ctx, param=param)
    elif isinstance(value, int) and not isinstance(value, bool) and not -MAX_INT <= value <= MAX_INT:
        message = f"{shorten(str(value))} is out of range (at most 2**63-1)"
        raise typer.BadParameter(message, ctx=ctx, param=param)


def harden(command: Any) -> None:
    """Check every number given to ``command`` and its subcommands: finite floats, 64-bit integers.

    Done once for the whole tree, so that no option of any command passes NaN, infinity or a 20-digit
    integer on to arithmetic or the store (the parser itself accepts all three).
    """
    if getattr(command, "_twisted_hardened", False):
        return
    for param in command.params:
        process = param.process_value

        def process_checked(
            ctx: typer.Context, value: Any, _process: Any = process, _param: Any = param
        ) -> Any:
            out = _process(ctx, value)
            _check_number(out, _param, ctx)
            return out

        param.process_value = process_checked  # type: ignore[method-assign]
    command._twisted_hardened = True  # type: ignore[attr-defined]
    for sub in getattr(command, "commands", {}).values():  # a group's subcommands
        harden(sub)


class _Commands(TyperGroup):
    """The root command group: numbers are checked (:func:`harden`) before any command runs, and a
    command ended by Ctrl-C / SIGTERM exits 130 / 143 with one line instead of a traceback."""

    def main(self, *args: Any, **kwargs: Any) -> Any:
        from twisted import runtime

        harden(self)
        runtime.received.clear()  # of an earlier command in this process (tests)
        try:
            return super().main(*args, **kwargs)
        except SystemExit as exc:
            # a signal while the command line is parsed: typer exits 130 silently whichever it was
            if exc.code == 130 and runtime.received:
                code = runtime.signal_exit_code(runtime.received[-1])
                err_console.print(f"interrupted (exit {code}) while starting", highlight=False)
                raise SystemExit(code) from None
            raise

    def invoke(self, ctx: Any) -> Any:
        from twisted import runtime

        try:
            return super().invoke(ctx)
        except (typer.Exit, SystemExit):
            runtime.received.clear()  # the command chose its exit code (and said why): nothing to add
            raise
        except BaseException as exc:
            code = runtime.exit_code(exc)
            if code is None:
                raise
            err_console.print(f"interrupted (exit {code}) before the command finished", highlight=False)
            runtime.received.clear()  # reported
            raise typer.Exit(code) from None


app = typer.Typer(
    cls=_Commands,
    no_args_is_help=True,
    add_completion=False,
    help="TWISTED: tie knots in a simulated rope with knot-theory planning and a learned inverse model.",
)
console = Console()
err_console = Console(stderr=True)


@dataclass
class AppState:
    db_url: str = DEFAULT_DB


@app.callback()
def main(
    ctx: typer.Context,
    db: str = typer.Option(
        DEFAULT_DB, "--db", envvar="TWISTED_DB", help="Database URL (SQLite file or postgresql+psycopg://...)."
    ),
) -> None:
    ctx.obj = AppState(db_url=db)


# Worker processes on this machine: each is a Python process with its own simulator (~100 MB); beyond a
# few per core they only compete, and thousands exhaust memory.
MAX_WORKERS_PER_CORE = 4


def check_workers(workers: int | None, option: str = "--workers") -> None:
    """Exit 2 unless ``workers`` (None: the default) is 1 .. 4 x the CPU cores of this machine."""
    limit = MAX_WORKERS_PER_CORE * cpu_cores()
    if workers is not None and not 1 <= workers <= limit:
        fail(
            f"{option} {workers}: give 1 to {limit} ({MAX_WORKERS_PER_CORE} per CPU core here; each worker "
            "is a process with its own simulator)"
        )


def seed_option(default: Any, help: str) -> Any:
    """The ``--seed`` option of every command: an integer in 0..2**63-1 (what runs.seed stores)."""
    return typer.Option(default, "--seed", min=0, max=MAX_SEED, help=help)


def db_url(ctx: typer.Context) -> str:
    """The database URL chosen by the global --db option (or TWISTED_DB)."""
    state = ctx.find_root().obj
    return state.db_url if isinstance(state, AppState) else DEFAULT_DB


def open_db(ctx: typer.Context, create: bool = True, readonly: bool = False) -> Any:
    """The store at --db (created when new and ``create``); a refused database exits 2 with the reason.

    ``readonly``: a command that only reads (stats, db) also opens a file it may not write, without
    writing to it. An in-memory SQLite database is refused: nothing written to it would be kept, and
    the worker processes of collect and plan could not see it.
    """
    from twisted.store import StoreError, open_store
    from twisted.store.db import parse_url, sqlite_path

    url = db_url(ctx)
    try:
        parsed = parse_url(url)
        if parsed.get_backend_name() == "sqlite" and sqlite_path(parsed) is None:
            fail(
                f"--db {shorten(url)}: an in-memory SQLite database keeps nothing (and worker processes "
                "cannot share it); give a file, e.g. sqlite:///twisted.db"
            )
        return open_store(url, create=create, readonly=readonly)
    except StoreError as exc:
        fail(str(exc))


def shorten(text: str, limit: int = 120) -> str:
    """``text`` cut to about ``limit`` characters (its start and end), for quoting input in a message."""
    if len(text) <= limit:
        return text
    keep = max(limit // 2 - 10, 8)
    return f"{text[:keep]} ...[{len(text) - 2 * keep:,} characters]... {text[-keep:]}"


def fail(message: str, code: int = EXIT_BAD_INPUT) -> NoReturn:
    """Print an actionable error to stderr and exit with ``code`` (2 = bad input by default).

    Messages quote what was given; a long one is cut (:func:`shorten`) so that the cause stays readable.
    """
    err_console.print(f"[bold red]error:[/] {escape(shorten(message, MAX_MESSAGE_CHARS))}", highlight=False)
    raise typer.Exit(code)
