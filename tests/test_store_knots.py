"""The store knows knots: topological_states.knot_type (migration 0006), the views, stats and knots list."""

from __future__ import annotations

import datetime as dt
import json

import numpy as np
from alembic import command
from sqlalchemy import create_engine, text
from typer.testing import CliRunner

from cli.main import app
from twisted.knots import identify
from twisted.store import Base, alembic_config, array_to_blob, head_revisions, open_store
from twisted.store.knots import configurations_per_state, knot_visits, knots_tied
from twisted.store.queries import add_configuration, get_or_create_state, start_run
from twisted.topology import EMPTY, parse_p_data

TREFOIL_2 = parse_p_data([[1, "O", 3, "+"], [2, "U", 4, "+"], [3, "U", 1, "+"], [4, "O", 2, "+"]])
TREFOIL_3_MINUS = parse_p_data(
    [
        [1, "O", 4, "-"],
        [2, "U", 5, "-"],
        [3, "O", 6, "-"],
        [4, "U", 1, "-"],
        [5, "O", 2, "-"],
        [6, "U", 3, "-"],
    ]
)
ONE = parse_p_data([[1, "O", 2, "+"], [2, "U", 1, "+"]])

runner = CliRunner()


def _configuration(session, run_id: int | None, p, seed: int) -> None:
    rng = np.random.default_rng(seed)
    add_configuration(
        session, run_id=run_id, p_data=p, q=rng.normal(size=93), points=rng.normal(size=(22, 3))
    )


def test_migration_fills_knot_type_of_existing_rows(db_url: str) -> None:
    """A database made before 0006 (states and configurations already there) gets every knot_type filled."""
    engine = create_engine(db_url)
    tables = Base.metadata.tables  # Core inserts name only the columns given: the 0001 ones
    at = dt.datetime(2026, 1, 1, tzinfo=dt.UTC)
    with engine.begin() as conn:
        command.upgrade(alembic_config(conn), "0001")
        for i, p in enumerate((EMPTY, ONE, TREFOIL_2, TREFOIL_3_MINUS), start=1):
            conn.execute(
                tables["topological_states"]
                .insert()
                .values(id=i, key=p.key, p_data=p.to_list(), cross=p.cross)
            )
        conn.execute(
            tables["runs"]
            .insert()
            .values(
                id=7,
                kind="collect",
                parameters={},
                status="finished",
                started_at=at,
                tried=0,
                kept=0,
                rejected=0,
                wall_seconds=0.0,
                sim_seconds=0.0,
            )  # fmt: skip
        )
        for cid, state_id in ((1, 1), (2, 3), (3, 3), (4, 4)):
            conn.execute(
                tables["configurations"]
                .insert()
                .values(
                    id=cid,
                    run_id=7,
                    state_id=state_id,
                    cross=0,
                    q=array_to_blob(np.zeros(3)),
                    points=array_to_blob(np.zeros(3)),
                    created_at=at + dt.timedelta(seconds=cid),
                )  # fmt: skip
            )
    engine.dispose()

    with open_store(db_url) as store, store.engine.connect() as conn:
        revisions = {r[0] for r in conn.execute(text("SELECT version_num FROM alembic_version"))}
        assert revisions == head_revisions() and "0009" in revisions  # 0009 merges 0006 (knots) with 0008
        filled = dict(conn.execute(text("SELECT key, knot_type FROM topological_states")).all())
        assert filled == {
            EMPTY.key: "0_1",
            ONE.key: "0_1",
            TREFOIL_2.key: "3_1+",
            TREFOIL_3_MINUS.key: "3_1-",
        }
        tied = conn.execute(
            text(
                "SELECT knot_type, run_id, run_kind, configurations, states"
                " FROM knots_tied ORDER BY knot_type"
            )
        ).all()
        assert [tuple(r) for r in tied] == [("3_1+", 7, "collect", 2, 1), ("3_1-", 7, "collect", 1, 1)]
        visits = conn.execute(
            text(
                "SELECT knot_type, states, visited_states, configurations FROM knot_visits ORDER BY knot_type"
            )
        ).all()
        assert [tuple(r) for r in visits] == [("0_1", 2, 1, 1), ("3_1+", 1, 1, 2), ("3_1-", 1, 1, 1)]


def test_new_states_get_their_knot_type_and_queries_match_the_views(db_url: str) -> None:
    with open_store(db_url) as store:
        with store.session(write=True) as session:
            assert get_or_create_state(session, TREFOIL_3_MINUS).knot_type == "3_1-"
            run_a = start_run(session, "collect", {}).id
            run_b = start_run(session, "plan", {}).id
            for i, (run, p) in enumerate(
                [(run_a, EMPTY), (run_a, TREFOIL_2), (run_a, TREFOIL_2), (run_b, TREFOIL_2), (run_b, ONE)]
            ):
                _configuration(session, run, p, i)
        with store.session() as session:
            tied = [
                (t.knot_type, t.run_id, t.run_kind, t.configurations, t.states) for t in knots_tied(session)
            ]
            assert tied == [("3_1+", run_a, "collect", 2, 1), ("3_1+", run_b, "plan", 1, 1)]
            view = session.execute(
                text("SELECT knot_type, run_id, run_kind, configurations, states FROM knots_tied")
            ).all()
            assert sorted(tuple(r) for r in view) == sorted(tied)
            visits = {
                v.knot_type: (v.states, v.visited_states, v.configurations) for v in knot_visits(session)
            }
            assert visits == {"0_1": (2, 2, 2), "3_1+": (1, 1, 3), "3_1-": (1, 0, 0)}
            counts = configurations_per_state(session, [TREFOIL_2.key, TREFOIL_3_MINUS.key, "[]"])
            assert counts == {TREFOIL_2.key: 3, TREFOIL_3_MINUS.key: 0, "[]": 1}


def test_stats_and_knots_list_show_visits_per_knot(sqlite_url: str) -> None:
    with open_store(sqlite_url) as store, store.session(write=True) as session:
        run = start_run(session, "collect", {}).id
        for i, p in enumerate([EMPTY, TREFOIL_2, TREFOIL_2, TREFOIL_2.mirror()]):
            _configuration(session, run, p, i)
    stats = runner.invoke(app, ["--db", sqlite_url, "stats", "--json"])
    assert stats.exit_code == 0, stats.output
    by_knot = {r["knot_type"]: r["configurations"] for r in json.loads(stats.output)["by_knot"]}
    assert by_knot == {"0_1": 1, "3_1+": 2, "3_1-": 1}

    listed = runner.invoke(app, ["--db", sqlite_url, "knots", "list", "--json"])
    assert listed.exit_code == 0, listed.output
    entries = {e["knot_type"]: e for e in json.loads(listed.stdout)}
    assert entries["3_1+"]["crossings"] == 2 and entries["3_1+"]["name"] == "overhand+"
    assert entries["3_1+"]["states"] == [{"p_data": TREFOIL_2.to_list(), "configurations": 2}]
    assert entries["3_1-"]["configurations"] == 1 and entries["0_1"]["configurations"] == 1
    assert entries["4_1"]["crossings"] == 3 and len(entries["4_1"]["states"]) == 4
    assert entries["4_1"]["visited_states"] == 0
    assert all(identify(parse_p_data(s["p_data"])).name == "4_1" for s in entries["4_1"]["states"])

    text_out = runner.invoke(app, ["--db", sqlite_url, "knots", "list", "--crossings", "3", "--limit", "2"])
    assert text_out.exit_code == 0 and "24 states of 3 crossings" in text_out.output


def test_knots_identify_command() -> None:
    ok = runner.invoke(app, ["knots", "identify", TREFOIL_3_MINUS.key, "--json"])
    assert ok.exit_code == 0 and json.loads(ok.stdout)["knot_type"] == "3_1-"
    bad = runner.invoke(app, ["knots", "identify", '[[1,"O",2,"+"]]'])
    assert bad.exit_code == 2 and "P_DATA" in bad.output
    bad_list = runner.invoke(app, ["knots", "list", "--crossings", "9"])
    assert bad_list.exit_code == 2 and "--crossings" in bad_list.output
