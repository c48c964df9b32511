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

import logging
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import func, select

from twisted.experiments.problems import EvalInputError, decode_goal_file, parse_goal_file
from twisted.goals import Goal, make_goal, state_goal
from twisted.store.experiments import EvalResult, Problem, ProblemSet
from twisted.store.improve import ImproveGeneration
from twisted.store.models import utcnow

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
    # how it runs, not what it learns: searches at once (each its own spawned process, one core) and the
    # torch device fine-tuning runs on
    parallel: int = 1
    device: str = "cpu"

    def check(self) -> None:
        """Raise :class:`EvalInputError` naming the option that is out of range."""
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
            ("--parallel", self.parallel),
        ):
            if count < 1:
                raise EvalInputError(f"{name} must be at least 1, got {count}")
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
    used = set(session.scalars(select(ProblemSet.name).join(EvalResult, EvalResult.set_id == ProblemSet.id)))
    named = {n for n in session.scalars(select(ProblemSet.name)) if n.startswith(EVALUATION_PREFIXES)}
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
    specs = session.scalars(
        select(Problem.goal_key)
        .join(ProblemSet, ProblemSet.id == Problem.set_id)
        .where(ProblemSet.name.in_(names))
    ).all()
    for spec in specs:
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
    specs = session.scalars(
        select(Problem.goal_key)
        .join(ProblemSet, ProblemSet.id == Problem.set_id)
        .where(ProblemSet.name == name)
        .order_by(Problem.idx)
    ).all()
    if not specs:
        known = sorted(session.scalars(select(ProblemSet.name)))
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

    def out_of_time(self) -> bool:
        return time.monotonic() >= self.deadline


def _shipped_model_id(store: Any) -> int:
    """The shipped model stored as ``shipped`` (once per database); EvalInputError on a rope it is not for."""
    from twisted.model.registry import ModelError, load_default_model, save_model
    from twisted.store.training import TrainedModel

    with store.session() as session:
        found = session.scalar(
            select(func.min(TrainedModel.id)).where(
                TrainedModel.name == "shipped", TrainedModel.training_run_id.is_(None)
            )
        )
    if found is not None:
        return int(found)
    try:
        shipped = load_default_model("a lineage starts from the shipped model without --init-model, but ")
    except ModelError as exc:
        raise EvalInputError(f"{exc}, then give it as --init-model ID") from None
    return save_model(store, shipped, name="shipped")


def _rows(store: Any, lineage: str) -> list[ImproveGeneration]:
    with store.session() as session:
        rows = session.scalars(
            select(ImproveGeneration)
            .where(ImproveGeneration.lineage == lineage)
            .order_by(ImproveGeneration.generation)
        ).all()
        session.expunge_all()
        return list(rows)


def _update(store: Any, row_id: int, **values: Any) -> None:
    with store.session(write=True) as session:
        row = session.get(ImproveGeneration, row_id)
        assert row is not None
        for k, v in values.items():
            setattr(row, k, v)
        row.updated_at = utcnow()


def _new_generation(
    store: Any, config: ImproveConfig, generation: int, parent: int | None
) -> ImproveGeneration:
    with store.session(write=True) as session:
        row = ImproveGeneration(
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
            created_at=utcnow(),
            updated_at=utcnow(),
        )
        session.add(row)
        session.flush()
        session.expunge(row)
        return row


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


def _plan_all(ctx: _Context, jobs: Sequence[_Search], record: Callable[[dict[str, Any]], None]) -> bool:
    """Run the searches, ``ctx.config.parallel`` at once (one in this process when 1), calling
    ``record(outcome)`` as each ends; False when the time ran out before every search started."""
    parallel = ctx.config.parallel
    if parallel <= 1:
        for job in jobs:
            if ctx.out_of_time():
                return False
            ctx.say(job.label)
            record(_plan(ctx.store, job))
        return True
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait

    db_url = ctx.store.url.render_as_string(hide_password=False)
    pending = list(jobs)
    running: set[Future[dict[str, Any]]] = set()
    started_all = True
    with ProcessPoolExecutor(
        max_workers=parallel, mp_context=multiprocessing.get_context("spawn"), max_tasks_per_child=1
    ) as pool:
        while pending or running:
            while pending and len(running) < parallel:
                if ctx.out_of_time():
                    started_all, pending = False, []
                    break
                job = pending.pop(0)
                ctx.say(job.label)
                running.add(pool.submit(_plan_in_process, db_url, job))
            if not running:
                break
            finished, running = wait(running, return_when=FIRST_COMPLETED)
            for future in finished:
                record(future.result())
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
        _update(ctx.store, row.id, data={**(row.data or {}), "goals": [g.spec for g in goals]})
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
        _update(ctx.store, row.id, training_goals=list(done))

    if not _plan_all(ctx, jobs, record):
        return False
    _update(ctx.store, row.id, training_goals=done, status="training")
    return True


def _phase_train(ctx: _Context, row: ImproveGeneration) -> bool:
    """Fine-tune the parent on the trees (and transitions); False when it was interrupted."""
    from dataclasses import replace

    import torch

    from twisted.model.config import TrainConfig
    from twisted.model.data import max_transition_id
    from twisted.model.train import train
    from twisted.store.training import TrainingRun

    config = ctx.config
    if config.device == "cpu":
        torch.set_num_threads(1)  # one core: the loop is measured on one
    if row.training_run_id is not None:
        with ctx.store.session() as session:
            run = session.get(TrainingRun, row.training_run_id)
            status = None if run is None else run.status
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
        _update(ctx.store, row.id, training_run_id=outcome.training_run_id)
        row.training_run_id = outcome.training_run_id
    if outcome.status != "finished" or outcome.model_id is None:
        return False
    return _after_training(ctx, row)


def _after_training(ctx: _Context, row: ImproveGeneration) -> bool:
    from twisted.store.training import TrainedModel

    with ctx.store.session() as session:
        model = session.scalar(
            select(TrainedModel).where(TrainedModel.training_run_id == row.training_run_id)
        )
        assert model is not None
        metrics = dict(model.metrics or {})
        model_id = int(model.id)
    data = {
        **(row.data or {}),
        **{k: v for k, v in metrics.items() if k.startswith(("n_train", "n_val"))},
        "best_epoch": metrics.get("best_epoch"),
        "val_loss": metrics.get("val_loss"),
        "val_link_accuracy": metrics.get("val_link_accuracy"),
    }
    _update(ctx.store, row.id, model_id=model_id, data=data, status="scoring")
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
        _update(
            ctx.store,
            row.id,
            tune_results=list(results),
            tune_runs=len(results),
            tune_solved=sum(r["solved"] for r in results),
            tune_calls=sum(r["sim_calls"] for r in results),
        )

    if not _plan_all(ctx, jobs, record):
        return False
    _update(ctx.store, row.id, status="finished")
    return True


def improve(
    store: Any, config: ImproveConfig, say: Callable[[str], None] | None = None
) -> list[ImproveGeneration]:
    """Run (or continue) the lineage until ``config.generations`` generations after generation 0 are
    finished or ``config.hours`` have passed; returns the lineage's rows."""
    config.check()
    started = time.monotonic()
    ctx = _Context(store, config, started + config.hours * 3600.0, say or (lambda _m: None))
    with store.session() as session:
        _set_goals(session, config.tune_set)  # the tuning set must exist
        folder = config.goal_files_folder()
        ctx.eval_keys, ctx.hold_out = evaluation_goal_keys(session, config.tune_set, folder)
        if config.train_set is not None:
            _check_train_set(
                _set_goals(session, config.train_set), config.train_set, ctx.eval_keys, ctx.hold_out
            )
    rows = _rows(store, config.lineage)
    if rows and rows[0].parameters.get("tune_set") != config.tune_set:
        raise EvalInputError(
            f"lineage {config.lineage!r} is scored on {rows[0].parameters.get('tune_set')!r}, not "
            f"{config.tune_set!r}: give another --name"
        )
    if not rows:
        parent = config.init_model_id if config.init_model_id is not None else _shipped_model_id(store)
        rows = [_new_generation(store, config, 0, parent)]
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
        _update(store, row.id, wall_s=float(row.wall_s or 0.0) + time.monotonic() - t0)
        if not ok or ctx.out_of_time() or row.generation >= config.generations:
            break
        rows.append(_new_generation(store, config, row.generation + 1, row.model_id))
    return _rows(store, config.lineage)
