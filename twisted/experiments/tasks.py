"""The things the parts of an evaluation hand each other, in a module of their own so that none of
them imports another for a type: :class:`PreparedEval` (the checked inputs, made by
:func:`twisted.experiments.runner.prepare_eval`), :class:`EvalTask` (one (goal, seed) to run),
:class:`TaskOutcome` (what it ended with), :class:`EvalSummary` (what one eval run did) and
:class:`TaskKind` (what a pool of the scheduler runs: eval tasks or ``twisted improve``'s searches).

The modules import one way: ``runner`` (inputs) -> ``scheduler`` (tasks in flight) -> ``leases`` (one
task and its row) -> ``tasks``; ``tests/test_import_cycles.py`` fails on a circle.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from twisted.store.experiments import ProblemSetRecord

__all__ = ["EvalSummary", "EvalTask", "PreparedEval", "TaskKind", "TaskOutcome"]


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


@dataclass(frozen=True)
class TaskKind:
    """What the tasks of a pool are.

    ``run(db_url, task) -> outcome`` runs one task in the worker (a spawned process or a Ray worker):
    a module-level function, so that the worker finds it by name. ``lost(store, task, status,
    message) -> outcome`` runs in the driver for a task that ended without reporting: ``failed`` when
    its worker died (killed, or lost with its node), ``interrupted`` when it was cancelled.
    """

    run: Callable[[str, Any], Any]
    lost: Callable[[Any, Any, str, str], Any]
