"""Episodes (docs/DESIGN.md section 15): a stored plan executed in a world, observed, replanned, resumed.

The planner here is ``random-low`` toward one crossing (seconds, no model to load); the worlds and the
simulation are real everywhere.
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from sqlalchemy import func, select
from typer.testing import CliRunner

from cli.main import app
from twisted.experiments.episodes import (
    FIT_REJECTED,
    MAX_LOOKS,
    Episode,
    EpisodeSettings,
    ModelPlanner,
    Replan,
    first_summand_goal,
    plan_of_run,
    resume_state,
    summand_cinched,
)
from twisted.experiments.robustness import FINISHED, robustness_markdown, robustness_table, settings_label
from twisted.goals import PlanInputError, check_goal, knot_goal, state_goal
from twisted.planner import stored_options
from twisted.store import open_store
from twisted.store.episodes import EpisodeRow, EpisodeStep, load_episode
from twisted.store.models import Run, blob_to_array
from twisted.store.search_tree import SearchNode, load_run
from twisted.world import LEVELS, PullVerdict, SimWorld, World

ONE_CROSSING = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
runner = CliRunner()


@pytest.fixture(scope="module")
def planned(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, int]:
    """A database holding one solved planner run toward one crossing (random-low, seed 0)."""
    db = f"sqlite:///{tmp_path_factory.mktemp('episodes') / 'twisted.db'}"
    args = ["--db", db, "plan", "--goal", ONE_CROSSING, "--planner", "random-low", "--workers", "1"]
    result = runner.invoke(app, [*args, "--timeout", "120", "--json"])
    assert result.exit_code == 0, result.output
    return db, int(json.loads(result.output)["run_id"])


def _execute(db: str, *args: str) -> tuple[int, str]:
    result = runner.invoke(app, ["--db", db, "execute", *args])
    return result.exit_code, result.output


def _count(db: str, model: Any) -> int:
    with open_store(db) as store, store.session() as session:
        return int(session.scalar(select(func.count()).select_from(model)) or 0)


@pytest.mark.parametrize(
    "level",
    ["hurricane", "moderate,friction=-0.5:1", "moderate,observation_noise_m=1", "none,lift_noise_m=x"],
)
def test_a_level_that_makes_no_sense_is_refused_before_anything_is_written(
    tmp_path: Path, planned: tuple[str, int], level: str
) -> None:
    new = tmp_path / "new.db"
    code, out = _execute(f"sqlite:///{new}", "1", "--world", level)
    assert code == 2 and "--world" in out
    assert not new.exists()
    db, run_id = planned
    runs = _count(db, Run)
    code, out = _execute(db, str(run_id), "--world", level, "--closed-loop")
    assert code == 2 and "--world" in out
    assert _count(db, Run) == runs
    result = runner.invoke(app, ["--db", f"sqlite:///{new}", "tie", "--knot", "overhand", "--world", level])
    assert result.exit_code == 2 and not new.exists()


def _observations(db: str, episode: int) -> list[bytes]:
    with open_store(db) as store, store.session() as session:
        rows = session.scalars(
            select(EpisodeStep.points).where(EpisodeStep.episode_id == episode).order_by(EpisodeStep.seq)
        )
        return [p for p in rows if p is not None]


def test_an_episode_is_stored_and_the_same_seed_gives_the_same_observations(planned: tuple[str, int]) -> None:
    db, run_id = planned
    outcomes = []
    for _ in range(2):
        code, out = _execute(db, str(run_id), "--world", "moderate", "--seed", "4", "--json")
        assert code in (0, 3), out
        outcomes.append(json.loads(out))
    first, second = (o["episode"] for o in outcomes)
    assert _observations(db, first) == _observations(db, second)
    with open_store(db) as store:
        stored = load_episode(store, first)
        assert stored.plan_run_id == run_id and stored.world_seed == 4 and not stored.closed_loop
        assert stored.level_ranges == LEVELS["moderate"].to_dict()
        kinds = [s.kind for s in stored.steps]
        assert kinds[0] == "reset" and kinds[-1] == "pull_test"
        assert kinds.count("curve") == outcomes[0]["actions"] == len(plan_of_run(store, run_id).steps)
        with store.session() as session:
            row = session.get(EpisodeRow, first)
            assert row is not None and set(row.physics) == {
                "friction",
                "stiffness",
                "damping",
                "mass",
                "radius_m",
            }
            assert row.outcome == outcomes[0]["outcome"]
    other = _execute(db, str(run_id), "--world", "moderate", "--seed", "5", "--json")[1]
    assert _observations(db, json.loads(other)["episode"]) != _observations(db, first)


class Spy:
    """Delegates to a world and records which of its attributes the episode used."""

    def __init__(self, world: SimWorld) -> None:
        self._world = world
        self.used: set[str] = set()

    def __getattr__(self, name: str) -> Any:
        self.used.add(name)
        return getattr(self._world, name)


class SeenByPlanner(ModelPlanner):
    """The model planner, recording what each replan was given."""

    given: list[tuple[Any, ...]]

    def replan(
        self,
        points: Any,
        seed: int,
        timeout_s: float,
        like: Any = None,
        staged: bool = False,
        cinched: bool = False,
    ) -> Any:
        self.given.append((points, seed, timeout_s, like))
        return super().replan(points, seed, timeout_s, like, staged, cinched)


def _parts(db: str, run_id: int) -> tuple[Any, Any, Any, Any]:
    store = open_store(db)
    info = load_run(store, run_id, with_nodes=False)
    assert info is not None
    return store, info.goal, stored_options(info.parameters), plan_of_run(store, run_id)


def _episode_row(store: Any, level: str, seed: int, plan: Any, closed_loop: bool) -> int:
    from twisted.store.episodes import create_episode

    world_level = LEVELS[level]
    return create_episode(
        store,
        {"drift_m": 0.001, "workers": 1, "level": world_level.to_dict()},
        plan_run_id=plan.run_id,
        goal_knot="0_1",
        level=level,
        level_ranges=world_level.to_dict(),
        world_seed=seed,
        physics=SimWorld(world_level, seed).physics.to_dict(),
        closed_loop=closed_loop,
        timeout_s=120.0,
        max_actions=4,
    )


def test_the_planner_gets_observations_only(planned: tuple[str, int]) -> None:
    db, run_id = planned
    store, goal, options, plan = _parts(db, run_id)
    episode_id = _episode_row(store, "strong", 3, plan, True)
    world = Spy(SimWorld(LEVELS["strong"], 3))
    planner = SeenByPlanner(store, goal, options, None, 1, episode_id)
    planner.given = []
    # a drift of 1 mm: every action is off plan, so the episode replans after each one
    settings = EpisodeSettings(closed_loop=True, timeout_s=60.0, max_actions=2, drift_m=0.001)
    try:
        episode = Episode(store, episode_id, world, goal, planner, settings)
        result = episode.run(episode.begin(plan))
    finally:
        planner.close()
        store.close()
    assert result.replans >= 1 and planner.given
    protocol = {name for name in dir(World) if not name.startswith("_")}
    assert world.used <= protocol, world.used - protocol
    for points, seed, timeout_s, _ in planner.given:
        assert isinstance(points, np.ndarray) and points.shape == (22, 3)
        assert isinstance(seed, int) and isinstance(timeout_s, float)
    # the replans start from configurations fitted to observations, stored under the episode's run
    with open_store(db) as store:
        # what the model expects the rope to be (where the fit starts) is the model's own: a node's q
        with store.session() as session:
            model_qs = [blob_to_array(q) for q in session.scalars(select(SearchNode.q))]
        assert all(any(np.array_equal(g[3], q) for q in model_qs) for g in planner.given)
        stored = load_episode(store, episode_id)
        replans = [s for s in stored.steps if s.kind == "replan"]
        assert len(replans) == result.replans and all(s.fit_residual_m is not None for s in replans)
        for step in replans:
            if step.replan_run_id is not None:
                info = load_run(store, step.replan_run_id, with_nodes=False)
                assert info is not None and info.start_configuration_id is not None
                assert info.parameters["episode"] == episode_id
        # the robustness table gives the median planning time of a replan over the group's episodes
        row = next(r for r in robustness_table(store) if r.closed_loop and r.level == "strong")
        planning = sorted(s.planning_s for s in replans if s.planning_s is not None)
        assert row.median_replan_s == pytest.approx(float(np.median(planning)), abs=1e-3)


class RejectsFits(ModelPlanner):
    """The model planner whose first ``rejects`` replans find the observation cannot be fitted (as a
    strand pressed through another in the noise of one camera frame at ``strong``)."""

    rejects: int

    def replan(self, *args: Any, **kwargs: Any) -> Any:
        if self.rejects > 0:
            self.rejects -= 1
            return Replan(None, None, 0.0, 0.01, FIT_REJECTED, unfitted=True)
        return super().replan(*args, **kwargs)


@pytest.mark.parametrize("rejects", [1, 99])
def test_an_observation_the_model_cannot_fit_is_taken_again_before_the_episode_is_lost(
    planned: tuple[str, int], rejects: int
) -> None:
    db, run_id = planned
    store, goal, options, plan = _parts(db, run_id)
    episode_id = _episode_row(store, "strong", 3, plan, True)
    planner = RejectsFits(store, goal, options, None, 1, episode_id)
    planner.rejects = rejects
    # a drift of 1 mm: the first action is off plan, so the episode replans after it
    settings = EpisodeSettings(closed_loop=True, timeout_s=60.0, max_actions=2, drift_m=0.001)
    try:
        episode = Episode(store, episode_id, SimWorld(LEVELS["strong"], 3), goal, planner, settings)
        result = episode.run(episode.begin(plan))
    finally:
        planner.close()
        store.close()
    with open_store(db) as store:
        steps = load_episode(store, episode_id).steps
    kinds = [s.kind for s in steps]
    looks = [s for s in steps if s.kind == "observe"]
    assert all(s.points is not None and s.world_checkpoint is not None for s in looks)
    if rejects == 1:  # one frame could not be fitted: the next one was, and the episode went on
        assert len(looks) == 1 and result.outcome != "lost"
        assert kinds[kinds.index("observe") - 1] == "replan" and kinds[kinds.index("observe") + 1] == "replan"
        assert result.replans >= 2
    else:  # none can be fitted: MAX_LOOKS frames more, then lost
        assert result.outcome == "lost" and len(looks) == MAX_LOOKS and result.replans == MAX_LOOKS + 1
        assert kinds[-2:] == ["observe", "replan"]
        # a resume counts the looks already taken
        with open_store(db) as store:
            assert resume_state(store, steps[:-1])[0].looks == MAX_LOOKS


class CannotPull(Spy):
    """A world whose simulator cannot carry a pull out (as the world's rope at twice the friction)."""

    def pull_test(self) -> PullVerdict:
        self.used.add("pull_test")
        return PullVerdict(None, "deep penetration (0.0112 m > 0.01115 m)", moved=False)


class PullsButPutsBack(Spy):
    """A world whose pull reads no knot but whose pulled rope would not rest: it lies as it did."""

    def pull_test(self) -> PullVerdict:
        self.used.add("pull_test")
        return PullVerdict("0_1", None, "the pulled rope did not come to rest: it lies as before", False)


def test_a_rope_the_world_cannot_pull_ends_unpulled_not_untied(planned: tuple[str, int]) -> None:
    db, run_id = planned
    store, goal, options, plan = _parts(db, run_id)
    episode_id = _episode_row(store, "none", 0, plan, False)
    planner = ModelPlanner(store, goal, options, None, 1, episode_id)
    try:
        episode = Episode(
            store,
            episode_id,
            CannotPull(SimWorld(LEVELS["none"], 0)),
            goal,
            planner,
            EpisodeSettings(False, 60.0),
        )
        result = episode.run(episode.begin(plan))
    finally:
        planner.close()
        store.close()
    assert result.outcome == "unpulled" and result.final_knot is None and "unpulled" in FINISHED
    with open_store(db) as store:
        stored = load_episode(store, episode_id)
        assert stored.outcome == "unpulled"
        assert stored.steps[-1].kind == "pull_test" and "deep penetration" in (stored.steps[-1].fault or "")
        # the robustness table says how the untied episodes ended
        row = next(r for r in robustness_table(store) if not r.closed_loop and r.level == "none")
        assert row.untied.get("unpulled", 0) >= 1 and row.to_dict()["untied"] == row.untied
        assert any("unpulled" in line for line in robustness_markdown([row]))


def _two_crossings() -> np.ndarray:
    """A configuration of the model's rope with two crossings (seeded random curves from straight)."""
    from twisted.sim import RopeSim, sample_curve

    sim, rng = RopeSim(), np.random.default_rng(0)
    reached = [sim.state()]
    for _ in range(400):
        sim.set_state(reached[int(rng.integers(len(reached)))])
        if sim.apply(sample_curve(rng)).ok:
            if sim.p_data().cross == 2:
                return sim.state()
            if sim.p_data().cross < 2:
                reached.append(sim.state())
    raise AssertionError("no two-crossing rope in 400 random curves")


class PullsAKnot(Spy):
    """A world whose pull reads a knot and leaves the rope as it was (a rope that will not come straight)."""

    knot = "3_1+"

    def pull_test(self) -> PullVerdict:
        self.used.add("pull_test")
        return PullVerdict(self.knot, None)


class PullsNoStraighter(PullsAKnot):
    """A world whose pull reads no knot but leaves the rope's crossings (a twist that does not pull out)."""

    knot = "0_1"


@pytest.mark.parametrize(
    "world_kind", ["straightens", "no-straighten", "knotted", "stays", "cannot", "put-back"]
)
def test_a_rope_in_a_dead_end_is_pulled_straight_before_the_replan(
    planned: tuple[str, int], world_kind: str
) -> None:
    """Toward one crossing, a rope of two crossings is a dead end: adding moves never reach the goal."""
    db, run_id = planned
    store, goal, options, plan = _parts(db, run_id)
    episode_id = _episode_row(store, "none", 0, plan, True)
    kinds_of_world = {
        "knotted": PullsAKnot,
        "stays": PullsNoStraighter,
        "cannot": CannotPull,
        "put-back": PullsButPutsBack,
    }
    world = kinds_of_world.get(world_kind, Spy)(SimWorld(LEVELS["none"], 0))
    planner = SeenByPlanner(store, goal, options, None, 1, episode_id)
    planner.given = []
    settings = EpisodeSettings(True, 20.0, max_actions=1, straighten=world_kind != "no-straighten")
    try:
        episode = Episode(store, episode_id, world, goal, planner, settings)
        state = episode.begin(plan)
        # the world's rope as a curve in another world might leave it: two crossings, off the plan
        state.points, state.plan = world.reset(_two_crossings()).points, None
        result = episode.run(state)
    finally:
        planner.close()
        store.close()
    with open_store(db) as store:
        steps = load_episode(store, episode_id).steps
        resumed = resume_state(store, steps)[0]
    kinds = [s.kind for s in steps]
    assert kinds[0] == "reset", (kinds, result)
    if world_kind == "no-straighten":
        assert "straighten" not in kinds and kinds[1] == "replan" and result.straightens == 0
        return
    # pulled once, stored with what the pull read and the world's checkpoint, then planned from
    assert kinds[1:3] == ["straighten", "replan"], (kinds, result)
    pulled = steps[1]
    assert pulled.world_checkpoint is not None and pulled.points is not None
    assert result.straightens == resumed.straightens == kinds.count("straighten")
    assert "pull_test" in world.used
    if world_kind not in ("stays", "put-back"):  # straight, knotted, or could not be pulled: once
        assert kinds.count("straighten") == 1
    like = planner.given[0][3]  # the model's expectation of the rope the first replan fits near
    if world_kind in ("cannot", "put-back"):  # the rope lies as it did: the expectation stands
        assert like is not None and np.array_equal(like, plan.root_q) and pulled.fault
        if world_kind == "cannot":  # and it is not pulled again
            assert pulled.knot is None and not resumed.may_straighten
        else:  # the pull read no knot: it may be pulled again after the next action
            assert pulled.knot == "0_1" and resumed.may_straighten
        return
    assert like is None  # a pulled rope is one the model never made: the fit takes the least bent roll
    if world_kind == "straightens":  # no knot: the rope comes straight, and the replan starts there
        assert pulled.knot == "0_1" and pulled.observed_key == "[]" and resumed.may_straighten
    elif world_kind == "stays":  # still in a dead end after the pull: planned from, not pulled again
        assert pulled.knot == "0_1" and pulled.observed_key != "[]"
        moved = [k for k in kinds if k in ("curve", "straighten")]
        assert all(a != b for a, b in zip(moved, moved[1:], strict=False)), kinds
    else:  # a rope that pulls to a knot is not pulled again: it stays knotted
        assert pulled.knot == "3_1+" and pulled.observed_key != "[]" and not resumed.may_straighten


@pytest.mark.parametrize(
    ("knot", "first"),
    [("granny", "3_1"), ("granny+", "3_1+"), ("square", "3_1"), ("3_1-#4_1", "3_1-"), ("overhand", None)],
)
def test_a_composite_knot_is_tied_in_stages_its_first_summand_first(knot: str, first: str | None) -> None:
    stage = first_summand_goal(knot_goal(knot))
    assert (stage and stage.knot) == first
    if stage is not None:  # the stage's states are the summand's: granny's and square's either chirality
        assert stage == knot_goal(first) and {p.cross for p in stage.states} == {3}
    assert first_summand_goal(knot_goal("5_2")) is None


class RecordsGoals(ModelPlanner):
    """The model planner whose searches record the goal they were asked for and search nothing."""

    goals: list[str]

    cinched: list[bool]

    def search(
        self, start: Any, seed: int, timeout_s: float, goal: Any = None, cinched: bool = False
    ) -> tuple[int, bool]:
        self.goals.append((goal or self.goal).spec)
        self.cinched.append(cinched)
        raise PlanInputError("recorded, not searched")


def test_a_staged_replan_aims_at_the_first_summand_until_the_rope_ties_one(planned: tuple[str, int]) -> None:
    db, run_id = planned
    store, _, options, plan = _parts(db, run_id)
    granny = knot_goal("granny")
    planner = RecordsGoals(store, granny, options, None, 1, _episode_row(store, "none", 0, plan, True))
    planner.goals, planner.cinched = [], []
    bent = plan.steps[-1].points  # a rope of one crossing: it ties no overhand
    try:
        for staged in (True, False):
            assert planner.replan(bent, 1, 5.0, None, staged).run_id is None
    finally:
        planner.close()
        store.close()
    assert planner.goals == [knot_goal("3_1").spec, granny.spec] and planner.cinched == [False, False]
    # a rope that ties an overhand aims at the granny (its search cinches the overhand first)
    overhand = knot_goal("3_1+").states[0]
    assert planner.goal_for(overhand, True) == granny != planner.goal_for(plan.steps[-1].p_data, True)
    assert planner.goal_for(None, True) == granny


class TiesASummand(RecordsGoals):
    """Sees a summand tied in every rope (what a rope the world left tying an overhand would show)."""

    def ties_summand(self, p_data: Any) -> bool:
        return True


def test_a_rope_that_ties_a_summand_is_cinched_in_the_world_before_the_replan(
    planned: tuple[str, int],
) -> None:
    db, run_id = planned
    store, _, options, plan = _parts(db, run_id)
    granny = knot_goal("granny")
    episode_id = _episode_row(store, "none", 0, plan, True)
    world = Spy(SimWorld(LEVELS["none"], 0))
    planner = TiesASummand(store, granny, options, None, 1, episode_id)
    planner.goals, planner.cinched = [], []
    try:
        episode = Episode(store, episode_id, world, granny, planner, EpisodeSettings(True, 20.0, 4))
        state = episode.begin(plan)
        state.plan = None  # off plan: the next thing is a replan
        result = episode.run(state)
        kinds = [s.kind for s in load_episode(store, episode_id).steps]
    finally:
        planner.close()
        store.close()
    # cinched once, in the world, then planned for the whole knot (the search records it and stops),
    # a search that cinches nothing: the world pulled the summand tight already
    assert kinds == ["reset", "cinch", "replan"] and "cinch" in world.used, kinds
    assert planner.goals == [granny.spec] and result.outcome == "lost" and result.actions == 1
    assert planner.cinched == [True]


def test_a_resumed_episode_knows_whether_its_summand_was_cinched() -> None:
    summands = frozenset({"3_1+", "3_1-"})
    tied, untied = knot_goal("3_1+").states[0].key, "[]"

    def step(kind: str, key: str, knot: str | None = None) -> Any:
        return SimpleNamespace(kind=kind, observed_key=key, knot=knot)

    assert not summand_cinched([step("reset", untied), step("curve", tied)], summands)
    assert summand_cinched([step("curve", tied), step("cinch", tied), step("curve", tied)], summands)
    assert not summand_cinched([step("cinch", tied), step("curve", untied), step("curve", tied)], summands)
    assert summand_cinched([step("curve", tied), step("straighten", tied, "3_1+")], summands)
    assert not summand_cinched([step("curve", tied), step("straighten", untied, "0_1")], summands)
    assert not summand_cinched([step("cinch", tied)], frozenset())  # a goal with no stages


def test_an_interrupted_episode_resumes_from_its_last_observation(planned: tuple[str, int]) -> None:
    db, run_id = planned
    code, out = _execute(db, str(run_id), "--world", "strong", "--seed", "9", "--json")
    assert code in (0, 3), out
    whole = json.loads(out)
    store, goal, options, plan = _parts(db, run_id)
    episode_id = _episode_row(store, "strong", 9, plan, False)
    calls = [0]

    def stop_after_the_first_action() -> bool:  # what a Ctrl-C between two actions does
        calls[0] += 1
        return calls[0] > 1

    planner = ModelPlanner(store, goal, options, None, 1, episode_id)
    settings = EpisodeSettings(closed_loop=False, timeout_s=120.0, max_actions=30, drift_m=0.05)
    episode = Episode(
        store, episode_id, SimWorld(LEVELS["strong"], 9), goal, planner, settings, stop_after_the_first_action
    )
    stopped = episode.run(episode.begin(plan))
    store.close()
    assert stopped.outcome == "interrupted" and stopped.actions == 1
    with open_store(db) as store, store.session() as session:
        run = session.get(Run, episode_id)
        assert run is not None and run.status == "interrupted"
    code, out = _execute(db, "--resume", str(episode_id), "--json")
    assert code in (0, 3), out
    resumed = json.loads(out)
    assert resumed["episode"] == episode_id and resumed["outcome"] == whole["outcome"]
    assert resumed["actions"] == whole["actions"]
    # the same observations as the episode that was never stopped
    assert _observations(db, episode_id) == _observations(db, whole["episode"])
    code, out = _execute(db, "--resume", str(episode_id))
    assert code == 2 and "has ended" in out
    code, out = _execute(db, "--resume", str(episode_id), "--world", "none")
    assert code == 2 and "drop --world" in out


def test_report_tables_and_plots_the_episodes_by_level(planned: tuple[str, int], tmp_path: Path) -> None:
    db, run_id = planned
    for level in ("none", "strong"):
        code, out = _execute(db, str(run_id), "--world", level, "--seed", "11", "--json")
        assert code in (0, 3), out
    with open_store(db) as store:
        # grouped by how the episodes ran too: this module's store holds several budgets
        table = {(r.level, r.closed_loop, r.settings): r for r in robustness_table(store)}
        finished = [o for o in load_levels(store) if o[1] in FINISHED]
    assert {("none", False, "600 s, 30 actions"), ("strong", False, "600 s, 30 actions")} <= set(table)
    assert sum(r.episodes for r in table.values()) == len(finished)
    assert table[("none", False, "600 s, 30 actions")].tied >= 1  # the model's own rope ties its plan
    result = runner.invoke(app, ["--db", db, "report", "--out", str(tmp_path / "report")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "report" / "robustness.png").stat().st_size > 0
    text = (tmp_path / "report" / "report.md").read_text()
    assert "## Robustness" in text and "| 0_1 | none | open | 600 s, 30 actions |" in text


def test_episodes_that_ran_with_other_settings_are_told_apart() -> None:
    closed = {"drift_m": 0.05, "straighten": True, "stages": True}
    assert settings_label("granny", True, 180.0, 100, closed) == "180 s, 100 actions"
    assert settings_label("granny", False, 600.0, 30, None) == "600 s, 30 actions"
    # stored before an option existed: it ran without it (stages only matter for a composite knot)
    before = {"drift_m": 0.05, "straighten": True}
    assert settings_label("granny", True, 180.0, 100, before) == "180 s, 100 actions, no stages"
    assert settings_label("overhand", True, 180.0, 100, before) == "180 s, 100 actions"
    odd = {"drift_m": 0.02, "straighten": False, "stages": "yes"}  # read back from the store as it is
    assert (
        settings_label("square", True, 60.0, 5, odd)
        == "60 s, 5 actions, drift 0.02 m, no pulls straight, no stages"
    )
    assert settings_label(ONE_CROSSING, True, 60.0, 5, closed) == "60 s, 5 actions"
    # a plan searched with --no-same-state, open or closed loop (stored before the option: kept them)
    moves = {**closed, "same_state": False}
    assert (
        settings_label("figure-eight", True, 180.0, 100, moves) == "180 s, 100 actions, no same-state curves"
    )
    assert (
        settings_label("figure-eight", False, 180.0, 100, moves) == "180 s, 100 actions, no same-state curves"
    )


def test_an_episode_stores_whether_its_plan_kept_curves_that_keep_the_state(planned: tuple[str, int]) -> None:
    """The episode's searches (its plan's and every replan's) run with the plan run's options: a plan searched
    with --no-same-state gives episodes stored and tabled apart."""
    db, kept = planned
    args = ["--db", db, "plan", "--goal", ONE_CROSSING, "--planner", "random-low", "--workers", "1"]
    result = runner.invoke(app, [*args, "--no-same-state", "--timeout", "120", "--json"])
    assert result.exit_code == 0, result.output
    assert _execute(db, str(kept), "--world", "none")[0] in (0, 3)
    code, out = _execute(db, str(json.loads(result.output)["run_id"]), "--world", "none", "--json")
    assert code in (0, 3), out
    with open_store(db) as store:
        with store.session() as session:
            stored = session.get(Run, int(json.loads(out)["episode"])).parameters
        labels = {r.settings for r in robustness_table(store)}
    assert stored["same_state"] is False
    assert "600 s, 30 actions, no same-state curves" in labels and "600 s, 30 actions" in labels


def test_robustness_skips_only_the_episodes_finished_with_the_settings_asked_for(
    planned: tuple[str, int],
) -> None:
    """What `twisted robustness` skips when run again (``done_episodes``) is keyed by the label the table
    shows: an episode with another budget or another planner option (--no-same-state) is not skipped."""
    from dataclasses import replace

    from twisted.experiments.robustness import _label, done_episodes

    db, run_id = planned
    code, out = _execute(db, str(run_id), "--world", "mild", "--seed", "5", "--json")
    assert code in (0, 3), out
    goal = state_goal(check_goal(ONE_CROSSING))
    with open_store(db) as store:
        done = done_episodes(store, run_id)
        with store.session() as session:
            options = stored_options(session.get(Run, run_id).parameters, run_id)
    asked = EpisodeSettings(False, 600.0, 30)
    assert ("mild", 5, False, _label(goal, asked, options)) in done
    assert ("mild", 5, False, _label(goal, replace(asked, timeout_s=180.0), options)) not in done
    assert ("mild", 5, False, _label(goal, asked, replace(options, same_state=False))) not in done


def test_a_model_plan_stored_before_an_option_is_reused_where_it_ran_as_asked() -> None:
    """`tie` / `robustness` reuse a solved model plan of the same options; a run stored before an option
    existed ran with its value from before (same_state: kept; cinch: off)."""
    from dataclasses import replace

    from twisted.experiments.robustness import same_options
    from twisted.planner import planner_options

    wanted = planner_options({"tighten": True, "seed": 0})
    older = {k: v for k, v in wanted.to_dict().items() if k != "same_state"}
    assert same_options(older, wanted)
    assert not same_options(older, replace(wanted, same_state=False))
    assert not same_options({k: v for k, v in older.items() if k != "cinch"}, wanted)  # ran without it
    assert not same_options({**older, "seed": 1}, wanted) and not same_options(None, wanted)
    assert not same_options({**older, "state_prior": 50.0}, wanted)  # a removed option: another search


def load_levels(store: Any) -> list[tuple[str, str]]:
    with store.session() as session:
        return [(r.level, r.outcome) for r in session.execute(select(EpisodeRow.level, EpisodeRow.outcome))]


@pytest.mark.parametrize(
    "args",
    [
        ["--levels", "moderate,hurricane"],
        ["--levels", "moderate,moderate"],
        ["--loops", "sideways"],
        ["--knot", "granny-knot-of-doom"],
        ["--drift", "-1"],
    ],
)
def test_robustness_refuses_bad_input_before_anything_is_written(tmp_path: Path, args: list[str]) -> None:
    new = tmp_path / "new.db"
    knot = [] if "--knot" in args else ["--knot", "overhand"]
    result = runner.invoke(app, ["--db", f"sqlite:///{new}", "robustness", *knot, *args])
    assert result.exit_code == 2, result.output
    assert not new.exists()


def test_the_browse_query_lists_an_episode_as_its_observed_ropes(planned: tuple[str, int]) -> None:
    import sqlite3

    from twisted.browse.queries import EPISODE, QUERIES

    db, run_id = planned
    code, out = _execute(db, str(run_id), "--world", "mild", "--seed", "2", "--json")
    assert code in (0, 3), out
    episode = json.loads(out)["episode"]
    assert QUERIES["episode"]["sql"] == EPISODE
    with sqlite3.connect(db.removeprefix("sqlite:///")) as conn:
        cursor = conn.execute(EPISODE, {"episode": episode, "page": ""})
        columns = [c[0] for c in cursor.description]
        rows = cursor.fetchall()
    assert {"state", "points", "kind", "expected_key"} <= set(columns)
    assert [r[columns.index("kind")] for r in rows][0] == "reset"
    assert all(r[columns.index("points")] is not None for r in rows if r[columns.index("kind")] != "replan")


@pytest.mark.slow
def test_ctrl_c_stops_an_episode_with_exit_130_and_it_resumes(planned: tuple[str, int]) -> None:
    import signal
    import sqlite3
    import subprocess
    import sys
    import time

    db, run_id = planned
    path = db.removeprefix("sqlite:///")
    with sqlite3.connect(path) as conn:
        before = conn.execute("SELECT COALESCE(MAX(run_id), 0) FROM episodes").fetchone()[0]
    # a drift of 1 mm: every action is off plan, so the episode replans (and runs long enough to stop)
    args = ["--db", db, "execute", str(run_id), "--world", "strong", "--seed", "3", "--closed-loop"]
    budget = ["--drift", "0.001", "--timeout", "30", "--json"]  # the resumed episode keeps the budget
    command = [sys.executable, "-c", "from cli.main import run; run()", *args, *budget]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 90
        steps = 0
        while steps < 2 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
            with sqlite3.connect(path, timeout=5) as conn:
                steps = conn.execute(
                    "SELECT COUNT(*) FROM episode_steps WHERE episode_id > ?", (before,)
                ).fetchone()[0]
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    stopped = json.loads(out)
    assert stopped["outcome"] == "interrupted" and "--resume" in err
    episode = stopped["episode"]
    with open_store(db) as store:
        kept = len(load_episode(store, episode).steps)
    code, out = _execute(db, "--resume", str(episode), "--json")
    assert code in (0, 3), out
    resumed = json.loads(out)
    assert resumed["episode"] == episode and resumed["outcome"] != "interrupted"
    with open_store(db) as store:
        steps_after = load_episode(store, episode).steps
    assert len(steps_after) > kept and resumed["actions"] >= stopped["actions"]
