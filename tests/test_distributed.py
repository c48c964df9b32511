"""Collection and evaluation on a local Ray cluster (2 CPUs, one per module): SQLite with the driver as the
one writer, PostgreSQL with the workers writing, a worker killed mid-run, eval tasks, the CLI's --ray."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import func, select
from typer.testing import CliRunner

from tests.collect_checks import check_collect_rows, replay_some
from twisted.collect import CollectOptions, CollectProgress
from twisted.experiments.runner import EvalOptions, run_eval
from twisted.store import CollectBatch, Run, Transition, open_store
from twisted.store.experiments import EvalResult, ProblemRecord, save_problem_set
from twisted.topology import parse_p_data

ray = pytest.importorskip("ray")

from twisted.distributed import (  # noqa: E402 - after the skip: needs ray
    DistributedError,
    RayBackend,
    collect_on_ray,
    ray_cluster,
    resolve_address,
)

pytestmark = pytest.mark.ray
REPO = Path(__file__).resolve().parents[1]
ONE = parse_p_data([[1, "O", 2, "+"], [2, "U", 1, "+"]])
ONE_UNDER = parse_p_data([[1, "U", 2, "+"], [2, "O", 1, "+"]])


@pytest.fixture(scope="module", autouse=True)
def local_ray() -> Any:
    """One local Ray cluster of 2 CPUs for the module (starting one takes ~10 s)."""
    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level="WARNING")
    yield ray
    ray.shutdown()


def committed(url: str) -> tuple[set[tuple], set[tuple]]:
    """(transitions, batches) committed so far, read through a separate connection."""
    with open_store(url) as store, store.session() as session:
        transitions = {tuple(r) for r in session.execute(select(Transition.__table__)).all()}
        batches = {tuple(r) for r in session.execute(select(CollectBatch.batch_id, CollectBatch.kept)).all()}
    return transitions, batches


def last_seq(url: str) -> dict[int, int]:
    """The last committed batch seq of each worker."""
    with open_store(url) as store, store.session() as session:
        rows = session.execute(
            select(CollectBatch.worker, func.max(CollectBatch.seq)).group_by(CollectBatch.worker)
        )
        return {int(w): int(seq) for w, seq in rows}


def _parent(pid: int) -> int:
    try:
        return int((Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[1])
    except (OSError, IndexError, ValueError):
        return 0


def collect_worker_pids() -> list[int]:
    """Processes of this test session's CollectWorker actors (Ray names them ``ray::CollectWorker...``).

    Only descendants of this process (the local cluster's raylet is our child): another session's
    cluster on the same machine is left alone.
    """
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                cmdline = (entry / "cmdline").read_bytes()
            except OSError:
                continue
            if not cmdline.startswith(b"ray::CollectWorker"):
                continue
            pid = ancestor = int(entry.name)
            while ancestor > 1 and ancestor != os.getpid():
                ancestor = _parent(ancestor)
            if ancestor == os.getpid():
                pids.append(pid)
    return sorted(pids)


# --- collect ------------------------------------------------------------------------------------------


def test_collect_into_sqlite_through_one_writer(sqlite_url: str) -> None:
    seen: list[CollectProgress] = []
    with open_store(sqlite_url) as store:
        options = CollectOptions(hours=60 / 3600, seed=3, max_kept=4, batch_size=2)
        summary = collect_on_ray(store, options, on_progress=lambda p: seen.append(p))
    assert summary.status == "finished", summary.message
    assert summary.workers == 2 and summary.kept >= 4 and summary.tried > summary.kept
    assert summary.kept == sum(summary.kept_by_to_cross.values())
    assert seen and seen[-1].kept == summary.kept
    check_collect_rows(sqlite_url)
    replay_some(sqlite_url)
    with open_store(sqlite_url) as store, store.session() as session:
        run = session.get(Run, summary.run_id)
        assert run is not None and run.status == "finished" and run.seed == 3
        assert run.parameters["workers"] == 2 and run.parameters["ray"]["writer"] == "driver"
        workers = set(session.scalars(select(CollectBatch.worker).where(CollectBatch.kept > 0)))
    assert workers <= {0, 1}


@pytest.mark.postgres
def test_collect_into_postgres_written_by_the_workers(postgres_url: str) -> None:
    with open_store(postgres_url) as store:
        summary = collect_on_ray(store, CollectOptions(hours=60 / 3600, seed=4, max_kept=4, batch_size=2))
    assert summary.status == "finished", summary.message
    assert summary.kept >= 4
    check_collect_rows(postgres_url)
    replay_some(postgres_url)
    with open_store(postgres_url) as store, store.session() as session:
        run = session.get(Run, summary.run_id)
        assert run is not None and run.parameters["ray"]["writer"] == "workers"
        assert run.wall_seconds == pytest.approx(summary.wall_seconds) and run.wall_seconds > 0


@pytest.mark.postgres
def test_killed_worker_is_restarted_and_nothing_is_lost_or_stored_twice(postgres_url: str) -> None:
    killed: list[tuple[int, float]] = []
    snapshot: list[tuple[set[tuple], set[tuple]]] = []
    seqs_at_kill: list[dict[int, int]] = []

    def kill_one(progress: CollectProgress) -> None:
        if not killed and progress.batches >= 3:
            snapshot.append(committed(postgres_url))
            seqs_at_kill.append(last_seq(postgres_url))
            pid = collect_worker_pids()[0]
            os.kill(pid, signal.SIGKILL)  # mid-batch: no chance to finish or roll back by itself
            killed.append((pid, progress.elapsed_s))

    with open_store(postgres_url) as store:
        options = CollectOptions(hours=16 / 3600, seed=5, batch_size=1, batch_seconds=1.0)
        summary = collect_on_ray(store, options, max_restarts=1, on_progress=kill_one)
    assert killed, "no worker was killed"
    assert summary.status == "finished", summary.message
    transitions_before, batches_before = snapshot[0]
    transitions_after, batches_after = committed(postgres_url)
    assert transitions_before <= transitions_after and batches_before <= batches_after
    assert len(batches_after) > len(batches_before)
    check_collect_rows(postgres_url)
    # Ray restarted the killed actor: both workers committed batches after the kill
    assert last_seq(postgres_url).keys() == {0, 1}
    assert all(last_seq(postgres_url)[w] > seq for w, seq in seqs_at_kill[0].items())
    assert killed[0][0] not in collect_worker_pids()


def test_dead_worker_without_restart_loses_one_batch_and_the_run_goes_on(sqlite_url: str) -> None:
    killed: list[float] = []
    snapshot: list[tuple[set[tuple], set[tuple]]] = []

    def kill_one(progress: CollectProgress) -> None:
        # kill only once both workers have committed, so each shows up in the batch counts below
        if not killed and progress.batches >= 2 and len(last_seq(sqlite_url)) == 2:
            snapshot.append(committed(sqlite_url))
            os.kill(collect_worker_pids()[-1], signal.SIGKILL)
            killed.append(progress.elapsed_s)

    with open_store(sqlite_url) as store:
        options = CollectOptions(hours=10 / 3600, seed=6, batch_size=1, batch_seconds=1.0)
        summary = collect_on_ray(store, options, max_restarts=0, on_progress=kill_one)
    assert killed
    assert summary.status == "finished"
    assert summary.message is not None and "died, lost its batch" in summary.message
    transitions_before, batches_before = snapshot[0]
    transitions_after, batches_after = committed(sqlite_url)
    assert transitions_before <= transitions_after and batches_before <= batches_after
    check_collect_rows(sqlite_url)
    # the survivor went on: it committed more batches than the dead worker
    with open_store(sqlite_url) as store, store.session() as session:
        per_worker = dict(
            session.execute(select(CollectBatch.worker, func.count()).group_by(CollectBatch.worker)).all()
        )
    assert len(per_worker) == 2 and max(per_worker.values()) > min(per_worker.values())


def test_options_that_do_not_fit_the_cluster_are_refused(sqlite_url: str) -> None:
    with open_store(sqlite_url) as store:
        with pytest.raises(DistributedError, match="more than the 2 CPUs"):
            collect_on_ray(store, CollectOptions(hours=0.01), workers=3)
        with pytest.raises(DistributedError, match="SQLite"):
            collect_on_ray(store, CollectOptions(hours=0.01), writer="workers")
        with store.session() as session:
            assert session.scalar(select(func.count(Run.id))) == 0  # nothing started


def test_resolve_address() -> None:
    assert resolve_address(True, None) is None
    assert resolve_address(True, "auto") == "auto"
    assert resolve_address(False, None) is None
    with pytest.raises(DistributedError, match="goes after --ray"):
        resolve_address(False, "10.0.0.1:6379")
    with pytest.raises(DistributedError, match="several seeds go in one argument"):
        resolve_address(False, "3")  # what `--seeds 2 3` leaves over


def test_ray_cluster_reuses_the_connection_it_finds() -> None:
    with ray_cluster("an-address-never-used-because-ray-is-initialised") as module:
        assert module.is_initialized()
    assert ray.is_initialized()  # left open: it was not ours


# --- eval ---------------------------------------------------------------------------------------------


def _two_goal_set(url: str) -> None:
    with open_store(url) as store, store.session(write=True) as session:
        problems = [ProblemRecord(None, i, p, 0, "imported") for i, p in enumerate((ONE, ONE_UNDER))]
        save_problem_set(session, "ones", problems, source="imported")


@pytest.mark.parametrize("backend", ["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def test_eval_tasks_on_ray_store_one_row_each_and_rerun_skips_them(
    backend: str, request: pytest.FixtureRequest
) -> None:
    url = request.getfixturevalue("sqlite_url" if backend == "sqlite" else "postgres_url")
    _two_goal_set(url)
    request = EvalOptions("ones", "random-low", timeout_s=1.5, seeds=[0, 1], workers=1)
    with open_store(url) as store:
        summary = run_eval(store, url, request, backend=RayBackend())
        assert summary.status == "finished" and summary.total == 4
        assert sorted((o.goal_key, o.seed) for o in summary.outcomes) == sorted(
            (g.key, s) for g in (ONE, ONE_UNDER) for s in (0, 1)
        )
        assert {o.status for o in summary.outcomes} <= {"solved", "timeout"}
        with store.session() as session:
            rows = session.scalars(select(EvalResult)).all()
            hosts_pids = {(r.host, r.pid) for r in rows}
        assert len(rows) == 4 and all(r.status in ("solved", "timeout") for r in rows)
        assert all(pid != os.getpid() for _, pid in hosts_pids)  # run by Ray workers, not here
        again = run_eval(store, url, request, backend=RayBackend())
    assert again.already_done == 4 and again.outcomes == []


# --- CLI ----------------------------------------------------------------------------------------------


def _cli(*args: str) -> Any:
    from cli.main import app

    return CliRunner().invoke(app, list(args))


def test_cli_collect_with_ray(sqlite_url: str) -> None:
    result = _cli("--db", sqlite_url, "collect", "--hours", "0.01", "--max-kept", "2", "--ray", "--seed", "8")
    assert result.exit_code == 0, result.output
    assert "kept" in result.output
    check_collect_rows(sqlite_url)
    with open_store(sqlite_url) as store, store.session() as session:
        run = session.scalars(select(Run)).one()
        assert run.status == "finished" and run.parameters["ray"]["writer"] == "driver"


def test_cli_ray_errors_exit_2(sqlite_url: str) -> None:
    result = _cli("--db", sqlite_url, "collect", "--hours", "0.01", "--ray", "--workers", "3")
    assert result.exit_code == 2 and "more than the 2 CPUs" in " ".join(result.output.split())
    result = _cli("--db", sqlite_url, "collect", "--hours", "0.01", "somewhere:6379")
    assert result.exit_code == 2 and "after --ray" in " ".join(result.output.split())


def test_cli_without_ray_installed_says_how_to_install(tmp_path: Path) -> None:
    # ray made unimportable in a fresh interpreter (what a base install without the extra looks like)
    code = (
        "import sys; sys.modules['ray'] = None; sys.argv = ['twisted', '--db', sys.argv[1], 'collect', "
        "'--hours', '0.01', '--ray']; from cli.main import run; run()"
    )
    result = subprocess.run(
        [sys.executable, "-c", code, f"sqlite:///{tmp_path / 'x.db'}"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    err = " ".join(result.stderr.split())
    assert result.returncode == 2, result.stderr
    assert "pip install 'twisted-knots[distributed]'" in err


def test_cli_eval_with_ray(sqlite_url: str) -> None:
    _two_goal_set(sqlite_url)
    args = ("--db", sqlite_url, "eval", "--set", "ones", "--planner", "random-low", "--timeout", "1")
    result = _cli(*args, "--ray")
    assert result.exit_code == 0, result.output
    with open_store(sqlite_url) as store, store.session() as session:
        rows = session.scalars(select(EvalResult)).all()
    assert len(rows) == 2 and {r.status for r in rows} <= {"solved", "timeout"}
    result = _cli(*args, "--ray", "--workers", "3")
    assert result.exit_code == 2 and "more than the 2 CPUs" in " ".join(result.output.split())


def test_cli_improve_with_ray_runs_each_search_as_a_ray_task(sqlite_url: str, tmp_path: Path) -> None:
    """`improve --ray`: every search of a generation (three training goals, one tuning goal) is a Ray
    task of the eval scheduler's backend (its run row made by a Ray worker, not by this process), and
    the outcomes are recorded under their goals' order."""
    import json

    from twisted.moves import enumerate_states
    from twisted.store.improve import lineage_rows

    goals = [p.to_list() for p in enumerate_states(1)[1]]
    for name, chosen in (("tune-ray", goals[:1]), ("train-ray", goals[1:4])):
        path = tmp_path / f"{name}.json"
        content = {"format": "twisted-goal-set/1", "name": name, "seed": 1, "goals": chosen}
        path.write_text(json.dumps(content))
        assert _cli("--db", sqlite_url, "problems", "import", str(path)).exit_code == 0
    (tmp_path / "none").mkdir()
    args = ["--tune-set", "tune-ray", "--train-set", "train-ray", "--name", "ray", "--generations", "1"]
    args += ["--goal-iterations", "4", "--tune-iterations", "2", "--epochs", "1", "--batch-size", "16"]
    result = _cli("--db", sqlite_url, "improve", *args, "--goalsets", str(tmp_path / "none"), "--ray")
    assert result.exit_code == 0, result.output
    with open_store(sqlite_url) as store:
        rows = lineage_rows(store, "ray")
        with store.session() as session:
            runs = {r.id: r for r in session.scalars(select(Run))}
    assert [r.status for r in rows] == ["finished", "finished"]
    planned = rows[1].training_goals
    assert [o["index"] for o in planned] == [0, 1, 2] and [o["seed"] for o in planned] == [1000, 1001, 1002]
    search_runs = [o["run_id"] for r in rows for o in (*r.training_goals, *r.tune_results)]
    assert len(search_runs) == 5 and all(runs[i].parameters["improve"] == "ray" for i in search_runs)
    assert all(runs[i].pid not in (None, os.getpid()) for i in search_runs)  # run by Ray workers
