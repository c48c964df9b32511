"""Experiments a researcher can rerun (paper section 5): problem sets, evaluations, report, sensitivity.

Problem sets (section 5.2, 5.4). The 3-crossing states our data visited are ranked by frequency,
the number of kept transitions that reached the state (``transitions.to_state_id``, what "how often
the random data visits it" means for a dataset of transitions), most frequent first, ties broken by
key. The ranking is cut into thirds by rank (``numpy.array_split``: sizes differ by at most one,
the first thirds take the extra): ``easy`` (top), ``medium``, ``hard`` (bottom). ``unseen-3`` holds
3-crossing states the high level reaches from the empty rope (``moves.enumerate_states(3)``) that
the data never visited. ``4`` holds 4-crossing states: those our data visited first (a rope has
reached them, so they are physically feasible), topped up with states the high level reaches but
the data never visited when fewer than ``per_set`` were visited; each goal's tag says which. ``5``
holds 5-crossing states likewise: those our data visited, topped up with states one move beyond the
goals of ``4``. From every pool ``per_set`` goals (10 in the paper) are drawn without replacement by
one seeded generator, in the fixed order easy, medium, hard, unseen-3, 4, 5, so a seed reproduces
every set.

Evaluation. ``run_eval`` runs every (goal, seed) of a set with one planner in separate processes
(``parallel`` at once, each planner with ``workers`` simulator processes, 1 = in-process) and stores
each outcome in ``eval_results`` under the unique key (set, planner, goal, seed, timeout_s,
friction_scale). A row is claimed (``running``) when its goal starts and gets the planner's run id
as soon as the planner made one; a rerun skips ``solved``/``timeout`` rows and continues
``interrupted`` ones from the planner's own checkpoint (same run id, elapsed time carried over).

Report. ``write_report`` draws success-vs-time curves (fraction of (goal, seed) attempts solved
within t, one plot per set, one line per planner/friction/timeout, like the paper's Figures 7-10)
and a Markdown table. ``friction_scale`` is part of every result, so the sensitivity experiment
(Figure 8: 95 % / 100 % / 105 %) is three evaluations and one more plot.

Discretisation (section 5.1). ``run_discretisation`` re-simulates stored transitions from their
start configuration with the curve rounded (z to 0.001 m, x and y to 0.01 m) and counts how often
the resulting state differs from the recorded one; the unrounded curve is re-simulated as a control
(the simulator is deterministic, so the control measures whether the data came from this simulator).
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import queue as queue_module
import signal
import socket
import time
import traceback
from collections import defaultdict
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from sqlalchemy import func, select, update
from sqlalchemy.exc import IntegrityError

from twisted.goals import Goal, state_goal
from twisted.moves import parse_state, successors
from twisted.runtime import sigterm_as_interrupt
from twisted.store.experiments import (
    FINISHED_STATUSES,
    DiscretisationResult,
    EvalResult,
    Problem,
    ProblemRecord,
    ProblemSet,
    ProblemSetRecord,
    count_results,
    delete_problem_set,
    end_eval_run,
    load_problem_set,
    pid_alive,
    save_problem_set,
    start_eval_run,
)
from twisted.store.models import Configuration, TopologicalState, Transition, utcnow
from twisted.topology import PData, PDataError, parse_p_data

__all__ = [
    "DIFFICULTY_SETS",
    "DISCRETE_STEP_XY_M",
    "DISCRETE_STEP_Z_M",
    "FOUR_SET",
    "PAPER_DISCRETISATION_CHANGED",
    "UNSEEN_SET",
    "goal_problems",
    "save_goal_sets",
    "DiscretisationSummary",
    "EvalInputError",
    "EvalSummary",
    "PreparedEval",
    "TaskOutcome",
    "import_problem_sets",
    "make_problem_sets",
    "make_problem_sets_in_store",
    "parse_goal_file",
    "pending_tasks",
    "prepare_eval",
    "result_key",
    "round_curve",
    "run_discretisation",
    "run_eval",
    "split_thirds",
    "state_frequencies",
    "success_curve",
    "write_report",
]

DIFFICULTY_SETS = ("easy", "medium", "hard")
UNSEEN_SET = "unseen-3"
FOUR_SET = "4"
FIVE_SET = "5"
ALL_MADE_SETS = (*DIFFICULTY_SETS, UNSEEN_SET, FOUR_SET, FIVE_SET)

DISCRETE_STEP_Z_M = 0.001
DISCRETE_STEP_XY_M = 0.01
PAPER_DISCRETISATION_CHANGED = 0.18  # 82 % accuracy over 600k transitions 2 -> 3 crossings


class EvalInputError(ValueError):
    """A set name, goal file, planner or option the experiments cannot take; the message says why."""


# --- problem sets ---------------------------------------------------------------------------------------


def state_frequencies(session: Any) -> dict[str, tuple[PData, int]]:
    """Every state our data reached: key -> (P-data, number of kept transitions reaching it)."""
    reached = (
        select(Transition.to_state_id.label("state_id"), func.count().label("n"))
        .group_by(Transition.to_state_id)
        .subquery()
    )
    rows = session.execute(
        select(TopologicalState.p_data, reached.c.n).join(reached, reached.c.state_id == TopologicalState.id)
    )
    out = {}
    for p_list, n in rows:
        p = parse_p_data(p_list)
        out[p.key] = (p, int(n))
    return out


def rank_by_frequency(frequencies: Mapping[str, int]) -> list[str]:
    """Keys, most frequent first; equal frequencies in key order (deterministic)."""
    return sorted(frequencies, key=lambda k: (-frequencies[k], k))


def split_thirds(frequencies: Mapping[str, int]) -> tuple[list[str], list[str], list[str]]:
    """Easy / medium / hard: the top, middle and bottom thirds of the ranking by frequency."""
    ranked = rank_by_frequency(frequencies)
    parts = np.array_split(np.arange(len(ranked)), 3)
    easy, medium, hard = ([ranked[i] for i in part] for part in parts)
    return easy, medium, hard


def _constant(tag: str) -> Callable[[str], str]:
    return lambda _key: tag


def _sample(pool: Sequence[str], n: int, rng: np.random.Generator) -> list[str]:
    if len(pool) <= n:
        return list(pool)
    picked = rng.choice(len(pool), size=n, replace=False)
    return [pool[i] for i in picked]


def make_problem_sets(
    frequencies: Mapping[str, tuple[PData, int]],
    reachable: Callable[[int], Sequence[PData]],
    *,
    per_set: int = 10,
    seed: int = 0,
    sets: Iterable[str] = ALL_MADE_SETS,
) -> dict[str, list[ProblemRecord]]:
    """Draw the goal sets from our data (pure: no store).

    ``frequencies``: key -> (state, transitions reaching it) for the visited states;
    ``reachable(c)``: the c-crossing states the high level reaches (c = 3, and 4 when needed).
    Goals of a set are listed most frequent first.
    """
    if per_set < 1:
        raise EvalInputError(f"--per-set must be at least 1, got {per_set}")
    wanted = set(sets)
    unknown = wanted - set(ALL_MADE_SETS)
    if unknown:
        raise EvalInputError(f"unknown set {sorted(unknown)[0]!r}: choose from {', '.join(ALL_MADE_SETS)}")
    visited = {k: (p, n) for k, (p, n) in frequencies.items() if n > 0}
    three = {k: n for k, (p, n) in visited.items() if p.cross == 3}
    rng = np.random.default_rng(seed)
    out: dict[str, list[ProblemRecord]] = {}

    def records(
        keys: Iterable[str], tag_of: Callable[[str], str], pool: Mapping[str, PData]
    ) -> list[ProblemRecord]:
        chosen = sorted(keys, key=lambda k: (-visited.get(k, (None, 0))[1], k))
        return [
            ProblemRecord(None, i, pool[k], visited.get(k, (None, 0))[1], tag_of(k))
            for i, k in enumerate(chosen)
        ]

    # Always draw in the same order so that a seed gives the same sets whichever subset is asked for.
    for name, third in zip(DIFFICULTY_SETS, split_thirds(three), strict=True):
        picked = _sample(third, per_set, rng)
        if name in wanted:
            out[name] = records(picked, _constant(name), {k: visited[k][0] for k in picked})
    all3 = {p.key: p for p in reachable(3)}
    unseen = sorted(k for k in all3 if k not in visited)
    picked = _sample(unseen, per_set, rng)
    if UNSEEN_SET in wanted:
        out[UNSEEN_SET] = records(picked, _constant("unseen"), all3)
    if FOUR_SET in wanted or FIVE_SET in wanted:  # 5 is drawn after 4, so 4 is drawn for it too
        four_visited = sorted(k for k, (p, _) in visited.items() if p.cross == 4)
        picked = _sample(four_visited, per_set, rng)
        pool = {k: visited[k][0] for k in picked}
        if len(picked) < per_set:
            all4 = {p.key: p for p in reachable(4)}
            extra = _sample(sorted(k for k in all4 if k not in visited), per_set - len(picked), rng)
            pool.update({k: all4[k] for k in extra})
            picked += extra
        four = records(picked, lambda k: "4-visited" if k in visited else "4-unseen", pool)
        if FOUR_SET in wanted:
            out[FOUR_SET] = four
    if FIVE_SET in wanted:
        # visited 5-crossing states first, topped up with states one move beyond the 4-crossing goals
        # (enumerating all 130,304 five-crossing states takes half a minute)
        five_visited = sorted(k for k, (p, _) in visited.items() if p.cross == 5)
        picked = _sample(five_visited, per_set, rng)
        pool = {k: visited[k][0] for k in picked}
        if len(picked) < per_set:
            beyond = {s.state.key: s.state for r in four for s in successors(r.p_data) if s.state.cross == 5}
            extra = _sample(sorted(k for k in beyond if k not in visited), per_set - len(picked), rng)
            pool.update({k: beyond[k] for k in extra})
            picked += extra
        out[FIVE_SET] = records(picked, lambda k: "5-visited" if k in visited else "5-unseen", pool)
    return out


def _enumerated(c: int) -> list[PData]:
    from twisted.moves import enumerate_states

    return enumerate_states(c)[c]


def make_problem_sets_in_store(
    store: Any,
    *,
    per_set: int = 10,
    seed: int = 0,
    prefix: str = "",
    replace: bool = False,
    sets: Iterable[str] = ALL_MADE_SETS,
    reachable: Callable[[int], Sequence[PData]] = _enumerated,
) -> list[ProblemSetRecord]:
    """Make the sets from the store's data and save them (names ``prefix + easy`` etc.).

    An existing set of the same name is an error unless ``replace`` (allowed only while no
    evaluation result refers to it).
    """
    sets = [s for s in ALL_MADE_SETS if s in set(sets)]
    with store.session() as session:
        frequencies = state_frequencies(session)
    three_visited = sum(1 for p, n in frequencies.values() if p.cross == 3 and n > 0)
    if three_visited < 3 and any(s in DIFFICULTY_SETS for s in sets):
        raise EvalInputError(
            f"the data visited {three_visited} three-crossing states; easy/medium/hard need at least 3 "
            "(collect data first: `twisted collect`)"
        )
    drawn = make_problem_sets(frequencies, reachable, per_set=per_set, seed=seed, sets=sets)
    parameters = {
        "per_set": per_set,
        "frequency": "kept transitions reaching the state",
        "three_crossing_states_visited": three_visited,
        "transitions": sum(n for _, n in frequencies.values()),
    }
    with store.session(write=True) as session:
        for name in drawn:
            full = f"{prefix}{name}"
            existing = session.scalar(select(ProblemSet).where(ProblemSet.name == full))
            if existing is not None:
                n_results = count_results(session, existing.id)
                if not replace:
                    raise EvalInputError(f"problem set {full!r} exists: use --replace or --prefix")
                if n_results:
                    raise EvalInputError(
                        f"problem set {full!r} has {n_results} evaluation results; it cannot be replaced "
                        "(use --prefix to make new sets)"
                    )
                delete_problem_set(session, existing.id)
                session.flush()
            save_problem_set(session, full, drawn[name], source="made", seed=seed, parameters=parameters)
    with store.session() as session:
        return [r for name in drawn if (r := load_problem_set(session, f"{prefix}{name}")) is not None]


def parse_goal_file(text: str, name: str | None = None) -> dict[str, list[Goal]]:
    """Goals from JSON: a list of goals (one set called ``name``) or an object of named lists.

    A goal is P-data, or a knot (``"overhand"``, ``"figure-eight@4"``: any state of that many crossings,
    default the knot's crossing number, that ties it). For an object the sets are called by their
    keys, prefixed ``name-`` when a name is given. Every goal is checked; the first bad one raises
    :class:`EvalInputError` naming set and index.
    """
    from twisted.goals import GoalError, goal_from_spec

    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise EvalInputError(
            f"goal file is not valid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})"
        ) from None
    except RecursionError:
        message = "goal file nests lists or objects far too deeply (a goal is a list of lists)"
        raise EvalInputError(message) from None
    if isinstance(data, list):
        if not name:
            raise EvalInputError("a goal file holding one list needs a set name (--name)")
        named = {name: data}
    elif isinstance(data, dict):
        named = {(f"{name}-{k}" if name else str(k)): v for k, v in data.items()}
    else:
        raise EvalInputError(
            "goal file must hold a JSON list of goals or an object of named lists, "
            f"got {type(data).__name__}"
        )
    out: dict[str, list[Goal]] = {}
    for set_name, goals in named.items():
        if not set_name or len(set_name) > 64:
            shown = set_name if len(set_name) <= 80 else f"{set_name[:80]}... ({len(set_name):,} characters)"
            raise EvalInputError(f"set name {shown!r} must have 1 to 64 characters")
        if not isinstance(goals, list) or not goals:
            raise EvalInputError(f"set {set_name!r}: expected a non-empty list of goals (P-data or knots)")
        seen: dict[str, int] = {}
        parsed = []
        for i, entry in enumerate(goals):
            where = f"set {set_name!r} entry {i}"
            # A list of entries that all are lists is a state; anything else is reported as malformed.
            try:
                if isinstance(entry, str):
                    goal = goal_from_spec(entry)
                else:
                    goal = state_goal(parse_state(entry, where))
            except GoalError as exc:
                raise EvalInputError(f"{where}: {exc}") from None
            except PDataError as exc:
                raise EvalInputError(str(exc)) from None
            if goal.cross == 0:
                raise EvalInputError(f"{where}: the empty rope [] is not a goal")
            if goal.spec in seen:
                raise EvalInputError(f"{where}: same goal as entry {seen[goal.spec]} ({goal.spec})")
            seen[goal.spec] = i
            parsed.append(goal)
        out[set_name] = parsed
    return out


def goal_problems(
    goals: Sequence[Goal], frequencies: Mapping[str, tuple[PData, int]], tag: str
) -> list[ProblemRecord]:
    """Problem records for ``goals``; a goal's frequency counts the transitions reaching any of its states."""
    return [
        ProblemRecord(
            None,
            i,
            goal.representative,
            sum(frequencies.get(p.key, (p, 0))[1] for p in goal.states),
            tag,
            spec=goal.spec if goal.knot is not None else None,
        )
        for i, goal in enumerate(goals)
    ]


def import_problem_sets(store: Any, text: str, name: str | None = None) -> list[ProblemSetRecord]:
    """Validate a goal file completely, then store all its sets in one transaction (or none)."""
    goals = parse_goal_file(text, name)
    return save_goal_sets(store, goals, "imported")


def save_goal_sets(store: Any, goals: Mapping[str, Sequence[Goal]], tag: str) -> list[ProblemSetRecord]:
    """Store new problem sets of the given goals (``source = 'imported'``) in one transaction, or none."""
    with store.session() as session:
        frequencies = state_frequencies(session)
    with store.session(write=True) as session:
        for set_name in goals:
            if session.scalar(select(ProblemSet.id).where(ProblemSet.name == set_name)) is not None:
                raise EvalInputError(f"problem set {set_name!r} exists already: import under another --name")
        for set_name, set_goals in goals.items():
            save_problem_set(
                session,
                set_name,
                goal_problems(set_goals, frequencies, tag),
                source="imported",
                parameters={"goals": len(set_goals)},
            )
    with store.session() as session:
        return [r for set_name in goals if (r := load_problem_set(session, set_name)) is not None]


# --- evaluation ----------------------------------------------------------------------------------------


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


def _task_process(db_url: str, task: EvalTask, queue: Any) -> None:
    outcome = run_task(db_url, task)
    queue.put(outcome)


@dataclass(frozen=True)
class PreparedEval:
    """The checked inputs of one evaluation (:func:`run_eval`, ``twisted.distributed.eval_on_ray``)."""

    set_name: str
    planner: str  # the planner kind (a key of ``twisted.planner.PLANNERS``)
    label: str  # what the results are stored under
    options: dict[str, Any]  # planner options; ``model_id`` resolved for the twisted planner
    record: ProblemSetRecord
    timeout_s: float
    seeds: Sequence[int]
    friction_scale: float
    workers: int

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


def prepare_eval(
    store: Any,
    set_name: str,
    planner: str,
    *,
    timeout_s: float,
    seeds: Sequence[int],
    friction_scale: float,
    workers: int,
    parallel: int,
    options: Mapping[str, Any] | None,
    label: str | None,
    min_parallel: int = 1,
) -> PreparedEval:
    """Check an evaluation's inputs, pick its label, load its model id and problem set.

    Raises :class:`EvalInputError` naming the first bad input, before any process or task starts.
    ``parallel`` must be at least ``min_parallel``: 1 for local processes, 0 on Ray (0 there means
    as many tasks as the cluster's CPUs allow). The default label is the planner kind, plus
    ``-<heuristic>`` when ``options`` choose one.
    """
    from twisted.planner import PLANNERS

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
    options = dict(options or {})
    if label is None:
        label = planner if options.get("heuristic") is None else f"{planner}-{options['heuristic']}"
    if not label or len(label) > 32:
        raise EvalInputError(f"--label must have 1 to 32 characters, got {label!r}")
    if planner in ("twisted", "sac"):
        from twisted.planner import PlanInputError, curve_sampler

        try:  # fail before starting any process or task when the model cannot be had
            options["model_id"] = curve_sampler(store, planner, options.get("model_id"))[1]
        except PlanInputError as exc:
            raise EvalInputError(str(exc)) from None
    with store.session() as session:
        record = load_problem_set(session, set_name)
    if record is None:
        raise EvalInputError(f"no problem set {set_name!r}: see `twisted problems list`")
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


def run_eval(
    store: Any,
    db_url: str,
    set_name: str,
    planner: str,
    *,
    timeout_s: float,
    seeds: Sequence[int] = (0,),
    friction_scale: float = 1.0,
    workers: int = 1,
    parallel: int = 1,
    options: Mapping[str, Any] | None = None,
    label: str | None = None,
    on_outcome: Callable[[TaskOutcome, EvalSummary], None] | None = None,
    on_start: Callable[[EvalSummary, int], None] | None = None,
) -> EvalSummary:
    """Run every (goal, seed) of a set not already finished; outcomes are stored as they come.

    Results are stored under ``label`` (default: the planner kind, plus ``-<heuristic>`` when
    ``options`` choose one), so variants of one planner are told apart in the report.
    Each task runs in its own process (spawned: nothing inherited), ``parallel`` at once. On
    Ctrl-C / SIGTERM / an exception from ``on_outcome`` the running tasks are asked to stop (their
    planners checkpoint and the rows become ``interrupted``), and the eval run is marked interrupted;
    running the same command again continues.
    """
    prepared = prepare_eval(
        store,
        set_name,
        planner,
        timeout_s=timeout_s,
        seeds=seeds,
        friction_scale=friction_scale,
        workers=workers,
        parallel=parallel,
        options=options,
        label=label,
    )
    summary, tasks = prepared.start(store, parallel)
    eval_run_id = summary.eval_run_id
    if on_start is not None:
        on_start(summary, len(tasks))

    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    running: dict[tuple[str, int], Any] = {}  # (goal, seed) -> process that has not reported yet
    dead_since: dict[tuple[str, int], float] = {}
    queued = list(reversed(tasks))
    status, message = "finished", None

    def received(outcome: TaskOutcome) -> None:
        summary.outcomes.append(outcome)
        proc = running.pop((outcome.goal_key, outcome.seed), None)
        if proc is not None:
            proc.join()

    def reap_silent() -> list[TaskOutcome]:
        """Children that died without reporting (killed); a clean exit's report may still be in the pipe."""
        lost = []
        for key, proc in list(running.items()):
            if proc.is_alive():
                continue
            first = dead_since.setdefault(key, time.monotonic())
            if proc.exitcode != 0 or time.monotonic() - first > 10.0:
                running.pop(key).join()
                lost.append(
                    TaskOutcome(key[0], key[1], "failed", message=f"worker exited with code {proc.exitcode}")
                )
        return lost

    def stop_children() -> None:
        for proc in running.values():
            if proc.is_alive():
                os.kill(proc.pid, signal.SIGINT)  # the planner checkpoints and marks its row
        deadline = time.monotonic() + 60.0
        while running and time.monotonic() < deadline:
            try:
                received(queue.get(timeout=0.5))
            except queue_module.Empty:
                summary.outcomes.extend(reap_silent())
        for proc in running.values():
            proc.kill()
            proc.join()
        running.clear()

    with sigterm_as_interrupt():  # SIGTERM: stop like Ctrl-C
        try:
            while queued or running:
                while queued and len(running) < parallel:
                    task = queued.pop()
                    proc = ctx.Process(target=_task_process, args=(db_url, task, queue), daemon=False)
                    proc.start()
                    running[(task.goal_key, task.seed)] = proc
                try:
                    outcomes = [queue.get(timeout=0.5)]
                except queue_module.Empty:
                    outcomes = reap_silent()
                for outcome in outcomes:
                    received(outcome)
                    if on_outcome is not None:
                        on_outcome(outcome, summary)
        except BaseException as exc:
            status = "interrupted" if isinstance(exc, KeyboardInterrupt) else "failed"
            message = None if status == "interrupted" else repr(exc)
            stop_children()
            raise
        finally:
            summary.status = status
            with store.session(write=True) as session:
                end_eval_run(session, eval_run_id, status, message)
    return summary


# --- report ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ResultRow:
    set_name: str
    planner: str
    goal_key: str
    seed: int
    timeout_s: float
    friction_scale: float
    solved: bool
    time_to_solve_s: float | None
    sim_calls: int | None
    frequency: int
    tag: str
    sim_calls_to_solve: int | None = None  # the simulation that produced the goal node


def load_results(session: Any, set_names: Sequence[str] | None = None) -> list[ResultRow]:
    """Finished results (solved or timed out), with their set, goal and the goal node's simulation."""
    from twisted.store.search import SearchNode, SearchRunRow

    q = (
        select(EvalResult, ProblemSet.name, Problem.frequency, Problem.tag, SearchNode.sim_call)
        .join(ProblemSet, ProblemSet.id == EvalResult.set_id)
        .join(Problem, Problem.id == EvalResult.problem_id)
        .outerjoin(SearchRunRow, SearchRunRow.run_id == EvalResult.plan_run_id)
        .outerjoin(SearchNode, SearchNode.id == SearchRunRow.goal_node_id)
        .where(EvalResult.status.in_(FINISHED_STATUSES))
        .order_by(ProblemSet.id, EvalResult.planner, Problem.idx, EvalResult.seed)
    )
    if set_names:
        q = q.where(ProblemSet.name.in_(list(set_names)))
    return [
        ResultRow(
            name,
            r.planner,
            r.goal_key,
            r.seed,
            r.timeout_s,
            r.friction_scale,
            bool(r.solved),
            r.time_to_solve_s,
            r.sim_calls,
            freq,
            tag,
            goal_call if r.solved else None,
        )
        for r, name, freq, tag, goal_call in session.execute(q)
    ]


def success_curve(times_s: Sequence[float | None], grid_s: npt.ArrayLike) -> np.ndarray:
    """Fraction of attempts solved within each time of ``grid_s`` (None = not solved)."""
    if not times_s:
        return np.zeros(np.shape(grid_s)[0])
    solved = np.array([t for t in times_s if t is not None], dtype=np.float64)
    grid = np.asarray(grid_s, dtype=np.float64)
    return (solved[None, :] <= grid[:, None]).sum(axis=1) / len(times_s)


def _series_label(planner: str, friction: float, timeout_s: float, many_timeouts: bool) -> str:
    label = planner
    if not math.isclose(friction, 1.0):
        label += f", friction {friction * 100:.0f}%"
    if many_timeouts:
        label += f", {timeout_s:g} s"
    return label


def _plot_curves(
    groups: Mapping[tuple[str, float, float], list[ResultRow]],
    title: str,
    path: Path,
    label: Callable[..., str],
) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax_calls) = plt.subplots(1, 2, figsize=(12.0, 4.2))
    t_max = max(k[2] for k in groups)
    grid = np.linspace(0.0, t_max, 400)
    calls_max = max((r.sim_calls or 0) for rows in groups.values() for r in rows) or 1
    calls_grid = np.linspace(0.0, calls_max, 400)
    for key in sorted(groups):
        rows = groups[key]
        y = success_curve([r.time_to_solve_s if r.solved else None for r in rows], grid)
        n = len(rows)
        (line,) = ax.step(grid, y, where="post", label=f"{label(*key)} ({sum(r.solved for r in rows)}/{n})")
        # Simulator calls do not depend on how busy the machine was, but a run that timed out
        # only says "not solved within its calls": the curve stops at the fewest such calls.
        to_solve = [r.sim_calls_to_solve if r.solved else None for r in rows]
        unsolved_calls = [r.sim_calls for r in rows if not r.solved and r.sim_calls is not None]
        known = min(unsolved_calls) if unsolved_calls else calls_max
        keep = calls_grid <= known
        ax_calls.step(
            calls_grid[keep], success_curve(to_solve, calls_grid[keep]), where="post", color=line.get_color()
        )
    ax.set_xlim(0, t_max)
    ax.set_xlabel("time (s)")
    ax_calls.set_xlim(0, calls_max)
    ax_calls.set_xlabel("simulator calls (curve stops where a run timed out)")
    for a in (ax, ax_calls):
        a.set_ylim(-0.02, 1.02)
        a.set_ylabel("fraction solved")
        a.grid(alpha=0.3)
    ax.set_title(title)
    ax_calls.set_title("the same, against simulator calls")
    ax.legend(fontsize=8, loc="upper left")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return path


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


@dataclass
class ReportFiles:
    markdown: Path
    plots: list[Path]
    sensitivity: list[Path]


def write_report(store: Any, out_dir: str | Path, set_names: Sequence[str] | None = None) -> ReportFiles:
    """Success-vs-time PNGs (one per set), friction plots where several scales exist, and report.md."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with store.session() as session:
        rows = load_results(session, set_names)
        set_order = [s.name for s in session.scalars(select(ProblemSet).order_by(ProblemSet.id))]
    by_set: dict[str, list[ResultRow]] = defaultdict(list)
    for r in rows:
        by_set[r.set_name].append(r)
    plots, sensitivity = [], []
    lines = ["# Evaluation report", "", f"{len(rows)} finished results.", ""]
    lines += [
        "| set | planner | friction | timeout (s) | attempts | solved | success | median time to solve (s) "
        "| mean sim calls |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for set_name in [s for s in set_order if s in by_set]:
        set_rows = by_set[set_name]
        groups: dict[tuple[str, float, float], list[ResultRow]] = defaultdict(list)
        for r in set_rows:
            groups[(r.planner, r.friction_scale, r.timeout_s)].append(r)
        many_timeouts = len({k[2] for k in groups}) > 1
        for (planner, friction, timeout_s), g in sorted(groups.items()):
            solved_times = [r.time_to_solve_s for r in g if r.solved and r.time_to_solve_s is not None]
            calls = [r.sim_calls for r in g if r.sim_calls is not None]
            median = f"{float(np.median(solved_times)):.1f}" if solved_times else "-"
            mean_calls = f"{float(np.mean(calls)):.0f}" if calls else "-"
            n_solved = sum(r.solved for r in g)
            lines.append(
                f"| {set_name} | {planner} | {friction:g} | {timeout_s:g} | {len(g)} | {n_solved} | "
                f"{n_solved / len(g):.0%} | {median} | {mean_calls} |"
            )
        plots.append(
            _plot_curves(
                groups,
                f"set {set_name}: success vs time",
                out / f"success_{_safe(set_name)}.png",
                lambda p, f, t, m=many_timeouts: _series_label(p, f, t, m),
            )
        )
        # Friction sensitivity: one plot per (planner, timeout) evaluated at several friction scales.
        by_planner: dict[tuple[str, float], dict[tuple[str, float, float], list[ResultRow]]] = defaultdict(
            dict
        )
        for key, g in groups.items():
            by_planner[(key[0], key[2])][key] = g
        for (planner, timeout_s), sub in sorted(by_planner.items()):
            if len(sub) > 1:
                sensitivity.append(
                    _plot_curves(
                        sub,
                        f"set {set_name}, {planner}: friction sensitivity",
                        out / f"friction_{_safe(set_name)}_{_safe(planner)}_{timeout_s:g}s.png",
                        lambda p, f, t: f"friction {f * 100:.0f}%",
                    )
                )
    lines += ["", "## Goals", ""]
    for set_name in [s for s in set_order if s in by_set]:
        lines += [
            f"### {set_name}",
            "",
            "| goal | tag | frequency | planner | friction | timeout (s) | solved | times (s) |",
        ]
        lines.append("|---|---|---|---|---|---|---|---|")
        per_goal: dict[tuple[str, str, float, float], list[ResultRow]] = defaultdict(list)
        for r in by_set[set_name]:
            per_goal[(r.goal_key, r.planner, r.friction_scale, r.timeout_s)].append(r)
        for (goal, planner, friction, timeout_s), g in per_goal.items():
            times = ", ".join(
                f"{r.time_to_solve_s:.0f}" for r in g if r.solved and r.time_to_solve_s is not None
            )
            lines.append(
                f"| `{goal}` | {g[0].tag} | {g[0].frequency} | {planner} | {friction:g} | {timeout_s:g} | "
                f"{sum(r.solved for r in g)}/{len(g)} | {times or '-'} |"
            )
        lines.append("")
    lines += _discretisation_lines(store)
    lines += ["## Plots", ""] + [f"![{p.stem}]({p.name})" for p in plots + sensitivity]
    md = out / "report.md"
    md.write_text("\n".join(lines) + "\n")
    return ReportFiles(md, plots, sensitivity)


# --- discretisation (section 5.1) -------------------------------------------------------------------------


def round_curve(curve: Any) -> Any:
    """The curve with z_max rounded to 0.001 m and x, y to 0.01 m (the paper's c_dis)."""
    from twisted.sim import Curve

    def r(v: float, step: float) -> float:
        return float(np.round(v / step) * step)

    return Curve(
        curve.link,
        r(curve.z_max_m, DISCRETE_STEP_Z_M),
        r(curve.x_m, DISCRETE_STEP_XY_M),
        r(curve.y_m, DISCRETE_STEP_XY_M),
    )


@dataclass
class VariantSummary:
    variant: str
    friction_scale: float
    transitions: int
    changed: int
    rejected: int

    @property
    def share_changed(self) -> float:
        return self.changed / self.transitions if self.transitions else float("nan")


@dataclass
class DiscretisationSummary:
    run_id: int
    requested: int
    available: int
    variants: list[VariantSummary]


def discretisation_summary(session: Any, run_id: int) -> list[VariantSummary]:
    """Per variant of one experiment: transitions, changed, rejected."""
    rows = session.execute(
        select(
            DiscretisationResult.variant,
            DiscretisationResult.friction_scale,
            func.count(),
            func.sum(func.cast(DiscretisationResult.changed, _int_type())),
            func.sum(func.cast(~DiscretisationResult.ok, _int_type())),
        )
        .where(DiscretisationResult.run_id == run_id)
        .group_by(DiscretisationResult.variant, DiscretisationResult.friction_scale)
        .order_by(DiscretisationResult.variant)
    )
    return [VariantSummary(v, f, int(n), int(c or 0), int(rj or 0)) for v, f, n, c, rj in rows]


def _discretisation_lines(store: Any) -> list[str]:
    """Markdown table of every stored discretisation experiment (empty when none)."""
    from twisted.store.models import Run

    with store.session() as session:
        runs = session.scalars(select(Run).where(Run.kind == "discretise").order_by(Run.id)).all()
        summaries = [(run, discretisation_summary(session, run.id)) for run in runs]
    if not summaries:
        return []
    lines = [
        "## Discretisation (paper section 5.1)",
        "",
        f"Share of re-simulated transitions whose resulting state differs from the stored one; the paper "
        f"reports {PAPER_DISCRETISATION_CHANGED:.0%} for rounded curves (2 -> 3 crossings, 600k).",
        "",
        "| run | transitions | from -> to cross | variant | friction | changed | share | rejected |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for run, variants in summaries:
        p = run.parameters or {}
        span = " -> ".join("any" if p.get(k) is None else str(p[k]) for k in ("from_cross", "to_cross"))
        for v in variants:
            lines.append(
                f"| {run.id} | {v.transitions} | {span} | {v.variant} | {v.friction_scale:g} | {v.changed} | "
                f"{v.share_changed:.1%} | {v.rejected} |"
            )
    return lines + [""]


def _int_type() -> Any:
    from sqlalchemy import Integer

    return Integer


def run_discretisation(
    store: Any,
    *,
    n: int,
    seed: int = 0,
    from_cross: int | None = 2,
    to_cross: int | None = 3,
    workers: int = 1,
    friction_scale: float | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> DiscretisationSummary:
    """Re-simulate ``n`` stored transitions (drawn with ``seed``) unrounded (control) and rounded.

    With ``friction_scale`` the unrounded curve is also re-simulated at that friction (the paper's
    friction check of section 5.3). A changed transition is one whose resulting state differs from
    the stored one; a curve the simulator now rejects counts as changed.
    """
    from twisted.sim import Curve, SimPool
    from twisted.store.queries import end_run, start_run

    if n < 1:
        raise EvalInputError(f"--n must be at least 1, got {n}")
    q = select(Transition.id)
    if from_cross is not None:
        q = q.where(Transition.from_cross == from_cross)
    if to_cross is not None:
        q = q.where(Transition.to_cross == to_cross)
    with store.session() as session:
        ids = list(session.scalars(q.order_by(Transition.id)))
    if not ids:
        raise EvalInputError(
            f"no stored transitions from {from_cross} to {to_cross} crossings: collect data first "
            "or choose other --from-cross/--to-cross"
        )
    rng = np.random.default_rng(seed)
    chosen = sorted(int(i) for i in rng.choice(ids, size=min(n, len(ids)), replace=False))
    with store.session() as session:
        rows = session.execute(
            select(Transition, Configuration.q, TopologicalState.key)
            .join(Configuration, Configuration.id == Transition.from_configuration_id)
            .join(TopologicalState, TopologicalState.id == Transition.to_state_id)
            .where(Transition.id.in_(chosen))
            .order_by(Transition.id)
        ).all()
    from twisted.store.models import blob_to_array

    items = [
        (t.id, blob_to_array(q_blob), Curve(t.link, t.z_max_m, t.x_m, t.y_m), key) for t, q_blob, key in rows
    ]
    parameters = {
        "n": n,
        "seed": seed,
        "from_cross": from_cross,
        "to_cross": to_cross,
        "workers": workers,
        "friction_scale": friction_scale,
        "step_z_m": DISCRETE_STEP_Z_M,
        "step_xy_m": DISCRETE_STEP_XY_M,
    }
    with store.session(write=True) as session:
        run_id = start_run(session, "discretise", parameters, seed=seed).id
    variants: list[tuple[str, float, Callable[[Any], Any]]] = [
        ("control", 1.0, lambda c: c),
        ("rounded", 1.0, round_curve),
    ]
    if friction_scale is not None:
        variants.append(("friction", float(friction_scale), lambda c: c))
    total = len(items) * len(variants)
    done = 0
    t0 = time.perf_counter()
    status = "failed"
    try:
        for variant, friction, transform in variants:
            with SimPool(workers, friction) as pool:
                jobs = [(q, transform(curve)) for _, q, curve, _ in items]
                chunk = 32
                for start in range(0, len(jobs), chunk):
                    results = pool.run(jobs[start : start + chunk])
                    with store.session(write=True) as session:
                        for (tid, _, _, recorded), (_, curve), res in zip(
                            items[start : start + chunk], jobs[start : start + chunk], results, strict=True
                        ):
                            result_key = res.p_data.key if res.ok and res.p_data is not None else None
                            session.add(
                                DiscretisationResult(
                                    run_id=run_id,
                                    transition_id=tid,
                                    variant=variant,
                                    friction_scale=friction,
                                    link=curve.link,
                                    z_max_m=curve.z_max_m,
                                    x_m=curve.x_m,
                                    y_m=curve.y_m,
                                    recorded_key=recorded,
                                    result_key=result_key,
                                    ok=res.ok,
                                    changed=result_key != recorded,
                                    reason=res.reason,
                                )
                            )
                    done += len(results)
                    if progress is not None:
                        progress(done, total)
        status = "finished"
    except KeyboardInterrupt:
        status = "interrupted"
        raise
    finally:
        with store.session(write=True) as session:
            end_run(session, run_id, status, wall_seconds=time.perf_counter() - t0)
    with store.session() as session:
        summary = discretisation_summary(session, run_id)
    return DiscretisationSummary(run_id, n, len(ids), summary)
