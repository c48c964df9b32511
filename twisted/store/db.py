"""The one place that opens the database: checks, engine set-up, Alembic upgrade, sessions.

``open_store(url)`` first inspects what is at ``url`` WITHOUT writing to it, and refuses (``StoreError``,
file untouched) a file that is not an SQLite database, an SQLite/PostgreSQL database holding other
tables but no twisted migration history, or one whose Alembic revision is unknown to this version
(a newer schema). Before a command writes, it also refuses a file whose ``-wal``/``-shm`` companions
cannot be written, and (``verify=True``) one whose pages SQLite's ``quick_check`` finds damaged. Only
then does it create the engine and upgrade to the current heads. Last, it compares the rope the
database's data was made on (``rope_profile``) with the process's (:data:`twisted.rope.ROPE`): a
database with none records the process's (unless opened read-only), one of another rope is refused
(:class:`RopeMismatchError`, nothing written).

SQLite connections run in WAL mode with a busy timeout, so readers (a ``sqlite3`` shell,
``twisted stats``) never block a running collector and several collectors can write the same file;
``Store.session(write=True)`` takes the write lock up front (``BEGIN IMMEDIATE``) so a read-then-write
transaction waits for its turn instead of failing with "database is locked".
"""

from __future__ import annotations

import hashlib
import math
import os
import sqlite3
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from sqlalchemy import Engine, create_engine, event, inspect, text
from sqlalchemy.engine import Connection, make_url
from sqlalchemy.engine.url import URL
from sqlalchemy.exc import ArgumentError, DBAPIError, NoSuchModuleError
from sqlalchemy.orm import Session, sessionmaker

from twisted.store.boundary import parse_json

SQLITE_BUSY_TIMEOUT_MS = 30_000
SQLITE_HEADER = b"SQLite format 3\x00"
# Tables an empty SQLite/PostgreSQL database may hold without being "someone else's" database.
_HOUSEKEEPING_TABLES = {"alembic_version", "sqlite_sequence", "sqlite_stat1", "sqlite_stat4"}
# Any fixed number: serialises concurrent migrations of one PostgreSQL database.
_PG_MIGRATION_LOCK = 0x7477_6973  # "twis"


class StoreError(RuntimeError):
    """The database cannot be used; the message says which database and what to do."""


class RopeMismatchError(StoreError):
    """The database holds data of another rope than the one this process runs (``TWISTED_ROPE``)."""


class Store:
    """An open twisted database: ``engine`` plus short-lived sessions."""

    def __init__(self, url: URL, engine: Engine) -> None:
        self.url = url
        self.engine = engine
        self._sessions = sessionmaker(bind=engine, expire_on_commit=False)
        self._write_engine = engine.execution_options(twisted_begin_immediate=True)
        self._write_sessions = sessionmaker(bind=self._write_engine, expire_on_commit=False)

    @property
    def dialect(self) -> str:
        """``"sqlite"`` or ``"postgresql"``."""
        return self.engine.dialect.name

    @contextmanager
    def session(self, write: bool = False) -> Iterator[Session]:
        """A session committed on success and rolled back on error.

        ``write=True`` takes SQLite's write lock when the transaction begins (``BEGIN IMMEDIATE``): use it
        for short transactions that read then write, which could otherwise fail at once with "database is
        locked" when another writer committed in between. Keep such sessions short: they hold other
        writers back. On PostgreSQL it makes no difference.
        """
        maker = self._write_sessions if write else self._sessions
        with maker() as session:
            try:
                yield session
                session.commit()
            except BaseException:
                session.rollback()
                raise

    @contextmanager
    def exclusive_session(self, name: str) -> Iterator[Session]:
        """A write session that no other process holds at the same time for the same ``name``.

        For a read-then-insert that must happen once (e.g. the root of D_Q when two collectors start
        together). SQLite's write lock already serialises writers; PostgreSQL takes a transaction-level
        advisory lock keyed by ``name``, released at commit or rollback.
        """
        with self.session(write=True) as session:
            if self.dialect == "postgresql":
                key = int.from_bytes(hashlib.sha1(name.encode()).digest()[:8], "big", signed=True)
                session.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": key})
            yield session

    def close(self) -> None:
        """Release every pooled connection."""
        self.engine.dispose()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Store({self.url.render_as_string(hide_password=True)!r})"


# A file name is quoted in messages up to this many characters (a 4,000-character name must not bury the
# cause); file systems allow at most this many bytes in one name and in a whole path.
_SHOWN_CHARS = 120
_NAME_MAX_BYTES = 255
_PATH_MAX_BYTES = 4095


def _shorten(text: str, limit: int = _SHOWN_CHARS) -> str:
    """``text`` cut to about ``limit`` characters (its start and its end) for a message."""
    if len(text) <= limit:
        return text
    keep = limit // 2 - 10
    return f"{text[:keep]}...[{len(text) - 2 * keep:,} characters]...{text[-keep:]}"


def _display(url: URL) -> str:
    return _shorten(url.render_as_string(hide_password=True))


def _shown_path(path: Path) -> str:
    """``path`` quoted for a message: ``repr`` (bytes that are not UTF-8 show as escapes), shortened."""
    return _shorten(repr(str(path)))


def parse_url(url: str | URL) -> URL:
    """Parse a database URL, raising :class:`StoreError` with the accepted forms when it is malformed."""
    if isinstance(url, str):
        _check_utf8(url, "database URL")
    try:
        parsed = make_url(url) if isinstance(url, str) else url
    except ArgumentError as exc:
        raise StoreError(
            f"cannot parse database URL {_shorten(repr(url))}: use sqlite:///path/to/file.db or "
            "postgresql+psycopg://user@host/dbname"
        ) from exc
    if parsed.get_backend_name() not in ("sqlite", "postgresql"):
        raise StoreError(
            f"unsupported database {_display(parsed)!r}: twisted stores its data in SQLite "
            "(sqlite:///file.db) or PostgreSQL (postgresql+psycopg://...)"
        )
    return parsed


def _sqlite_options(parsed: URL, readonly: bool) -> tuple[URL, bool]:
    """The SQLite URL without its query, and whether it asked to be read-only (``?mode=ro``).

    ``mode=ro`` is honoured: a command that only reads opens the file read-only as it always does, and
    nothing (not a new database, not an upgrade) is written; a command that writes is refused. Any
    other option would be silently dropped by the driver, so it is refused too.
    """
    if parsed.get_backend_name() != "sqlite" or not parsed.query:
        return parsed, False
    shown = f"database URL {_display(parsed)!r}"
    options = dict(parsed.query)
    mode = options.pop("mode", None)
    if options or mode != "ro":
        given = ", ".join(sorted(options)) if options else f"mode={mode}"
        raise StoreError(
            f"{shown}: the SQLite option {_shorten(given)} is not understood (only mode=ro, read-only, is); "
            "give the file alone, e.g. sqlite:///twisted.db"
        )
    if not readonly:
        raise StoreError(
            f"{shown} is read-only (mode=ro), and this command writes to the database; nothing was "
            "written: drop ?mode=ro to let it write, or use a command that only reads"
        )
    return parsed.difference_update_query(["mode"]), True


def sqlite_path(url: URL) -> Path | None:
    """The file of an SQLite URL, or None for an in-memory database."""
    database = url.database or ""
    if url.get_backend_name() != "sqlite" or database in ("", ":memory:") or database.startswith("file:"):
        return None
    return Path(database)


# --- inspection before any write -------------------------------------------------------------------


def _classify(tables: set[str], revisions: list[str] | None, where: str) -> list[str]:
    """Revisions stored in an existing database, or StoreError if it is not a twisted database.

    ``revisions`` is None when the database has no ``alembic_version`` table.
    """
    own = tables - _HOUSEKEEPING_TABLES
    if not revisions:
        if own:
            listed = ", ".join(sorted(own)[:6]) + (", ..." if len(own) > 6 else "")
            raise StoreError(
                f"{where} is not a twisted database (it has tables {listed} but no twisted migration "
                "history); it was left untouched: choose another --db"
            )
        return []
    known = _known_revisions()
    unknown = [r for r in revisions if r not in known]
    if unknown:
        raise StoreError(
            f"{where} has schema revision {', '.join(unknown)} that this version of twisted does not know "
            "(a newer twisted wrote it, or it is not a twisted database); it was left untouched: upgrade "
            "twisted or choose another --db"
        )
    return revisions


def _check_utf8(text: str, what: str) -> None:
    """Refuse ``text`` (from the command line or the environment) that holds bytes which are not UTF-8:
    Python keeps them as lone surrogates, which SQLite and SQLAlchemy cannot encode."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as exc:
        char = ord(exc.object[exc.start])
        byte = f"byte 0x{char - 0xDC00:02x}" if 0xDC80 <= char <= 0xDCFF else f"character U+{char:04X}"
        raise StoreError(
            f"{what} {_shorten(repr(text))} is not valid UTF-8 ({byte} at position {exc.start}); SQLite "
            "takes UTF-8 file names: rename the file or give another --db"
        ) from None


def _check_path_name(path: Path) -> None:
    """Refuse, before the path is used, a file name SQLite or the file system cannot take."""
    shown = _shown_path(path)
    text = str(path)
    _check_utf8(text, "database file name")
    encoded = text.encode("utf-8")
    if "\x00" in text:
        raise StoreError(f"database file name {shown} holds a NUL character: give another --db")
    longest = max((len(part.encode()) for part in path.parts), default=0)
    if longest > _NAME_MAX_BYTES:
        raise StoreError(
            f"database file name {shown} has a name of {longest:,} bytes (file systems allow at most "
            f"{_NAME_MAX_BYTES} per file or folder name): give a shorter --db"
        )
    if len(encoded) > _PATH_MAX_BYTES:
        raise StoreError(
            f"database file name {shown} is {len(encoded):,} bytes long (at most {_PATH_MAX_BYTES}): give a "
            "shorter --db"
        )


def _check_companions(path: Path, where: str) -> None:
    """Refuse a database whose ``-wal`` / ``-shm`` file exists but cannot be written (every write would fail).

    A plain SQLite reader of a read-only copy leaves them read-only (SQLite gives them the database's
    permissions); making the database writable again does not change them.
    """
    companions = [Path(f"{path}{suffix}") for suffix in ("-wal", "-shm")]
    readonly = [c for c in companions if c.exists() and not os.access(c, os.W_OK)]
    if readonly:
        names = " and ".join(_shown_path(c) for c in readonly)
        raise StoreError(
            f"{where} cannot be written: {names} beside it {'is' if len(readonly) == 1 else 'are'} read-only "
            "(left by a program that read a read-only copy?); it was left untouched: make "
            f"{'it' if len(readonly) == 1 else 'them'} writable (chmod u+w), or delete "
            f"{'it' if len(readonly) == 1 else 'them'} while no program has the database open"
        )


_CHECK_MMAP_BYTES = 1 << 40  # SQLite caps it at its own limit (2 GB by default)


def _quick_check(conn: sqlite3.Connection, where: str) -> None:
    """Refuse a database whose pages SQLite's ``quick_check`` finds damaged (overwritten, cut short).

    ``quick_check`` walks every page of every table and index, checking the B-tree structure, without
    comparing indexes with their tables (``integrity_check`` does, at several times the cost).
    """
    try:
        # Read through a memory map: the kernel then reads ahead, and a file not in the page cache is
        # checked ~10x faster than page by page (1 GB: ~3 s instead of ~33 s, bench/bench_store_check.py).
        conn.execute(f"PRAGMA mmap_size = {_CHECK_MMAP_BYTES}")
        # quick_check(1) stops at the first problem; asked for more, SQLite may go on and fail as a whole
        # ("database disk image is malformed"), losing the page numbers it had found.
        problems = [str(row[0]) for row in conn.execute("PRAGMA quick_check(1)")]
    except sqlite3.DatabaseError as exc:
        problems = [str(exc)]
    if problems != ["ok"]:
        lines = (" ".join(p.replace("*** in database main ***", "").split()) for p in problems)
        found = "; ".join(_shorten(line) for line in lines)
        raise StoreError(
            f"{where} is damaged (SQLite's quick_check: {found}); nothing was written to it: restore it from "
            "a copy (the sqlite3 shell's .recover may salvage what is left)"
        )


def _writable(path: Path) -> bool:
    return os.access(path, os.W_OK) and os.access(path.parent, os.W_OK)


def _readonly_uri(path: Path) -> str:
    """An SQLite URI that opens ``path`` without ever writing to it or beside it."""
    # mode=ro never writes the database. A WAL-mode file without its -wal companion is complete on disk,
    # and immutable=1 then keeps SQLite from creating -wal/-shm files beside it; while a -wal exists (a
    # writer may be running) a plain read-only connection reads the latest commits.
    uri = f"{path.resolve().as_uri()}?mode=ro"
    with path.open("rb") as fh:
        wal_mode = fh.read(20)[18:20] == b"\x02\x02"
    if wal_mode and not Path(f"{path}-wal").exists():
        uri += "&immutable=1"
    return uri


def _inspect_sqlite_file(path: Path, where: str, readonly: bool = False, verify: bool = False) -> list[str]:
    """Read-only look at an existing SQLite file: its Alembic revisions (empty list = a new database).

    Unless ``readonly`` (the caller will only read), a file that cannot be written, or whose companion
    files cannot, is refused. ``verify``: also refuse a file with damaged pages (:func:`_quick_check`).
    """
    if path.is_dir():
        raise StoreError(f"{where} is a directory, not a database file: give a file path")
    try:
        with path.open("rb") as fh:
            header = fh.read(len(SQLITE_HEADER))
    except OSError as exc:
        raise StoreError(f"cannot read {where}: {exc.strerror}") from exc
    if not header:
        return []  # an empty file is what sqlite3 itself treats as a new database
    if header != SQLITE_HEADER:
        raise StoreError(
            f"{where} is not an SQLite database (it does not start with the SQLite header); it was left "
            "untouched: choose another --db"
        )
    if not readonly and not _writable(path):
        raise StoreError(
            f"{where} is not writable (the file and its directory must be writable: SQLite keeps its "
            "write-ahead log beside the file)"
        )
    if not readonly:
        _check_companions(path, where)
    try:
        conn = sqlite3.connect(_readonly_uri(path), uri=True, timeout=30)
    except sqlite3.Error as exc:
        raise StoreError(f"cannot open {where}: {exc}") from exc
    try:
        tables = {row[0] for row in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        revisions = None
        if "alembic_version" in tables:
            revisions = [row[0] for row in conn.execute("SELECT version_num FROM alembic_version")]
        found = _classify(tables, revisions, where)
        if verify:
            _quick_check(conn, where)
    except sqlite3.DatabaseError as exc:
        raise StoreError(f"{where} is not a readable SQLite database ({exc}); it was left untouched") from exc
    finally:
        conn.close()
    return found


def _check_new_sqlite_path(path: Path, where: str) -> None:
    parent = path.parent if str(path.parent) else Path(".")
    shown = _shown_path(parent)
    if not parent.exists():
        raise StoreError(f"cannot create {where}: directory {shown} does not exist")
    if not parent.is_dir():
        raise StoreError(f"cannot create {where}: {shown} is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise StoreError(f"cannot create {where}: directory {shown} is not writable")


def _inspect_connection(conn: Connection, where: str) -> list[str]:
    tables = set(inspect(conn).get_table_names())
    revisions = None
    if "alembic_version" in tables:
        revisions = [row[0] for row in conn.execute(text("SELECT version_num FROM alembic_version"))]
    return _classify(tables, revisions, where)


# --- engine -------------------------------------------------------------------------------------------


def _sqlite_on_connect(dbapi_connection: Any, _record: Any) -> None:
    # Let SQLAlchemy's "begin" event issue BEGIN itself (pysqlite's implicit BEGIN cannot be IMMEDIATE
    # and does not cover DDL, which Alembic needs to be transactional).
    dbapi_connection.isolation_level = None
    cursor = dbapi_connection.cursor()
    try:
        cursor.execute(f"PRAGMA busy_timeout = {SQLITE_BUSY_TIMEOUT_MS}")
        cursor.execute("PRAGMA journal_mode = WAL")
        # In WAL mode NORMAL is still safe against a killed process (only an OS crash can lose the latest
        # commits) and saves an fsync per commit.
        cursor.execute("PRAGMA synchronous = NORMAL")
        cursor.execute("PRAGMA foreign_keys = ON")
    finally:
        cursor.close()


def _sqlite_on_begin(conn: Connection) -> None:
    immediate = conn.get_execution_options().get("twisted_begin_immediate", False)
    conn.exec_driver_sql("BEGIN IMMEDIATE" if immediate else "BEGIN")


def _sqlite_readonly_on_connect(dbapi_connection: Any, _record: Any) -> None:
    dbapi_connection.isolation_level = None  # as above; no journal-mode change: that would be a write
    cursor = dbapi_connection.cursor()
    try:
        cursor.execute(f"PRAGMA busy_timeout = {SQLITE_BUSY_TIMEOUT_MS}")
        cursor.execute("PRAGMA query_only = ON")
    finally:
        cursor.close()


def make_engine(url: URL, readonly: bool = False) -> Engine:
    """Create the engine with twisted's connection settings (SQLite: WAL, busy timeout, foreign keys).

    ``readonly``: every connection only reads (SQLite: the file opened with ``mode=ro``; PostgreSQL:
    read-only transactions).
    """
    # every JSON column read back is parsed within bounds of size and depth (twisted.store.boundary)
    kwargs: dict[str, Any] = {"json_deserializer": parse_json}
    path = sqlite_path(url) if readonly else None
    if path is not None:
        uri = _readonly_uri(path)
        kwargs["creator"] = lambda: sqlite3.connect(
            uri, uri=True, timeout=SQLITE_BUSY_TIMEOUT_MS / 1000, check_same_thread=False
        )
    elif url.get_backend_name() == "sqlite":
        kwargs["connect_args"] = {"timeout": SQLITE_BUSY_TIMEOUT_MS / 1000}
    else:
        kwargs["pool_pre_ping"] = True
        if readonly:
            kwargs["connect_args"] = {"options": "-c default_transaction_read_only=on"}
    try:
        engine = create_engine(url, **kwargs)
    except (ArgumentError, NoSuchModuleError, ImportError) as exc:
        hint = ""
        if isinstance(exc, ImportError) and url.get_backend_name() == "postgresql":
            hint = " (PostgreSQL needs the distributed extra: pip install 'twisted-knots[distributed]')"
        raise StoreError(f"cannot use database {_display(url)!r}: {exc}{hint}") from exc
    if url.get_backend_name() == "sqlite":
        on_connect = _sqlite_readonly_on_connect if path is not None else _sqlite_on_connect
        event.listen(engine, "connect", on_connect)
        event.listen(engine, "begin", _sqlite_on_begin)
    return engine


# --- Alembic -------------------------------------------------------------------------------------------


def alembic_config(connection: Connection | None = None) -> Any:
    """An Alembic ``Config`` pointing at the installed ``migrations`` package (no alembic.ini needed)."""
    from alembic.config import Config

    import migrations

    config = Config()
    # __path__ rather than __file__: an editable install made before migrations/__init__.py existed
    # exposes it as a namespace package.
    config.set_main_option("script_location", str(Path(next(iter(migrations.__path__))).resolve()))
    if connection is not None:
        config.attributes["connection"] = connection
    return config


def _script_directory() -> Any:
    from alembic.script import ScriptDirectory

    return ScriptDirectory.from_config(alembic_config())


def _known_revisions() -> set[str]:
    return {script.revision for script in _script_directory().walk_revisions()}


def head_revisions() -> set[str]:
    """The current heads of twisted's migrations (one per area branch)."""
    return set(_script_directory().get_heads())


def _upgrade(engine: Engine, url: URL) -> None:
    from alembic import command

    heads = head_revisions()
    where = _display(url)
    sqlite = url.get_backend_name() == "sqlite"
    with engine.connect() as conn:
        raw: Any = conn.connection.driver_connection
        if sqlite:
            # Batch-mode migrations rebuild tables (copy, drop, rename): SQLite's documented procedure
            # needs foreign keys off, and the pragma only takes effect outside a transaction.
            raw.execute("PRAGMA foreign_keys = OFF")
        try:
            conn.execution_options(twisted_begin_immediate=True)
            with conn.begin():
                # Re-check under the write lock: another process may have created or upgraded it meanwhile.
                if not sqlite:
                    conn.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": _PG_MIGRATION_LOCK})
                current = set(_inspect_connection(conn, where))
                if current == heads:
                    return
                command.upgrade(alembic_config(conn), "heads")
                if sqlite:
                    broken = conn.exec_driver_sql("PRAGMA foreign_key_check").fetchall()
                    if broken:
                        raise StoreError(f"migration of {where} broke foreign keys: {broken[:5]}")
        finally:
            if sqlite:
                raw.execute("PRAGMA foreign_keys = ON")


def open_store(
    url: str | URL,
    *,
    create: bool = True,
    upgrade: bool = True,
    readonly: bool = False,
    verify: bool = False,
) -> Store:
    """Open (creating if new and ``create``) the twisted database at ``url`` and upgrade it to the heads.

    ``upgrade=False`` only checks (for Alembic run by hand). ``readonly``: for commands that only read;
    an existing database is opened without writing to it (nor beside it), even a file this process may
    not write; only a schema older than this twisted's is upgraded first, when that is possible, and a
    database that does not exist yet is created when ``create`` (else refused).
    ``verify``: an existing SQLite file that will be written is first read whole by SQLite's
    ``quick_check`` (what a command about to write asks; a few seconds per GB, docs/DESIGN.md 11).
    Raises :class:`StoreError`, leaving whatever is at ``url`` untouched, when the URL is malformed, the
    path cannot be created or written, the file is not a twisted database, its schema is newer, or
    (``verify``) its pages are damaged.
    """
    parsed = parse_url(url)
    # A new SQLite file that other processes create and migrate at the same moment (collectors started
    # together) can answer "database is locked" at once, without waiting for the busy timeout (a journal
    # mode change, a hot journal seen read-only): such an open is retried after a short pause.
    for attempt in range(_OPEN_ATTEMPTS):
        try:
            return _open_store(parsed, create=create, upgrade=upgrade, readonly=readonly, verify=verify)
        except StoreError as exc:
            retry = sqlite_path(parsed) is not None and "database is locked" in str(exc)
            if not retry or attempt == _OPEN_ATTEMPTS - 1:
                raise
            time.sleep(0.2 * (attempt + 1))
    raise AssertionError("unreachable")


_OPEN_ATTEMPTS = 5


def stored_rope(conn: Connection) -> Any:
    """The rope recorded in ``rope_profile`` (a :class:`twisted.rope.RopeProfile`), or None; a row that is
    no rope is a :class:`StoreError`. Reads only: a connection to a store opened read-only will do."""
    from twisted.rope import DEFAULT_MAX_CROSSINGS, RopeProfile

    # before revision 0017 the table has no crossing limit: every such store was made with the default's
    columns = {c["name"] for c in inspect(conn).get_columns("rope_profile")}
    limit = "max_crossings" if "max_crossings" in columns else str(DEFAULT_MAX_CROSSINGS)
    row = conn.execute(
        text(f"SELECT n_links, link_spacing_m, {limit} FROM rope_profile ORDER BY id LIMIT 1")
    ).first()
    if row is None:
        return None
    n_links, spacing, max_crossings = row
    # read back, the row is input: integer counts and a finite positive length, or the store is refused
    if not (
        type(n_links) is int
        and 0 < n_links <= 100_000
        and type(spacing) in (int, float)
        and math.isfinite(spacing)
        and spacing > 0
        and type(max_crossings) is int
        and 1 <= max_crossings <= 100
    ):
        raise StoreError(
            f"the database's rope_profile holds n_links {n_links!r:.40}, link_spacing_m {spacing!r:.40}, "
            f"max_crossings {max_crossings!r:.40}: not a rope (the row is damaged); nothing was changed"
        )
    return RopeProfile(n_links, float(spacing), max_crossings)


def _peek_rope(conn: Connection) -> Any:
    """The rope of a database at any revision: its ``rope_profile``, else (a database from before revision
    0013) the default rope when it holds configurations, else None."""
    from twisted.rope import DEFAULT_ROPE

    tables = set(inspect(conn).get_table_names())
    if "rope_profile" in tables:
        return stored_rope(conn)
    if "configurations" in tables and conn.execute(text("SELECT 1 FROM configurations LIMIT 1")).first():
        return DEFAULT_ROPE  # what migration 0013 will record
    return None


def _compare_rope(stored: Any, where: str) -> None:
    from twisted.rope import ROPE

    if stored is not None and stored != ROPE:
        raise RopeMismatchError(rope_mismatch_message(where, stored))


def _check_rope(engine: Engine, where: str, readonly: bool) -> None:
    """Refuse (:class:`RopeMismatchError`) a database whose data was made on another rope than this
    process's; record this process's rope in one that has none yet, unless ``readonly``."""
    from sqlalchemy import insert
    from sqlalchemy.exc import IntegrityError

    from twisted.rope import ROPE
    from twisted.store.models import utcnow
    from twisted.store.rope_profile import ROPE_ROW_ID, StoredRope

    with engine.connect() as conn:
        stored = stored_rope(conn)
    if stored is None and not readonly:
        try:
            with engine.execution_options(twisted_begin_immediate=True).begin() as conn:
                stored = stored_rope(conn)  # under the write lock: another process may have been first
                if stored is None:
                    values = {
                        "id": ROPE_ROW_ID,
                        "n_links": ROPE.n_links,
                        "link_spacing_m": ROPE.link_spacing_m,
                        "max_crossings": ROPE.max_crossings,
                        "created_at": utcnow(),
                    }
                    conn.execute(insert(StoredRope).values(**values))
                    stored = ROPE
        except IntegrityError:  # PostgreSQL: another process inserted it meanwhile
            with engine.connect() as conn:
                stored = stored_rope(conn)
    _compare_rope(stored, where)


def rope_mismatch_message(where: str, stored: Any) -> str:
    """Why a process on :data:`twisted.rope.ROPE` must not use data of the rope ``stored``, and how to run
    with it."""
    from twisted.rope import DEFAULT_ROPE, ROPE, ROPE_ENV

    value = os.environ.get(ROPE_ENV, "")
    given = f"{ROPE_ENV}={value!r}" if value.strip() else f"{ROPE_ENV} unset"
    if stored == DEFAULT_ROPE:
        how = f"run without {ROPE_ENV} (or {ROPE_ENV}={stored.env_value})"
    else:
        how = f"run with {ROPE_ENV}={stored.env_value} (e.g. `{ROPE_ENV}={stored.env_value} twisted ...`)"
    return (
        f"{where} holds data of a rope of {stored.name}, but this process runs a rope of {ROPE.name} "
        f"({given}); nothing was written to it: {how} to use this "
        "database, or choose another --db for this rope"
    )


def _open_store(
    parsed: URL, *, create: bool, upgrade: bool, readonly: bool = False, verify: bool = False
) -> Store:
    parsed, pinned = _sqlite_options(parsed, readonly)  # pinned: ?mode=ro, nothing may be written
    where = f"database {_display(parsed)!r}"
    heads = head_revisions()
    reads_only = readonly  # as asked (an older schema is upgraded first, but the rope is never recorded)
    path = sqlite_path(parsed)
    current: list[str] | None = None
    if path is not None:
        where = f"database file {_shown_path(path)}"
        _check_path_name(path)
        if pinned and (not path.exists() or set(_inspect_sqlite_file(path, where, readonly=True)) != heads):
            raise StoreError(
                f"{where} was given read-only (mode=ro) but does not exist or needs its tables created or "
                "upgraded first, which writes: run a command without ?mode=ro once"
            )
        if path.exists():
            current = _inspect_sqlite_file(path, where, readonly=readonly, verify=verify and not readonly)
            if readonly and not current and create:
                readonly = False  # a new database: made as any command makes it (its tables only)
            elif readonly and set(current) != heads:
                if not current:
                    raise StoreError(f"{where} holds no twisted data yet (run `twisted collect` first)")
                if not _writable(path):
                    raise StoreError(
                        f"{where} has the older schema {', '.join(sorted(current))} and cannot be written "
                        "to upgrade it: make it writable once, or copy it"
                    )
                _check_companions(path, where)
                readonly = False  # upgraded below like any command does, then read as usual
        elif not create:
            raise StoreError(f"{where} does not exist (run `twisted collect` first, or check --db)")
        else:
            _check_new_sqlite_path(path, where)
            readonly = False
    engine = make_engine(parsed, readonly=readonly)
    try:
        if current is None:
            # PostgreSQL / in-memory SQLite: inspect through the engine (read-only queries).
            try:
                with engine.connect() as conn:
                    current = _inspect_connection(conn, where)
            except DBAPIError as exc:
                raise StoreError(f"cannot connect to {where}: {exc.orig}") from exc
        if upgrade and current and set(current) != heads:
            # An older schema: refuse a process of another rope before the upgrade writes anything.
            try:
                with engine.connect() as conn:
                    _compare_rope(_peek_rope(conn), where)
            except DBAPIError as exc:
                raise StoreError(f"cannot read the rope profile of {where}: {exc.orig}") from exc
        if upgrade and set(current) != heads:
            writer = make_engine(parsed) if readonly else engine  # PostgreSQL: read-only sessions only after
            try:
                _upgrade(writer, parsed)
            except DBAPIError as exc:
                raise StoreError(f"cannot create or upgrade {where}: {exc.orig}") from exc
            finally:
                if writer is not engine:
                    writer.dispose()
        if upgrade:  # without the upgrade (Alembic by hand) the table may not exist yet
            try:
                _check_rope(engine, where, readonly=reads_only)
            except DBAPIError as exc:
                raise StoreError(f"cannot read the rope profile of {where}: {exc.orig}") from exc
    except BaseException:
        engine.dispose()
        raise
    return Store(parsed, engine)
