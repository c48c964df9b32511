"""Eval runs: every (goal, seed) of a problem set with one planner, stored as it finishes.

:func:`run_eval` checks the inputs (:func:`prepare_eval`), stores a new ``eval_runs`` row and hands
the tasks still to run (:func:`pending_tasks`) to the one scheduler, :func:`schedule`. The scheduler
keeps ``parallel`` tasks in flight on a backend (:class:`EvalBackend`): :class:`ProcessBackend` runs
each task in its own local process (spawned: nothing inherited), ``twisted.distributed.RayBackend``
as a Ray task. Either way a task is :func:`run_task`, which runs the planner (with ``workers``
simulator processes, 1 = in-process) and stores the outcome in ``eval_results`` under the unique key
(set, planner, goal, seed, timeout_s, friction_scale). A row is claimed (``running``) when its goal
starts and gets the planner's run id as soon as the planner made one; a rerun skips
``solved``/``timeout`` rows and continues ``interrupted`` ones from the planner's own checkpoint
(same run id, elapsed time carried over). On Ctrl-C, SIGTERM or an exception the scheduler cancels
the running tasks (their planners checkpoint) and marks the eval run interrupted or failed.
"""

from __future__ import annotations

import logging
import math
import multiprocessing
import os
import queue as queue_module
import signal
import socket
import time
import traceback
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass, field
from typing import Any, Protocol

from sqlalchemy import select, update
from sqlalchemy.exc import IntegrityError

from twisted.experiments.problems import EvalInputError
from twisted.runtime import sigterm_as_interrupt
from twisted.store.experiments import (
    FINISHED_STATUSES,
    EvalResult,
    EvalRun,
    ProblemSetRecord,
    end_eval_run,
    load_problem_set,
    pid_alive,
    start_eval_run,
)
from twisted.store.models import utcnow

__all__ = [
    "EvalBackend",
    "EvalOptions",
    "EvalSummary",
    "EvalTask",
    "PreparedEval",
    "ProcessBackend",
    "TaskOutcome",
    "TaskPool",
    "free_row",
    "pending_tasks",
    "prepare_eval",
    "result_key",
    "run_eval",
    "run_prepared",
    "run_task",
    "schedule",
]

log = logging.getLogger(__name__)

# How long a stopping eval waits for its cancelled tasks (their planners checkpoint) before killing them.
CANCEL_WAIT_S = 60.0
# How long the scheduler waits for a finished task before it looks again (a signal is seen in between).
POLL_S = 0.5


@dataclass(frozen=True)
class EvalTask:
    """One (goal, seed) to run; ``resume_run_id`` continues an interrupted planner run."""

    eval_run_id: int
    set_id: int
    problem_id: int
    goal_key: str
    planner: str  # the planner kind (twisted, random-low, low-level-only)
    label: str  # what the results are stored under (eval_results.planner), e.g. "twisted-rnd"
    seed: int
    timeout_s: float
    friction_scale: float
    workers: int
    options: dict[str, Any] = field(default_factory=dict)
    resume_run_id: int | None = None


@dataclass(frozen=True)
class TaskOutcome:
    """What one task ended with (``skipped``: another process holds it or it was done meanwhile)."""

    goal_key: str
    seed: int
    status: str  # solved | timeout | interrupted | failed | skipped
    time_to_solve_s: float | None = None
    sim_calls: int | None = None
    plan_run_id: int | None = None
    message: str | None = None


@dataclass
class EvalSummary:
    eval_run_id: int
    set_name: str
    planner: str
    total: int  # goals x seeds
    already_done: int  # finished before this invocation
    outcomes: list[TaskOutcome] = field(default_factory=list)
    status: str = "running"

    @property
    def solved(self) -> int:
        return sum(o.status == "solved" for o in self.outcomes)


def result_key(task: EvalTask) -> Any:
    """SQL condition selecting the result row of ``task`` (set, label, goal, seed, timeout, friction)."""
    return (
        (EvalResult.set_id == task.set_id)
        & (EvalResult.planner == task.label)
        & (EvalResult.goal_key == task.goal_key)
        & (EvalResult.seed == task.seed)
        & (EvalResult.timeout_s == task.timeout_s)
        & (EvalResult.friction_scale == task.friction_scale)
    )


def _claim(store: Any, task: EvalTask) -> tuple[int, int | None] | None:
    """Mark the task's row ``running`` for this process; (row id, planner run to resume) or None."""
    me = (socket.gethostname(), os.getpid())
    try:
        with store.session(write=True) as session:
            row = session.scalar(select(EvalResult).where(result_key(task)))
            if row is not None:
                if row.status in FINISHED_STATUSES:
                    return None
                if row.status == "running" and (row.host, row.pid) != me and pid_alive(row.host, row.pid):
                    return None
                resume = row.plan_run_id
                row.status, row.eval_run_id, row.host, row.pid = "running", task.eval_run_id, *me
                row.started_at, row.ended_at, row.message = utcnow(), None, None
                return row.id, resume
            row = EvalResult(
                eval_run_id=task.eval_run_id,
                set_id=task.set_id,
                problem_id=task.problem_id,
                planner=task.label,
                goal_key=task.goal_key,
                seed=task.seed,
                timeout_s=task.timeout_s,
                friction_scale=task.friction_scale,
                status="running",
                solved=False,
                host=me[0],
                pid=me[1],
                started_at=utcnow(),
            )
            session.add(row)
            session.flush()
            return row.id, None
    except IntegrityError:  # another process inserted the same key first
        return None


def _set_row(store: Any, row_id: int, **values: Any) -> None:
    with store.session(write=True) as session:
        session.execute(update(EvalResult).where(EvalResult.id == row_id).values(**values))


def run_task(db_url: str, task: EvalTask) -> TaskOutcome:
    """Run one (goal, seed) with the planner and store its outcome (in the calling process)."""
    from twisted.goals import make_goal
    from twisted.planner import PlannerOptions, curve_sampler, resume_search, start_search
    from twisted.runtime import StopSignals
    from twisted.sim import SimPool
    from twisted.store import open_store

    t0 = time.perf_counter()
    store = open_store(db_url)
    row_id: int | None = None
    try:
        claimed = _claim(store, task)
        if claimed is None:
            return TaskOutcome(task.goal_key, task.seed, "skipped")
        row_id, resume_run_id = claimed
        goal = make_goal(task.goal_key)
        option_fields = {k: v for k, v in task.options.items() if k in PlannerOptions.__dataclass_fields__}
        options = PlannerOptions(**{**option_fields, "planner": task.planner, "seed": task.seed})
        stop = StopSignals()
        with stop.installed(), SimPool(task.workers, task.friction_scale) as pool:
            search = None
            if resume_run_id is not None:
                from twisted.store.search import load_run

                info = load_run(store, resume_run_id, with_nodes=False)
                if info is not None and info.outcome != "solved" and info.checkpoint is not None:
                    # continue with the model the run started with
                    sampler, _ = curve_sampler(store, task.planner, info.parameters.get("model_id"))
                    search = resume_search(store, resume_run_id, pool, sampler=sampler, stop=stop)
            if search is None:
                sampler, model_id = curve_sampler(store, task.planner, task.options.get("model_id"))
                search = start_search(
                    store,
                    goal,
                    options,
                    pool,
                    sampler=sampler,
                    stop=stop,
                    extra_parameters={"model_id": model_id, "eval_run_id": task.eval_run_id},
                )
            _set_row(store, row_id, plan_run_id=search.run_id)
            result = search.run(timeout_s=task.timeout_s)
        status = result.status if result.status in ("solved", "timeout", "interrupted") else "failed"
        time_to_solve = None
        if result.solved:
            # the goal node's creation time is the moment the goal entered T
            goal_node = result.path[-1] if result.path else None
            time_to_solve = getattr(goal_node, "created_s", None) or result.elapsed_s
        _set_row(
            store,
            row_id,
            status=status,
            solved=result.solved,
            time_to_solve_s=time_to_solve,
            elapsed_s=result.elapsed_s,
            sim_calls=result.sim_calls,
            iterations=result.iterations,
            wall_s=time.perf_counter() - t0,
            ended_at=utcnow(),
            message=None if status != "failed" else f"planner ended with status {result.status!r}",
        )
        return TaskOutcome(task.goal_key, task.seed, status, time_to_solve, result.sim_calls, search.run_id)
    except BaseException as exc:  # noqa: BLE001 - record why, whatever it was, then re-raise interrupts
        interrupted = isinstance(exc, KeyboardInterrupt)
        message = "interrupted" if interrupted else "".join(traceback.format_exception_only(exc)).strip()
        if row_id is not None:
            try:
                _set_row(
                    store,
                    row_id,
                    status="interrupted" if interrupted else "failed",
                    wall_s=time.perf_counter() - t0,
                    ended_at=utcnow(),
                    message=message[-2000:],
                )
            except Exception:  # noqa: BLE001 - the row stays 'running' with a dead pid: rerun later
                pass
        return TaskOutcome(
            task.goal_key, task.seed, "interrupted" if interrupted else "failed", message=message
        )
    finally:
        store.close()


@dataclass(frozen=True)
class EvalOptions:
    """What one evaluation runs (``twisted eval``'s options); checked by :func:`prepare_eval`."""

    set_name: str
    planner: str  # the planner kind (a key of ``twisted.planner.PLANNERS``)
    timeout_s: float  # search time per (goal, seed)
    seeds: Sequence[int] = (0,)
    friction_scale: float = 1.0
    workers: int = 1  # simulator processes per planner (1 = in-process)
    parallel: int | None = None  # tasks at once; None: the backend's smallest (``min_parallel``)
    planner_options: Mapping[str, Any] | None = None  # e.g. heuristic, model_id
    label: str | None = None  # what the results are stored under (default: planner[-heuristic])


@dataclass(frozen=True)
class PreparedEval:
    """The checked inputs of one evaluation (:func:`run_eval`)."""

    set_name: str
    planner: str  # the planner kind (a key of ``twisted.planner.PLANNERS``)
    label: str  # what the results are stored under
    options: dict[str, Any]  # planner options; ``model_id`` resolved for the twisted planner
    record: ProblemSetRecord
    timeout_s: float
    seeds: Sequence[int]
    friction_scale: float
    workers: int
    parallel: int  # tasks at once (0: as many as the backend has room for)

    @property
    def total(self) -> int:
        """Number of tasks of the evaluation: goals x seeds."""
        return len(self.record.problems) * len(self.seeds)

    def start(
        self, store: Any, parallel: int, parameters: Mapping[str, Any] | None = None
    ) -> tuple[EvalSummary, list[EvalTask]]:
        """Store a new ``running`` eval run; its summary and the tasks still to run.

        The run's parameters are the planner options, the planner kind and ``parameters``.
        """
        with store.session(write=True) as session:
            eval_run_id = start_eval_run(
                session,
                set_id=self.record.id,
                planner=self.label,
                timeout_s=self.timeout_s,
                friction_scale=self.friction_scale,
                seeds=self.seeds,
                workers=self.workers,
                parallel=parallel,
                parameters={**self.options, "planner": self.planner, **(parameters or {})},
            )
        with store.session() as session:
            tasks, done = pending_tasks(session, self, eval_run_id)
        return EvalSummary(eval_run_id, self.set_name, self.label, self.total, done), tasks


def prepare_eval(store: Any, request: EvalOptions, min_parallel: int = 1) -> PreparedEval:
    """Check an evaluation's inputs, pick its label, load its model id and problem set.

    Raises :class:`EvalInputError` naming the first bad input, before any process or task starts.
    ``parallel`` must be at least ``min_parallel`` (its default): 1 for local processes, 0 on Ray (0
    there means as many tasks as the cluster's CPUs allow). The default label is the planner kind,
    plus ``-<heuristic>`` when the planner options choose one.
    """
    from twisted.planner import PLANNERS

    set_name, planner, timeout_s, seeds = request.set_name, request.planner, request.timeout_s, request.seeds
    friction_scale, workers, label = request.friction_scale, request.workers, request.label
    parallel = min_parallel if request.parallel is None else request.parallel

    if planner not in PLANNERS:
        raise EvalInputError(f"unknown planner {planner!r}: choose from {', '.join(PLANNERS)}")
    if not (math.isfinite(timeout_s) and timeout_s > 0):
        raise EvalInputError(f"--timeout must be a positive number of seconds, got {timeout_s}")
    if not (math.isfinite(friction_scale) and friction_scale > 0):
        raise EvalInputError(f"--friction-scale must be positive, got {friction_scale}")
    if workers < 1 or parallel < min_parallel:
        if min_parallel == 1:
            raise EvalInputError(f"--workers and --parallel must be at least 1, got {workers} and {parallel}")
        raise EvalInputError(
            f"--workers must be at least 1 and --parallel at least {min_parallel}, got {workers}, {parallel}"
        )
    if not seeds:
        raise EvalInputError("give at least one seed")
    options = dict(request.planner_options or {})
    if label is None:
        label = planner if options.get("heuristic") is None else f"{planner}-{options['heuristic']}"
    if not label or len(label) > 32:
        raise EvalInputError(f"--label must have 1 to 32 characters, got {label!r}")
    # the defaults are stored as values: a later change of a default then starts new results instead of
    # counting this label's old ones as done
    from twisted.planner import PlanInputError, PlannerOptions, curve_sampler, planner_options

    asked = {k: v for k, v in options.items() if k in PlannerOptions.__dataclass_fields__}
    try:
        resolved = planner_options({**asked, "planner": planner})
    except PlanInputError as exc:
        raise EvalInputError(str(exc)) from None
    stored = [k for k in RESULT_OPTIONS if k in PlannerOptions.__dataclass_fields__ and k != "planner"]
    options.update({k: getattr(resolved, k) for k in stored})
    if planner in ("twisted", "sac"):
        try:  # fail before starting any process or task when the model cannot be had
            options["model_id"] = curve_sampler(store, planner, options.get("model_id"))[1]
        except PlanInputError as exc:
            raise EvalInputError(str(exc)) from None
    with store.session() as session:
        record = load_problem_set(session, set_name)
        if record is None:
            raise EvalInputError(f"no problem set {set_name!r}: see `twisted problems list`")
        _check_label_options(session, record, label, {**options, "planner": planner})
    return PreparedEval(
        set_name=set_name,
        planner=planner,
        label=label,
        options=options,
        record=record,
        timeout_s=timeout_s,
        seeds=seeds,
        friction_scale=friction_scale,
        workers=workers,
        parallel=parallel,
    )


# planner options that change what a result is: results stored under one label must agree on them
RESULT_OPTIONS = (
    "planner",
    "model_id",
    "heuristic",
    "k",
    "p_expand",
    "k_expand",
    "retry_weight",
    "state_prior",
    "cross_move",
    "r1_room",
)
# options added after evaluations stored every option's value: one missing from an evaluation ran with
# the planner's OPTIONS_BEFORE value (one missing from an older evaluation, like state_prior, was the
# default of its day: unknown)
ADDED_OPTIONS = ("cross_move", "r1_room")


def _shown(stored: Any) -> str:
    """A stored planner option; evaluations before the defaults were stored left them out."""
    return "unrecorded (the default of its day)" if stored is None else str(stored)


def _check_label_options(
    session: Any, record: ProblemSetRecord, label: str, options: Mapping[str, Any]
) -> None:
    """Refuse to add results under ``label`` that were made with other planner options.

    Finished results count as done for every later evaluation under the same label, so an
    evaluation with another model or K would silently reuse them.
    """
    here = (EvalResult.set_id == record.id) & (EvalResult.planner == label)
    runs = select(EvalResult.eval_run_id).where(here)
    q = select(EvalRun.parameters).where(EvalRun.id.in_(runs))  # no DISTINCT: PostgreSQL's json has no "="
    from twisted.planner.search import OPTIONS_BEFORE

    ours = {key: options.get(key) for key in RESULT_OPTIONS}
    added = {key: OPTIONS_BEFORE[key] for key in ADDED_OPTIONS}
    for (parameters,) in session.execute(q):
        theirs = {key: (parameters or {}).get(key, added.get(key)) for key in RESULT_OPTIONS}
        differ = [
            f"{key} {_shown(theirs[key])} (now {ours[key]})"
            for key in RESULT_OPTIONS
            if theirs[key] != ours[key]
        ]
        if differ:
            raise EvalInputError(
                f"--label {label}: the results on set {record.name!r} under this label were made with "
                f"{', '.join(differ)}; give another --label"
            )


def pending_tasks(session: Any, prepared: PreparedEval, eval_run_id: int) -> tuple[list[EvalTask], int]:
    """Tasks still to run (finished ones and ones another live process holds are left out)."""
    record, planner, label = prepared.record, prepared.planner, prepared.label
    timeout_s, friction_scale = prepared.timeout_s, prepared.friction_scale
    rows = session.scalars(
        select(EvalResult).where(
            (EvalResult.set_id == record.id)
            & (EvalResult.planner == label)
            & (EvalResult.timeout_s == timeout_s)
            & (EvalResult.friction_scale == friction_scale)
        )
    ).all()
    by_key = {(r.goal_key, r.seed): r for r in rows}
    tasks, done = [], 0
    for seed in prepared.seeds:
        for problem in record.problems:
            row = by_key.get((problem.goal_key, seed))
            if row is not None and row.status in FINISHED_STATUSES:
                done += 1
                continue
            if row is not None and row.status == "running" and pid_alive(row.host, row.pid):
                continue
            assert problem.id is not None
            tasks.append(
                EvalTask(
                    eval_run_id=eval_run_id,
                    set_id=record.id,
                    problem_id=problem.id,
                    goal_key=problem.goal_key,
                    planner=planner,
                    label=label,
                    seed=int(seed),
                    timeout_s=float(timeout_s),
                    friction_scale=float(friction_scale),
                    workers=prepared.workers,
                    options=dict(prepared.options),
                )
            )
    return tasks, done


def free_row(store: Any, task: EvalTask, message: str) -> None:
    """Mark the task's row ``interrupted`` when it is still ``running``: its runner died holding it."""
    with store.session(write=True) as session:
        session.execute(
            update(EvalResult)
            .where(result_key(task) & (EvalResult.status == "running"))
            .values(status="interrupted", message=message)
        )


# --- the scheduler and its backends ----------------------------------------------------------------------


class TaskPool(Protocol):
    """Tasks running somewhere, as the scheduler sees them (one pool per eval)."""

    @property
    def in_flight(self) -> int:
        """How many tasks may run at once."""

    @property
    def parameters(self) -> dict[str, Any]:
        """What the eval run stores about the backend (e.g. the Ray cluster)."""

    @property
    def running(self) -> int:
        """Tasks submitted whose outcome has not been returned yet."""

    def submit(self, task: EvalTask) -> None:
        """Start one task."""

    def wait(self, timeout_s: float) -> list[TaskOutcome]:
        """Outcomes of tasks that finished within ``timeout_s`` (often none, seldom more than one)."""

    def cancel_all(self) -> list[TaskOutcome]:
        """Ask the running tasks to stop (their planners checkpoint), wait for them; their outcomes."""


class EvalBackend(Protocol):
    """Where the tasks of an eval run: :class:`ProcessBackend` or ``twisted.distributed.RayBackend``."""

    @property
    def name(self) -> str:
        """The backend in words, for the log."""

    @property
    def min_parallel(self) -> int:
        """The smallest ``parallel`` it takes, and the default (0: as many tasks as it has room for)."""

    def open(self, store: Any, db_url: str, workers: int, parallel: int) -> AbstractContextManager[TaskPool]:
        """A pool for one eval's tasks (each with ``workers`` simulator processes), for the block."""


def _task_process(db_url: str, task: EvalTask, queue: Any) -> None:
    outcome = run_task(db_url, task)
    queue.put(outcome)


class _ProcessPool:
    """Each task in its own spawned process, which reports its outcome through a queue."""

    def __init__(self, db_url: str, in_flight: int) -> None:
        self.db_url, self.in_flight = db_url, in_flight
        self.parameters: dict[str, Any] = {}
        self._ctx = multiprocessing.get_context("spawn")
        self._queue = self._ctx.Queue()
        self._procs: dict[tuple[str, int], Any] = {}  # (goal, seed) -> process that has not reported yet
        self._dead_since: dict[tuple[str, int], float] = {}

    @property
    def running(self) -> int:
        return len(self._procs)

    def submit(self, task: EvalTask) -> None:
        proc = self._ctx.Process(target=_task_process, args=(self.db_url, task, self._queue), daemon=False)
        proc.start()
        self._procs[(task.goal_key, task.seed)] = proc

    def wait(self, timeout_s: float) -> list[TaskOutcome]:
        try:
            outcome = self._queue.get(timeout=timeout_s)
        except queue_module.Empty:
            return self._reap_silent()
        proc = self._procs.pop((outcome.goal_key, outcome.seed), None)
        if proc is not None:
            proc.join()
        return [outcome]

    def _reap_silent(self) -> list[TaskOutcome]:
        """Children that died without reporting (killed); a clean exit's report may still be in the pipe."""
        lost = []
        for key, proc in list(self._procs.items()):
            if proc.is_alive():
                continue
            first = self._dead_since.setdefault(key, time.monotonic())
            if proc.exitcode != 0 or time.monotonic() - first > 10.0:
                self._procs.pop(key).join()
                lost.append(
                    TaskOutcome(key[0], key[1], "failed", message=f"worker exited with code {proc.exitcode}")
                )
        return lost

    def cancel_all(self) -> list[TaskOutcome]:
        for proc in self._procs.values():
            if proc.is_alive():
                os.kill(proc.pid, signal.SIGINT)  # the planner checkpoints and marks its row
        outcomes = []
        deadline = time.monotonic() + CANCEL_WAIT_S
        while self._procs and time.monotonic() < deadline:
            outcomes += self.wait(POLL_S)
        for proc in self._procs.values():
            proc.kill()
            proc.join()
        self._procs.clear()
        return outcomes


class ProcessBackend:
    """Each task in its own local process (spawned: nothing inherited), ``parallel`` at once."""

    name = "local processes"
    min_parallel = 1

    @contextmanager
    def open(self, store: Any, db_url: str, workers: int, parallel: int) -> Iterator[TaskPool]:
        yield _ProcessPool(db_url, parallel)


def _log_outcome(eval_run_id: int, label: str, outcome: TaskOutcome) -> None:
    how = outcome.status
    if outcome.time_to_solve_s is not None:
        how += f" in {outcome.time_to_solve_s:.1f} s"
    if outcome.message and outcome.status != "interrupted":
        how += f": {outcome.message.splitlines()[-1][:300]}"
    log.info(
        "eval run %d: goal %s, planner %s, seed %d: %s (%s sim calls)",
        eval_run_id,
        outcome.goal_key,
        label,
        outcome.seed,
        how,
        "?" if outcome.sim_calls is None else outcome.sim_calls,
    )


def schedule(
    store: Any,
    prepared: PreparedEval,
    pool: TaskPool,
    *,
    backend: str = "",
    on_outcome: Callable[[TaskOutcome, EvalSummary], None] | None = None,
    on_start: Callable[[EvalSummary, int], None] | None = None,
) -> EvalSummary:
    """THE eval scheduler: start an eval run of ``prepared`` and run its pending tasks on ``pool``.

    ``pool.in_flight`` tasks run at once; every outcome is added to the summary and passed to
    ``on_outcome`` as it comes. On Ctrl-C / SIGTERM (inside, SIGTERM raises KeyboardInterrupt) / an
    exception from ``on_outcome`` the running tasks are cancelled (their planners checkpoint and the
    rows become ``interrupted``), the eval run is marked interrupted (failed for an exception) and the
    exception propagates; running the same eval again continues.
    """
    summary, tasks = prepared.start(store, pool.in_flight, pool.parameters)
    log.info(
        "eval run %d started: set %s, planner %s (%s), seeds %s, timeout %g s, friction %g, workers %d; "
        "%d of %d tasks to run (%d finished before), %d at once on %s",
        summary.eval_run_id,
        prepared.set_name,
        prepared.label,
        prepared.planner,
        ",".join(map(str, prepared.seeds)),
        prepared.timeout_s,
        prepared.friction_scale,
        prepared.workers,
        len(tasks),
        summary.total,
        summary.already_done,
        pool.in_flight,
        backend or type(pool).__name__,
    )
    if on_start is not None:
        on_start(summary, len(tasks))
    queued = list(reversed(tasks))
    status, message = "finished", None
    with sigterm_as_interrupt():
        try:
            while queued or pool.running:
                while queued and pool.running < pool.in_flight:
                    pool.submit(queued.pop())
                for outcome in pool.wait(POLL_S):
                    summary.outcomes.append(outcome)
                    _log_outcome(summary.eval_run_id, prepared.label, outcome)
                    if on_outcome is not None:
                        on_outcome(outcome, summary)
        except BaseException as exc:
            status = "interrupted" if isinstance(exc, KeyboardInterrupt) else "failed"
            message = None if status == "interrupted" else repr(exc)
            log.info(
                "eval run %d: stopping (%s), cancelling %d tasks", summary.eval_run_id, status, pool.running
            )
            cancelled = pool.cancel_all()
            for outcome in cancelled:
                _log_outcome(summary.eval_run_id, prepared.label, outcome)
            summary.outcomes.extend(cancelled)
            raise
        finally:
            summary.status = status
            with store.session(write=True) as session:
                end_eval_run(session, summary.eval_run_id, status, message)
            log.info(
                "eval run %d %s: %d of %d solved this time, %d finished before%s",
                summary.eval_run_id,
                status,
                summary.solved,
                len(summary.outcomes),
                summary.already_done,
                f" ({message})" if message else "",
            )
    return summary


def run_eval(
    store: Any,
    db_url: str,
    request: EvalOptions,
    *,
    backend: EvalBackend | None = None,
    on_outcome: Callable[[TaskOutcome, EvalSummary], None] | None = None,
    on_start: Callable[[EvalSummary, int], None] | None = None,
) -> EvalSummary:
    """Run every (goal, seed) of a set not already finished; outcomes are stored as they come.

    Results are stored under ``request.label`` (default: the planner kind, plus ``-<heuristic>`` when
    the planner options choose one), so variants of one planner are told apart in the report.
    ``backend``: where the tasks run (default :class:`ProcessBackend`). Stops as :func:`schedule`
    says; running the same eval again continues.
    """
    chosen: EvalBackend = backend if backend is not None else ProcessBackend()
    prepared = prepare_eval(store, request, chosen.min_parallel)
    return run_prepared(store, db_url, prepared, chosen, on_outcome=on_outcome, on_start=on_start)


def run_prepared(
    store: Any,
    db_url: str,
    prepared: PreparedEval,
    backend: EvalBackend,
    *,
    on_outcome: Callable[[TaskOutcome, EvalSummary], None] | None = None,
    on_start: Callable[[EvalSummary, int], None] | None = None,
) -> EvalSummary:
    """:func:`run_eval` for inputs already checked by :func:`prepare_eval` (with ``backend.min_parallel``):
    what runs several evaluations after checking them all uses."""
    with backend.open(store, db_url, prepared.workers, prepared.parallel) as pool:
        return schedule(store, prepared, pool, backend=backend.name, on_outcome=on_outcome, on_start=on_start)
