"""A throwaway PostgreSQL cluster for the tests (and benchmarks): ``initdb`` + ``pg_ctl`` in a temp dir.

The cluster listens on 127.0.0.1 only, on a free port, with its unix socket inside the temporary
directory, trust authentication and a superuser ``postgres``; ``stop()`` shuts it down and removes the
directory. Durability is switched off (``fsync=off``): the data is thrown away anyway.

PostgreSQL refuses to run as root, so when the tests run as root the cluster is created and run as an
unprivileged system user (``postgres``, as Debian's package creates it, else ``nobody``) that owns the
temporary directory.

    with PostgresServer() as server:
        open_store(server.url)          # postgresql+psycopg://postgres@127.0.0.1:PORT/postgres

Run ``python -m tests.postgres_server`` to keep one running by hand (prints its URL; Ctrl-C stops it).
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

SUPERUSER = "postgres"
# Users that may own the cluster when we are root, in order of preference.
UNPRIVILEGED_USERS = ("postgres", "nobody")


class PostgresUnavailable(RuntimeError):
    """No PostgreSQL server binaries on this machine (the message says how to install them)."""


def find_bin_dir() -> Path:
    """The directory of ``initdb`` and ``pg_ctl``: PATH first, then /usr/lib/postgresql/*/bin (Debian)."""
    on_path = shutil.which("initdb")
    if on_path and shutil.which("pg_ctl"):
        return Path(os.path.realpath(on_path)).parent
    candidates = sorted(
        glob.glob("/usr/lib/postgresql/*/bin/initdb"),
        key=lambda p: int(Path(p).parent.parent.name) if Path(p).parent.parent.name.isdigit() else 0,
    )
    for initdb in reversed(candidates):  # the newest major version
        if Path(initdb).with_name("pg_ctl").exists():
            return Path(initdb).parent
    raise PostgresUnavailable(
        "no PostgreSQL server binaries (initdb, pg_ctl) on PATH or in /usr/lib/postgresql/*/bin: "
        "install them (Debian/Ubuntu: apt-get install postgresql) or set TWISTED_TEST_POSTGRES_URL"
    )


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _run_as() -> pwd.struct_passwd | None:
    """The unprivileged account to run PostgreSQL as when we are root (None: run as ourselves)."""
    if os.geteuid() != 0:
        return None
    for name in UNPRIVILEGED_USERS:
        try:
            return pwd.getpwnam(name)
        except KeyError:
            continue
    raise PostgresUnavailable(
        "running as root and no unprivileged 'postgres' or 'nobody' user to run PostgreSQL as"
    )


class PostgresServer:
    """One PostgreSQL cluster in a temporary directory; ``url`` is its superuser URL (database postgres)."""

    def __init__(self, base_dir: str | os.PathLike[str] | None = None) -> None:
        self.bin_dir = find_bin_dir()
        self.user = _run_as()
        self.base_dir = base_dir
        self.root: Path | None = None
        self.port: int | None = None

    @property
    def data_dir(self) -> Path:
        assert self.root is not None
        return self.root / "data"

    @property
    def url(self) -> str:
        """SQLAlchemy URL of the ``postgres`` database as the superuser (may CREATE DATABASE)."""
        if self.port is None:
            raise RuntimeError("the PostgreSQL server is not running")
        return f"postgresql+psycopg://{SUPERUSER}@127.0.0.1:{self.port}/postgres"

    def _run(self, *args: str, timeout_s: float = 120) -> subprocess.CompletedProcess[str]:
        kwargs: dict[str, Any] = {}
        env = {k: v for k, v in os.environ.items() if not k.startswith("PG")}
        env["LC_ALL"] = "C"
        if self.user is not None:
            kwargs.update(user=self.user.pw_uid, group=self.user.pw_gid, extra_groups=[])
            env.update(HOME=str(self.root), USER=self.user.pw_name, LOGNAME=self.user.pw_name)
        result = subprocess.run(
            [str(self.bin_dir / args[0]), *args[1:]],
            cwd=self.root,
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout_s,
            **kwargs,
        )
        return result

    def start(self) -> str:
        """Create and start the cluster; returns :attr:`url`. Raises RuntimeError with PostgreSQL's log."""
        self.root = Path(tempfile.mkdtemp(prefix="twisted-pg-", dir=self.base_dir))
        if self.user is not None:
            os.chown(self.root, self.user.pw_uid, self.user.pw_gid)
        init = self._run(
            "initdb",
            "-D",
            str(self.data_dir),
            "-U",
            SUPERUSER,
            "--auth=trust",
            "--encoding=UTF8",
            "--locale=C",
            "--no-sync",
        )
        if init.returncode != 0:
            self._remove()
            raise RuntimeError(f"initdb failed ({init.returncode}):\n{init.stdout}\n{init.stderr}")
        last_error = ""
        for _ in range(5):  # a port found free may be taken before the server binds it: retry
            self.port = free_port()
            options = (
                f"-c listen_addresses=127.0.0.1 -p {self.port} -c unix_socket_directories={self.root} "
                "-c fsync=off -c synchronous_commit=off -c full_page_writes=off -c max_connections=200"
            )
            started = self._run(
                "pg_ctl", "-D", str(self.data_dir), "-l", str(self.root / "server.log"), "-o", options,
                "-w", "-t", "60", "start",
            )  # fmt: skip
            if started.returncode == 0:
                return self.url
            last_error = f"{started.stdout}\n{started.stderr}\n{self.log()}"
        self.port = None
        self._remove()
        raise RuntimeError(f"pg_ctl start failed:\n{last_error}")

    def log(self) -> str:
        """The server's log so far (empty if none)."""
        try:
            return (self.root / "server.log").read_text() if self.root else ""
        except OSError:
            return ""

    def stop(self) -> None:
        """Stop the server (immediately: the data is thrown away) and remove its directory."""
        if self.root is None:
            return
        if self.port is not None and (self.data_dir / "postmaster.pid").exists():
            self._run("pg_ctl", "-D", str(self.data_dir), "-m", "immediate", "-w", "stop", timeout_s=60)
        self.port = None
        self._remove()

    def _remove(self) -> None:
        if self.root is not None:
            shutil.rmtree(self.root, ignore_errors=True)
            self.root = None

    def __enter__(self) -> PostgresServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def main() -> None:
    """Keep a throwaway server running until Ctrl-C or SIGTERM (to try ``--db postgresql+psycopg://...``)."""
    # Also when started in the background (where the shell ignores SIGINT): both signals stop it cleanly.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    with PostgresServer() as server:
        print(server.url, flush=True)
        try:
            while True:
                time.sleep(3600)
        except KeyboardInterrupt:
            pass


if __name__ == "__main__":
    main()
