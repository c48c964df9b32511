"""Goal sets: plan to "an overhand knot" (any state that ties it) instead of to one P-data state."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sqlalchemy import select
from typer.testing import CliRunner

from cli.main import app
from twisted.experiments.problems import parse_goal_file
from twisted.goals import Goal, GoalError, PlanInputError, goal_from_spec, knot_goal, make_goal, state_goal
from twisted.knots import identify
from twisted.model.registry import load_model
from twisted.moves import Plan, enumerate_states, plans, plans_to_any
from twisted.planner import high_level, replay
from twisted.store import open_store
from twisted.store.experiments import EvalResult, load_problem_set
from twisted.store.knots import knots_tied
from twisted.store.plans import PlanQuery
from twisted.store.search_tree import SearchRunRow, find_resumable_run, load_run
from twisted.topology import EMPTY, parse_p_data

runner = CliRunner()
ONE_CROSSING = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
# the README's old "overhand": under the table a trefoil, over it the unknot (a knotoid, not a knot)
README_KNOTOID = '[[1,"O",5,"-"],[2,"U",6,"-"],[3,"O",4,"+"],[4,"U",3,"+"],[5,"U",1,"-"],[6,"O",2,"-"]]'
TREFOIL_PLUS = '[[1,"O",4,"+"],[2,"U",5,"+"],[3,"O",6,"+"],[4,"U",1,"+"],[5,"O",2,"+"],[6,"U",3,"+"]]'


def _cli(db: str, *args: str) -> tuple[int, str]:
    result = runner.invoke(app, ["--db", db, *args])
    return result.exit_code, result.output


# --- the goal itself --------------------------------------------------------------------------------


def test_overhand_goal_is_every_three_crossing_state_that_really_ties_a_trefoil() -> None:
    goal = knot_goal("overhand")
    assert goal.knot == "overhand" and goal.crossings == 3 and goal.cross == 3
    assert goal.spec == "knot:overhand@3"
    # the four alternating states (two per chirality): both closures are the trefoil
    assert len(goal.states) == 4
    for p in goal.states:
        k = identify(p)
        assert p.cross == 3 and k.is_knot and k.under.name == k.over.name == k.name in ("3_1+", "3_1-")
    # ... and nothing else among the 3-crossing states: knotoids whose under-closure is a trefoil are out
    others = [p for p in enumerate_states(3)[3] if p not in goal]
    assert others and not any(identify(p).name.startswith("3_1") for p in others)
    # the old goal (under-closure a trefoil) had 48 states: 44 of them are knotoids
    assert sum(identify(p).under.name.startswith("3_1") for p in others) == 44
    assert parse_p_data(README_KNOTOID) not in goal
    # one chirality is half of it
    right = knot_goal("overhand+")
    assert set(right.keys) < set(goal.keys) and len(right.states) == 2
    assert {identify(p).name for p in right.states} == {"3_1+"}
    assert goal.knot_types == {"3_1+", "3_1-"} and right.knot_types == {"3_1+"}


def test_knots_need_their_crossing_number_more_crossings_when_asked() -> None:
    # two crossings tie a trefoil through the under-closure only (the end tucked inside a loop): knotoids
    with pytest.raises(GoalError, match="no rope state with 2 crossings ties the knot 'overhand'"):
        knot_goal("overhand", 2)
    with pytest.raises(GoalError, match="no rope state with 3 crossings ties the knot 'figure-eight'"):
        knot_goal("figure-eight", 3)
    figure_eight = knot_goal("figure-eight")
    assert figure_eight.crossings == 4 and len(figure_eight.states) == 8
    assert all(identify(p).name == "4_1" for p in figure_eight.states)
    four = knot_goal("overhand", 4)
    assert four.crossings == 4 and len(four.states) == 140 and four.spec == "knot:overhand@4"
    assert all(p.cross == 4 and identify(p).is_knot for p in four.states)


def test_composite_knot_goals_are_built_at_six_crossings() -> None:
    granny, square = knot_goal("granny"), knot_goal("square")
    assert granny.crossings == square.crossings == granny.cross == 6
    assert granny.spec == "knot:granny@6" and square.spec == "knot:square@6"
    assert len(granny.states) == len(square.states) == 48 and not granny.keys & square.keys
    assert granny.knot_types == {"3_1+#3_1+", "3_1-#3_1-"} and square.knot_types == {"3_1+#3_1-"}
    assert {identify(p).name for p in square.states} == {"3_1+#3_1-"}
    assert goal_from_spec("reef") == knot_goal("reef", 6) and goal_from_spec("reef").keys == square.keys


def test_knot_types_and_the_pull_test_verdict() -> None:
    """What a tightened rope must tie: a knot goal's types; a state goal's knot, or nothing for a knotoid."""
    overhand = knot_goal("overhand")
    assert overhand.tightened_ties("3_1+") and overhand.tightened_ties("3_1-")
    assert not overhand.tightened_ties("0_1") and not overhand.tightened_ties("knotoid")
    assert not overhand.tightened_ties(None)  # the pull test failed: no knot
    assert not overhand.tightened_ties("3_1+#3_1+")
    trefoil = state_goal(parse_p_data(TREFOIL_PLUS))
    assert (
        trefoil.knot_types == {"3_1+"}
        and trefoil.tightened_ties("3_1+")
        and not trefoil.tightened_ties("3_1-")
    )
    knotoid = state_goal(parse_p_data(README_KNOTOID))
    assert knotoid.knot_types == frozenset()
    assert not any(knotoid.tightened_ties(t) for t in ("0_1", "3_1-", "knotoid", None))
    assert state_goal(parse_p_data(ONE_CROSSING)).knot_types == {"0_1"}
    assert knot_goal("granny").tightened_ties("3_1-#3_1-") and not knot_goal("granny").tightened_ties(
        "3_1+#3_1-"
    )


def test_specs_round_trip_and_name_the_bad_part() -> None:
    for goal in (knot_goal("overhand"), knot_goal("figure-eight", 4), state_goal(parse_p_data(ONE_CROSSING))):
        assert goal_from_spec(goal.spec) == goal
    assert goal_from_spec("figure-eight@4") == knot_goal("figure-eight", 4)
    assert goal_from_spec("overhand") == knot_goal("overhand")
    assert goal_from_spec("knot:granny@6") == goal_from_spec("granny") == knot_goal("granny")
    with pytest.raises(GoalError, match="unknown knot name 'bowline'.*overhand.*granny"):
        goal_from_spec("bowline")
    with pytest.raises(GoalError, match="a knotoid is not a knot"):
        goal_from_spec("knotoid")
    with pytest.raises(GoalError, match="crossings must be 1 to 7"):
        knot_goal("overhand", 8)
    # above its crossing number a knot's states are enumerated, never beyond 5 crossings (6 would be
    # millions of states)
    with pytest.raises(GoalError, match="would have to be enumerated"):
        knot_goal("overhand", 6)
    with pytest.raises(GoalError, match="straight rope"):
        knot_goal("unknot")
    with pytest.raises(GoalError, match="no rope state with 1 crossings ties"):
        knot_goal("figure-eight", 1)
    with pytest.raises(PlanInputError, match="exactly one goal"):
        make_goal(ONE_CROSSING, knot="overhand")
    with pytest.raises(PlanInputError, match="--crossings goes with --knot"):
        make_goal(ONE_CROSSING, crossings=3)


def test_high_level_plans_lead_to_any_member_shortest_first_and_are_cached(sqlite_url: str) -> None:
    goal = knot_goal("overhand")
    with open_store(sqlite_url) as store:
        found = high_level(store, goal, 20)(EMPTY)
        with store.session() as session:
            stored = session.scalars(select(PlanQuery.goal_key).where(PlanQuery.start_key == EMPTY.key)).all()
    assert stored == [goal.cache_key] and goal.cache_key.startswith("knot:overhand@3#4:")
    # only 16 move sequences lead from the straight rope to the four alternating states: all of them
    assert len(found) == len(plans_to_any(EMPTY, goal.states, 10_000)) == 16
    assert all(plan.states[0] == EMPTY and plan.states[-1] in goal for plan in found)
    lengths = [len(plan.moves) for plan in found]
    assert lengths == sorted(lengths)
    assert len({plan.states[-1].key for plan in found}) >= 2
    # no plan passes through a state that ties the knot already (plans stop at the first goal state)
    assert all(p not in goal for plan in found for p in plan.states[:-1])


def test_plans_to_any_is_the_union_of_the_members_plans() -> None:
    one = enumerate_states(1)[1][0]
    for start in (EMPTY, one):
        for name in ("overhand", "figure-eight"):
            goal = knot_goal(name)
            union = plans_to_any(start, goal.states, 10_000)
            per_member = [p for g in goal.states for p in plans(start, g, 10_000)]
            assert union and len(union) < 10_000
            key = lambda plan: tuple(s.key for s in plan.states)  # noqa: E731
            assert sorted(map(key, union)) == sorted(map(key, per_member))
            assert [len(p.moves) for p in union] == sorted(len(p.moves) for p in union)
    # one goal: exactly plans()
    target = knot_goal("overhand").states[0]
    assert plans_to_any(EMPTY, [target], 50) == plans(EMPTY, target, 50)
    assert plans_to_any(target, knot_goal("overhand").states) == [Plan([target], [])]


def test_goal_files_take_knot_names() -> None:
    sets = parse_goal_file(json.dumps({"knots": ["overhand", "figure-eight@4"], "states": [ONE_CROSSING]}))
    assert sets["knots"] == [knot_goal("overhand"), knot_goal("figure-eight", 4)]
    assert sets["states"] == [state_goal(parse_p_data(ONE_CROSSING))]
    assert isinstance(sets["knots"][0], Goal)


# --- planning to a knot, end to end -------------------------------------------------------------------


@pytest.mark.slow
def test_plan_to_an_overhand_knot_solves_replays_and_is_stored(tmp_path: Path) -> None:
    db = f"sqlite:///{tmp_path / 'knot.db'}"
    picture = tmp_path / "knot.png"
    args = ["--workers", "1", "--timeout", "240", "--picture", str(picture), "--json"]
    code, out = _cli(db, "plan", "--knot", "overhand", *args)
    assert code == 0, out
    assert picture.read_bytes().startswith(b"\x89PNG")  # --picture: the solved run's final rope
    result = json.loads(out)
    assert result["solved"] and result["goal"] == "knot:overhand@3" and result["knot"] == "overhand"
    assert len(result["goal_states"]) == 4 and result["tighten"] is False and result["pull_tests"] == 0
    # the database holds no model: the shipped default (no id) sampled the curves; its training data
    shipped = load_model(None).metadata
    assert result["model_id"] is None and result["model_samples"] == shipped["data_sources"]
    reached = parse_p_data(result["reached_state"])
    assert result["plan"][-1]["state"] == result["reached_state"]
    k = identify(reached)
    assert reached.cross == 3 and k.is_knot and k.under.name == k.over.name == k.name in ("3_1+", "3_1-")
    with open_store(db) as store:
        info = load_run(store, result["run_id"], with_nodes=False)
        assert info is not None and info.goal == knot_goal("overhand")
        replayed = replay(store, result["run_id"])
        assert replayed.reached_goal and all(step.matches for step in replayed.steps)
        with store.session() as session:
            row = session.scalar(select(SearchRunRow).where(SearchRunRow.run_id == result["run_id"]))
            assert row is not None and row.goal_knot == "overhand" and row.goal_cross == 3
            # the planner's tree counts in "which knots have we tied" (nodes of T, by run)
            tied = {(t.knot_type, t.run_kind) for t in knots_tied(session) if t.run_id == result["run_id"]}
            assert (identify(reached).name, "plan") in tied
    code, out = _cli(db, "replay", str(result["run_id"]))
    assert code == 0 and "reaches the goal overhand" in out


def test_knot_runs_resume_by_knot_and_refuse_another_goal(db_url: str) -> None:
    db = db_url
    args = ["--planner", "random-low", "--workers", "1", "--p-expand", "0", "--k", "1", "--json"]
    code, out = _cli(db, "plan", "--knot", "figure-eight", "--max-iterations", "1", *args)
    assert code == 3, out
    run_id = json.loads(out)["run_id"]
    with open_store(db) as store:
        assert find_resumable_run(store, knot_goal("figure-eight")) == run_id
        assert find_resumable_run(store, knot_goal("overhand")) is None
        assert find_resumable_run(store, state_goal(knot_goal("figure-eight").representative)) is None
    code, out = _cli(db, "plan", "--resume", "--knot", "overhand", "--timeout", "1")
    assert code == 2 and "no unfinished planner run for goal knot:overhand@3" in out
    code, out = _cli(db, "plan", "--resume", str(run_id), "--goal", ONE_CROSSING, "--timeout", "1")
    assert code == 2 and "knot:figure-eight@4" in out
    code, out = _cli(db, "plan", "--resume", "--knot", "figure-eight", "--max-iterations", "2", "--json")
    assert code == 3 and json.loads(out)["run_id"] == run_id


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--knot", "bowline"], "unknown knot name"),
        (["--knot", "knotoid"], "a knotoid is not a knot"),
        (["--knot", "overhand", "--goal", ONE_CROSSING], "exactly one goal"),
        (["--goal", ONE_CROSSING, "--crossings", "3"], "--crossings goes with --knot"),
        (["--knot", "overhand", "--crossings", "9"], "crossings must be 1 to 7"),
        (["--knot", "figure-eight", "--crossings", "1"], "no rope state"),
        (
            ["--knot", "overhand", "--crossings", "2"],
            "no rope state with 2 crossings ties the knot 'overhand'",
        ),
    ],
)
def test_bad_knot_goals_exit_2(tmp_path: Path, args: list[str], message: str) -> None:
    code, out = _cli(f"sqlite:///{tmp_path / 'bad.db'}", "plan", *args, "--timeout", "1")
    assert code == 2 and message in " ".join(out.split()), out


def test_problem_sets_of_knots_feed_eval(tmp_path: Path) -> None:
    db = f"sqlite:///{tmp_path / 'sets.db'}"
    code, out = _cli(db, "problems", "knots", "overhand", "figure-eight@4", "--name", "knots")
    assert code == 0, out
    code, out = _cli(db, "problems", "knots", "bowline", "--name", "bad")
    assert code == 2 and "knot 1 ('bowline')" in out
    code, out = _cli(db, "problems", "knots", "overhand@2", "--name", "bad")
    assert code == 2 and "knot 1 ('overhand@2')" in out
    code, out = _cli(db, "problems", "knots", "granny", "square", "--name", "composite")
    assert code == 0, out
    with open_store(db) as store:
        with store.session() as session:
            record = load_problem_set(session, "knots")
            assert load_problem_set(session, "bad") is None
            composite = load_problem_set(session, "composite")
        assert composite is not None
        assert [p.goal_key for p in composite.problems] == ["knot:granny@6", "knot:square@6"]
        assert [p.p_data.cross for p in composite.problems] == [6, 6]
        assert record is not None
        assert [p.goal_key for p in record.problems] == ["knot:overhand@3", "knot:figure-eight@4"]
        assert [p.p_data.cross for p in record.problems] == [3, 4]
    code, out = _cli(db, "problems", "list", "--show", "knots", "--json")
    assert code == 0 and json.loads(out) == ["knot:overhand@3", "knot:figure-eight@4"]
    # one overhand goal, random-low, one seed: the result is stored under the knot's spec
    code, out = _cli(
        db, "eval", "--set", "knots", "--planner", "random-low", "--timeout", "3", "--parallel", "1"
    )
    assert code == 0, out
    with open_store(db) as store, store.session() as session:
        rows = list(session.scalars(select(EvalResult)))
        assert sorted(r.goal_key for r in rows) == ["knot:figure-eight@4", "knot:overhand@3"]
        assert all(r.status in ("solved", "timeout") and r.plan_run_id is not None for r in rows)


def test_rope_env_takes_knot_goals_like_the_planner(tmp_path: Path) -> None:
    pytest.importorskip("gymnasium", reason="the rl extra (gymnasium) is not installed")
    from twisted.envs import goal_pool

    assert goal_pool(knot="overhand") == list(knot_goal("overhand").states)
    assert goal_pool(knot="overhand", knot_crossings=4) == list(knot_goal("overhand", 4).states)
    with pytest.raises(ValueError, match="no rope state with 2 crossings"):
        goal_pool(knot="overhand", knot_crossings=2)  # only knotoids: no goal
    db = f"sqlite:///{tmp_path / 'env.db'}"
    assert _cli(db, "problems", "knots", "figure-eight", "--name", "k")[0] == 0
    # a knot goal of a problem set stands for all its states
    assert goal_pool(problem_set="k", db_url=db) == list(knot_goal("figure-eight").states)


# --- goal sets drawn the way people name goals (issue 36) ------------------------------------------------


def test_a_set_drawn_with_a_seed_is_the_same_set_again() -> None:
    import numpy as np

    from twisted.experiments.goalsets import sample_states
    from twisted.experiments.problems import draw_named_set

    first = [r.goal_key for r in draw_named_set("u4", 5, seed=3)]
    assert first == [r.goal_key for r in draw_named_set("u4", 5, seed=3)]
    assert first != [r.goal_key for r in draw_named_set("u4", 5, seed=4)]
    assert len(set(first)) == 5 and all(parse_p_data(k).cross == 4 for k in first)
    # the sampler (6 crossings; 3 here to keep the test short) is seeded the same way
    a = [p.key for p in sample_states(3, 4, np.random.default_rng(9))]
    assert a == [p.key for p in sample_states(3, 4, np.random.default_rng(9))]
    assert len(set(a)) == 4 and all(parse_p_data(k).cross == 3 for k in a)


def test_the_head_tree_holds_every_state_once() -> None:
    """Each state of n crossings is the head child of exactly one state of n - 1 (the sampler's tree)."""
    from twisted.experiments.goalsets import head_children, head_parent

    layers = enumerate_states(3)
    for c in (1, 2, 3):
        children = [k for p in layers[c - 1] for k in head_children(p)]
        assert sorted(children, key=lambda p: p.key) == layers[c]
        assert all(head_parent(k) in layers[c - 1] for k in children)


def test_uniform_draws_leave_out_excluded_states() -> None:
    import numpy as np

    from twisted.experiments.goalsets import uniform_states

    three = enumerate_states(3)[3]
    keep = {p.key for p in three[:4]}
    drawn = uniform_states(3, 10, np.random.default_rng(0), exclude=frozenset(p.key for p in three) - keep)
    assert {p.key for p in drawn} == keep


def test_goal_set_files_are_imported_with_their_seed(sqlite_url: str, tmp_path: Path) -> None:
    code, out = _cli(
        sqlite_url, "problems", "make", "--set", "u4", "--seed", "5", "--per-set", "3", "--prefix", "t-"
    )
    assert code == 0, out
    target = tmp_path / "t-u4.json"
    code, out = _cli(sqlite_url, "problems", "export", "t-u4", "--out", str(target), "--kind", "u4")
    assert code == 0, out
    text = target.read_text()
    assert json.loads(text)["seed"] == 5
    # the file says the command that draws the set again, not the export that wrote it
    assert json.loads(text)["command"] == "twisted problems make --set u4 --seed 5 --prefix t- --per-set 3"
    other = f"sqlite:///{tmp_path / 'other.db'}"
    code, out = _cli(other, "problems", "import", str(target))
    assert code == 0, out
    with open_store(sqlite_url) as a, a.session() as s1, open_store(other) as b, b.session() as s2:
        made, imported = load_problem_set(s1, "t-u4"), load_problem_set(s2, "t-u4")
        assert made is not None and imported is not None
        assert [p.goal_key for p in made.problems] == [p.goal_key for p in imported.problems]
    with open_store(other) as b, b.session() as s2:
        from twisted.store.experiments import ProblemSet

        row = s2.scalar(select(ProblemSet).where(ProblemSet.name == "t-u4"))
        assert row is not None and row.seed == 5 and row.parameters["kind"] == "u4"


def test_an_imported_goal_set_file_exports_as_the_same_file(sqlite_url: str, tmp_path: Path) -> None:
    """Import keeps what the file says about the draw as a made set's parameters (the catalogue's pull
    test among them), so export writes the file back unchanged, round after round."""
    from twisted.experiments.runner import _pull_test_required
    from twisted.store.experiments import ProblemSet

    goalsets = Path(__file__).parent.parent / "goalsets"
    source = goalsets / "tune-u4.json"
    again = tmp_path / "tune-u4.json"
    assert _cli(sqlite_url, "problems", "import", str(source))[0] == 0
    code, out = _cli(sqlite_url, "problems", "export", "tune-u4", "--out", str(again))
    assert code == 0, out
    assert again.read_text() == source.read_text()
    # the catalogue's header, with its three-crossing goals only (the others take a minute to enumerate)
    catalogue = json.loads((goalsets / "catalogue.json").read_text())
    catalogue["goals"] = [g for g in catalogue["goals"] if g.endswith("@3")]
    small = tmp_path / "catalogue.json"
    small.write_text(json.dumps(catalogue))
    assert _cli(sqlite_url, "problems", "import", str(small))[0] == 0
    with open_store(sqlite_url) as store, store.session() as session:
        row = session.scalar(select(ProblemSet).where(ProblemSet.name == "catalogue"))
        assert row is not None and _pull_test_required(row.parameters)
        assert row.parameters["command"] == "twisted problems make --set catalogue"
        assert "format" not in row.parameters and "parameters" not in row.parameters
    back = tmp_path / "back.json"
    assert _cli(sqlite_url, "problems", "export", "catalogue", "--out", str(back))[0] == 0
    assert json.loads(back.read_text()) == catalogue


def test_a_goal_set_file_with_parameters_that_are_not_an_object_is_refused(
    sqlite_url: str, tmp_path: Path
) -> None:
    data = json.loads((Path(__file__).parent.parent / "goalsets" / "tune-u4.json").read_text())
    data["parameters"] = [data["parameters"]]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    code, out = _cli(sqlite_url, "problems", "import", str(bad))
    assert code == 2 and "parameters must be an object" in out
    assert not Path(sqlite_url.removeprefix("sqlite:///")).exists()


def test_0015_flattens_the_parameters_of_sets_imported_before(db_url: str) -> None:
    """A set imported before 0015 kept the file's whole header; the upgrade stores it as import does now,
    the downgrade nests it again."""
    from alembic import command
    from sqlalchemy import create_engine, text

    from twisted.store import alembic_config

    header = {
        "format": "twisted-goal-set/1",
        "name": "catalogue",
        "kind": "catalogue",
        "seed": 0,
        "command": "twisted problems make --set catalogue",
        "parameters": {"kind": "catalogue", "knots": ["3_1+"], "tighten": True, "pull_test": "required"},
        "goals": 1,
    }
    insert = text(
        "INSERT INTO problem_sets (id, name, source, seed, parameters, created_at) "
        "VALUES (:id, :name, :source, 0, :parameters, '2026-01-01 00:00:00')"
    )
    engine = create_engine(db_url)
    with engine.begin() as conn:
        command.upgrade(alembic_config(conn), "0005")
        conn.execute(
            insert, {"id": 1, "name": "catalogue", "source": "imported", "parameters": json.dumps(header)}
        )
        conn.execute(
            insert, {"id": 2, "name": "u4", "source": "made", "parameters": json.dumps({"kind": "u4"})}
        )
        conn.execute(
            insert, {"id": 3, "name": "plain", "source": "imported", "parameters": json.dumps({"goals": 2})}
        )
    read = text("SELECT parameters FROM problem_sets ORDER BY id")

    def stored() -> list[dict[str, object]]:
        with engine.connect() as conn:
            return [p if isinstance(p, dict) else json.loads(p) for (p,) in conn.execute(read)]

    with engine.begin() as conn:
        command.upgrade(alembic_config(conn), "0015")
    flat = {**header["parameters"], "command": header["command"], "goals": 1}
    assert stored() == [flat, {"kind": "u4"}, {"goals": 2}]
    with engine.begin() as conn:
        command.downgrade(alembic_config(conn), "0005")
    assert stored() == [header, {"kind": "u4"}, {"goals": 2}]
    engine.dispose()


def test_the_committed_goal_sets_import() -> None:
    from twisted.experiments.problems import goal_file_header

    files = sorted(Path(__file__).parent.parent.joinpath("goalsets").glob("*.json"))
    assert files, "goalsets/ holds the sets behind the figures"
    for path in files:
        text = path.read_text()
        header = goal_file_header(json.loads(text))
        assert isinstance(header["seed"], int) and header["name"] == path.stem
        (goals,) = parse_goal_file(text).values()
        assert goals


def test_the_knots_set_asks_for_each_named_knot_in_either_hand_with_the_pull_test() -> None:
    """`problems make --set knots`: the six names `plan --knot` takes, each goal any state of either hand
    (after the committed sets above, so the 5-crossing states are enumerated once in this process)."""
    from twisted.experiments.problems import KNOT_NAMES, _named_parameters, draw_named_set
    from twisted.experiments.runner import _pull_test_required

    drawn = draw_named_set("knots", 10, seed=3)
    assert [r.spec for r in drawn] == [
        f"knot:{name}@{c}" for name, c in zip(KNOT_NAMES, (3, 4, 5, 5, 6, 6), strict=True)
    ]
    assert [r.goal_key for r in drawn] == [r.goal_key for r in draw_named_set("knots", 2, seed=0)]
    assert _pull_test_required(_named_parameters("knots", 10))


def test_knot_state_sets_are_kept_in_the_store(sqlite_url: str) -> None:
    """Computed once, read back by the next process: the same sets (3 crossings keep the test short)."""
    from twisted.knots import prime_states_by_type, states_by_type, states_tying
    from twisted.store.knots import KnotStateSet, cached_states_by_type

    with open_store(sqlite_url) as store:
        first = cached_states_by_type(store, 3)
        with store.session() as session:
            rows = session.scalars(select(KnotStateSet).where(KnotStateSet.crossings == 3)).all()
            assert {r.knot_type for r in rows} == set(first)
            assert sum(r.n_states for r in rows) == len(enumerate_states(3)[3]) == 528
        prime_states_by_type(3, {})  # as a new process would start: nothing known
        assert states_by_type(3) == {}
        again = cached_states_by_type(store, 3)
    assert again == first
    assert states_tying("overhand", 3) == sorted(first["3_1+"] + first["3_1-"], key=lambda p: p.key)
