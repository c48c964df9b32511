"""Eval runs: every (goal, seed) of a problem set with one planner, stored as it finishes.

:func:`run_eval` checks the inputs (:func:`prepare_eval`: the planner options, the model, the set and
the label, :mod:`twisted.experiments.labels`), stores a new ``eval_runs`` row and hands the tasks still
to run (:func:`twisted.experiments.leases.pending_tasks`) to the one scheduler
(:func:`twisted.experiments.scheduler.schedule`). A task is
:func:`twisted.experiments.leases.run_task`: it claims its row in ``eval_results`` under the unique key
(set, planner label, goal, seed, timeout_s, friction_scale), runs the planner and stores the outcome;
a rerun skips finished rows and continues interrupted ones from the planner's own checkpoint.

The types the parts share are in :mod:`twisted.experiments.tasks`. The names of the other modules
listed below are re-exported here, where the commands and
``twisted.distributed`` find the evaluation's parts.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from twisted.experiments.labels import check_label_options, default_label, result_options
from twisted.experiments.leases import free_row, pending_tasks, result_key, run_task
from twisted.experiments.problems import EvalInputError
from twisted.experiments.scheduler import (
    CANCEL_WAIT_S,
    POLL_S,
    EvalBackend,
    ProcessBackend,
    TaskPool,
    schedule,
)
from twisted.experiments.tasks import EvalSummary, EvalTask, PreparedEval, TaskOutcome
from twisted.store.experiments import load_problem_set

__all__ = [
    "CANCEL_WAIT_S",
    "POLL_S",
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


def _pull_test_required(parameters: Mapping[str, Any]) -> bool:
    """Whether a set's parameters (made by ``problems make``, or imported from a goal-set file: the same
    keys, revision 0015) say its goals count only when the rope pulls tight."""
    return parameters.get("pull_test") == "required"


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
        label = default_label(planner, options)
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
    stored = [k for k in result_options() if k in PlannerOptions.__dataclass_fields__ and k != "planner"]
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
        if _pull_test_required(record.parameters or {}) and not options.get("tighten"):
            raise EvalInputError(f"set {set_name!r} requires the pull test: add --tighten")
        check_label_options(session, record, label, {**options, "planner": planner})
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
