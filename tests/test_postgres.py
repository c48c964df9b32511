"""The same commands and schema on a real PostgreSQL server (started by the ``postgres_admin_url`` fixture).

The store's own tests run on both backends through ``db_url``; these add what only shows with several
processes or the whole CLI: the multi-process collector into PostgreSQL and resuming its D_Q, two
collectors at once, concurrent first opens (migrations under an advisory lock), every command with
``--db postgresql+psycopg://...``, and clear errors for an unreachable server.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from sqlalchemy import select, text
from sqlalchemy.engine import make_url
from typer.testing import CliRunner

from cli.main import app
from tests.collect_checks import check_collect_rows, replay_some
from tests.postgres_server import free_port
from twisted.collect import CollectOptions, collect, collection_stats
from twisted.store import Run, head_revisions, open_store
from twisted.store.db import StoreError

pytestmark = pytest.mark.postgres
REPO = Path(__file__).resolve().parents[1]
ONE_CROSSING = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
runner = CliRunner()


def _cli(url: str, *args: str) -> tuple[int, str]:
    result = runner.invoke(app, ["--db", url, *args])
    return result.exit_code, result.output


def test_multiprocess_collect_into_postgres_then_again(postgres_url: str) -> None:
    with open_store(postgres_url) as store:
        assert store.dialect == "postgresql"
        first = collect(store, CollectOptions(hours=0.02, workers=2, seed=1, max_kept=3, batch_size=1))
        second = collect(store, CollectOptions(hours=0.02, workers=1, seed=2, max_kept=1, batch_size=1))
    assert (first.status, second.status) == ("finished", "finished")
    assert first.kept >= 3 and second.kept >= 1
    check_collect_rows(postgres_url)
    replay_some(postgres_url)
    with open_store(postgres_url) as store:
        stats = collection_stats(store)
        with store.session() as session:
            runs = session.execute(select(Run.id, Run.status, Run.kept).order_by(Run.id)).all()
    assert [(r.id, r.status) for r in runs] == [(1, "finished"), (2, "finished")]
    assert sum(row["transitions_in"] for row in stats["by_cross"]) == first.kept + second.kept
    assert [row["run_id"] for row in stats["runs"]] == [1, 2]


@pytest.mark.slow
def test_two_collectors_write_one_postgres_database(postgres_url: str) -> None:
    common = ["--hours", "0.05", "--workers", "1", "--max-kept", "2", "--batch-size", "1"]
    processes = [
        subprocess.Popen(
            [sys.executable, "-m", "cli.main", "--db", postgres_url, "collect", *common, "--seed", str(seed)],
            cwd=REPO,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for seed in (1, 2)
    ]
    try:
        outputs = [p.communicate(timeout=170) for p in processes]
    finally:
        for p in processes:
            p.kill()
    assert [p.returncode for p in processes] == [0, 0], outputs
    check_collect_rows(postgres_url)
    with open_store(postgres_url) as store, store.session() as session:
        kept = session.execute(select(Run.kept).where(Run.status == "finished")).scalars().all()
    assert len(kept) == 2 and min(kept) >= 2


def test_concurrent_first_opens_migrate_once(postgres_url: str) -> None:
    errors: list[BaseException] = []

    def open_close() -> None:
        try:
            open_store(postgres_url).close()
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=open_close) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not errors, errors
    with open_store(postgres_url) as store, store.engine.connect() as conn:
        revisions = set(conn.execute(text("SELECT version_num FROM alembic_version")).scalars())
    assert revisions == head_revisions()


def test_every_command_works_on_postgres(postgres_url: str, tmp_path: Path) -> None:
    from tests.test_train import fill_store

    code, out = _cli(
        postgres_url, "collect", "--hours", "0.02", "--workers", "1", "--max-kept", "2", "--seed", "3"
    )
    assert code == 0, out
    code, out = _cli(postgres_url, "stats", "--json")
    assert code == 0, out
    stats = json.loads(out)
    assert stats["runs"][0]["kept"] >= 2
    code, out = _cli(postgres_url, "db")
    assert code == 0 and "transitions" in out, out

    # the inverse model: trained from the store, stored in it, listed
    fill_store(postgres_url, 60, seed=1)
    code, out = _cli(
        postgres_url, "train", "--epochs", "1", "--batch-size", "32", "--hidden", "16", "--seed", "4"
    )
    assert code == 0, out
    code, out = _cli(postgres_url, "models")
    assert code == 0 and "run-1" in out, out

    # high-level plans (cached in the store), a planner run, its replay
    code, out = _cli(postgres_url, "moves", "plan", "--goal", ONE_CROSSING)
    assert code == 0 and json.loads(out.splitlines()[0])["length"] == 1, out
    code, out = _cli(
        postgres_url, "plan", "--goal", ONE_CROSSING, "--planner", "random-low", "--workers", "1",
        "--timeout", "120", "--json",
    )  # fmt: skip
    assert code == 0, out
    result = json.loads(out)
    assert result["solved"]
    code, out = _cli(postgres_url, "replay", str(result["run_id"]))
    assert code == 0, out

    # experiments: a goal set, an evaluation, the report
    goals = tmp_path / "goals.json"
    goals.write_text(json.dumps({"ones": [json.loads(ONE_CROSSING)]}))
    code, out = _cli(postgres_url, "problems", "import", str(goals))
    assert code == 0, out
    code, out = _cli(
        postgres_url, "eval", "--set", "ones", "--planner", "random-low", "--timeout", "2", "--parallel", "1"
    )
    assert code == 0, out
    code, out = _cli(postgres_url, "report", "--out", str(tmp_path / "report"))
    assert code == 0, out
    assert (tmp_path / "report" / "report.md").exists()


def test_unreachable_server_and_missing_database_exit_2(postgres_admin_url: str) -> None:
    nobody = f"postgresql+psycopg://postgres@127.0.0.1:{free_port()}/twisted"
    code, out = _cli(nobody, "stats")
    assert code == 2 and "cannot connect" in " ".join(out.split()), out
    missing = make_url(postgres_admin_url).set(database="no_such_database_here")
    with pytest.raises(StoreError, match="cannot connect"):
        open_store(missing)
