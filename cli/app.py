"""The Typer application object and what every command shares (the --db option, errors, exit codes)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NoReturn

import typer
from rich.console import Console
from rich.markup import escape

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_NOT_REACHED = 3

DEFAULT_DB = "sqlite:///twisted.db"

app = typer.Typer(
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


def db_url(ctx: typer.Context) -> str:
    """The database URL chosen by the global --db option (or TWISTED_DB)."""
    state = ctx.find_root().obj
    return state.db_url if isinstance(state, AppState) else DEFAULT_DB


def open_db(ctx: typer.Context, create: bool = True) -> Any:
    """The store at --db (created when new and ``create``); a refused database exits 2 with the reason."""
    from twisted.store import StoreError, open_store

    try:
        return open_store(db_url(ctx), create=create)
    except StoreError as exc:
        fail(str(exc))


def fail(message: str, code: int = EXIT_BAD_INPUT) -> NoReturn:
    """Print an actionable error to stderr and exit with ``code`` (2 = bad input by default)."""
    err_console.print(f"[bold red]error:[/] {escape(message)}", highlight=False)
    raise typer.Exit(code)
