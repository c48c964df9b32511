"""Expert iteration (``twisted improve``): the low level learns from its own searches.

One lineage (``--name``) is a chain of generations, each a row of ``improve_generations``
(:mod:`twisted.store.improve`):

* generation 0 is the model the loop starts from (``--init-model``, else the shipped model, stored
  under the name ``shipped`` so that it has an id): it is only scored;
* generation ``g >= 1`` draws ``goals`` training goals by ``default_rng([seed, g])`` from the
  distributions asked for (``u4``, ``u5``: uniform over every state of 4 and 5 crossings, ``u6``: the
  head-tree sampler; :mod:`twisted.experiments.goalsets`), or takes them from a stored set
  (``--train-set``); plans toward each with its parent's model, ``goal_timeout_s`` each; fine-tunes the
  parent (:func:`twisted.model.train.train` with ``init_model_id``) on every planner tree edge that
  adds crossings (hindsight: the state a curve reached is a goal it achieves;
  :func:`twisted.model.data.load_tree_edges`) plus the collected transitions when the store has any;
  and is scored like generation 0.

Scoring: the first ``tune_goals`` goals of the tuning set (a stored problem set), seeds
``0 .. tune_seeds - 1``, ``tune_timeout_s`` each, one core; solved runs, and every simulator call of
every run (so that ``tune_calls / tune_solved`` charges unsolved runs their whole budget).

Never training on an evaluation goal. The evaluation goals are those of every stored problem set that
has evaluation results or whose name starts with ``final-``, ``eval-`` or ``tune-``, of every goal-set
file so named in the project's committed ``goalsets/`` (found from the package, whatever the current
folder; ``--goalsets`` names another folder, which must exist, and a file there that cannot be read
is refused, not skipped), and of the tuning set. A drawn goal among them is never drawn; a
``--train-set`` holding one is refused (:class:`EvalInputError`); and training holds out the stored
ones (``hold_out_sets``: the trees of runs toward them and every sample reaching one of their states).

Resuming: the loop continues the newest generation of the lineage in its phase; a goal whose run is
recorded is not planned again, and an unfinished training run is resumed. Planner runs carry
``improve``, ``generation`` and ``phase`` in their parameters.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twisted.experiments.problems import EvalInputError, decode_goal_file, parse_goal_file
from twisted.experiments.scheduler import EvalBackend, ProcessBackend, TaskPool, run_on
from twisted.experiments.tasks import TaskKind
from twisted.goals import Goal, make_goal, state_goal
from twisted.store.improve import (
    ImproveGeneration,
    add_generation,
    lineage_rows,
    model_of_training_run,
    problem_set_names,
    set_goal_specs,
    shipped_model_id,
    training_run_status,
    update_generation,
)

__all__ = [
    "DISTRIBUTIONS",
    "EVALUATION_PREFIXES",
    "ImproveConfig",
    "evaluation_goal_keys",
    "evaluation_set_names",
    "improve",
    "training_goals",
]

log = logging.getLogger(__name__)

# Training-goal distributions: crossing counts drawn from (uniform up to 5, the sampler at 6)
DISTRIBUTIONS = {"u4": 4, "u5": 5, "u6": 6}
# Stored sets and goal-set files whose names start so are evaluation (or tuning) sets
EVALUATION_PREFIXES = ("final-", "eval-", "tune-")
# The goal-set files committed with the project (the sets behind the figures): the folder beside the
# package, found from it so the guard does not depend on the folder a command is run from
COMMITTED_GOALSETS = Path(__file__).resolve().parents[2] / "goalsets"


@dataclass(frozen=True)
class ImproveConfig:
    """What one ``twisted improve`` does (stored with every generation of the lineage)."""

    tune_set: str
    lineage: str = "improve"
    hours: float = 1.0
    seed: int = 0
    generations: int = 3  # generations after generation 0
    goals: int = 8  # training goals per generation
    distributions: tuple[str, ...] = ("u4", "u5")
    train_set: str | None = None  # a stored set as the training goals instead of drawn ones
    goal_timeout_s: float = 60.0
    # search budget in iterations (None: time only); a shared machine's load then does not change what
    # a generation is scored on (the timeouts stay as a cap)
    goal_iterations: int | None = None
    tune_goals: int | None = None  # the first N goals of the tuning set (None: all)
    tune_seeds: int = 1
    tune_timeout_s: float = 60.0
    tune_iterations: int | None = None
    epochs: int = 10
    batch_size: int = 128
    init_model_id: int | None = None
    goalsets_dir: str | None = None  # None: COMMITTED_GOALSETS
    # how it runs, not what it learns: searches at once (each a task of the eval scheduler's backend, one
    # core: a spawned local process, or a Ray task; 0 on Ray: one per CPU of the cluster) and the torch
    # device fine-tuning runs on
    parallel: int = 1
    device: str = "cpu"

    def check(self, min_parallel: int = 1) -> None:
        """Raise :class:`EvalInputError` naming the option that is out of range (``--parallel`` below
        ``min_parallel``: 1 locally, 0 on Ray)."""
        from twisted.runtime import name_problem

        for option, name in (
            ("--name", self.lineage),
            ("--tune-set", self.tune_set),
            ("--train-set", self.train_set),
        ):
            problem = None if name is None else name_problem(name)
            if problem is not None:
                raise EvalInputError(f"{option} {name!r} {problem}")
        for name, value in (("--hours", self.hours), ("--goal-timeout", self.goal_timeout_s)):
            if not value > 0:
                raise EvalInputError(f"{name} must be positive, got {value}")
        if not self.tune_timeout_s > 0:
            raise EvalInputError(f"--tune-timeout must be positive, got {self.tune_timeout_s}")
        for name, count in (
            ("--generations", self.generations),
            ("--goals", self.goals),
            ("--tune-seeds", self.tune_seeds),
            ("--epochs", self.epochs),
            ("--batch-size", self.batch_size),
        ):
            if count < 1:
                raise EvalInputError(f"{name} must be at least 1, got {count}")
        if self.parallel < min_parallel:
            raise EvalInputError(f"--parallel must be at least {min_parallel}, got {self.parallel}")
        for name, cap in (
            ("--goal-iterations", self.goal_iterations),
            ("--tune-iterations", self.tune_iterations),
        ):
            if cap is not None and cap < 1:
                raise EvalInputError(f"{name} must be at least 1, got {cap}")
        if self.tune_goals is not None and self.tune_goals < 1:
            raise EvalInputError(f"--tune-goals must be at least 1, got {self.tune_goals}")
        _file_goals(self.goal_files_folder())  # every evaluation goal file readable, before the store opens
        unknown = [d for d in self.distributions if d not in DISTRIBUTIONS]
        if unknown or not self.distributions:
            raise EvalInputError(
                f"--draw {', '.join(map(repr, unknown)) or '(none)'}: choose among {', '.join(DISTRIBUTIONS)}"
            )

    def goal_files_folder(self) -> Path:
        """The folder of evaluation goal-set files (``--goalsets``, else the committed one); it must
        exist, or the guard against training on evaluation goals would check nothing."""
        folder = COMMITTED_GOALSETS if self.goalsets_dir is None else Path(self.goalsets_dir)
        if not folder.is_dir():
            given = f"--goalsets {self.goalsets_dir}" if self.goalsets_dir is not None else f"{folder}"
            what = "is not a folder" if folder.exists() else "does not exist"
            hint = "" if self.goalsets_dir is not None else " (the project's own goalsets/); give --goalsets"
            raise EvalInputError(
                f"{given} {what}: it must hold the evaluation goal-set files (final-, eval-, tune-*.json) "
                f"so that no training goal is one of theirs{hint}"
            )
        return folder

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["distributions"] = list(self.distributions)
        return out


# --- evaluation goals -------------------------------------------------------------------------------


def evaluation_set_names(session: Any, tune_set: str | None = None) -> list[str]:
    """Stored sets that are evaluation sets: with evaluation results, or named ``final-`` / ``eval-`` /
    ``tune-``; and the tuning set."""
    used = set(problem_set_names(session, evaluated=True))
    named = {n for n in problem_set_names(session) if n.startswith(EVALUATION_PREFIXES)}
    if tune_set is not None:
        named.add(tune_set)
    return sorted(used | named)


def _file_goals(goalsets_dir: Path) -> dict[str, list[Goal]]:
    """The goals of every evaluation goal-set file in ``goalsets_dir``; EvalInputError naming a file that
    cannot be read as one (the guard must not skip it)."""
    out: dict[str, list[Goal]] = {}
    for path in sorted(goalsets_dir.glob("*.json")):
        if not path.name.startswith(EVALUATION_PREFIXES):
            continue
        try:
            if not path.is_file():
                raise EvalInputError("is not a file")
            out.update(parse_goal_file(decode_goal_file(path.read_bytes()), None))
        except OSError as exc:
            raise EvalInputError(f"evaluation goal file {path}: cannot be read ({exc.strerror})") from None
        except EvalInputError as exc:
            raise EvalInputError(f"evaluation goal file {path}: {exc}") from None
    return out


def evaluation_goal_keys(
    session: Any, tune_set: str | None, goalsets_dir: Path | None = None
) -> tuple[frozenset[str], list[str]]:
    """The keys of every evaluation goal's states (stored evaluation sets, the tuning set, final goal
    files) and the names of the stored sets they come from."""
    names = evaluation_set_names(session, tune_set)
    keys: set[str] = set()
    for spec in set_goal_specs(session, names):
        keys.update(make_goal(spec).keys)
    for goals in _file_goals(goalsets_dir or COMMITTED_GOALSETS).values():
        for goal in goals:
            keys.update(goal.keys)
    return frozenset(keys), names


# --- training goals -----------------------------------------------------------------------------------


def training_goals(
    distributions: Sequence[str], n: int, seed: int, generation: int, exclude: frozenset[str]
) -> list[Goal]:
    """``n`` goals drawn by ``default_rng([seed, generation])``, the distributions taken in turn; no
    state in ``exclude`` and no goal twice."""
    from twisted.experiments.goalsets import MAX_UNIFORM_ENUMERATED, sample_states, uniform_states

    rng = np.random.default_rng([seed, generation])
    counts = {d: 0 for d in distributions}
    for i in range(n):
        counts[distributions[i % len(distributions)]] += 1
    goals: list[Goal] = []
    for d in distributions:
        c = DISTRIBUTIONS[d]
        if counts[d] == 0:
            continue
        if c <= MAX_UNIFORM_ENUMERATED:
            drawn = uniform_states(c, counts[d], rng, exclude=exclude)
        else:
            drawn = sample_states(c, counts[d], rng, exclude=exclude)
        goals.extend(state_goal(p) for p in drawn)
    return goals


def _set_goals(session: Any, name: str) -> list[Goal]:
    specs = set_goal_specs(session, [name])
    if not specs:
        known = problem_set_names(session)
        raise EvalInputError(
            f"no problem set named {name!r} (the database has: {', '.join(known) or 'none'})"
        )
    return [make_goal(spec) for spec in specs]


def _check_train_set(
    goals: Iterable[Goal], name: str, exclude: frozenset[str], eval_sets: Sequence[str]
) -> None:
    if name in eval_sets:
        raise EvalInputError(
            f"--train-set {name}: it is an evaluation set (evaluation results, a final-/eval-/tune- name, "
            "or the tuning set): expert iteration never trains toward evaluation goals"
        )
    for i, goal in enumerate(goals):
        if exclude & set(goal.keys):
            raise EvalInputError(
                f"--train-set {name}: goal {i} ({goal.spec}) is a goal of an evaluation set or file; "
                "expert iteration never trains toward evaluation goals"
            )


# --- the loop ----------------------------------------------------------------------------------------


@dataclass
class _Context:
    store: Any
    config: ImproveConfig
    deadline: float
    say: Callable[[str], None]
    eval_keys: frozenset[str] = frozenset()
    hold_out: list[str] = field(default_factory=list)
    pool: TaskPool | None = None  # where the searches run; None: one at a time in this process

    def out_of_time(self) -> bool:
        return time.monotonic() >= self.deadline


def _shipped_model_id(store: Any) -> int:
    """The shipped model stored as ``shipped`` (once per database); EvalInputError on a rope it is not for."""
    from twisted.model.registry import ModelError, load_default_model, save_model

    with store.session() as session:
        found = shipped_model_id(session)
    if found is not None:
        return found
    try:
        shipped = load_default_model("a lineage starts from the shipped model without --init-model, but ")
    except ModelError as exc:
        raise EvalInputError(f"{exc}, then give it as --init-model ID") from None
    return save_model(store, shipped, name="shipped")


def _new_generation(
    store: Any, config: ImproveConfig, generation: int, parent: int | None
) -> ImproveGeneration:
    return add_generation(
        store,
        lineage=config.lineage,
        generation=generation,
        status="scoring" if generation == 0 else "planning",
        seed=config.seed,
        parameters=config.to_dict(),
        parent_model_id=parent,
        model_id=parent if generation == 0 else None,
        training_goals=[],
        data={},
        tune_set=config.tune_set,
        tune_results=[],
        tune_runs=0,
        tune_solved=0,
        tune_calls=0,
        wall_s=0.0,
    )


def _id(model_id: int | None) -> int:
    if model_id is None:
        raise RuntimeError("a generation without its model")
    return int(model_id)


@dataclass(frozen=True)
class _Search:
    """One search of a phase: the ``index``-th goal of its list, with its model, seed and budget."""

    index: int
    goal: str  # the goal's spec
    model_id: int
    seed: int
    timeout_s: float
    iterations: int | None
    tags: dict[str, Any]  # stored with the run's parameters
    label: str = ""  # what the loop says when it starts


def _plan(store: Any, job: _Search) -> dict[str, Any]:
    """One search on one core (:func:`twisted.planner.run_search`, the search time alone timed); its
    outcome as a dict."""
    from twisted.planner import SearchRequest, run_search

    request = SearchRequest(
        goal=job.goal,
        options={"planner": "twisted", "seed": job.seed},
        model_id=job.model_id,
        workers=1,
        timeout_s=job.timeout_s,
        max_iterations=job.iterations,
        parameters=job.tags,
        timed_setup=False,
    )
    result = run_search(store, request)
    calls_to_solve = result.path[-1].sim_call if result.solved and result.path else None
    return {
        "index": job.index,
        "goal": job.goal,
        "seed": job.seed,
        "run_id": result.run_id,
        "status": result.status,
        "solved": result.solved,
        "sim_calls": result.sim_calls,
        "calls_to_solve": calls_to_solve,
        "elapsed_s": round(result.elapsed_s, 1),
        "iterations": result.iterations,
        "steps_by_move": {k: list(v) for k, v in result.steps_by_move().items()},
    }


def _plan_in_process(db_url: str, job: _Search) -> dict[str, Any]:
    """:func:`_plan` in a spawned worker process: its own store connection, one torch thread."""
    import torch

    from twisted.store import open_store

    torch.set_num_threads(1)
    with open_store(db_url) as store:
        return _plan(store, job)


def _indexed(outcomes: Sequence[dict[str, Any]] | None) -> list[dict[str, Any]]:
    """Recorded outcomes, each with its search's ``index`` (rows stored before the index was are in
    order)."""
    return [{**o, "index": int(o.get("index", i))} for i, o in enumerate(outcomes or [])]


def _search_lost(store: Any, job: _Search, status: str, message: str) -> dict[str, Any]:
    """What a search whose worker ended without reporting leaves: not an outcome (nothing recorded)."""
    return {"index": job.index, "goal": job.goal, "lost": f"{status}: {message}"}


# What the scheduler's pools run for ``twisted improve``: one search each
SEARCHES = TaskKind(_plan_in_process, _search_lost)


def _plan_all(ctx: _Context, jobs: Sequence[_Search], record: Callable[[dict[str, Any]], None]) -> bool:
    """Run the searches (on ``ctx.pool``, else one by one in this process), calling ``record(outcome)``
    as each ends; False when the time ran out before every search started. A search whose worker died
    is not recorded: RuntimeError once the others have ended (a rerun plans it again)."""

    def may_start(job: _Search) -> bool:
        if ctx.out_of_time():
            return False
        ctx.say(job.label)
        return True

    if ctx.pool is None:
        for job in jobs:
            if not may_start(job):
                return False
            record(_plan(ctx.store, job))
        return True
    lost: list[dict[str, Any]] = []

    def outcome_in(outcome: dict[str, Any]) -> None:
        (lost.append if "lost" in outcome else record)(outcome)

    started_all = run_on(ctx.pool, jobs, outcome_in, may_start=may_start)
    if lost:
        which = "; ".join(f"search {o['index']} ({o['lost']})" for o in lost)
        raise RuntimeError(f"{len(lost)} searches ended without an outcome: {which}; run again to plan them")
    return started_all


def _phase_plan(ctx: _Context, row: ImproveGeneration) -> bool:
    """Plan toward the generation's training goals; False when the time ran out first."""
    config = ctx.config
    done = _indexed(row.training_goals)
    if not done and not (row.data or {}).get("goals"):
        if config.train_set is not None:
            with ctx.store.session() as session:
                goals = _set_goals(session, config.train_set)
        else:
            from twisted.store.knots import CACHED_CROSSINGS, load_states_by_type

            for crossings in sorted({DISTRIBUTIONS[d] for d in config.distributions} & set(CACHED_CROSSINGS)):
                load_states_by_type(ctx.store, crossings)  # the enumeration, when the store keeps it
            goals = training_goals(
                config.distributions, config.goals, config.seed, row.generation, ctx.eval_keys
            )
        update_generation(ctx.store, row.id, data={**(row.data or {}), "goals": [g.spec for g in goals]})
        row.data = {**(row.data or {}), "goals": [g.spec for g in goals]}
    specs = list(row.data["goals"])
    goals = [make_goal(spec) for spec in specs]
    for goal in goals:
        assert not (ctx.eval_keys & set(goal.keys)), "a training goal is an evaluation goal"
    recorded = {o["index"] for o in done}
    tags = {"improve": config.lineage, "generation": row.generation, "phase": "train"}
    jobs = [
        _Search(
            index=i,
            goal=spec,
            model_id=_id(row.parent_model_id),
            seed=row.generation * 1000 + i,
            timeout_s=config.goal_timeout_s,
            iterations=config.goal_iterations,
            tags=tags,
            label=f"generation {row.generation}: training goal {i + 1}/{len(specs)} ({goal.cross} crossings)",
        )
        for i, (spec, goal) in enumerate(zip(specs, goals, strict=True))
        if i not in recorded
    ]

    def record(outcome: dict[str, Any]) -> None:
        done.append(outcome)
        done.sort(key=lambda o: int(o["index"]))
        update_generation(ctx.store, row.id, training_goals=list(done))

    if not _plan_all(ctx, jobs, record):
        return False
    update_generation(ctx.store, row.id, training_goals=done, status="training")
    return True


def _phase_train(ctx: _Context, row: ImproveGeneration) -> bool:
    """Fine-tune the parent on the trees (and transitions); False when it was interrupted."""
    from dataclasses import replace

    import torch

    from twisted.model.config import TrainConfig
    from twisted.model.data import max_transition_id
    from twisted.model.train import train
    config = ctx.config
    if config.device == "cpu":
        torch.set_num_threads(1)  # one core: the loop is measured on one
    if row.training_run_id is not None:
        with ctx.store.session() as session:
            status = training_run_status(session, row.training_run_id)
        if status == "finished":
            return _after_training(ctx, row)
        ctx.say(f"generation {row.generation}: resuming training run {row.training_run_id}")
        outcome = train(
            ctx.store, resume=True, device=config.device, command=f"twisted improve --name {config.lineage}"
        )
    else:
        collected = max_transition_id(ctx.store, removing=TrainConfig.removing) is not None  # what it reads
        sources = ("collect", "search") if collected else ("search",)
        train_config = replace(
            TrainConfig(),
            epochs=config.epochs,
            batch_size=config.batch_size,
            seed=config.seed * 1000 + row.generation,
            sources=sources,
            hold_out_sets=tuple(ctx.hold_out),
            init_model_id=_id(row.parent_model_id),
            hours=max((ctx.deadline - time.monotonic()) / 3600.0, 1e-3),
        )
        ctx.say(
            f"generation {row.generation}: fine-tuning model {row.parent_model_id} on {', '.join(sources)}"
        )
        outcome = train(
            ctx.store,
            train_config,
            command=f"twisted improve --name {config.lineage} (generation {row.generation})",
            device=config.device,
            log=ctx.say,
        )
        update_generation(ctx.store, row.id, training_run_id=outcome.training_run_id)
        row.training_run_id = outcome.training_run_id
    if outcome.status != "finished" or outcome.model_id is None:
        return False
    return _after_training(ctx, row)


def _after_training(ctx: _Context, row: ImproveGeneration) -> bool:
    assert row.training_run_id is not None
    with ctx.store.session() as session:
        made = model_of_training_run(session, row.training_run_id)
    if made is None:
        raise RuntimeError(f"training run {row.training_run_id} finished without a model")
    model_id, metrics = made
    data = {
        **(row.data or {}),
        **{k: v for k, v in metrics.items() if k.startswith(("n_train", "n_val"))},
        "best_epoch": metrics.get("best_epoch"),
        "val_loss": metrics.get("val_loss"),
        "val_link_accuracy": metrics.get("val_link_accuracy"),
    }
    update_generation(ctx.store, row.id, model_id=model_id, data=data, status="scoring")
    row.model_id, row.data = model_id, data
    return True


def _phase_score(ctx: _Context, row: ImproveGeneration) -> bool:
    """Plan toward the tuning goals with the generation's model; False when the time ran out first."""
    config = ctx.config
    with ctx.store.session() as session:
        goals = _set_goals(session, config.tune_set)
    if config.tune_goals is not None:
        goals = goals[: config.tune_goals]
    results = _indexed(row.tune_results)
    recorded = {o["index"] for o in results}
    todo = [(g, s) for s in range(config.tune_seeds) for g in goals]
    tags = {"improve": config.lineage, "generation": row.generation, "phase": "tune"}
    jobs = [
        _Search(
            index=i,
            goal=goal.spec,
            model_id=_id(row.model_id),
            seed=seed,
            timeout_s=config.tune_timeout_s,
            iterations=config.tune_iterations,
            tags=tags,
            label=f"generation {row.generation}: tuning goal {i + 1}/{len(todo)}",
        )
        for i, (goal, seed) in enumerate(todo)
        if i not in recorded
    ]

    def record(outcome: dict[str, Any]) -> None:
        results.append(outcome)
        results.sort(key=lambda o: int(o["index"]))
        update_generation(
            ctx.store,
            row.id,
            tune_results=list(results),
            tune_runs=len(results),
            tune_solved=sum(r["solved"] for r in results),
            tune_calls=sum(r["sim_calls"] for r in results),
        )

    if not _plan_all(ctx, jobs, record):
        return False
    update_generation(ctx.store, row.id, status="finished")
    return True


def improve(
    store: Any,
    config: ImproveConfig,
    say: Callable[[str], None] | None = None,
    backend: EvalBackend | None = None,
) -> list[ImproveGeneration]:
    """Run (or continue) the lineage until ``config.generations`` generations after generation 0 are
    finished or ``config.hours`` have passed; returns the lineage's rows.

    The searches run on ``backend``, the eval scheduler's (``twisted.distributed.RayBackend``: a Ray
    task each), ``config.parallel`` at once; without one, in this process one at a time when
    ``parallel`` is 1, else in spawned local processes (:class:`ProcessBackend`).
    """
    config.check(1 if backend is None else backend.min_parallel)
    ctx = _Context(store, config, time.monotonic() + config.hours * 3600.0, say or (lambda _m: None))
    rows = _checked_lineage(ctx)  # every input checked before a process or a cluster starts
    if backend is None and config.parallel > 1:
        backend = ProcessBackend()
    with contextlib.ExitStack() as stack:
        if backend is not None:
            db_url = store.url.render_as_string(hide_password=False)
            ctx.pool = stack.enter_context(backend.open(store, db_url, 1, config.parallel, SEARCHES))
        return _run_lineage(ctx, rows)


def _checked_lineage(ctx: _Context) -> list[ImproveGeneration]:
    """The lineage's rows (generation 0 stored when it is new), after checking the sets, the lineage's
    tuning set and the model it starts from."""
    store, config = ctx.store, ctx.config
    with store.session() as session:
        _set_goals(session, config.tune_set)  # the tuning set must exist
        folder = config.goal_files_folder()
        ctx.eval_keys, ctx.hold_out = evaluation_goal_keys(session, config.tune_set, folder)
        if config.train_set is not None:
            _check_train_set(
                _set_goals(session, config.train_set), config.train_set, ctx.eval_keys, ctx.hold_out
            )
    rows = lineage_rows(store, config.lineage)
    if rows and rows[0].parameters.get("tune_set") != config.tune_set:
        raise EvalInputError(
            f"lineage {config.lineage!r} is scored on {rows[0].parameters.get('tune_set')!r}, not "
            f"{config.tune_set!r}: give another --name"
        )
    if not rows:
        parent = config.init_model_id if config.init_model_id is not None else _shipped_model_id(store)
        rows = [_new_generation(store, config, 0, parent)]
    return rows


def _run_lineage(ctx: _Context, rows: list[ImproveGeneration]) -> list[ImproveGeneration]:
    store, config = ctx.store, ctx.config
    while True:
        row = rows[-1]
        t0 = time.monotonic()
        ok = True
        if row.status == "planning":
            ok = _phase_plan(ctx, row)
            row.status = "training" if ok else row.status
        if ok and row.status == "training":
            ok = _phase_train(ctx, row)
            row.status = "scoring" if ok else row.status
        if ok and row.status == "scoring":
            ok = _phase_score(ctx, row)
        update_generation(store, row.id, wall_s=float(row.wall_s or 0.0) + time.monotonic() - t0)
        if not ok or ctx.out_of_time() or row.generation >= config.generations:
            break
        rows.append(_new_generation(store, config, row.generation + 1, row.model_id))
    return lineage_rows(store, config.lineage)
