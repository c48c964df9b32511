"""The pull test (issue 14): hold both ends, lift them a little, pull them apart; a real knot stays, a
knotoid (an end tucked in a loop) comes out.

Simulation is real: short seeded plans (``--seed 4`` reaches an overhand in a few seconds of search with
the shipped model, one worker) on a tmp store, then ``twisted replay --tighten``.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cli.main import app
from twisted.knots import identify
from twisted.planner import straight_rope
from twisted.rope import ROPE_LENGTH_M
from twisted.sim.mjcf import LINK_RADIUS_M
from twisted.store import open_store
from twisted.store.knots import tightenings
from twisted.tighten import Tightened, tighten, tightening_sim
from twisted.topology import EMPTY, parse_p_data, top

runner = CliRunner()
SEED = "0"
# Whether the first overhand a search reaches holds when pulled depends on the seed (about half did, with
# the shipped model: 6 of 14 seeds, docs/log/2026-12-01.md); the stored-plan fixture takes the first of
# these seeds whose plan holds instead of one seed picked by hand (none of 12 holding: ~0.1 %).
HOLD_SEEDS = range(12)
# two crossings, the end tucked in a loop: under the table a trefoil, over it the unknot
KNOTOID_2 = '[[1,"U",3,"+"],[2,"O",4,"+"],[3,"O",1,"+"],[4,"U",2,"+"]]'


def _cli(db: str, *args: str) -> tuple[int, str]:
    result = runner.invoke(app, ["--db", db, *args])
    return result.exit_code, result.output


def _json(out: str) -> dict:
    return json.loads(out[out.index("{") : out.rindex("}") + 1])


def _plan(db: str, *args: str, seed: str = SEED) -> dict:
    """A solved plan. Bounded by iterations, which a seed replays on any machine, not by a wall-clock
    timeout (a busy CI machine made 157 simulator calls in 120 s where an idle one makes over 1,000)."""
    limits = ["--max-iterations", "1000", "--timeout", "3600"]
    code, out = _cli(db, "plan", *args, "--workers", "1", "--seed", seed, *limits, "--json")
    assert code == 0, out
    result = _json(out)
    assert result["solved"], result
    return result


@pytest.fixture(scope="module")
def overhand_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, dict]:
    """A stored plan (no pull test during the search) from the straight rope to an overhand knot whose
    final rope holds when pulled: the first of HOLD_SEEDS that makes one (a database per seed)."""
    folder = tmp_path_factory.mktemp("tighten")
    for seed in HOLD_SEEDS:
        db = f"sqlite:///{folder / f'overhand-{seed}.db'}"
        result = _plan(db, "--knot", "overhand", seed=str(seed))
        code, out = _cli(db, "replay", str(result["run_id"]), "--tighten", "--json")
        if code == 0:
            return _tightened_away(db, result["run_id"]), result
    pytest.fail(f"no overhand of seeds {HOLD_SEEDS} held when pulled; about half should")


def _tightened_away(db: str, run_id: int) -> str:
    """``db`` with the pull test the fixture ran on ``run_id`` deleted, so the tests see the plan alone."""
    from sqlalchemy import delete

    from twisted.store.knots import Tightening

    with open_store(db) as store, store.session(write=True) as session:
        session.execute(delete(Tightening).where(Tightening.run_id == run_id))
    return db


# --- the pull test itself ------------------------------------------------------------------------------


def test_the_straight_rope_pulled_tight_is_the_unknot_with_its_ends_a_rope_length_apart() -> None:
    q, _, p = straight_rope()
    assert p == EMPTY
    sim = tightening_sim()
    result = tighten(sim, q)
    assert isinstance(result, Tightened)
    assert result.ok and result.reason is None, result.reason
    assert result.p_data == EMPTY and result.knot is not None
    assert result.knot.is_knot and result.knot_name == "0_1"
    assert result.knot.under.name == result.knot.over.name == "0_1"
    assert result.end_distance_m == pytest.approx(ROPE_LENGTH_M, abs=0.02)  # 0.84 m: taut, not stretched
    assert result.points is not None and result.points.shape == (22, 3)
    # lifted "a little": the ends are held just above the table, the rope did not fly
    assert result.points[:, 2].min() > 0 and result.points[:, 2].max() < 4 * LINK_RADIUS_M
    assert result.sim_seconds > 0 and result.wall_seconds > 0
    # deterministic given the state (it starts from set_state like every curve)
    again = tighten(sim, q)
    assert again.end_distance_m == result.end_distance_m and np.array_equal(again.points, result.points)


def test_the_pull_test_needs_the_second_gripper() -> None:
    from twisted.sim import RopeSim

    q, _, _ = straight_rope()
    with pytest.raises(ValueError, match="tail gripper"):
        tighten(RopeSim(), q)


# --- from a stored plan ----------------------------------------------------------------------------------


def test_a_tightened_overhand_from_a_stored_plan_stays_a_trefoil(overhand_run: tuple[str, dict]) -> None:
    db, result = overhand_run
    run_id = result["run_id"]
    reached = parse_p_data(result["reached_state"])
    before = identify(reached)
    assert before.is_knot and before.name in ("3_1+", "3_1-")
    assert result["tighten"] is False and result["pull_tests"] == 0

    code, out = _cli(db, "replay", str(run_id), "--tighten", "--json")
    assert code == 0, out
    replayed = _json(out)
    assert replayed["reached_goal"] is True and replayed["ties_goal"] is True
    assert replayed["goal_knot_types"] == ["3_1+", "3_1-"]
    t = replayed["tightened"]
    assert t["ok"] is True and t["reason"] is None
    # the same trefoil, same chirality, under both closures: pulling did not undo (or mirror) it
    assert t["knot_type"] == before.name
    assert t["knot"]["is_knot"] is True
    assert t["knot"]["under"]["knot_type"] == t["knot"]["over"]["knot_type"] == before.name
    assert identify(parse_p_data(t["p_data"])).name == before.name
    # the knot holds rope: the ends are apart but closer than the rope is long
    assert 0.2 < t["end_distance_m"] < ROPE_LENGTH_M - 0.05
    assert t["sim_seconds"] > 0

    # stored with the run
    with open_store(db) as store, store.session() as session:
        [row] = tightenings(session, run_id)
    assert row.ok and row.ties_goal is True and row.goal_knot == "overhand"
    assert row.knot_before == before.name and row.knot_after == before.name
    assert row.end_distance_m == pytest.approx(t["end_distance_m"])
    assert row.points is not None and row.points.shape == (22, 3)
    assert top(row.points) == parse_p_data(t["p_data"])  # the stored points are the tightened rope

    # the text form says so too; without --tighten nothing is pulled (nor stored)
    code, out = _cli(db, "replay", str(run_id), "--tighten")
    flat = " ".join(out.split())
    assert code == 0 and f"the tightened rope is {before.name}" in flat and "ties the goal's knot" in flat
    code, out = _cli(db, "replay", str(run_id), "--json")
    assert code == 0 and "tightened" not in _json(out)
    with open_store(db) as store, store.session() as session:
        assert len(tightenings(session, run_id)) == 2  # one per --tighten replay


def test_a_pull_to_half_the_tension_reads_the_same_trefoil(overhand_run: tuple[str, dict]) -> None:
    """A world whose rope the full pull presses through itself pulls again to half the tension
    (twisted.world.SimWorld.pull_test): on a rope the full pull can do, both read the same knot."""
    from twisted.store.search_tree import solved_run
    from twisted.tighten import TAUT_LAG_M

    db, result = overhand_run
    with open_store(db) as store:
        _, path = solved_run(store, result["run_id"])
    sim = tightening_sim()
    full = tighten(sim, path[-1].q)
    half = tighten(sim, path[-1].q, taut_lag_m=0.5 * TAUT_LAG_M)
    assert full.ok and half.ok, (full.reason, half.reason)
    assert half.knot_name == full.knot_name and full.knot_name in ("3_1+", "3_1-")
    assert half.end_distance_m is not None and full.end_distance_m is not None
    assert half.end_distance_m < full.end_distance_m + 1e-6  # less tension: the ends no further apart


def test_render_draws_the_plan_beside_the_tightened_knot(
    overhand_run: tuple[str, dict], tmp_path: Path
) -> None:
    db, result = overhand_run
    png = tmp_path / "tight.png"
    code, out = _cli(db, "render", "--run", str(result["run_id"]), "--tightened", "--out", str(png))
    assert code == 0, out
    assert png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plan_with_tighten_ends_only_on_a_goal_state_that_passes_the_pull_test(tmp_path: Path) -> None:
    db = f"sqlite:///{tmp_path / 'plan-tighten.db'}"
    picture = tmp_path / "knot.png"
    result = _plan(db, "--knot", "overhand", "--tighten", "--picture", str(picture))
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"  # the final rope beside the taut one
    assert result["tighten"] is True and result["pull_tests"] >= 1
    reached = parse_p_data(result["reached_state"])
    with open_store(db) as store, store.session() as session:
        stored = tightenings(session, result["run_id"])
    # every pull test of the search is stored; the last one is the success that ended it
    assert len(stored) == result["pull_tests"]
    assert stored[-1].ok and stored[-1].ties_goal is True
    assert stored[-1].knot_before == identify(reached).name == stored[-1].knot_after
    assert all(not t.ties_goal for t in stored[:-1])
    # a tightened-plan run replays and passes its pull test again
    code, out = _cli(db, "replay", str(result["run_id"]), "--tighten", "--json")
    assert code == 0 and _json(out)["ties_goal"] is True, out


def test_a_knotoid_goal_names_no_knot_and_replay_tighten_exits_3(tmp_path: Path) -> None:
    """The end tucked in a loop is not a knot: the rope reaches the state, and pulled tight it ties one of
    the two closures (which one depends on how the end leaves the loop: the unknot or the trefoil); the
    state names no knot, so the pull test cannot pass (exit 3)."""
    assert identify(parse_p_data(KNOTOID_2)).describe() == "knotoid: under 0_1, over 3_1+"
    db = f"sqlite:///{tmp_path / 'knotoid.db'}"
    result = _plan(db, "--goal", KNOTOID_2)
    run_id = str(result["run_id"])
    assert _cli(db, "replay", run_id)[0] == 0  # it reaches the state
    code, out = _cli(db, "replay", run_id, "--tighten", "--json")
    assert code == 3, out
    replayed = _json(out)
    assert replayed["reached_goal"] is True and replayed["ties_goal"] is False
    assert replayed["goal_knot_types"] == []
    t = replayed["tightened"]
    assert t["ok"] is True and t["knot_type"] in ("0_1", "3_1+") and t["knot"]["is_knot"] is True
    if t["knot_type"] == "0_1":
        assert t["end_distance_m"] > ROPE_LENGTH_M - 0.1  # nothing left to hold rope
    with open_store(db) as store, store.session() as session:
        [row] = tightenings(session, result["run_id"])
    assert row.knot_before == "knotoid: under 0_1, over 3_1+" and row.knot_after == t["knot_type"]
    assert row.ties_goal is False and row.goal_knot is None
    code, out = _cli(db, "replay", run_id, "--tighten")
    assert code == 3 and "does not tie" in " ".join(out.split())


def _final_configuration(db: str, run_id: int) -> tuple[np.ndarray, np.ndarray]:
    """The q and the link points of a solved run's goal node."""
    from twisted.store.search_tree import solved_run

    with open_store(db) as store:
        end = solved_run(store, run_id)[1][-1]
    return end.q, end.points


def test_a_cinched_overhand_is_the_same_trefoil_in_fewer_links_with_its_ends_free(
    overhand_run: tuple[str, dict],
) -> None:
    from twisted.tighten import cinch

    db, result = overhand_run
    q, points = _final_configuration(db, result["run_id"])
    before = identify(top(points))
    sim = tightening_sim()
    done = cinch(sim, q)
    assert done.ok and done.reason is None and done.state is not None and done.points is not None
    assert done.p_data == top(done.points) and identify(done.p_data).name == before.name
    # let go and settled: on the table, at rest, no end held
    assert not sim.data.eq_active.any()
    assert float(done.points[:, 2].max()) < 0.05
    # the knot holds less rope than before: the ends lie further apart
    apart = lambda pts: float(np.linalg.norm(pts[-1, :2] - pts[0, :2]))  # noqa: E731
    assert apart(done.points) > apart(points) + 0.05
    assert done.sim_seconds > 0
    # deterministic, as every simulation here
    again = cinch(tightening_sim(), q)
    assert again.state is not None and np.array_equal(again.state, done.state)


def test_a_search_for_a_granny_cinches_the_overhand_it_starts_from_and_stores_the_cinch(
    overhand_run: tuple[str, dict], tmp_path: Path
) -> None:
    """Real simulation: a granny search started from the overhand of the fixture cinches that rope
    before its first plan step, keeps the cinched rope as a node (action "cinch", no curve) and starts
    its steps from it; resumed, it knows the cinch and does not pull the rope again. --no-cinch does not
    cinch."""
    from sqlalchemy import select

    from twisted.store.queries import add_configuration
    from twisted.store.search_tree import SearchNode

    source_db, result = overhand_run
    q, points = _final_configuration(source_db, result["run_id"])
    db = f"sqlite:///{tmp_path / 'granny.db'}"
    with open_store(db) as store, store.session(write=True) as session:
        config_id = add_configuration(session, run_id=None, p_data=top(points), q=q, points=points).id
    args = ["plan", "--knot", "granny", "--start-config", str(config_id), "--workers", "1", "--seed", "0"]
    code, out = _cli(db, *args, "--max-iterations", "2", "--timeout", "3600", "--json")
    assert code == 3, out  # exit 3: not solved (the iteration cap)
    first = _json(out)
    assert first["sim_calls_by_source"]["cinch"] == 1
    with open_store(db) as store, store.session() as session:
        rows = session.execute(
            select(
                SearchNode.seq,
                SearchNode.id.label("node_id"),
                SearchNode.parent_id,
                SearchNode.action,
                SearchNode.link,
                SearchNode.cross,
                SearchNode.state_id,
            )
            .where(SearchNode.run_id == first["run_id"])
            .order_by(SearchNode.seq)
        ).all()
        stats = json.loads(json.dumps(_checkpoint_stats(session, first["run_id"])))
    assert rows[0].action == "curve" and rows[0].parent_id is None  # the root
    [cinched] = [r for r in rows if r.action == "cinch"]
    assert cinched.seq == 1 and cinched.link is None and cinched.cross == 3
    # every plan step but the first starts from a tight rope (the cinched one or one made from it); the
    # first starts from the loose root only where the cinch drew the trefoil otherwise (this fixture's
    # overhand: the root's state then had no other node)
    seq_of = {r.node_id: r.seq for r in rows}
    parent = {r.seq: seq_of.get(r.parent_id) for r in rows}

    def tight(seq: int | None) -> bool:
        return seq is not None and (rows[seq].action == "cinch" or tight(parent[seq]))

    tries = Counter()
    for key, (tried, _) in stats["pair"].items():
        tries[int(key.split("|")[0])] += tried
    assert tries and all(tight(seq) for seq in tries if seq != 0)
    assert tries[0] <= (0 if cinched.state_id == rows[0].state_id else 1)

    resume = ["plan", str(first["run_id"]), "--resume", "--workers", "1", "--max-iterations", "4"]
    code, out = _cli(db, *resume, "--timeout", "3600", "--json")
    assert code == 3, out  # exit 3: not solved (the iteration cap)
    assert _json(out)["sim_calls_by_source"]["cinch"] == 1  # counted once: the resumed run did not pull again

    code, out = _cli(db, *args, "--no-cinch", "--max-iterations", "2", "--timeout", "3600", "--json")
    assert code == 3, out  # exit 3: not solved (the iteration cap)
    assert "cinch" not in _json(out)["sim_calls_by_source"]


def _checkpoint_stats(session: object, run_id: int) -> dict:
    from sqlalchemy import select

    from twisted.store.search_tree import SearchCheckpoint

    query = select(SearchCheckpoint.stats).where(SearchCheckpoint.run_id == run_id)
    return session.scalars(query).one()  # type: ignore[attr-defined]
