"""Serve one SQLite store with Datasette, read-only, on 127.0.0.1 (``twisted browse``).

Read-only by construction: every connection to the store is opened by SQLite itself with ``mode=ro``
on a ``file:`` URI whose path is percent-escaped (so ``?``, ``#`` and ``%`` in a file name are part of
the name, never URI parameters), with ``PRAGMA query_only``; whatever SQL Datasette lets through
(``WITH ... DELETE``), SQLite refuses to write. In front of Datasette a small guard answers only
GET and HEAD, only for a Host header naming 127.0.0.1 or localhost at the served port (a web page
cannot read the store through DNS rebinding), and only for the ``/-/`` pages this server has.
"""

from __future__ import annotations

import re
import socket
import sqlite3
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from twisted.browse.queries import metadata

__all__ = ["DATABASE", "HOST", "SETTINGS", "datasette_app", "guarded", "listen", "serve", "store_uri"]

DATABASE = "twisted"  # the name in every address: /twisted/runs, /twisted/run_tree?run_id=2
HOST = "127.0.0.1"
HOST_NAMES = (HOST, "localhost")

SETTINGS = {
    "default_page_size": 50,  # table pages: 50 rows, each with its pictures
    "max_returned_rows": 1000,
    "sql_time_limit_ms": 5000,  # a local store of millions of configurations: let a canned query finish
    "suggest_facets": False,  # each suggestion is a query per column on every table page
    "allow_download": False,
}

# The /-/ pages served: Datasette's static files and read-only information pages, and the plugin's
# pictures. Any other /-/ address is a 404 (Datasette 0.65 would take "-" for a database: a 500).
_OWN_PAGES = re.compile(
    r"^/-/(static/|static-plugins/|(metadata|versions|plugins|settings|databases|threads|actor)(\.json)?$"
    r"|twisted/state\.svg$|twisted/runs/\d{1,18}(/plan\.(png|gif))?$)"
)
# Datasette's own error pages print each error's traceback with its local variables on the terminal
_CONSOLE_TRACEBACKS = "datasette.handle_exception"
_GRACEFUL_SHUTDOWN_S = 2  # on SIGINT / SIGTERM, requests still running after this are cancelled


def listen(port: int) -> socket.socket:
    """A socket listening on 127.0.0.1:``port``; OSError (in use, not allowed) before anything starts."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((HOST, port))
        sock.listen(128)
    except OSError:
        sock.close()
        raise
    sock.set_inheritable(True)
    return sock


def store_uri(path: Path, immutable: bool = False) -> str:
    """The SQLite URI that opens exactly the file ``path``, read-only: the path resolved and
    percent-escaped (``r.db?mode=rw`` stays one file name), ``mode=ro``, and ``immutable=1`` when asked
    (a file nobody can be writing: no locks, no files beside it)."""
    return path.resolve().as_uri() + "?mode=ro" + ("&immutable=1" if immutable else "")


def _read_only_database(datasette: Any, path: Path, immutable: bool) -> Any:
    """A Datasette database whose every connection is :func:`store_uri` plus ``PRAGMA query_only``."""
    from datasette.database import Database

    class StoreFile(Database):  # type: ignore[misc]  # Datasette has no type hints
        def connect(self, write: bool = False) -> sqlite3.Connection:
            if write:
                raise sqlite3.OperationalError(f"{path} is served read-only")
            conn = sqlite3.connect(store_uri(path, immutable), uri=True, check_same_thread=False)
            conn.execute("PRAGMA query_only = ON")
            self._all_file_connections.append(conn)
            return conn

    return StoreFile(datasette, path=str(path), is_mutable=not immutable)


def datasette_app(path: Path, db_url: str) -> Any:
    """The Datasette instance for the store file at ``path``, with the plugin registered.

    The file is opened read-only (``mode=ro``: a collector or planner writing to it at the same time is
    seen as it commits); when its folder cannot be written and no write-ahead log is beside it, it is
    opened immutable instead (SQLite could not create the files a read-only WAL reader needs, and
    nobody can be writing). Datasette's in-memory ``_memory`` database is not served.
    """
    from datasette.app import Datasette
    from datasette.plugins import pm

    from twisted.browse import plugin

    if not pm.is_registered(plugin):
        pm.register(plugin, name="twisted_browse")
    if pm.has_plugin(_CONSOLE_TRACEBACKS):  # the plugin's handle_exception answers instead
        pm.unregister(name=_CONSOLE_TRACEBACKS)
    wal = Path(f"{path}-wal").exists()
    immutable = not (wal or (path.parent.is_dir() and _writable(path.parent)))
    settings = metadata(DATABASE, db_url, _example_rows(path, immutable))
    datasette = Datasette(metadata=settings, settings=SETTINGS)
    datasette.remove_database("_memory")
    served = _read_only_database(datasette, path, immutable)
    datasette.add_database(served, name=DATABASE)
    return datasette


def _example_rows(path: Path, immutable: bool) -> dict[str, tuple[Any, ...] | None]:
    """The first row of each :data:`twisted.browse.queries.EXAMPLE_ROWS` query in the store (None: none)."""
    from twisted.browse.queries import EXAMPLE_ROWS

    conn = sqlite3.connect(store_uri(path, immutable), uri=True)
    try:
        conn.execute("PRAGMA query_only = ON")
        rows = {}
        for name, (sql, _) in EXAMPLE_ROWS.items():
            try:
                rows[name] = conn.execute(sql).fetchone()
            except sqlite3.Error:  # a table of an optional part missing
                rows[name] = None
        return rows
    finally:
        conn.close()


def _writable(folder: Path) -> bool:
    import os

    return os.access(folder, os.W_OK | os.X_OK)


_Asgi = Callable[[dict[str, Any], Any, Any], Awaitable[None]]  # scope, receive, send


def _refusal(scope: dict[str, Any], port: int) -> tuple[int, str, list[tuple[bytes, bytes]]] | None:
    """Why the guard answers a request itself (status, text, headers), or None to pass it on."""
    hosts = [value for name, value in scope.get("headers", []) if name == b"host"]
    allowed = {f"{name}:{port}".encode() for name in HOST_NAMES} | {name.encode() for name in HOST_NAMES}
    if len(hosts) != 1 or hosts[0].lower() not in allowed:
        shown = hosts[0].decode("latin-1")[:80] if hosts else "none"
        return 421, f"Host {shown!r} is not served: open http://{HOST}:{port}/{DATABASE}\n", []
    if scope["method"] not in ("GET", "HEAD"):
        return 405, "read-only: only GET and HEAD are answered\n", [(b"allow", b"GET, HEAD")]
    path = scope.get("path", "")
    if path.startswith("/-/") and not _OWN_PAGES.match(path):
        return 404, f"no page {path[:80]!r}\n", []
    return None


def guarded(app: _Asgi, port: int) -> _Asgi:
    """``app`` behind the guard of this module's docstring (Host, method, ``/-/`` pages)."""

    async def guard(scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] == "lifespan":
            await app(scope, receive, send)
            return
        if scope["type"] != "http":  # websockets: not served
            await send({"type": "websocket.close", "code": 1008})
            return
        refusal = _refusal(scope, port)
        if refusal is None:
            await app(scope, receive, send)
            return
        status, text, headers = refusal
        body = text.encode()
        await send(
            {
                "type": "http.response.start",
                "status": status,
                "headers": [(b"content-type", b"text/plain; charset=utf-8"), *headers],
            }
        )
        await send({"type": "http.response.body", "body": b"" if scope["method"] == "HEAD" else body})

    return guard


def serve(path: Path, db_url: str, sock: socket.socket) -> None:
    """Serve the store at ``path`` on the listening ``sock`` until interrupted (SIGINT / SIGTERM).

    On a signal, requests still running after a short grace (a picture being drawn) are cancelled, so
    the server stops at once; the signal is then raised again for the caller's exit code.
    """
    import uvicorn

    app = guarded(datasette_app(path, db_url).app(), sock.getsockname()[1])
    config = uvicorn.Config(
        app, log_level="warning", lifespan="on", timeout_graceful_shutdown=_GRACEFUL_SHUTDOWN_S
    )
    uvicorn.Server(config).run(sockets=[sock])
