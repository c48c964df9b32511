"""THE eval scheduler (:func:`schedule`) and where tasks run: ``parallel`` tasks in flight on a
backend (:class:`EvalBackend`), :class:`ProcessBackend` (each task in its own spawned local process) or
``twisted.distributed.RayBackend`` (a Ray task each). What a task is, a pool is told by a
:class:`TaskKind`: an evaluation's (goal, seed) (:data:`twisted.experiments.leases.EVAL_TASKS`, the
default) or one search of ``twisted improve`` (:mod:`twisted.experiments.improve`). :func:`run_on`
keeps a pool busy with a list of tasks; on Ctrl-C, SIGTERM or an exception it cancels the running
tasks (their planners checkpoint), and :func:`schedule` then marks the eval run interrupted or failed.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import queue as queue_module
import signal
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager
from typing import Any, Protocol

from twisted.experiments.leases import EVAL_TASKS, start_eval
from twisted.experiments.tasks import EvalSummary, PreparedEval, TaskKind, TaskOutcome
from twisted.runtime import sigterm_as_interrupt
from twisted.store.experiments import end_eval_run

__all__ = [
    "CANCEL_WAIT_S",
    "POLL_S",
    "EvalBackend",
    "ProcessBackend",
    "TaskKind",
    "TaskPool",
    "run_on",
    "schedule",
]

log = logging.getLogger("twisted.experiments.runner")  # the eval log keeps its logger name

# How long a stopping eval waits for its cancelled tasks (their planners checkpoint) before killing them.
CANCEL_WAIT_S = 60.0
# How long the scheduler waits for a finished task before it looks again (a signal is seen in between).
POLL_S = 0.5


class TaskPool(Protocol):
    """Tasks of one :class:`TaskKind` running somewhere, as the scheduler sees them (one pool per eval,
    or per ``twisted improve`` call)."""

    @property
    def in_flight(self) -> int:
        """How many tasks may run at once."""

    @property
    def parameters(self) -> dict[str, Any]:
        """What the eval run stores about the backend (e.g. the Ray cluster)."""

    @property
    def running(self) -> int:
        """Tasks submitted whose outcome has not been returned yet."""

    def submit(self, task: Any) -> None:
        """Start one task."""

    def wait(self, timeout_s: float) -> list[Any]:
        """Outcomes of tasks that finished within ``timeout_s`` (often none, seldom more than one)."""

    def cancel_all(self) -> list[Any]:
        """Ask the running tasks to stop (their planners checkpoint), wait for them; their outcomes."""


class EvalBackend(Protocol):
    """Where tasks run: :class:`ProcessBackend` or ``twisted.distributed.RayBackend``."""

    @property
    def name(self) -> str:
        """The backend in words, for the log."""

    @property
    def min_parallel(self) -> int:
        """The smallest ``parallel`` it takes, and the default (0: as many tasks as it has room for)."""

    def open(
        self, store: Any, db_url: str, workers: int, parallel: int, kind: TaskKind = EVAL_TASKS
    ) -> AbstractContextManager[TaskPool]:
        """A pool for tasks of ``kind`` (each with ``workers`` simulator processes), for the block."""


def _task_process(run: Callable[[str, Any], Any], db_url: str, key: int, task: Any, queue: Any) -> None:
    queue.put((key, run(db_url, task)))


class _ProcessPool:
    """Each task in its own spawned process, which reports its outcome through a queue."""

    def __init__(self, store: Any, db_url: str, in_flight: int, kind: TaskKind) -> None:
        self.store, self.db_url, self.in_flight, self.kind = store, db_url, in_flight, kind
        self.parameters: dict[str, Any] = {}
        self._ctx = multiprocessing.get_context("spawn")
        self._queue = self._ctx.Queue()
        self._procs: dict[int, tuple[Any, Any]] = {}  # number -> (process that has not reported, task)
        self._dead_since: dict[int, float] = {}
        self._submitted = 0

    @property
    def running(self) -> int:
        return len(self._procs)

    def submit(self, task: Any) -> None:
        key, self._submitted = self._submitted, self._submitted + 1
        args = (self.kind.run, self.db_url, key, task, self._queue)
        proc = self._ctx.Process(target=_task_process, args=args, daemon=False)
        proc.start()
        self._procs[key] = (proc, task)

    def wait(self, timeout_s: float) -> list[Any]:
        try:
            key, outcome = self._queue.get(timeout=timeout_s)
        except queue_module.Empty:
            return self._reap_silent()
        proc, _task = self._procs.pop(key, (None, None))
        if proc is not None:
            proc.join()
        return [outcome]

    def _reap_silent(self) -> list[Any]:
        """Children that died without reporting (killed); a clean exit's report may still be in the pipe."""
        lost = []
        for key, (proc, task) in list(self._procs.items()):
            if proc.is_alive():
                continue
            first = self._dead_since.setdefault(key, time.monotonic())
            if proc.exitcode != 0 or time.monotonic() - first > 10.0:
                self._procs.pop(key)
                proc.join()
                message = f"worker exited with code {proc.exitcode}"
                lost.append(self.kind.lost(self.store, task, "failed", message))
        return lost

    def cancel_all(self) -> list[Any]:
        for proc, _task in self._procs.values():
            if proc.is_alive():
                os.kill(proc.pid, signal.SIGINT)  # the planner checkpoints and marks its row
        outcomes = []
        deadline = time.monotonic() + CANCEL_WAIT_S
        while self._procs and time.monotonic() < deadline:
            outcomes += self.wait(POLL_S)
        for proc, _task in self._procs.values():
            proc.kill()
            proc.join()
        self._procs.clear()
        return outcomes


class ProcessBackend:
    """Each task in its own local process (spawned: nothing inherited), ``parallel`` at once."""

    name = "local processes"
    min_parallel = 1

    @contextmanager
    def open(
        self, store: Any, db_url: str, workers: int, parallel: int, kind: TaskKind = EVAL_TASKS
    ) -> Iterator[TaskPool]:
        yield _ProcessPool(store, db_url, parallel, kind)


def run_on(
    pool: TaskPool,
    tasks: Sequence[Any],
    on_outcome: Callable[[Any], None],
    *,
    may_start: Callable[[Any], bool] | None = None,
    on_cancelled: Callable[[list[Any]], None] | None = None,
) -> bool:
    """Run ``tasks`` in order on ``pool``, ``pool.in_flight`` at once, passing each outcome to
    ``on_outcome`` as it comes; False when ``may_start(task)`` refused a task (none is started after
    it). On any exception (Ctrl-C included) the running tasks are cancelled, their outcomes passed to
    ``on_cancelled``, and the exception propagates."""
    queued = list(reversed(tasks))
    started_all = True
    try:
        while queued or pool.running:
            while queued and pool.running < pool.in_flight:
                if may_start is not None and not may_start(queued[-1]):
                    queued, started_all = [], False
                    break
                pool.submit(queued.pop())
            for outcome in pool.wait(POLL_S):
                on_outcome(outcome)
    except BaseException:
        cancelled = pool.cancel_all()
        if on_cancelled is not None:
            on_cancelled(cancelled)
        raise
    return started_all


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
    summary, tasks = start_eval(store, prepared, pool.in_flight, pool.parameters)
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

    def outcome_in(outcome: TaskOutcome) -> None:
        summary.outcomes.append(outcome)
        _log_outcome(summary.eval_run_id, prepared.label, outcome)
        if on_outcome is not None:
            on_outcome(outcome, summary)

    def cancelled_in(cancelled: list[TaskOutcome]) -> None:
        log.info("eval run %d: stopping, %d running tasks cancelled", summary.eval_run_id, len(cancelled))
        for outcome in cancelled:
            _log_outcome(summary.eval_run_id, prepared.label, outcome)
        summary.outcomes.extend(cancelled)

    status, message = "finished", None
    with sigterm_as_interrupt():
        try:
            run_on(pool, tasks, outcome_in, on_cancelled=cancelled_in)
        except BaseException as exc:
            status = "interrupted" if isinstance(exc, KeyboardInterrupt) else "failed"
            message = None if status == "interrupted" else repr(exc)
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
