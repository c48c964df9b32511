"""The tasks of an evaluation and their rows in ``eval_results``: each (goal, seed) is claimed by one
live process (its lease: ``running`` with the host and pid), run with the planner and stored as it ends.

A row is claimed (:func:`claim`) when its goal starts and gets the planner's run id as soon as the
planner made one; a claim skips ``solved``/``timeout`` rows and rows a live process holds, and takes
over ``interrupted`` ones and rows of a process that died, continuing from the planner's own checkpoint
(same run id, elapsed time carried over). :func:`free_row` marks the row of a runner that died holding
it; :func:`pending_tasks` lists what an evaluation still has to run. The rows are read and written
through named functions of :mod:`twisted.store.experiments` (``claim_result``, ``update_result``,
``free_result``, ``result_rows``).
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Mapping
from typing import Any

from twisted.experiments.tasks import EvalSummary, EvalTask, PreparedEval, TaskKind, TaskOutcome
from twisted.store.experiments import (
    FINISHED_STATUSES,
    ResultKey,
    claim_result,
    free_result,
    pid_alive,
    result_rows,
    start_eval_run,
    update_result,
)
from twisted.store.models import utcnow

__all__ = [
    "EVAL_TASKS",
    "claim",
    "free_row",
    "lost_task",
    "pending_tasks",
    "result_key",
    "run_task",
    "start_eval",
]


def result_key(task: EvalTask) -> ResultKey:
    """The key of the result row of ``task`` (set, label, goal, seed, timeout, friction)."""
    return ResultKey(task.set_id, task.label, task.goal_key, task.seed, task.timeout_s, task.friction_scale)


def claim(store: Any, task: EvalTask) -> tuple[int, int | None] | None:
    """Mark the task's row ``running`` for this process; (row id, planner run to resume) or None."""
    return claim_result(store, result_key(task), task.eval_run_id, task.problem_id)


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
                update_result(store, row_id, plan_run_id=search.run_id)

        stop = StopSignals()
        with stop.installed():
            result = run_search(store, request, stop, RowProgress())
        status = result.status if result.status in ("solved", "timeout", "interrupted") else "failed"
        time_to_solve = None
        if result.solved:
            # the goal node's creation time is the moment the goal entered T
            goal_node = result.path[-1] if result.path else None
            time_to_solve = getattr(goal_node, "created_s", None) or result.elapsed_s
        update_result(
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
                update_result(
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
    from twisted.store.search_tree import load_run

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
    rows = result_rows(session, record.id, label, timeout_s, friction_scale)
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
    free_result(store, result_key(task), message)


def lost_task(store: Any, task: EvalTask, status: str, message: str) -> TaskOutcome:
    """The outcome of a task that ended without reporting; the row of a worker that died is freed."""
    if status == "failed":
        free_row(store, task, message)
    return TaskOutcome(task.goal_key, task.seed, status, message=message)


def start_eval(
    store: Any, prepared: PreparedEval, parallel: int, parameters: Mapping[str, Any] | None = None
) -> tuple[EvalSummary, list[EvalTask]]:
    """Store a new ``running`` eval run of ``prepared``; its summary and the tasks still to run.

    The run's parameters are the planner options, the planner kind and ``parameters``.
    """
    with store.session(write=True) as session:
        eval_run_id = start_eval_run(
            session,
            set_id=prepared.record.id,
            planner=prepared.label,
            timeout_s=prepared.timeout_s,
            friction_scale=prepared.friction_scale,
            seeds=prepared.seeds,
            workers=prepared.workers,
            parallel=parallel,
            parameters={**prepared.options, "planner": prepared.planner, **(parameters or {})},
        )
    with store.session() as session:
        tasks, done = pending_tasks(session, prepared, eval_run_id)
    return EvalSummary(eval_run_id, prepared.set_name, prepared.label, prepared.total, done), tasks


# What the scheduler's pools run for an evaluation (the default kind of every backend)
EVAL_TASKS = TaskKind(run_task, lost_task)
