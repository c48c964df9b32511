"""The store: opening/creating/upgrading, refusing foreign or newer databases, views, idempotent batches."""

from __future__ import annotations

import hashlib
import importlib
import pkgutil
import sqlite3
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import create_engine, func, inspect, select, text

import twisted.store
from twisted.store import (
    VIEW_NAMES,
    Base,
    CollectBatch,
    Configuration,
    Run,
    StoreError,
    TopologicalState,
    Transition,
    alembic_config,
    array_to_blob,
    blob_to_array,
    head_revisions,
    open_store,
)
from twisted.store.models import by_id_or_newest
from twisted.store.queries import (
    BatchRecord,
    KeptTransition,
    TryCount,
    acceptance_by_cross,
    add_collect_batch,
    add_configuration,
    batch_id,
    collect_throughput,
    configuration_index,
    end_run,
    get_or_create_state,
    mark_stale_runs,
    sample_configurations,
    start_run,
    states_by_cross,
    transitions_by_cross,
    transitions_per_run,
)
from twisted.topology import EMPTY, PData, parse_p_data

ONE = parse_p_data([[1, "O", 2, "+"], [2, "U", 1, "+"]])
ONE_MINUS = ONE.mirror()
TWO = parse_p_data([[1, "O", 4, "+"], [2, "O", 3, "-"], [3, "U", 2, "-"], [4, "U", 1, "+"]])


def _fingerprint(directory: Path) -> dict[str, str]:
    """Name -> sha256 of every file in ``directory`` (detects any write, including new WAL/SHM files)."""
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(directory.iterdir())}


def _points(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(22, 3))


def _kept(
    from_id: int, from_state: int, from_cross: int, link: int, p_data: PData, seed: int
) -> KeptTransition:
    """A kept transition to a new configuration with made-up arrays (seeded)."""
    return KeptTransition(
        from_id,
        from_state,
        from_cross,
        link,
        0.05,
        0.1,
        -0.2,
        array_to_blob([seed]),
        array_to_blob(_points(seed)),
        p_data,
    )


# --- opening ------------------------------------------------------------------------------------------


def test_new_database_is_created_at_heads(db_url: str) -> None:
    with open_store(db_url) as store:
        with store.engine.connect() as conn:
            revisions = {r[0] for r in conn.execute(text("SELECT version_num FROM alembic_version"))}
            tables = set(inspect(conn).get_table_names())
            views = set(inspect(conn).get_view_names())
    assert revisions == head_revisions()
    assert {"runs", "topological_states", "configurations", "transitions", "collect_batches"} <= tables
    assert set(VIEW_NAMES) <= views
    # Opening again is a plain open (nothing to upgrade).
    open_store(db_url).close()


def test_sqlite_connections_use_wal_busy_timeout_and_foreign_keys(sqlite_url: str) -> None:
    with open_store(sqlite_url) as store, store.engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert conn.exec_driver_sql("PRAGMA busy_timeout").scalar() >= 30_000
        assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1


def test_models_match_migrations(db_url: str) -> None:
    """Every area's models (twisted/store/*.py) and the migrations describe the same schema."""
    for module in pkgutil.iter_modules(twisted.store.__path__):
        importlib.import_module(f"twisted.store.{module.name}")
    with open_store(db_url) as store, store.engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn, opts={"compare_type": True}), Base.metadata)
    assert diff == []


def test_older_revision_is_upgraded(sqlite_url: str) -> None:
    engine = create_engine(sqlite_url)
    with engine.begin() as conn:
        command.upgrade(alembic_config(conn), "0001")
    engine.dispose()
    with open_store(sqlite_url) as store, store.engine.connect() as conn:
        revisions = {r[0] for r in conn.execute(text("SELECT version_num FROM alembic_version"))}
    assert revisions == head_revisions()


def test_newer_schema_is_refused_and_left_untouched(sqlite_url: str, tmp_path: Path) -> None:
    open_store(sqlite_url).close()
    path = tmp_path / "twisted.db"
    with sqlite3.connect(path) as conn:
        conn.execute("INSERT INTO alembic_version (version_num) VALUES ('9999_future')")
    conn.close()
    before = _fingerprint(tmp_path)
    with pytest.raises(StoreError, match="9999_future.*does not know"):
        open_store(sqlite_url)
    assert _fingerprint(tmp_path) == before


def test_newer_schema_is_refused_on_any_backend(db_url: str) -> None:
    with open_store(db_url) as store, store.session() as session:
        session.execute(text("INSERT INTO alembic_version (version_num) VALUES ('9999_future')"))
    with pytest.raises(StoreError, match="9999_future"):
        open_store(db_url)


def test_random_bytes_file_is_refused_and_left_untouched(tmp_path: Path) -> None:
    path = tmp_path / "notes.db"
    path.write_bytes(np.random.default_rng(0).bytes(4096))
    before = _fingerprint(tmp_path)
    with pytest.raises(StoreError, match="not an SQLite database"):
        open_store(f"sqlite:///{path}")
    assert _fingerprint(tmp_path) == before


def test_text_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "README.txt"
    path.write_text("hello\n" * 100)
    with pytest.raises(StoreError, match="not an SQLite database"):
        open_store(f"sqlite:///{path}")
    assert path.read_text() == "hello\n" * 100


def test_other_sqlite_database_is_refused_and_left_untouched(tmp_path: Path) -> None:
    path = tmp_path / "other.db"
    with sqlite3.connect(path) as conn:
        conn.execute("CREATE TABLE customers (id INTEGER PRIMARY KEY, name TEXT)")
        conn.execute("INSERT INTO customers (name) VALUES ('ada')")
    conn.close()
    before = _fingerprint(tmp_path)
    with pytest.raises(StoreError, match="not a twisted database.*customers"):
        open_store(f"sqlite:///{path}")
    assert _fingerprint(tmp_path) == before


def test_other_postgres_or_sqlite_database_is_refused(db_url: str) -> None:
    engine = create_engine(db_url)
    with engine.begin() as conn:
        conn.execute(text("CREATE TABLE customers (id INTEGER PRIMARY KEY, name TEXT)"))
    engine.dispose()
    with pytest.raises(StoreError, match="not a twisted database"):
        open_store(db_url)


def test_empty_file_is_a_new_database(tmp_path: Path) -> None:
    path = tmp_path / "empty.db"
    path.touch()
    with open_store(f"sqlite:///{path}") as store, store.session() as session:
        assert session.scalar(select(func.count(Run.id))) == 0


@pytest.mark.parametrize(
    ("relative", "message"),
    [
        ("missing_dir/twisted.db", "does not exist"),
        ("a_file/twisted.db", "is not a directory"),
        ("a_dir", "is a directory"),
    ],
)
def test_unusable_paths_are_refused_clearly(tmp_path: Path, relative: str, message: str) -> None:
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "a_dir").mkdir()
    before = _fingerprint(tmp_path / "a_dir") | {"a_file": (tmp_path / "a_file").read_text()}
    with pytest.raises(StoreError, match=message):
        open_store(f"sqlite:///{tmp_path / relative}")
    assert not (tmp_path / "missing_dir").exists()
    assert _fingerprint(tmp_path / "a_dir") | {"a_file": (tmp_path / "a_file").read_text()} == before


def test_missing_database_is_not_created_when_create_is_false(tmp_path: Path) -> None:
    with pytest.raises(StoreError, match="does not exist"):
        open_store(f"sqlite:///{tmp_path / 'nothing.db'}", create=False)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("url", ["mysql://u@h/db", "not a url at all"])
def test_unsupported_urls_are_refused(url: str) -> None:
    with pytest.raises(StoreError, match="sqlite:///"):
        open_store(url)


# --- rows, views, batches -------------------------------------------------------------------------------


def test_arrays_round_trip_exactly() -> None:
    q = np.random.default_rng(1).normal(size=93) * 1e-3
    assert np.array_equal(blob_to_array(array_to_blob(q)), q)
    points = _points(2)
    assert np.array_equal(blob_to_array(array_to_blob(points), (-1, 3)), points)


def test_get_or_create_state_is_unique_per_key(db_url: str) -> None:
    with open_store(db_url) as store:
        with store.session(write=True) as session:
            a = get_or_create_state(session, ONE)
            b = get_or_create_state(session, parse_p_data(ONE.to_json()))
            c = get_or_create_state(session, ONE_MINUS)
        assert a.id == b.id != c.id
        with store.session() as session:
            row = session.get(TopologicalState, a.id)
            assert row is not None and row.key == ONE.key and row.cross == 1
            assert parse_p_data(row.p_data) == ONE


def test_configuration_round_trip(db_url: str) -> None:
    q = np.random.default_rng(3).normal(size=93)
    with open_store(db_url) as store:
        with store.session(write=True) as session:
            run = start_run(session, "collect", {"workers": 2}, seed=7)
            config_id = add_configuration(session, run_id=run.id, p_data=ONE, q=q, points=_points(4)).id
        with store.session() as session:
            config = session.get(Configuration, config_id)
            assert config is not None and config.cross == 1
            assert np.array_equal(config.q_array(), q)
            assert np.array_equal(config.points_array(), _points(4))


def _seed_rows(store: twisted.store.Store) -> dict[str, int]:
    """Hand-made rows: a root, 2 one-crossing configurations (2 states), 1 two-crossing; 2 runs."""
    with store.session(write=True) as session:
        run_a = start_run(session, "collect", {}, seed=1)
        run_b = start_run(session, "collect", {}, seed=2)
        root = add_configuration(session, run_id=run_a.id, p_data=EMPTY, q=np.zeros(3), points=_points(0))
        ids = {"run_a": run_a.id, "run_b": run_b.id, "root": root.id, "root_state": root.state_id}
    batch_a = BatchRecord(
        batch_id=batch_id(run_a.id, 0, 0),
        run_id=run_a.id,
        worker=0,
        seq=0,
        tries={0: TryCount(tried=10, kept=2, rejected=1)},
        transitions=[
            _kept(root.id, root.state_id, 0, 3, ONE, seed=1),
            _kept(root.id, root.state_id, 0, 4, ONE_MINUS, seed=2),
        ],
        sim_seconds=1.5,
    )
    with store.session(write=True) as session:
        new = add_collect_batch(session, batch_a, wall_seconds=3600.0)
    assert new is not None and [c for _, c in new] == [1, 1]
    one_id = new[0][0]
    with store.session() as session:
        one_state = session.get(Configuration, one_id).state_id  # type: ignore[union-attr]
    batch_b = BatchRecord(
        batch_id=batch_id(run_b.id, 1, 0),
        run_id=run_b.id,
        worker=1,
        seq=0,
        tries={0: TryCount(tried=5, kept=0, rejected=0), 1: TryCount(tried=20, kept=1, rejected=2)},
        transitions=[
            _kept(one_id, one_state, 1, 7, TWO, seed=3),
        ],
        sim_seconds=2.0,
    )
    with store.session(write=True) as session:
        assert add_collect_batch(session, batch_b, wall_seconds=1800.0) is not None
    ids.update(one=one_id, batch_a_tries=len(batch_a.tries))
    return ids


def test_views_count_hand_inserted_rows(db_url: str) -> None:
    with open_store(db_url) as store:
        ids = _seed_rows(store)
        with store.session() as session:
            by_cross = {r["cross"]: r for r in states_by_cross(session)}
            assert {
                c: (r["states"], r["visited_states"], r["configurations"]) for c, r in by_cross.items()
            } == {
                0: (1, 1, 1),
                1: (2, 2, 2),
                2: (1, 1, 1),
            }
            acceptance = {r["from_cross"]: r for r in acceptance_by_cross(session)}
            assert (acceptance[0]["tried"], acceptance[0]["kept"], acceptance[0]["rejected"]) == (15, 2, 1)
            assert acceptance[0]["kept_rate"] == pytest.approx(2 / 15)
            assert (acceptance[1]["tried"], acceptance[1]["kept"]) == (20, 1)
            throughput = {r["run_id"]: r for r in collect_throughput(session)}
            a, b = throughput[ids["run_a"]], throughput[ids["run_b"]]
            assert (a["tried"], a["kept"], a["rejected"]) == (10, 2, 1)
            assert a["kept_per_hour"] == pytest.approx(2.0) and a["kept_rate"] == pytest.approx(0.2)
            assert (b["tried"], b["kept"]) == (25, 1) and b["kept_per_hour"] == pytest.approx(2.0)
            per_run = {r["run_id"]: r for r in transitions_per_run(session)}
            assert (per_run[ids["run_a"]]["transitions"], per_run[ids["run_a"]]["configurations"]) == (2, 3)
            assert per_run[ids["run_a"]]["max_cross"] == 1 and per_run[ids["run_b"]]["max_cross"] == 2
            assert transitions_by_cross(session) == [
                {"from_cross": 0, "to_cross": 1, "transitions": 2},
                {"from_cross": 1, "to_cross": 2, "transitions": 1},
            ]
            visits = {
                r[0]: r[1:]
                for r in session.execute(
                    text("SELECT key, configurations, transitions_in, transitions_out FROM state_visits")
                )
            }
            assert visits[EMPTY.key] == (1, 0, 2)
            assert visits[ONE.key] == (1, 1, 1)
            assert visits[TWO.key] == (1, 1, 0)
            run = session.get(Run, ids["run_a"])
            assert run is not None and run.sim_seconds == pytest.approx(1.5) and run.wall_seconds == 3600.0


def test_same_batch_twice_is_a_no_op(db_url: str) -> None:
    with open_store(db_url) as store:
        ids = _seed_rows(store)

        def counts() -> tuple[int, ...]:
            with store.session() as session:
                run = session.get(Run, ids["run_a"])
                assert run is not None
                return (
                    session.scalar(select(func.count(Transition.id))) or 0,
                    session.scalar(select(func.count(Configuration.id))) or 0,
                    session.scalar(select(func.count(CollectBatch.batch_id))) or 0,
                    run.tried,
                    run.kept,
                )

        before = counts()
        again = BatchRecord(
            batch_id=batch_id(ids["run_a"], 0, 0),
            run_id=ids["run_a"],
            worker=0,
            seq=0,
            tries={0: TryCount(tried=10, kept=1)},
            transitions=[_kept(ids["root"], ids["root_state"], 0, 3, ONE, seed=1)],
        )
        with store.session(write=True) as session:
            assert add_collect_batch(session, again) is None
        assert counts() == before


def test_configuration_index_and_sampling(db_url: str) -> None:
    with open_store(db_url) as store:
        ids = _seed_rows(store)
        with store.session() as session:
            all_ids, crosses = configuration_index(session)
            assert crosses.tolist() == [0, 1, 1, 2] and all_ids[0] == ids["root"]
            low_ids, _ = configuration_index(session, max_cross=1, after_id=int(all_ids[0]))
            assert low_ids.tolist() == all_ids[1:3].tolist()
            sampled = sample_configurations(session, np.random.default_rng(0), 50, cross=1)
            assert len(sampled) == 50 and {c.cross for c in sampled} == {1}
            assert len({c.id for c in sampled}) == 2  # both one-crossing configurations drawn
            assert sample_configurations(session, np.random.default_rng(0), 3, cross=5) == []


def test_stale_running_runs_are_marked_interrupted(db_url: str) -> None:
    with open_store(db_url) as store:
        with store.session(write=True) as session:
            dead = start_run(session, "collect", {}, seed=1)
            dead.pid = 2**22 + 12345  # above pid_max of typical systems: no such process
            alive = start_run(session, "collect", {}, seed=2)  # this test's own pid
            done = start_run(session, "collect", {}, seed=3)
            end_run(session, done.id, "finished")
        with store.session(write=True) as session:
            assert mark_stale_runs(session, "collect") == [dead.id]
        with store.session() as session:
            statuses = {r.id: r.status for r in session.scalars(select(Run))}
        assert statuses == {dead.id: "interrupted", alive.id: "running", done.id: "finished"}


def test_a_row_by_id_or_the_newest_and_a_missing_id_lists_the_ids(db_url: str) -> None:
    with open_store(db_url) as store:
        with store.session() as session:
            assert by_id_or_newest(session, Run, None, what="run", see="twisted runs") is None
        with store.session(write=True) as session:
            first, second = (start_run(session, "collect", {}).id for _ in range(2))
            end_run(session, first, "failed", "it broke")
        with store.session() as session:
            newest = by_id_or_newest(session, Run, None, what="run", see="twisted runs")
            asked = by_id_or_newest(session, Run, first, what="run", see="twisted runs")
            assert newest is not None and newest.id == second and newest.ended_at is None
            assert asked is not None and (asked.status, asked.message) == ("failed", "it broke")
            assert asked.ended_at is not None
            missing = second + 7
            listed = rf"no run {missing} .*\(ids: \[{first}, {second}\]\); see `twisted runs`"
            with pytest.raises(LookupError, match=listed):
                by_id_or_newest(session, Run, missing, what="run", see="twisted runs")


def test_reader_does_not_block_writer(sqlite_url: str, tmp_path: Path) -> None:
    """A reader holding a read transaction open (as a sqlite3 shell would) does not stop commits."""
    with open_store(sqlite_url) as store:
        _seed_rows(store)
        reader = sqlite3.connect(tmp_path / "twisted.db", isolation_level=None)
        reader.execute("BEGIN")
        assert reader.execute("SELECT COUNT(*) FROM configurations").fetchone() == (4,)
        started = time.perf_counter()
        with store.session(write=True) as session:
            run = start_run(session, "collect", {})
            add_configuration(session, run_id=run.id, p_data=EMPTY, q=np.zeros(2), points=_points(9))
        assert time.perf_counter() - started < 5.0
        assert reader.execute("SELECT COUNT(*) FROM configurations").fetchone() == (4,)  # its snapshot
        reader.execute("COMMIT")
        assert reader.execute("SELECT COUNT(*) FROM configurations").fetchone() == (5,)
        reader.close()


def test_two_stores_write_the_same_file_concurrently(sqlite_url: str) -> None:
    """Two writers (threads with their own engines) interleave read-then-write transactions without errors."""
    open_store(sqlite_url).close()
    errors: list[BaseException] = []

    def writer(worker: int) -> None:
        try:
            with open_store(sqlite_url) as store:
                with store.session(write=True) as session:
                    run_id = start_run(session, "collect", {}).id
                for seq in range(15):
                    with store.session(write=True) as session:
                        # read then write in one transaction: the pattern that fails without BEGIN IMMEDIATE
                        state = get_or_create_state(session, ONE if seq % 2 else ONE_MINUS)
                        add_configuration(
                            session, run_id=run_id, p_data=TWO, q=np.full(3, seq), points=_points(seq)
                        )
                        assert state.id is not None
        except BaseException as exc:  # noqa: BLE001 - reported by the main thread
            errors.append(exc)

    threads = [threading.Thread(target=writer, args=(w,)) for w in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    with open_store(sqlite_url) as store, store.session() as session:
        assert session.scalar(select(func.count(Configuration.id))) == 45
        assert session.scalar(select(func.count(TopologicalState.id))) == 3


def test_open_retries_a_new_file_that_another_process_holds_locked(
    sqlite_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Collectors started together on a new file: an open that meets "database is locked" is retried."""
    from twisted.store import db

    real = db._open_store
    calls: list[int] = []

    def flaky(parsed, **kwargs):  # noqa: ANN001, ANN003, ANN202 - db._open_store's signature
        calls.append(1)
        if len(calls) < 3:
            raise db.StoreError(f"cannot create or upgrade database file {parsed}: database is locked")
        return real(parsed, **kwargs)

    monkeypatch.setattr(db, "_open_store", flaky)
    monkeypatch.setattr(db.time, "sleep", lambda _s: None)
    with db.open_store(sqlite_url) as store:
        assert store.dialect == "sqlite"
    assert len(calls) == 3

    def refused(parsed, **kwargs):  # noqa: ANN001, ANN003, ANN202
        calls.append(1)
        raise db.StoreError("database file x is not an SQLite database")

    calls.clear()
    monkeypatch.setattr(db, "_open_store", refused)
    with pytest.raises(db.StoreError, match="not an SQLite database"):
        db.open_store(sqlite_url)
    assert len(calls) == 1  # other errors are not retried
