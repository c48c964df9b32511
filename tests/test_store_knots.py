"""The store knows knots: topological_states.knot_type (0006; since 0010 the knot both closures agree on,
or "knotoid") and closure_under / closure_over (0010), the views, stats, knots list / identify, and the
pull tests (table tightenings, 0010)."""

from __future__ import annotations

import datetime as dt
import json

import numpy as np
import pytest
from alembic import command
from sqlalchemy import create_engine, inspect, text
from typer.testing import CliRunner

from cli.main import app
from twisted.knots import identify
from twisted.store import Base, alembic_config, array_to_blob, head_revisions, open_store
from twisted.store.knots import (
    Tightening,
    configurations_per_state,
    knot_visits,
    knots_tied,
    record_tightening,
    tightenings,
)
from twisted.store.queries import add_configuration, get_or_create_state, start_run
from twisted.topology import EMPTY, parse_p_data

# a 2-crossing rope with the end tucked in a loop: under the table a trefoil, over it the unknot (issue 10
# counted it as a trefoil)
KNOTOID_2 = parse_p_data([[1, "O", 3, "+"], [2, "U", 4, "+"], [3, "U", 1, "+"], [4, "O", 2, "+"]])
# the README's old overhand picture: knotoid, under 3_1-, over 0_1
README_KNOTOID = parse_p_data(
    [
        [1, "O", 5, "-"],
        [2, "U", 6, "-"],
        [3, "O", 4, "+"],
        [4, "U", 3, "+"],
        [5, "U", 1, "-"],
        [6, "O", 2, "-"],
    ]
)
TREFOIL_3_PLUS = parse_p_data(
    [
        [1, "O", 4, "+"],
        [2, "U", 5, "+"],
        [3, "O", 6, "+"],
        [4, "U", 1, "+"],
        [5, "O", 2, "+"],
        [6, "U", 3, "+"],
    ]
)
TREFOIL_3_MINUS = TREFOIL_3_PLUS.mirror()
ONE = parse_p_data([[1, "O", 2, "+"], [2, "U", 1, "+"]])

runner = CliRunner()


def _configuration(session, run_id: int | None, p, seed: int) -> int:
    rng = np.random.default_rng(seed)
    return add_configuration(
        session, run_id=run_id, p_data=p, q=rng.normal(size=93), points=rng.normal(size=(22, 3))
    ).id


def test_the_fixtures_are_what_their_names_say() -> None:
    assert identify(KNOTOID_2).describe() == "knotoid: under 3_1+, over 0_1"
    assert identify(README_KNOTOID).describe() == "knotoid: under 3_1-, over 0_1"
    assert identify(TREFOIL_3_PLUS).describe() == "3_1+" and identify(TREFOIL_3_MINUS).describe() == "3_1-"


def _insert_old_rows(conn, states: list, configurations: list[tuple[int, int]], knot_types: bool) -> None:
    """Rows as an old revision wrote them (Core inserts name only the columns given)."""
    tables = Base.metadata.tables
    at = dt.datetime(2026, 1, 1, tzinfo=dt.UTC)
    for i, p in enumerate(states, start=1):
        values = {"id": i, "key": p.key, "p_data": p.to_list(), "cross": p.cross}
        if knot_types:  # 0006's meaning: the knot of the closure under the table
            values["knot_type"] = identify(p).under.name
        conn.execute(tables["topological_states"].insert().values(**values))
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
    for cid, state_id in configurations:
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


STATES = [EMPTY, ONE, KNOTOID_2, TREFOIL_3_MINUS, README_KNOTOID]
# configuration id -> state id: EMPTY once, KNOTOID_2 twice, TREFOIL_3_MINUS once, README_KNOTOID once
CONFIGURATIONS = [(1, 1), (2, 3), (3, 3), (4, 4), (5, 5)]
FILLED = {
    EMPTY.key: ("0_1", "0_1", "0_1"),
    ONE.key: ("0_1", "0_1", "0_1"),
    KNOTOID_2.key: ("knotoid", "3_1+", "0_1"),
    TREFOIL_3_MINUS.key: ("3_1-", "3_1-", "3_1-"),
    README_KNOTOID.key: ("knotoid", "3_1-", "0_1"),
}


def _check_filled_and_views(conn) -> None:
    rows = conn.execute(text("SELECT key, knot_type, closure_under, closure_over FROM topological_states"))
    assert {key: (k, u, o) for key, k, u, o in rows} == FILLED
    tied = conn.execute(
        text("SELECT knot_type, run_id, run_kind, configurations, states FROM knots_tied ORDER BY knot_type")
    ).all()
    # the knotoids whose under-closure is a trefoil no longer count as tied trefoils
    assert [tuple(r) for r in tied] == [("3_1-", 7, "collect", 1, 1)]
    visits = conn.execute(
        text("SELECT knot_type, states, visited_states, configurations FROM knot_visits ORDER BY knot_type")
    ).all()
    assert [tuple(r) for r in visits] == [("0_1", 2, 1, 1), ("3_1-", 1, 1, 1), ("knotoid", 2, 2, 3)]


def test_migrations_fill_knot_type_and_both_closures_of_existing_rows(db_url: str) -> None:
    """A database made before 0006 (states and configurations already there) gets every column filled."""
    engine = create_engine(db_url)
    with engine.begin() as conn:
        command.upgrade(alembic_config(conn), "0001")
        _insert_old_rows(conn, STATES, CONFIGURATIONS, knot_types=False)
    engine.dispose()

    with open_store(db_url) as store, store.engine.connect() as conn:
        revisions = {r[0] for r in conn.execute(text("SELECT version_num FROM alembic_version"))}
        # the knots branch: 0006 .. 0010, 0012, 0014 (which the planner's 0004 .. 0009 joined)
        assert revisions == head_revisions() and "0014" in revisions
        _check_filled_and_views(conn)
        assert "tightenings" in inspect(conn).get_table_names()


def test_0010_recomputes_the_old_meaning_and_downgrade_restores_it(db_url: str) -> None:
    """Rows written at 0009 (knot_type = the under-closure's knot) become knotoids where the closures
    differ; downgrading to 0009 puts the under-closure back and drops the new columns and table."""
    engine = create_engine(db_url)
    with engine.begin() as conn:
        command.upgrade(alembic_config(conn), "0009")
        _insert_old_rows(conn, STATES, CONFIGURATIONS, knot_types=True)
        old = dict(conn.execute(text("SELECT key, knot_type FROM topological_states")).all())
        assert old[KNOTOID_2.key] == "3_1+" and old[README_KNOTOID.key] == "3_1-"
        tied = conn.execute(text("SELECT knot_type FROM knots_tied ORDER BY knot_type")).scalars().all()
        assert tied == ["3_1+", "3_1-"]  # the old answer: the knotoids counted as trefoils
    engine.dispose()

    with open_store(db_url) as store, store.engine.connect() as conn:
        _check_filled_and_views(conn)

    engine = create_engine(db_url)
    with engine.begin() as conn:
        command.downgrade(alembic_config(conn), "0009")
        assert dict(conn.execute(text("SELECT key, knot_type FROM topological_states")).all()) == old
        columns = {c["name"] for c in inspect(conn).get_columns("topological_states")}
        assert "knot_type" in columns and not {"closure_under", "closure_over"} & columns
        assert "tightenings" not in inspect(conn).get_table_names()
        tied = conn.execute(text("SELECT knot_type FROM knots_tied ORDER BY knot_type")).scalars().all()
        assert tied == ["3_1+", "3_1-"]
    engine.dispose()


def test_new_states_get_both_closures_and_queries_match_the_views(db_url: str) -> None:
    with open_store(db_url) as store:
        with store.session(write=True) as session:
            state = get_or_create_state(session, TREFOIL_3_MINUS)
            assert (state.knot_type, state.closure_under, state.closure_over) == ("3_1-", "3_1-", "3_1-")
            state = get_or_create_state(session, KNOTOID_2)
            assert (state.knot_type, state.closure_under, state.closure_over) == ("knotoid", "3_1+", "0_1")
            run_a = start_run(session, "collect", {}).id
            run_b = start_run(session, "plan", {}).id
            rows = [
                (run_a, EMPTY), (run_a, TREFOIL_3_PLUS), (run_a, TREFOIL_3_PLUS), (run_a, KNOTOID_2),
                (run_b, TREFOIL_3_PLUS), (run_b, ONE), (run_b, KNOTOID_2),
            ]  # fmt: skip
            for i, (run, p) in enumerate(rows):
                _configuration(session, run, p, i)
        with store.session() as session:
            tied = [
                (t.knot_type, t.run_id, t.run_kind, t.configurations, t.states) for t in knots_tied(session)
            ]
            # knotoids are never tied knots
            assert tied == [("3_1+", run_a, "collect", 2, 1), ("3_1+", run_b, "plan", 1, 1)]
            view = session.execute(
                text("SELECT knot_type, run_id, run_kind, configurations, states FROM knots_tied")
            ).all()
            assert sorted(tuple(r) for r in view) == sorted(tied)
            visits = {
                v.knot_type: (v.states, v.visited_states, v.configurations) for v in knot_visits(session)
            }
            assert visits == {"0_1": (2, 2, 2), "3_1+": (1, 1, 3), "3_1-": (1, 0, 0), "knotoid": (1, 1, 2)}
            view_visits = session.execute(
                text("SELECT knot_type, states, visited_states, configurations FROM knot_visits")
            ).all()
            assert {k: (a, b, c) for k, a, b, c in view_visits} == visits
            counts = configurations_per_state(session, [TREFOIL_3_PLUS.key, TREFOIL_3_MINUS.key, "[]"])
            assert counts == {TREFOIL_3_PLUS.key: 3, TREFOIL_3_MINUS.key: 0, "[]": 1}


def test_pull_tests_are_stored_and_read_back(db_url: str) -> None:
    from twisted.tighten import Tightened

    points = np.linspace(0.0, 1.0, 66).reshape(22, 3)
    tight = Tightened(True, None, TREFOIL_3_PLUS, identify(TREFOIL_3_PLUS), points, 0.55, 3.5, 0.1)
    untied = Tightened(True, None, EMPTY, identify(EMPTY), points, 0.82, 6.6, 0.1)
    failed = Tightened(False, "penetration deeper than a radius", None, None, None, None, 1.2, 0.05)
    assert tight.knot_name == "3_1+" and untied.knot_name == "0_1" and failed.knot_name is None
    with open_store(db_url) as store:
        with store.session(write=True) as session:
            run = start_run(session, "plan", {}).id
            other = start_run(session, "plan", {}).id
            first = record_tightening(
                session, tight, TREFOIL_3_PLUS, run_id=run, node_seq=5, goal_knot="overhand", ties_goal=True
            )
            config = _configuration(session, run, README_KNOTOID, 1)
            second = record_tightening(
                session, untied, README_KNOTOID, run_id=run, configuration_id=config, ties_goal=False
            )
            record_tightening(
                session, failed, TREFOIL_3_MINUS, run_id=other, goal_knot="overhand", ties_goal=False
            )
        with store.session() as session:
            stored = tightenings(session, run)
            assert [t.id for t in stored] == [first, second]
            a, b = stored
            assert (a.run_id, a.node_seq, a.knot_before, a.knot_after) == (run, 5, "3_1+", "3_1+")
            assert (a.goal_knot, a.ties_goal, a.ok, a.reason) == ("overhand", True, True, None)
            assert a.end_distance_m == pytest.approx(0.55) and a.sim_seconds == pytest.approx(3.5)
            assert a.points is not None and np.array_equal(a.points, points)
            # a knotoid before, the unknot after: what a pulled-out tucked end looks like
            assert (b.knot_before, b.knot_after, b.ties_goal) == (
                "knotoid: under 3_1-, over 0_1",
                "0_1",
                False,
            )
            [c] = tightenings(session, other)
            assert (c.ok, c.reason, c.knot_after, c.points, c.end_distance_m) == (
                False, "penetration deeper than a radius", None, None, None,
            )  # fmt: skip
            assert tightenings(session, 999) == []
            row = session.get(Tightening, second)
            assert row is not None and row.configuration_id == config
            assert row.state_id == get_or_create_state(session, README_KNOTOID).id
            assert row.tightened_state_id == get_or_create_state(session, EMPTY).id
            assert session.get(Tightening, c.id).tightened_state_id is None


def test_stats_and_knots_list_show_visits_per_knot(sqlite_url: str) -> None:
    with open_store(sqlite_url) as store, store.session(write=True) as session:
        run = start_run(session, "collect", {}).id
        for i, p in enumerate([EMPTY, TREFOIL_3_PLUS, TREFOIL_3_PLUS, TREFOIL_3_MINUS, KNOTOID_2]):
            _configuration(session, run, p, i)
    stats = runner.invoke(app, ["--db", sqlite_url, "stats", "--json"])
    assert stats.exit_code == 0, stats.output
    by_knot = {r["knot_type"]: r["configurations"] for r in json.loads(stats.output)["by_knot"]}
    assert by_knot == {"0_1": 1, "3_1+": 2, "3_1-": 1, "knotoid": 1}

    listed = runner.invoke(app, ["--db", sqlite_url, "knots", "list", "--json"])
    assert listed.exit_code == 0, listed.output
    entries = {e["knot_type"]: e for e in json.loads(listed.stdout)}
    assert "knotoid" not in entries
    plus = entries["3_1+"]
    assert plus["crossings"] == plus["crossing_number"] == 3 and plus["name"] == "overhand+"
    # the two states that really tie it, the visited one first
    visited = {"p_data": TREFOIL_3_PLUS.to_list(), "configurations": 2, "nodes": 0, "visits": 2}
    assert plus["states"][0] == visited
    assert len(plus["states"]) == 2 and plus["states"][1]["visits"] == 0
    assert plus["visited_states"] == 1 and plus["configurations"] == plus["visits"] == 2
    assert entries["3_1-"]["configurations"] == 1 and entries["0_1"]["configurations"] == 1
    assert entries["4_1"]["crossings"] == 4 and len(entries["4_1"]["states"]) == 8
    assert entries["4_1"]["visited_states"] == 0
    assert all(identify(parse_p_data(s["p_data"])).name == "4_1" for s in entries["4_1"]["states"])
    # every table knot at its crossing number: cut from its diagram, composites joined from their summands
    assert entries["3_1+#3_1+"]["crossings"] == 6 and len(entries["3_1+#3_1+"]["states"]) == 24
    assert entries["3_1+#3_1-"]["name"] == "square" and len(entries["3_1+#3_1-"]["states"]) == 48
    assert entries["3_1+#3_1-"]["determinant"] == 9
    assert entries["5_1+"]["crossings"] == 5 and entries["5_1+"]["listed"] is True
    assert len(entries["5_1+"]["states"]) == 2 and entries["7_7-"]["knotinfo"] == "7_7"
    assert entries["7_7-"]["crossings"] == 7 and len(entries["7_7-"]["states"]) == 28
    # above the crossing number the states are enumerated, up to --max-crossings
    assert entries["4_1"]["listed"] and len(entries) == 32
    listed_keys = {
        json.dumps(s["p_data"], separators=(",", ":")) for e in entries.values() for s in e["states"]
    }
    assert KNOTOID_2.key not in listed_keys and README_KNOTOID.key not in listed_keys

    text_out = runner.invoke(app, ["--db", sqlite_url, "knots", "list", "--crossings", "3", "--limit", "1"])
    assert text_out.exit_code == 0, text_out.output
    flat = " ".join(text_out.output.split())
    assert "2 states of 3 crossings" in flat and "1 more" in flat


def test_knots_identify_command() -> None:
    ok = runner.invoke(app, ["knots", "identify", TREFOIL_3_MINUS.key, "--json"])
    assert ok.exit_code == 0, ok.output
    out = json.loads(ok.stdout)
    assert set(out) == {"knot_type", "is_knot", "under", "over"}
    assert out["knot_type"] == "3_1-" and out["is_knot"] is True
    assert out["under"] == out["over"]
    assert out["under"]["knot_type"] == "3_1-" and out["under"]["alexander"] == [1, -1, 1]
    assert out["under"]["determinant"] == 3 and out["under"]["jones"] == [[-4, -1], [-3, 1], [-1, 1]]
    assert out["under"]["writhe"] == -3
    assert out == identify(TREFOIL_3_MINUS).to_dict()

    knotoid = runner.invoke(app, ["knots", "identify", README_KNOTOID.key, "--json"])
    assert knotoid.exit_code == 0, knotoid.output
    out = json.loads(knotoid.stdout)
    assert out["knot_type"] == "knotoid" and out["is_knot"] is False
    assert out["under"]["knot_type"] == "3_1-" and out["over"]["knot_type"] == "0_1"
    plain = runner.invoke(app, ["knots", "identify", README_KNOTOID.key])
    assert plain.exit_code == 0 and "knotoid: under 3_1-, over 0_1" in plain.output
    assert "closed under" in plain.output and "closed over" in plain.output

    bad = runner.invoke(app, ["knots", "identify", '[[1,"O",2,"+"]]'])
    assert bad.exit_code == 2 and "P_DATA" in bad.output
    bad_list = runner.invoke(app, ["knots", "list", "--crossings", "9"])
    assert bad_list.exit_code == 2 and "--crossings" in bad_list.output


def _tree(session, run_id: int, states: list) -> None:
    """A planner tree: the root (seq 0, the run's start) and then one node per state, a chain."""
    from twisted.store.search import SearchNode

    parent = None
    for seq, p in enumerate(states):
        node = SearchNode(
            run_id=run_id, seq=seq, parent_id=parent, state_id=get_or_create_state(session, p).id,
            cross=p.cross, q=array_to_blob(np.zeros(93)), points=array_to_blob(np.zeros((22, 3))),
            iteration=seq, sim_call=seq, created_s=0.1 * seq,
        )  # fmt: skip
        session.add(node)
        session.flush()
        parent = node.id


def test_knots_list_counts_planner_nodes_as_visits(sqlite_url: str) -> None:
    """Issue 63 item 7: an overhand just tied by the planner (no configuration collected) is visited."""
    with open_store(sqlite_url) as store, store.session(write=True) as session:
        # the root is the start (an overhand given as the start counts no visit), then two nodes tie it
        _tree(session, start_run(session, "plan", {}).id, [TREFOIL_3_MINUS, ONE, TREFOIL_3_MINUS])
        _tree(session, start_run(session, "plan", {}).id, [EMPTY, ONE, TREFOIL_3_MINUS])
        _configuration(session, None, TREFOIL_3_MINUS, 1)
    listed = runner.invoke(app, ["--db", sqlite_url, "knots", "list", "--json"])
    assert listed.exit_code == 0, listed.output
    minus = {e["knot_type"]: e for e in json.loads(listed.stdout)}["3_1-"]
    assert minus["states"][0] == {
        "p_data": TREFOIL_3_MINUS.to_list(), "configurations": 1, "nodes": 2, "visits": 3
    }  # fmt: skip
    assert minus["visited_states"] == 1 and (minus["nodes"], minus["visits"]) == (2, 3)
    text_out = runner.invoke(app, ["--db", sqlite_url, "knots", "list", "--limit", "1"])
    row = next(line for line in text_out.output.splitlines() if "overhand-" in line and "3_1-" in line)
    assert row.replace("│", " ").split()[-2:] == ["1", "3"], row  # visited states, visits


@pytest.mark.parametrize("invariants", [False, True], ids=["plain", "invariants"])
def test_knots_list_reads_at_80_columns(sqlite_url: str, invariants: bool, monkeypatch) -> None:
    """Issue 63 item 7: at 80 columns every knot's name and type print whole (rich cut them with "…")."""
    from cli.app import console

    with open_store(sqlite_url):
        pass
    args = ["--db", sqlite_url, "knots", "list", "--limit", "1", *(["--invariants"] if invariants else [])]
    monkeypatch.setattr(console, "width", 80)  # what COLUMNS=80 gives (read when the console is made)
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert max(len(line) for line in lines) <= 80 and "…" not in result.output
    rows = {tuple(line.split("│")[1:3]) for line in lines if line.count("│") > 3}
    names = {(r[0].strip(), r[1].strip()) for r in rows}
    entries = json.loads(runner.invoke(app, ["--db", sqlite_url, "knots", "list", "--json"]).stdout)
    assert {(e["name"], e["knot_type"]) for e in entries} <= names
    assert ("Jones" in result.output) is invariants
