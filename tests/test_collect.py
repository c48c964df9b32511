"""`twisted collect` / `twisted stats`: D_Q scheme, bad input, signals, SIGKILL + resume, two collectors."""

from __future__ import annotations

import hashlib
import logging
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select

from tests.collect_checks import check_collect_rows
from twisted.collect import CollectError, CollectOptions, DQIndex, collect
from twisted.sim import Curve, RopeSim
from twisted.store import Configuration, Run, TopologicalState, Transition, open_store
from twisted.topology import parse_p_data

REPO = Path(__file__).resolve().parents[1]


def _twisted(db: str, *args: str, timeout_s: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "cli.main", "--db", db, *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def _err(result: subprocess.CompletedProcess[str]) -> str:
    """stderr with rich's line wrapping undone."""
    return " ".join(result.stderr.split())


def _start(db: str, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "cli.main", "--db", db, "collect", *args],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _query(path: Path, sql: str) -> list[tuple]:
    """Read through a separate read-only sqlite3 connection (what a user's shell would do)."""
    conn = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, timeout=30)
    try:
        return conn.execute(sql).fetchall()
    finally:
        conn.close()


def _wait_for(path: Path, sql: str, at_least: int, timeout_s: float = 90) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if path.exists():
            try:
                if _query(path, sql)[0][0] >= at_least:
                    return
            except sqlite3.OperationalError:
                pass  # tables not created yet
        time.sleep(0.2)
    raise AssertionError(f"timed out waiting for {sql} >= {at_least}")


def _children(pid: int) -> list[int]:
    """Direct children of ``pid`` (from /proc)."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(entry.name))
    return out


def _gone(pids: list[int], timeout_s: float = 30) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        alive = []
        for pid in pids:
            try:
                state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
            except OSError:
                continue
            if state != "Z":
                alive.append(pid)
        if not alive:
            return True
        time.sleep(0.2)
    return False


# --- options and bad input (no simulation) ---------------------------------------------------------------


@pytest.mark.parametrize("hours", ["-1", "0", "abc", "nan", "inf"])
def test_bad_hours_exit_2_and_create_nothing(tmp_path: Path, hours: str) -> None:
    result = _twisted(f"sqlite:///{tmp_path / 'x.db'}", "collect", "--hours", hours, "--workers", "1")
    assert result.returncode == 2, result.stderr
    assert "--hours" in _err(result)
    assert list(tmp_path.iterdir()) == []


def test_non_database_file_exit_2_and_untouched(tmp_path: Path) -> None:
    path = tmp_path / "photo.db"
    path.write_bytes(np.random.default_rng(5).bytes(10_000))
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    result = _twisted(f"sqlite:///{path}", "collect", "--hours", "0.01", "--workers", "1")
    assert result.returncode == 2
    assert "not an SQLite database" in _err(result)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest
    assert sorted(p.name for p in tmp_path.iterdir()) == ["photo.db"]


def test_unwritable_database_path_exit_2(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("x")
    result = _twisted(f"sqlite:///{tmp_path / 'file' / 'twisted.db'}", "collect", "--hours", "1")
    assert result.returncode == 2
    assert "cannot create" in _err(result) and "not a directory" in _err(result)


def test_stats_on_missing_database_exit_2(tmp_path: Path) -> None:
    result = _twisted(f"sqlite:///{tmp_path / 'none.db'}", "stats")
    assert result.returncode == 2 and "does not exist" in _err(result)
    assert list(tmp_path.iterdir()) == []


def test_db_command_shows_revisions_and_rows(sqlite_url: str) -> None:
    open_store(sqlite_url).close()
    result = _twisted(sqlite_url, "db")
    assert result.returncode == 0, result.stderr
    assert "schema revisions" in result.stdout and "transitions" in result.stdout


def test_options_are_validated() -> None:
    for bad in (
        CollectOptions(hours=-0.5),
        CollectOptions(hours=1, workers=0),
        CollectOptions(hours=1, max_cross=0),
        CollectOptions(hours=1, cross_bias=float("nan")),
        CollectOptions(hours=1, cross_bias=-1),
        CollectOptions(hours=1, max_kept=0),
    ):
        with pytest.raises(CollectError):
            bad.validate()


def test_dq_sampling_is_biased_toward_more_crossings() -> None:
    dq = DQIndex(max_cross=3, cross_bias=1.0)
    dq.add(np.arange(1, 8), np.array([0, 1, 1, 2, 2, 2, 3]))
    # weights 1+c for the counts present below max_cross (3 crossings cannot rise and stay <= 3)
    assert dq.cross_probabilities() == pytest.approx({0: 1 / 6, 1: 2 / 6, 2: 3 / 6})
    rng = np.random.default_rng(0)
    draws = np.array([dq.sample(rng) for _ in range(6000)])
    assert 7 not in draws
    share = {c: np.isin(draws, ids).mean() for c, ids in dq.by_cross.items()}
    assert share == pytest.approx({0: 1 / 6, 1: 2 / 6, 2: 3 / 6}, abs=0.03)
    # uniform inside a crossing count
    assert np.mean(draws == 2) == pytest.approx(np.mean(draws == 3), abs=0.03)
    uniform = DQIndex(max_cross=3, cross_bias=0.0)
    uniform.add(np.arange(1, 8), np.array([0, 1, 1, 2, 2, 2, 3]))
    assert uniform.cross_probabilities() == pytest.approx({0: 1 / 3, 1: 1 / 3, 2: 1 / 3})


# --- collecting ---------------------------------------------------------------------------------------


def test_collect_keeps_replayable_rising_transitions(
    sqlite_url: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG, logger="twisted.collect")
    with open_store(sqlite_url) as store:
        summary = collect(store, CollectOptions(hours=0.05, workers=1, seed=3, max_kept=4, batch_size=2))
    assert summary.status == "finished" and summary.kept >= 4 and summary.tried > summary.kept
    # the log tells the run's story: its start, one line per committed batch, how it ended
    lines = [r.getMessage() for r in caplog.records if r.name.startswith("twisted.collect")]
    assert lines[0].startswith(f"collect run {summary.run_id} started: seed 3, 1 workers")
    assert sum(" committed: " in line for line in lines) == summary.batches
    ended = f"collect run {summary.run_id} finished: kept {summary.kept} of {summary.tried} tried"
    assert lines[-1].startswith(ended)
    check_collect_rows(sqlite_url)
    sim = RopeSim()
    with open_store(sqlite_url) as store, store.session() as session:
        run = session.get(Run, summary.run_id)
        assert run is not None and run.status == "finished" and run.seed == 3 and run.ended_at is not None
        assert run.parameters["workers"] == 1 and run.parameters["max_kept"] == 4
        for t in session.scalars(select(Transition)):
            start = session.get(Configuration, t.from_configuration_id)
            end = session.get(Configuration, t.to_configuration_id)
            end_state = session.get(TopologicalState, t.to_state_id)
            assert start is not None and end is not None and end_state is not None
            assert start.cross == t.from_cross < t.to_cross == end.cross == end_state.cross <= 6
            # the stored transition replays exactly in the simulator
            sim.set_state(start.q_array())
            assert sim.apply(Curve(t.link, t.z_max_m, t.x_m, t.y_m)).ok
            assert np.array_equal(sim.state(), end.q_array())
            assert np.array_equal(sim.link_points(), end.points_array())
            assert sim.p_data() == parse_p_data(end_state.p_data)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_signal_stops_cleanly_and_keeps_rows(tmp_path: Path, signum: int) -> None:
    path = tmp_path / "twisted.db"
    url = f"sqlite:///{path}"
    process = _start(url, "--hours", "0.5", "--workers", "1", "--batch-size", "1", "--seed", "1")
    try:
        _wait_for(path, "SELECT COUNT(*) FROM collect_batches WHERE kept > 0", 1)
        before = set(_query(path, "SELECT id, from_configuration_id, to_configuration_id FROM transitions"))
        children = _children(process.pid)
        process.send_signal(signum)
        _, stderr = process.communicate(timeout=60)
    finally:
        process.kill()
    assert process.returncode == 128 + signum, stderr  # 130 for Ctrl-C, 143 for SIGTERM
    assert _gone(children), "worker processes outlived the collector"
    after = set(_query(path, "SELECT id, from_configuration_id, to_configuration_id FROM transitions"))
    assert before <= after and len(after) >= 1
    assert _query(path, "SELECT status, message FROM runs") == [("interrupted", f"stopped by {signum.name}")]
    check_collect_rows(url)


@pytest.mark.slow
def test_sigkill_then_resume_loses_and_duplicates_nothing(tmp_path: Path) -> None:
    path = tmp_path / "twisted.db"
    url = f"sqlite:///{path}"
    process = _start(url, "--hours", "0.5", "--workers", "2", "--batch-size", "1", "--seed", "11")
    try:
        _wait_for(path, "SELECT COUNT(*) FROM collect_batches WHERE kept > 0", 3)
        children = _children(process.pid)
        committed = set(_query(path, "SELECT * FROM transitions"))
        batches = set(_query(path, "SELECT batch_id, tried, kept FROM collect_batches"))
        process.kill()  # SIGKILL: no chance to flush or mark the run
        process.wait(timeout=30)
    finally:
        process.kill()
    assert _gone(children), "worker processes outlived the killed collector"
    after_kill = set(_query(path, "SELECT * FROM transitions"))
    assert committed <= after_kill
    assert _query(path, "SELECT status FROM runs") == [("running",)]
    check_collect_rows(url)

    resumed = _twisted(
        url, "collect", "--hours", "0.03", "--workers", "1", "--max-kept", "3", "--seed", "12", timeout_s=170
    )
    assert resumed.returncode == 0, resumed.stderr
    assert set(_query(path, "SELECT * FROM transitions")) >= after_kill
    assert set(_query(path, "SELECT batch_id, tried, kept FROM collect_batches")) >= batches
    assert _query(path, "SELECT id, status FROM runs ORDER BY id") == [(1, "interrupted"), (2, "finished")]
    # the same D_Q: run 2 added no new root and started from configurations that were already there
    check_collect_rows(url)
    starts = _query(path, "SELECT MIN(from_configuration_id) FROM transitions WHERE run_id = 2")[0][0]
    assert starts is not None


@pytest.mark.slow
def test_two_collectors_share_one_sqlite_file(tmp_path: Path) -> None:
    path = tmp_path / "twisted.db"
    url = f"sqlite:///{path}"
    first = _start(
        url, "--hours", "0.04", "--workers", "1", "--max-kept", "6", "--batch-size", "1", "--seed", "1"
    )
    second = _start(
        url, "--hours", "0.04", "--workers", "1", "--max-kept", "6", "--batch-size", "1", "--seed", "2"
    )
    try:
        outputs = [p.communicate(timeout=170) for p in (first, second)]
    finally:
        first.kill()
        second.kill()
    assert (first.returncode, second.returncode) == (0, 0), outputs
    assert sorted(_query(path, "SELECT status FROM runs")) == [("finished",), ("finished",)]
    assert len(_query(path, "SELECT DISTINCT run_id FROM transitions")) == 2  # both kept transitions
    (a_start, a_end), (b_start, b_end) = _query(path, "SELECT started_at, ended_at FROM runs ORDER BY id")
    assert a_start < b_end and b_start < a_end, "the two collectors did not run at the same time"
    check_collect_rows(url)
    stats = _twisted(url, "stats", "--json")
    assert stats.returncode == 0 and '"acceptance"' in stats.stdout
