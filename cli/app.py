"""The Typer application object and what every command shares: the global options (--db, --log-file,
--verbose, --version), opening the database, errors and exit codes."""

from __future__ import annotations

import functools
import inspect
import logging
import math
import os
import time
import typing
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Annotated, Any, NoReturn

import typer
from rich.console import Console
from rich.markup import escape
from typer.core import TyperGroup

from twisted.runtime import cpu_cores

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_NOT_REACHED = 3

DEFAULT_DB = "sqlite:///twisted.db"
GLOBAL_PANEL = "Global options"  # the --help panel of the options every command takes

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


# the options that name something (a set, a label, a model): no control characters, no blank ends
NAME_OPTIONS = ("name", "label", "prefix")


def _check_name(value: Any, param: Any, ctx: typer.Context) -> None:
    from twisted.runtime import name_problem

    if param.name not in NAME_OPTIONS or not isinstance(value, str) or (param.name == "prefix" and not value):
        return
    problem = name_problem(value)
    if problem is not None:
        raise typer.BadParameter(f"{escape_text(shorten(value))} {problem}", ctx=ctx, param=param)


def escape_text(text: str) -> str:
    """``text`` quoted with its control characters as escapes (safe to print to a terminal)."""
    return repr(text)


def _check_given_number(value: Any, param: Any, ctx: typer.Context) -> None:
    """A value that the parser refused (e.g. out of range) but that is NaN or infinite: say that."""
    try:
        number = float(value) if isinstance(value, str) else None
    except ValueError:
        return
    if number is not None and not math.isfinite(number):
        raise typer.BadParameter(f"{value} is not a finite number", ctx=ctx, param=param)


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
            try:
                out = _process(ctx, value)
            except typer.BadParameter:
                _check_given_number(value, _param, ctx)  # NaN given: say so, not "must be >= 0"
                raise
            _check_number(out, _param, ctx)
            _check_name(out, _param, ctx)
            return out

        param.process_value = process_checked  # type: ignore[method-assign]
    command._twisted_hardened = True  # type: ignore[attr-defined]
    for sub in getattr(command, "commands", {}).values():  # a group's subcommands
        harden(sub)


def readable_help(command: Any) -> None:
    """``--help`` that reads, for ``command`` and its subcommands: a docstring's paragraphs flow as prose
    (typer keeps the line breaks of every paragraph after the first, cutting sentences mid-line), and a
    flag shows no ``<bool>`` value placeholder (it takes no value)."""
    if getattr(command, "_twisted_readable", False):
        return
    if command.help:
        paragraphs = inspect.cleandoc(command.help).split("\n\n")
        command.help = "\n\n".join(p if p.startswith("\b") else " ".join(p.split()) for p in paragraphs)
    import click

    for param in [*command.params, command.get_help_option(click.Context(command))]:
        if getattr(param, "is_flag", False) and param.metavar is None:
            param.metavar = ""
    command._twisted_readable = True
    for sub in getattr(command, "commands", {}).values():
        readable_help(sub)


class _Commands(TyperGroup):
    """The root command group: numbers are checked (:func:`harden`) before any command runs, and a
    command ended by Ctrl-C / SIGTERM exits 130 / 143 with one line instead of a traceback."""

    def main(self, *args: Any, **kwargs: Any) -> Any:
        from twisted import runtime

        harden(self)
        readable_help(self)
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
                _refuse_stored_value(exc)
                raise
            runtime.received.clear()  # reported
            if _running.done is not None:
                err_console.print(
                    f"interrupted after {_running.done}: that stands (exit 0); what the command had left "
                    "to do after it (printing, a picture) may be cut short",
                    highlight=False,
                )
                raise typer.Exit(EXIT_OK) from None
            err_console.print(f"interrupted (exit {code}) before the command finished", highlight=False)
            raise typer.Exit(code) from None


def done_before_interrupt(what: str) -> None:
    """The command has stored ``what`` for good (e.g. "run 6 was solved and stored"): a Ctrl-C or SIGTERM
    from here on ends it with exit 0 and a line saying so, not 130 (which means "resume it")."""
    _running.done = what


def _refuse_stored_value(exc: BaseException) -> None:
    """A value read back from the store that its boundary refused (:mod:`twisted.store.boundary`): exit 2
    with "table, row, field: what is wrong", whichever command read it."""
    from twisted.store.boundary import StoredValueError

    if isinstance(exc, StoredValueError):
        fail(str(exc))


class Commands(typer.Typer):
    """A Typer app whose every command also takes the global options after its name
    (``twisted plan --db URL``; :func:`_with_global_options`)."""

    def command(self, *args: Any, **kwargs: Any) -> Any:
        register = super().command(*args, **kwargs)

        def decorator(function: Callable[..., Any]) -> Callable[..., Any]:
            register(_with_global_options(function))
            return function

        return decorator


app = Commands(
    cls=_Commands,
    no_args_is_help=True,
    add_completion=False,
    help="TWISTED: tie knots in a simulated rope with knot-theory planning and a learned inverse model.",
)
console = Console()
err_console = Console(stderr=True)
log = logging.getLogger(__name__)


def subcommands(name: str, help: str) -> Commands:
    """A group of commands, ``twisted NAME ...``."""
    group = Commands(no_args_is_help=True, help=help)
    app.add_typer(group, name=name)
    return group


@dataclass
class AppState:
    """The global options: before the command (the root callback), then after it (they win)."""

    db_url: str = DEFAULT_DB
    log_file: Path | None = None
    verbose: bool = False
    force: bool = False
    done: str | None = None  # what the command has stored for good (done_before_interrupt)


# the global options of the command that runs (what unwritable() checks outputs against)
_running = AppState()


# The global options, defined once: the root callback takes them before the command (``--db`` also
# from TWISTED_DB), every command after its name (overriding the root's; ``--verbose`` adds).
def _db_option(default: str | None, **extra: Any) -> Any:
    return typer.Option(
        default,
        "--db",
        metavar="URL",
        help="Database URL (SQLite file or postgresql+psycopg://...); given after the command it wins "
        "over one given before it.",
        rich_help_panel=GLOBAL_PANEL,
        **extra,
    )


def _checked_log_file(value: Path | None) -> Path | None:
    problem = None if value is None else unwritable(value, append=True)
    if problem is not None:
        raise typer.BadParameter(problem)
    return value


def _log_file_option() -> Any:
    return typer.Option(
        "--log-file",
        metavar="PATH",
        callback=_checked_log_file,
        help="Append the log (timestamped: start, parameters, progress, end) to this file.",
        show_default=False,
        rich_help_panel=GLOBAL_PANEL,
    )


def _verbose_option() -> Any:
    help = "Show the log on the console too, down to DEBUG."
    return typer.Option(False, "--verbose", help=help, rich_help_panel=GLOBAL_PANEL)


def _force_option() -> Any:
    return typer.Option(
        False,
        "--force",
        help="Let an output (--out, --export, --picture, ...) write over an existing file.",
        rich_help_panel=GLOBAL_PANEL,
    )


def _print_version(value: bool) -> None:
    if value:
        typer.echo(f"twisted {package_version()}")
        raise typer.Exit(EXIT_OK)


def package_version() -> str:
    """The installed version of the distribution that holds the ``twisted`` package."""
    from importlib import metadata

    names = metadata.packages_distributions().get("twisted", [])
    for name in names or ["twisted-knots"]:
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return "(not installed)"


@app.callback()
def main(
    ctx: typer.Context,
    db: str = _db_option(DEFAULT_DB, envvar="TWISTED_DB"),
    log_file: Annotated[Path | None, _log_file_option()] = None,
    verbose: bool = _verbose_option(),
    force: bool = _force_option(),
    version: bool = typer.Option(
        False, "--version", is_eager=True, callback=_print_version, help="Print the version and exit."
    ),
) -> None:
    check_rope_env()
    ctx.obj = AppState(db_url=db, log_file=log_file, verbose=verbose, force=force)


def check_rope_env() -> None:
    """Exit 2, before any command opens or writes anything, when ``TWISTED_ROPE`` names no rope."""
    from twisted import rope

    try:
        rope.check_rope_env()
    except ValueError as exc:
        fail(f"{exc}; unset {rope.ROPE_ENV} to run the default rope ({rope.DEFAULT_ROPE.name})")


def _with_global_options(command: Callable[..., Any]) -> Callable[..., Any]:
    """``command`` taking the global options too; it runs with the log configured, its start (with its
    parameters) and its end logged."""
    signature = inspect.signature(command, eval_str=True)
    hints = typing.get_type_hints(command, include_extras=True)
    # typer hands the context to one parameter: the command's own, if it has one
    own_ctx = next((name for name, hint in hints.items() if hint is typer.Context), None)
    extra: dict[str, tuple[Any, Any]] = {
        "global_db": (str | None, _db_option(None, show_default=False)),
        "global_log_file": (Annotated[Path | None, _log_file_option()], None),
        "global_verbose": (bool, _verbose_option()),
        "global_force": (bool, _force_option()),
    }
    if own_ctx is None:
        extra["global_ctx"] = (typer.Context, inspect.Parameter.empty)

    @functools.wraps(command)
    def run(*args: Any, **kwargs: Any) -> Any:
        db, log_file, verbose, force = (
            kwargs.pop("global_db"),
            kwargs.pop("global_log_file"),
            kwargs.pop("global_verbose"),
            kwargs.pop("global_force"),
        )
        ctx = kwargs[own_ctx] if own_ctx is not None else kwargs.pop("global_ctx")
        state = ctx.find_root().obj
        if not isinstance(state, AppState):
            state = ctx.find_root().obj = AppState()
        state.db_url = db if db is not None else state.db_url
        state.log_file = log_file if log_file is not None else state.log_file
        state.verbose = state.verbose or verbose
        state.force = state.force or force
        given = {name: v for name, v in kwargs.items() if name != own_ctx}
        return _logged(ctx, state, functools.partial(command, *args, **kwargs), given)

    parameters = [
        p.replace(annotation=hints.get(p.name, p.annotation)) for p in signature.parameters.values()
    ]
    parameters += [
        inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, annotation=annotation, default=default)
        for name, (annotation, default) in extra.items()
    ]
    run.__signature__ = signature.replace(parameters=parameters)  # type: ignore[attr-defined]
    run.__annotations__ = {**hints, **{name: annotation for name, (annotation, _) in extra.items()}}
    return run


def _logged(ctx: typer.Context, state: AppState, command: Callable[[], Any], given: dict[str, Any]) -> Any:
    """Run ``command`` with the log configured (:mod:`cli.logs`), its start (with the options ``given``)
    and its end logged."""
    from cli import logs

    global _running
    _running = state
    problem = None if state.log_file is None else unwritable(state.log_file, append=True)
    if problem is not None:  # the database is known now (--db may come after --log-file)
        fail(f"--log-file {state.log_file}: {problem}")
    logs.configure(err_console, verbose=state.verbose, log_file=state.log_file)
    shown = ", ".join(
        f"{name}={shorten(repr(v.value if isinstance(v, Enum) else v))}" for name, v in given.items()
    )
    log.info("%s started (database %s): %s", ctx.command_path, _shown_url(state.db_url), shown)
    started = time.monotonic()
    code: int | str = EXIT_OK
    try:
        return command()
    except typer.Exit as exc:
        code = exc.exit_code
        raise
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
        raise
    except BaseException as exc:
        code = type(exc).__name__
        raise
    finally:
        log.info("%s ended: exit %s after %.1f s", ctx.command_path, code, time.monotonic() - started)
        logs.close()


def _shown_url(url: str) -> str:
    """``url`` with its password hidden, shortened (bytes that are not UTF-8, of a file name, as escapes)."""
    from sqlalchemy.engine import make_url

    url = url.encode("utf-8", "backslashreplace").decode("utf-8")
    try:
        return shorten(make_url(url).render_as_string(hide_password=True))
    except Exception:  # malformed: open_db says so
        return shorten(url)


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


def open_db(
    ctx: typer.Context, create: bool = True, readonly: bool = False, needed_by: str | None = None
) -> Any:
    """The store at --db (created when new and ``create``); a refused database exits 2 with the reason.

    ``needed_by``: the input that names something stored (e.g. ``--set easy``): a database that does not
    exist yet is then refused, naming that input, instead of created.

    ``readonly``: a command that only reads (stats, db, models, report, ...) also opens a file it may not
    write, without writing to it. A command that writes has an existing SQLite file checked for damaged
    pages first (``verify``: SQLite's quick_check), so that it stops before writing to a broken store. An
    in-memory SQLite database is refused: nothing written to it would be kept, and the worker processes
    of collect and plan could not see it.
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
        store = open_store(url, create=create and needed_by is None, readonly=readonly, verify=not readonly)
    except StoreError as exc:
        fail(f"{needed_by}: {exc}" if needed_by else str(exc))
    # closed with the command at the latest (a `with` block closes it sooner): a connection left to the
    # garbage collector would checkpoint an SQLite WAL into the file whenever it runs
    return ctx.with_resource(store)


def store_exists(ctx: typer.Context) -> bool:
    """Whether the store at --db exists already (a PostgreSQL server's database counts as existing)."""
    files = _store_files(db_url(ctx))
    return not files or os.path.exists(files[0])


def unwritable(path: Path, append: bool = False) -> str | None:
    """Why a command must not write the file ``path`` (None: it may); nothing is created
    (:func:`twisted.runtime.output_problem`): never the open database or its -wal/-shm files, nor an
    existing file without --force (``append``: a log added to), nor in a folder that does not exist."""
    from twisted.runtime import output_problem

    return output_problem(path, protected=_store_files(_running.db_url), force=_running.force, append=append)


def unwritable_folder(path: Path, marker: str) -> str | None:
    """Why a command must not write its files into the folder ``path``, one that holds ``marker`` being
    written over only with --force (:func:`twisted.runtime.output_folder_problem`)."""
    from twisted.runtime import output_folder_problem

    protected = _store_files(_running.db_url)
    return output_folder_problem(path, marker=marker, protected=protected, force=_running.force)


def _store_files(url: str) -> tuple[str, ...]:
    """The files of the SQLite database at ``url`` (none for PostgreSQL or a malformed URL)."""
    from twisted.runtime import store_files
    from twisted.store.db import parse_url, sqlite_path

    try:
        parsed = parse_url(url)
    except Exception:  # noqa: BLE001 (malformed: open_db says so)
        return ()
    path = sqlite_path(parsed) if parsed.get_backend_name() == "sqlite" else None
    return store_files(path) if path is not None else ()


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
    shown = escape(shorten(visible(message), MAX_MESSAGE_CHARS))
    err_console.print(f"[bold red]error:[/] {shown}", highlight=False)
    raise typer.Exit(code)


def visible(text: str) -> str:
    """``text`` with control characters (terminal escapes, NUL, ...) written as ``\\x1b``-style escapes.

    Messages quote what was given; a quoted escape sequence must not reach the terminal raw (it would
    colour or move the cursor). Newlines stay: messages may have several lines.
    """
    return "".join(ch if ch == "\n" or ch.isprintable() else ascii(ch)[1:-1] for ch in text)


def shown_name(text: object) -> str:
    """A name read back from the store (a set, model, label, tag), ready for the console.

    The store is input like any other (docs/security.md): a name written there by hand may hold terminal
    escapes (clear the screen, set the clipboard). Every one the CLI prints goes through here: control
    and invisible characters (newlines too) become ``\\x1b``-style escapes and brackets are never read
    as rich markup.
    """
    return escape(visible(str(text)).replace("\n", "\\n"))
