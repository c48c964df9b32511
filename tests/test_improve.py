"""Expert iteration (`twisted improve`): evaluation goals are never trained on; a generation plans."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sqlalchemy import select
from typer.testing import CliRunner

from cli.main import app
from twisted.experiments.improve import ImproveConfig, evaluation_goal_keys, improve, training_goals
from twisted.experiments.problems import draw_named_set
from twisted.moves import enumerate_states
from twisted.store import open_store
from twisted.store.improve import ImproveGeneration

runner = CliRunner()


def _cli(db: str, *args: str) -> tuple[int, str]:
    result = runner.invoke(app, ["--db", db, *args])
    return result.exit_code, result.output


def _write_set(tmp_path: Path, name: str, goals: list[object]) -> Path:
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps({"format": "twisted-goal-set/1", "name": name, "seed": 1, "goals": goals}))
    return path


def _empty_folder(path: Path) -> Path:
    path.mkdir(exist_ok=True)
    return path


def _one_crossing_goals() -> list[object]:
    return [p.to_list() for p in enumerate_states(1)[1]]


def test_improve_refuses_an_evaluation_set_as_training_goals(sqlite_url: str, tmp_path: Path) -> None:
    tune = _write_set(tmp_path, "tune-x", _one_crossing_goals()[:1])
    final = _write_set(tmp_path, "final-x", _one_crossing_goals()[1:3])
    for path in (tune, final):
        code, out = _cli(sqlite_url, "problems", "import", str(path))
        assert code == 0, out
    empty = tmp_path / "no-files"
    empty.mkdir()
    # a stored set named as an evaluation set, and the tuning set itself
    for train_set in ("final-x", "tune-x"):
        code, out = _cli(
            sqlite_url, "improve", "--tune-set", "tune-x", "--train-set", train_set, "--goalsets", str(empty)
        )
        assert code == 2, out
        assert "evaluation" in out
    # a set with another name that holds an evaluation goal
    sneaky = _write_set(tmp_path, "mine", _one_crossing_goals()[2:4])
    assert _cli(sqlite_url, "problems", "import", str(sneaky))[0] == 0
    code, out = _cli(
        sqlite_url, "improve", "--tune-set", "tune-x", "--train-set", "mine", "--goalsets", str(empty)
    )
    assert code == 2 and "goal 0" in out, out
    with open_store(sqlite_url) as store, store.session() as session:
        assert session.scalars(select(ImproveGeneration)).all() == []


def test_goal_files_named_final_are_evaluation_goals(sqlite_url: str, tmp_path: Path) -> None:
    folder = tmp_path / "goalsets"
    folder.mkdir()
    goals = _one_crossing_goals()
    _write_set(folder, "final-u1", goals[:2])
    _write_set(folder, "other", goals[2:3])
    tune = _write_set(tmp_path, "tune-y", goals[3:4])
    assert _cli(sqlite_url, "problems", "import", str(tune))[0] == 0
    with open_store(sqlite_url) as store, store.session() as session:
        keys, names = evaluation_goal_keys(session, "tune-y", folder)
    expected = {json.dumps(g, separators=(",", ":")) for g in (goals[0], goals[1], goals[3])}
    assert keys == expected and names == ["tune-y"]


def test_the_guard_reads_the_committed_sets_from_any_folder_and_refuses_bad_ones(
    sqlite_url: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 62, item 4. Before: run from a folder without goalsets/, `improve --train-set mine` (goal 0
    of goalsets/final-u4.json) went on to train; --goalsets /nonexistent was accepted; a final-*.json that
    is not UTF-8, or a folder so named, gave a traceback."""
    from twisted.experiments.problems import parse_goal_file

    final = parse_goal_file((Path(__file__).resolve().parents[1] / "goalsets" / "final-u4.json").read_text())
    mine = _write_set(tmp_path, "mine", [next(iter(final.values()))[0].spec])
    tune = _write_set(tmp_path, "tune-z", _one_crossing_goals()[:1])
    for path in (mine, tune):
        assert _cli(sqlite_url, "problems", "import", str(path))[0] == 0
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # no goalsets/ here
    base = ["improve", "--tune-set", "tune-z", "--train-set", "mine"]

    def wide(db: str, *args: str) -> tuple[int, str]:  # wide: the long paths stay on one line
        result = runner.invoke(app, ["--db", db, *args], env={"COLUMNS": "400"})
        return result.exit_code, result.output

    code, out = wide(sqlite_url, *base)
    assert code == 2 and "goal 0" in out and "evaluation set or file" in out, out

    code, out = wide(sqlite_url, *base, "--goalsets", str(tmp_path / "nonexistent"))
    assert code == 2 and "does not exist" in out, out
    bad = _empty_folder(tmp_path / "bad")
    (bad / "final-bad.json").write_bytes(b"\xff\xfe{")
    code, out = wide(sqlite_url, *base, "--goalsets", str(bad))
    assert code == 2 and "final-bad.json" in out and "UTF-16" in out, out
    (bad / "final-bad.json").unlink()
    (bad / "final-x.json").mkdir()
    code, out = wide(sqlite_url, *base, "--goalsets", str(bad))
    assert code == 2 and "final-x.json" in out and "not a file" in out, out
    (bad / "final-x.json").rmdir()
    (bad / "eval-y.json").write_text('[[[1,"O",9,"+"]]]')
    code, out = wide(sqlite_url, *base, "--goalsets", str(bad))
    assert code == 2 and "eval-y.json" in out, out
    with open_store(sqlite_url) as store, store.session() as session:
        assert session.scalars(select(ImproveGeneration)).all() == []


def test_drawn_training_goals_never_hold_an_evaluation_goal() -> None:
    fours = enumerate_states(4)[4]
    allowed = {p.key for p in fours[:6]}
    exclude = frozenset(p.key for p in fours) - allowed
    drawn = training_goals(("u4",), 6, seed=0, generation=1, exclude=exclude)
    assert {g.spec for g in drawn} == allowed
    # seeded: the same generation draws the same goals, another generation others
    eval_keys = frozenset(r.goal_key for r in draw_named_set("u4", 10, seed=101))
    first = [g.spec for g in training_goals(("u4",), 5, 3, 1, eval_keys)]
    assert first == [g.spec for g in training_goals(("u4",), 5, 3, 1, eval_keys)]
    assert first != [g.spec for g in training_goals(("u4",), 5, 3, 2, eval_keys)]
    assert not eval_keys & set(first)


def test_bad_improve_options_exit_2_before_anything_is_written(sqlite_url: str) -> None:
    for args in (
        ["--goals", "0"],
        ["--draw", "u9"],
        ["--hours", "0"],
        ["--tune-iterations", "0"],
        ["--parallel", "0"],
        ["--device", "tpu"],
    ):
        code, out = _cli(sqlite_url, "improve", "--tune-set", "t", *args)
        assert code == 2, (args, out)
    assert not Path(sqlite_url.removeprefix("sqlite:///")).exists()


def _one_generation(
    db: str, tmp_path: Path, suffix: str, train_goals: list[object], **options: object
) -> ImproveConfig:
    """A lineage of one generation, imported into ``db``: tuning set ``tune-SUFFIX`` (the first 1-crossing
    goal), training set ``train-SUFFIX``, 30 s budgets, one epoch; ``options`` add to the config."""
    tune = _write_set(tmp_path, f"tune-{suffix}", _one_crossing_goals()[:1])
    train = _write_set(tmp_path, f"train-{suffix}", train_goals)
    for path in (tune, train):
        assert _cli(db, "problems", "import", str(path))[0] == 0
    return ImproveConfig(
        tune_set=f"tune-{suffix}",
        hours=0.5,
        generations=1,
        train_set=f"train-{suffix}",
        goal_timeout_s=30.0,
        tune_timeout_s=30.0,
        epochs=1,
        batch_size=16,
        goalsets_dir=str(_empty_folder(tmp_path / "none")),
        **options,
    )


@pytest.mark.slow
def test_a_generation_trained_on_a_tiny_store_loads_and_plans(sqlite_url: str, tmp_path: Path) -> None:
    """Generation 1 of a tiny lineage (two 1-crossing goals, one epoch) is a stored model that plans."""
    from twisted.model.registry import load_model
    from twisted.planner import PlannerOptions, curve_sampler, start_search
    from twisted.sim import SimPool

    goals = _one_crossing_goals()
    config = _one_generation(
        sqlite_url, tmp_path, "z", goals[1:3], lineage="tiny", goal_iterations=8, tune_iterations=3
    )
    with open_store(sqlite_url) as store:
        rows = improve(store, config)
        assert [r.generation for r in rows] == [0, 1]
        assert all(r.status == "finished" for r in rows)
        zero, one = rows
        assert one.parent_model_id == zero.model_id and one.model_id not in (None, zero.model_id)
        assert one.data["n_train_search"] + one.data.get("n_val_search", 0) > 0
        assert one.tune_runs == 1 and len(one.training_goals) == 2
        model = load_model(store, one.model_id)
        assert model.model_id == one.model_id
        sampler, used = curve_sampler(store, "twisted", one.model_id)
        assert used == one.model_id
        with SimPool(1) as pool:
            search = start_search(store, _goal(goals[3]), PlannerOptions(seed=0), pool, sampler=sampler)
            result = search.run(timeout_s=60.0, max_iterations=3)
        assert result.sim_calls > 0 and result.nodes > 1
        # a second call continues the lineage: nothing left to do for generation 1, so no new rows
        assert [r.id for r in improve(store, config)] == [r.id for r in rows]
    wide = runner.invoke(app, ["--db", sqlite_url, "models"], env={"COLUMNS": "300"})
    assert wide.exit_code == 0 and "tiny g1 (parent 1)" in wide.output and "tiny g0" in wide.output, (
        wide.output
    )


@pytest.mark.slow
def test_searches_in_parallel_processes_are_recorded_in_goal_order(sqlite_url: str, tmp_path: Path) -> None:
    """``parallel=2``: the training goals' searches run in spawned processes on the same store, and each
    outcome is recorded under its goal's index, whichever ends first."""
    from twisted.store.models import Run

    goals = _one_crossing_goals()
    config = _one_generation(
        sqlite_url, tmp_path, "p", goals[1:4], lineage="two", goal_iterations=4, tune_iterations=2, parallel=2
    )
    with open_store(sqlite_url) as store:
        rows = improve(store, config)
        assert [r.status for r in rows] == ["finished", "finished"]
        planned = rows[1].training_goals
        assert [o["index"] for o in planned] == [0, 1, 2]
        assert [o["goal"] for o in planned] == [json.dumps(g, separators=(",", ":")) for g in goals[1:4]]
        assert [o["seed"] for o in planned] == [1000, 1001, 1002]
        with store.session() as session:
            runs = {r.id: r for r in session.scalars(select(Run))}
        assert all(runs[o["run_id"]].parameters["phase"] == "train" for o in planned)
        assert len({o["run_id"] for o in planned}) == 3 and rows[1].tune_runs == 1


def _goal(p_data: object):  # noqa: ANN202 - a Goal
    from twisted.goals import goal_from_spec

    return goal_from_spec(json.dumps(p_data))


def test_every_store_module_maps_on_its_own() -> None:
    """Each table module, imported alone in a fresh process, knows every table its foreign keys name (a
    lineage resumed in a new process once failed to write its generation row: no ``models`` table)."""
    import subprocess
    import sys

    store_dir = Path(__file__).resolve().parents[1] / "twisted" / "store"
    modules = sorted(p.stem for p in store_dir.glob("*.py") if p.stem != "__init__")
    assert "improve" in modules and "training" in modules
    code = (
        "import importlib, sys\n"
        "importlib.import_module('twisted.store.' + sys.argv[1])\n"
        "from twisted.store.models import Base\n"
        "Base.metadata.sorted_tables\n"
    )
    for module in modules:
        done = subprocess.run([sys.executable, "-c", code, module], capture_output=True, text=True)
        assert done.returncode == 0, (module, done.stderr[-500:])


def test_outcomes_stored_before_the_index_keep_their_order() -> None:
    """Rows written before outcomes carried their goal's index are in goal order: the i-th reads as goal
    i (and a resumed phase skips the indices read)."""
    from twisted.experiments.improve import _indexed

    old = [{"goal": "a", "solved": True}, {"goal": "b", "solved": False}]
    assert [o["index"] for o in _indexed(old)] == [0, 1]
    mixed = [{"goal": "c", "index": 3}, {"goal": "a", "index": 0}]
    assert [o["index"] for o in _indexed(mixed)] == [3, 0]
    assert _indexed(None) == []
