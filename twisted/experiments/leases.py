"""The tasks of an evaluation and their rows in ``eval_results``: each (goal, seed) is claimed by one
live process (its lease: ``running`` with the host and pid), run with the planner and stored as it ends.

A row is claimed (:func:`claim`) when its goal starts and gets the planner's run id as soon as the
planner made one; a claim skips ``solved``/``timeout`` rows and rows a live process holds, and takes
over ``interrupted`` ones and rows of a process that died, continuing from the planner's own checkpoint
(same run id, elapsed time carried over). :func:`free_row` marks the row of a runner that died holding
it; :func:`pending_tasks` lists what an evaluation still has to run.
"""

from __future__ import annotations

import os
import socket
import time
import traceback
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sqlalchemy import select, update
from sqlalchemy.exc import IntegrityError

from twisted.store.experiments import FINISHED_STATUSES, EvalResult, pid_alive
from twisted.store.models import utcnow

if TYPE_CHECKING:
    from twisted.experiments.runner import PreparedEval

__all__ = [
    "EvalTask",
    "TaskOutcome",
    "claim",
    "free_row",
    "pending_tasks",
    "result_key",
    "run_task",
    "set_row",
]


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


def claim(store: Any, task: EvalTask) -> tuple[int, int | None] | None:
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


def set_row(store: Any, row_id: int, **values: Any) -> None:
    """Update the result row ``row_id`` (in its own transaction)."""
    with store.session(write=True) as session:
        session.execute(update(EvalResult).where(EvalResult.id == row_id).values(**values))


def run_task(db_url: str, task: EvalTask) -> TaskOutcome:
    """Run one (goal, seed) with the planner and store its outcome (in the calling process)."""
    from twisted.planner import SearchProgress, run_search
    from twisted.runtime import StopSignals
    from twisted.store import open_store

    t0 = time.perf_counter()
    store = open_store(db_url)
    row_id: int | None = None
    try:
        claimed = claim(store, task)
        if claimed is None:
            return TaskOutcome(task.goal_key, task.seed, "skipped")
        row_id, resume_run_id = claimed
        request = _request(store, task, resume_run_id)

        class RowProgress(SearchProgress):
            def started(self, search: Any) -> None:  # the row names its planner run from the start
                assert row_id is not None
                set_row(store, row_id, plan_run_id=search.run_id)

        stop = StopSignals()
        with stop.installed():
            result = run_search(store, request, stop, RowProgress())
        status = result.status if result.status in ("solved", "timeout", "interrupted") else "failed"
        time_to_solve = None
        if result.solved:
            # the goal node's creation time is the moment the goal entered T
            goal_node = result.path[-1] if result.path else None
            time_to_solve = getattr(goal_node, "created_s", None) or result.elapsed_s
        set_row(
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
        return TaskOutcome(task.goal_key, task.seed, status, time_to_solve, result.sim_calls, result.run_id)
    except BaseException as exc:  # noqa: BLE001 - record why, whatever it was, then re-raise interrupts
        interrupted = isinstance(exc, KeyboardInterrupt)
        message = "interrupted" if interrupted else "".join(traceback.format_exception_only(exc)).strip()
        if row_id is not None:
            try:
                set_row(
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


def _request(store: Any, task: EvalTask, resume_run_id: int | None) -> Any:
    """The search of ``task``: its interrupted planner run continued (with the options and model it
    started with) when it can be, else a new run with the task's options, seed and model. An evaluation
    times the search alone (``timed_setup`` off)."""
    import dataclasses

    from twisted.planner import PlannerOptions, SearchRequest
    from twisted.store.search import load_run

    base = SearchRequest(
        workers=task.workers, friction_scale=task.friction_scale, timeout_s=task.timeout_s, timed_setup=False
    )
    if resume_run_id is not None:
        info = load_run(store, resume_run_id, with_nodes=False)
        if info is not None and info.outcome != "solved" and info.checkpoint is not None:
            return dataclasses.replace(base, resume=True, run_id=resume_run_id)
    option_fields = {k: v for k, v in task.options.items() if k in PlannerOptions.__dataclass_fields__}
    return dataclasses.replace(
        base,
        goal=task.goal_key,
        options={**option_fields, "planner": task.planner, "seed": task.seed},
        model_id=task.options.get("model_id"),
        parameters={"eval_run_id": task.eval_run_id},
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
