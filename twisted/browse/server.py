"""Serve one SQLite store with Datasette, read-only, on 127.0.0.1 (``twisted browse``)."""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Any

from twisted.browse.queries import metadata

__all__ = ["DATABASE", "SETTINGS", "datasette_app", "listen", "serve"]

DATABASE = "twisted"  # the name in every address: /twisted/runs, /twisted/run_tree?run_id=2
HOST = "127.0.0.1"

SETTINGS = {
    "default_page_size": 50,  # table pages: 50 rows, each with its pictures
    "max_returned_rows": 1000,
    "sql_time_limit_ms": 5000,  # a local store of millions of configurations: let a canned query finish
    "suggest_facets": False,  # each suggestion is a query per column on every table page
    "allow_download": False,
}


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


def datasette_app(path: Path, db_url: str) -> Any:
    """The Datasette instance for the store file at ``path``, with the plugin registered.

    The file is opened read-only by Datasette (``mode=ro``: a collector or planner writing to it at the
    same time is seen as it commits); when its folder cannot be written and no write-ahead log is
    beside it, it is opened immutable instead (SQLite could not create the files a read-only WAL
    reader needs, and nobody can be writing).
    """
    from datasette.app import Datasette
    from datasette.database import Database
    from datasette.plugins import pm

    from twisted.browse import plugin

    if not pm.is_registered(plugin):
        pm.register(plugin, name="twisted_browse")
    datasette = Datasette(metadata=metadata(DATABASE, db_url), settings=SETTINGS)
    wal = Path(f"{path}-wal").exists()
    writable = path.parent.is_dir() and _writable(path.parent)
    datasette.add_database(Database(datasette, path=str(path), is_mutable=wal or writable), name=DATABASE)
    return datasette


def _writable(folder: Path) -> bool:
    import os

    return os.access(folder, os.W_OK | os.X_OK)


def serve(path: Path, db_url: str, sock: socket.socket) -> None:
    """Serve the store at ``path`` on the listening ``sock`` until interrupted (SIGINT / SIGTERM)."""
    import uvicorn

    app = datasette_app(path, db_url).app()
    config = uvicorn.Config(app, log_level="warning", lifespan="on")
    uvicorn.Server(config).run(sockets=[sock])
