"""Robustness: knots tied in worlds drawn at each perturbation level, open against closed loop.

``run_robustness`` plans each knot once in the model from the straight rope (with the pull test; a solved
run of the same knot and options in the store is reused), then runs one episode per (level, world seed,
loop) (:func:`twisted.experiments.episodes.run_episode`), skipping those the store already holds finished,
so that running it again continues. ``robustness_table`` reads every finished episode back, grouped by
knot, level, loop and settings (:func:`settings_label`: the budget, and what a closed loop had switched
off; a store whose episodes ran with other settings shows them apart): episodes, tied, the success rate,
and per success the actions, replans, planning seconds and wall seconds. A finished episode is skipped
only when it ran with the settings asked for. ``plot_robustness`` draws the success rate against the
level (docs/DESIGN.md section 15.7); ``twisted report`` writes both when the store holds episodes.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import select

from twisted.goals import PlanInputError
from twisted.runtime import StopSignals

LEVEL_ORDER = ("none", "mild", "moderate", "strong")
FINISHED = ("tied", "not_tied", "unpulled", "out_of_budget", "lost")


def _composite(knot: str) -> bool:
    from twisted.knots import KnotNameError, resolve_knot

    try:
        return any("#" in t for t in resolve_knot(knot))
    except KnotNameError:  # a state goal's label: no summands
        return False


def settings_label(knot: str, closed_loop: bool, timeout_s: float, max_actions: int, parameters: Any) -> str:
    """How a group's episodes ran, as the table names it: the budget, plans searched with
    ``--no-same-state`` (DESIGN 8), and for a closed loop what differs from today's defaults (a drift other
    than the default; no pulls straight; a composite knot not tied in stages: DESIGN 15.4).
    ``parameters``: the episode run's stored parameters, as read back (an episode stored before an option
    existed ran without it)."""
    from twisted.experiments.episodes import DEFAULT_DRIFT_M

    parts = [f"{timeout_s:g} s", f"{max_actions} actions"]
    if isinstance(parameters, dict) and parameters.get("same_state") is False:
        parts.append("no same-state curves")  # the plan (and replans) searched with --no-same-state
    if closed_loop:
        stored = parameters if isinstance(parameters, dict) else {}
        drift = stored.get("drift_m")
        if isinstance(drift, float) and drift != DEFAULT_DRIFT_M:
            parts.append(f"drift {drift:g} m")
        if stored.get("straighten") is not True:
            parts.append("no pulls straight")
        if stored.get("stages") is not True and _composite(knot):
            parts.append("no stages")
    return ", ".join(parts)


@dataclass
class RobustnessRow:
    """One (knot, level, loop, settings) group of finished episodes."""

    knot: str
    level: str
    closed_loop: bool
    episodes: int
    tied: int
    actions_per_success: float | None
    replans_per_success: float | None
    planning_s_per_success: float | None
    wall_s_per_success: float | None
    median_replan_s: float | None = None  # planning time of one replan, median over every episode's replans
    # how the episodes that did not tie ended: outcome -> count (not_tied, unpulled, out_of_budget, lost)
    untied: dict[str, int] = field(default_factory=dict)
    settings: str = ""  # how they ran (settings_label)

    @property
    def success(self) -> float:
        return self.tied / self.episodes if self.episodes else 0.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "knot": self.knot,
            "level": self.level,
            "loop": "closed" if self.closed_loop else "open",
            "episodes": self.episodes,
            "tied": self.tied,
            "success": round(self.success, 3),
            "actions_per_success": self.actions_per_success,
            "replans_per_success": self.replans_per_success,
            "planning_s_per_success": self.planning_s_per_success,
            "wall_s_per_success": self.wall_s_per_success,
            "median_replan_s": self.median_replan_s,
            "untied": self.untied,
            "settings": self.settings,
        }


def _mean(values: Sequence[float]) -> float | None:
    return round(float(np.mean(values)), 3) if values else None


def _median(values: Sequence[float]) -> float | None:
    return round(float(np.median(values)), 3) if values else None


def _level_key(level: str) -> tuple[int, str]:
    return (LEVEL_ORDER.index(level) if level in LEVEL_ORDER else len(LEVEL_ORDER), level)


def robustness_table(store: Any) -> list[RobustnessRow]:
    """Every finished episode, grouped by (knot, level, loop, settings), in knot, level (none .. strong),
    loop and settings order."""
    from twisted.store.episodes import EpisodeRow, EpisodeStep

    with store.session() as session:
        rows = finished_episodes(session)
        replans = session.execute(
            select(EpisodeStep.episode_id, EpisodeStep.planning_s)
            .join(EpisodeRow, EpisodeStep.episode_id == EpisodeRow.run_id)
            .where(
                EpisodeRow.outcome.in_(FINISHED),
                EpisodeStep.kind == "replan",
                EpisodeStep.planning_s.is_not(None),
            )
        ).all()

    Key = tuple[str, str, bool, str]
    keys: dict[int, Key] = {}
    groups: dict[Key, list[Any]] = {}
    for r, label in rows:
        keys[r.run_id] = (r.goal_knot, r.level, bool(r.closed_loop), label)
        groups.setdefault(keys[r.run_id], []).append(r)
    replan_s: dict[Key, list[float]] = {}
    for r in replans:
        replan_s.setdefault(keys[r.episode_id], []).append(float(r.planning_s))
    table = []
    for k in sorted(groups, key=lambda k: (k[0], _level_key(k[1]), k[2], k[3])):
        group = groups[k]
        tied = [r for r in group if r.outcome == "tied"]
        table.append(
            RobustnessRow(
                k[0],
                k[1],
                k[2],
                len(group),
                len(tied),
                _mean([r.actions for r in tied]),
                _mean([r.replans for r in tied]),
                _mean([r.planning_s for r in tied]),
                _mean([r.elapsed_s for r in tied]),
                _median(replan_s.get(k, [])),
                {o: n for o in FINISHED if o != "tied" and (n := sum(r.outcome == o for r in group))},
                k[3],
            )
        )
    return table


def plot_robustness(table: Sequence[RobustnessRow], path: Path) -> Path:
    """Success rate against perturbation level, one line per knot, loop and settings."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from twisted.render.draw import save_png

    levels = sorted({r.level for r in table}, key=_level_key)
    fig, ax = plt.subplots(figsize=(7.0, 4.2))
    lines = sorted({(r.knot, r.closed_loop, r.settings) for r in table})
    several = {(knot, closed) for knot, closed, _ in lines if sum(k[:2] == (knot, closed) for k in lines) > 1}
    for knot, closed, settings in lines:
        rows = {r.level: r for r in table if (r.knot, r.closed_loop, r.settings) == (knot, closed, settings)}
        xs = [i for i, level in enumerate(levels) if level in rows]
        ys = [rows[levels[i]].success for i in xs]
        n = sum(r.episodes for r in rows.values())
        label = f"{knot}, {'closed' if closed else 'open'} loop ({n} episodes"
        label += f"; {settings})" if (knot, closed) in several else ")"
        ax.plot(xs, ys, marker="o", linestyle="-" if closed else "--", label=label)
    ax.set_xticks(range(len(levels)), levels)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("perturbation level (docs/DESIGN.md section 15.2)")
    ax.set_ylabel("fraction tied (pull test in the world)")
    ax.set_title("tying success against model mismatch")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save_png(fig, path)


def robustness_markdown(table: Sequence[RobustnessRow]) -> list[str]:
    """The table as Markdown lines (a section of report.md)."""

    def cell(x: float | None) -> str:
        return "-" if x is None else f"{x:g}"

    lines = [
        "| knot | level | loop | settings | episodes | tied | success | actions / success "
        "| replans / success | planning s / success | wall s / success | median s / replan "
        "| not tied: how they ended |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in table:
        lines.append(
            f"| {r.knot} | {r.level} | {'closed' if r.closed_loop else 'open'} | {r.settings} | {r.episodes} "
            f"| {r.tied} "
            f"| {r.success:.2f} | {cell(r.actions_per_success)} | {cell(r.replans_per_success)} "
            f"| {cell(r.planning_s_per_success)} | {cell(r.wall_s_per_success)} | {cell(r.median_replan_s)} "
            f"| {', '.join(f'{o} {n}' for o, n in r.untied.items()) or '-'} |"
        )
    return lines


def model_plan(
    store: Any,
    knot: str,
    seed: int,
    timeout_s: float,
    workers: int,
    stop: StopSignals,
    same_state: bool = True,
) -> tuple[Any, Any, Any, float]:
    """The knot's plan in the model from the straight rope (with the pull test; ``same_state``: the option of
    that name, which the replans then search with too): a solved run of the same goal and options reused,
    else a new search. (plan, goal, options, planning seconds spent here)."""
    from twisted.experiments.episodes import ModelPlanner, plan_of_run
    from twisted.planner import planner_options
    from twisted.planner.both_ways import make_any_goal
    from twisted.store.models import Run
    from twisted.store.search_tree import SearchRunRow

    goal = make_any_goal(None, knot, None)
    options = planner_options({"tighten": True, "seed": seed, "same_state": same_state})
    with store.session() as session:
        candidates = session.execute(
            select(SearchRunRow.run_id, Run.parameters)
            .join(Run, Run.id == SearchRunRow.run_id)
            .where(
                SearchRunRow.goal_knot == goal.knot,
                SearchRunRow.outcome == "solved",
                SearchRunRow.start_configuration_id.is_(None),
            )
            .order_by(SearchRunRow.run_id)
        ).all()
    for run_id, parameters in candidates:
        if (
            same_options(parameters, options)
            and not parameters.get("episode")
            and not parameters.get("both_ways")
        ):
            return plan_of_run(store, run_id), goal, options, 0.0
    planner = ModelPlanner(store, goal, options, None, workers, None, stop)
    started = time.perf_counter()
    try:
        run_id, solved = planner.search(None, seed, timeout_s)
    finally:
        planner.close()
    if not solved:
        raise PlanInputError(f"the model found no plan for {knot} in {timeout_s:g} s (run {run_id})")
    return plan_of_run(store, run_id), goal, options, time.perf_counter() - started


def same_options(parameters: Any, wanted: Any) -> bool:
    """Whether a stored run's ``parameters`` (as read back) searched with the :class:`PlannerOptions`
    ``wanted``, read as a resume reads them (``PlannerOptions.from_dict``: an option the run stored no value
    for ran with its value from before it existed; a run searched with a removed option is no such run)."""
    from twisted.planner import PlannerOptions

    if not isinstance(parameters, dict):
        return False
    try:
        return bool(PlannerOptions.from_dict(parameters) == wanted)
    except (TypeError, ValueError):
        return False


def finished_episodes(session: Any, *where: Any) -> list[tuple[Any, str]]:
    """The finished episodes (those ``where`` keeps, every one without), each with its
    :func:`settings_label`: one query for the table and for what :func:`run_robustness` skips."""
    from twisted.store.episodes import EpisodeRow
    from twisted.store.models import Run

    rows = session.execute(
        select(
            EpisodeRow.run_id,
            EpisodeRow.goal_knot,
            EpisodeRow.level,
            EpisodeRow.world_seed,
            EpisodeRow.closed_loop,
            EpisodeRow.timeout_s,
            EpisodeRow.max_actions,
            EpisodeRow.outcome,
            EpisodeRow.actions,
            EpisodeRow.replans,
            EpisodeRow.planning_s,
            EpisodeRow.elapsed_s,
            Run.parameters,
        )
        .join(Run, Run.id == EpisodeRow.run_id)
        .where(EpisodeRow.outcome.in_(FINISHED), *where)
    ).all()
    return [
        (r, settings_label(r.goal_knot, bool(r.closed_loop), r.timeout_s, r.max_actions, r.parameters))
        for r in rows
    ]


def done_episodes(store: Any, plan_run_id: int) -> set[tuple[str, int, bool, str]]:
    """(level, world seed, closed loop, settings) of the finished episodes of a plan."""
    from twisted.store.episodes import EpisodeRow

    with store.session() as session:
        rows = finished_episodes(session, EpisodeRow.plan_run_id == plan_run_id)
    return {(r.level, int(r.world_seed), bool(r.closed_loop), label) for r, label in rows}


def _label(goal: Any, settings: Any, options: Any) -> str:
    """:func:`settings_label` of the episodes ``settings`` would run with planner ``options`` (their stored
    parameters)."""
    stored = {"drift_m": settings.drift_m, "straighten": settings.straighten, "stages": settings.stages}
    stored["same_state"] = options.same_state
    label = goal.knot_label or goal.spec
    return settings_label(label, settings.closed_loop, settings.timeout_s, settings.max_actions, stored)


def run_robustness(
    store: Any,
    knots: Sequence[str],
    levels: Sequence[Any],
    seeds: Sequence[int],
    loops: Sequence[bool],
    settings: Any,
    workers: int,
    stop: StopSignals,
    progress: Callable[[str], None],
    same_state: bool = True,
) -> list[Any]:
    """Every (knot, level, seed, loop) episode not yet finished in the store with ``settings`` (and planner
    option ``same_state``, :func:`model_plan`); the results of those run."""
    from dataclasses import replace

    from twisted.experiments.episodes import ModelPlanner, run_episode

    results: list[Any] = []
    for knot in knots:
        plan, goal, options, planning_s = model_plan(
            store, knot, 0, settings.timeout_s, workers, stop, same_state
        )
        progress(f"{knot}: plan run {plan.run_id} ({planning_s:.1f} s in the model)")
        done = done_episodes(store, plan.run_id)
        # one planner for the knot's episodes: the model and the simulator workers are loaded once
        planner = ModelPlanner(store, goal, options, None, workers, None, stop)
        try:
            for level in levels:
                for seed in seeds:
                    for closed in loops:
                        if stop():
                            return results
                        episode = replace(settings, closed_loop=closed)
                        if (level.name, seed, closed, _label(goal, episode, options)) in done:
                            continue
                        result = run_episode(store, plan, goal, planner, level, seed, episode)
                        loop = "closed" if closed else "open"
                        progress(
                            f"{knot} {level.name} seed {seed} {loop} loop: episode {result.run_id} "
                            f"{result.outcome}, {result.actions} actions, {result.replans} replans, "
                            f"{result.elapsed_s:.1f} s"
                        )
                        results.append(result)
        finally:
            planner.close()
    return results
