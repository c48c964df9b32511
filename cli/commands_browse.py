"""`twisted browse`: the store in a web browser (Datasette, read-only, 127.0.0.1; docs/browse.md)."""

from __future__ import annotations

import importlib.util

import typer

from cli.app import app, db_url, fail, open_db, shorten
from twisted.runtime import received, signal_exit_code, signal_name

BROWSE_EXTRA = "pip install 'twisted-knots[browse]'"


@app.command("browse")
def browse_command(
    ctx: typer.Context,
    port: int = typer.Option(
        8001, "--port", min=1, max=65535, help="Port on 127.0.0.1 to serve on (the server is local only)."
    ),
) -> None:
    """Browse the store in a web browser: every table and view, canned queries, ropes and knots drawn.

    Datasette serves the SQLite file read-only on http://127.0.0.1:PORT/ (a running collector or
    planner can keep writing to it); Ctrl-C stops it. Needs the optional extra 'browse'.
    """
    missing = [name for name in ("datasette", "uvicorn") if importlib.util.find_spec(name) is None]
    if missing:
        fail(f"twisted browse needs Datasette ({', '.join(missing)} is not installed): {BROWSE_EXTRA}")
    from twisted.browse.server import HOST, listen, serve
    from twisted.store import StoreError
    from twisted.store.db import parse_url, sqlite_path

    url = db_url(ctx)
    try:
        backend = parse_url(url).get_backend_name()
    except StoreError as exc:
        fail(str(exc))
    if backend != "sqlite":
        fail(
            f"--db {shorten(url)}: only an SQLite store can be browsed (Datasette reads SQLite files); "
            "this one is on PostgreSQL"
        )
    try:
        sock = listen(port)
    except OSError as exc:
        fail(f"--port {port}: cannot listen on {HOST}:{port} ({exc.strerror or exc}); give another port")
    try:
        store = open_db(ctx, create=False, readonly=True)  # a twisted database, schema up to date
        store.close()
        path = sqlite_path(store.url)
        assert path is not None  # open_db refuses an in-memory database
        typer.echo(f"Serving {path} read-only at http://{HOST}:{port}/ (Datasette); Ctrl-C stops.")
        serve(path, url, sock)
    except KeyboardInterrupt:
        signum = received[-1] if received else 2
        typer.echo(f"stopped ({signal_name(signum)})")
        raise typer.Exit(signal_exit_code(signum)) from None
    finally:
        sock.close()
