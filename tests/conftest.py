"""Shared fixtures: database URLs for the store tests.

``db_url`` is parametrized over the backends: SQLite always, PostgreSQL when a server is available
(``postgres_admin_url``; skipped otherwise). A test that takes ``db_url`` therefore runs once per backend;
``sqlite_url`` is for tests of SQLite-only behaviour (files, WAL, foreign files).

The PostgreSQL variants use the server at ``TWISTED_TEST_POSTGRES_URL`` (a URL whose user may CREATE
DATABASE, e.g. ``postgresql+psycopg://postgres@localhost/postgres``) when it is set, otherwise a throwaway
cluster that ``postgres_admin_url`` starts itself (``tests/postgres_server.py``).
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator

import pytest
from sqlalchemy import create_engine, text
from sqlalchemy.engine import make_url

# Rich wraps the CLI's messages at the terminal's width, 80 columns without a terminal, and can break a
# long path inside a word a test looks for; the temporary paths of pytest-xdist workers (.../popen-gw0/...)
# are longer still. Set before cli.app makes its consoles (at import), so every test sees one width.
os.environ["COLUMNS"] = "200"


@pytest.fixture
def sqlite_url(tmp_path) -> str:
    """URL of a new (not yet existing) SQLite file in the test's temporary directory."""
    return f"sqlite:///{tmp_path / 'twisted.db'}"


@pytest.fixture(scope="session")
def postgres_admin_url() -> Iterator[str]:
    """URL of a PostgreSQL database on a server where test databases may be created.

    ``TWISTED_TEST_POSTGRES_URL`` if set; otherwise a throwaway cluster started for the session
    (``tests/postgres_server.py``: initdb + pg_ctl on 127.0.0.1 in a temporary directory, removed at
    the end). Skips only when no PostgreSQL server binaries are installed.
    """
    url = os.environ.get("TWISTED_TEST_POSTGRES_URL")
    if url:
        yield url
        return
    from tests.postgres_server import PostgresServer, PostgresUnavailable

    try:
        server = PostgresServer()
    except PostgresUnavailable as exc:
        pytest.skip(str(exc))
    with server:
        yield server.url


@pytest.fixture
def postgres_url(postgres_admin_url: str) -> Iterator[str]:
    """URL of a fresh, empty PostgreSQL database (dropped after the test)."""
    admin = make_url(postgres_admin_url)
    name = f"twisted_test_{uuid.uuid4().hex[:12]}"
    engine = create_engine(admin, isolation_level="AUTOCOMMIT")
    with engine.connect() as conn:
        conn.execute(text(f'CREATE DATABASE "{name}"'))
    try:
        yield admin.set(database=name).render_as_string(hide_password=False)
    finally:
        with engine.connect() as conn:
            conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        engine.dispose()


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def db_url(request: pytest.FixtureRequest) -> str:
    """URL of a new, empty database, once per backend."""
    return request.getfixturevalue("sqlite_url" if request.param == "sqlite" else "postgres_url")
