"""The report: success-vs-time curves and a Markdown table from the stored eval results.

:func:`write_report` draws, for every set, the fraction of (goal, seed) attempts solved within t (one
line per planner/friction/timeout, like the paper's Figures 7-10), beside the same against simulator
calls; the friction plots of :mod:`twisted.experiments.sensitivity` where a planner was evaluated at
several scales; and ``report.md`` with a table per set, one per goal, and the discretisation
experiments (:mod:`twisted.experiments.discretise`).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from sqlalchemy import select

from twisted.experiments.discretise import discretisation_lines
from twisted.experiments.robustness import plot_robustness, robustness_markdown, robustness_table
from twisted.experiments.sensitivity import friction_label, friction_plots
from twisted.store.experiments import FINISHED_STATUSES, EvalResult, Problem, ProblemSet

__all__ = ["ReportFiles", "ResultRow", "load_results", "success_curve", "write_report"]


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


def success_until(
    times_s: Sequence[float | None], grid_s: npt.ArrayLike, timeout_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`success_curve` on the times of ``grid_s`` before ``timeout_s`` and at ``timeout_s`` itself
    (times, fractions): a run says nothing past its timeout, so a series of shorter runs stops there."""
    grid = np.asarray(grid_s, dtype=np.float64)
    times = np.append(grid[grid < timeout_s], timeout_s)
    return times, success_curve(times_s, times)


def _series_label(planner: str, friction: float, timeout_s: float, many_timeouts: bool) -> str:
    label = planner
    if not math.isclose(friction, 1.0):
        label += f", friction {friction * 100:.0f}%"
    if many_timeouts:
        label += f", {timeout_s:g} s"
    return label


def _plot_curves(
    groups: Mapping[tuple[str, float, float], Sequence[ResultRow]],
    title: str,
    path: Path,
    label: Callable[..., str],
) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from twisted.render.draw import save_png

    fig, (ax, ax_calls) = plt.subplots(1, 2, figsize=(12.0, 4.2))
    t_max = max(k[2] for k in groups)
    grid = np.linspace(0.0, t_max, 400)
    calls_max = max((r.sim_calls or 0) for rows in groups.values() for r in rows) or 1
    calls_grid = np.linspace(0.0, calls_max, 400)
    for key in sorted(groups):
        rows = groups[key]
        times, y = success_until([r.time_to_solve_s if r.solved else None for r in rows], grid, key[2])
        n = len(rows)
        (line,) = ax.step(times, y, where="post", label=f"{label(*key)} ({sum(r.solved for r in rows)}/{n})")
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
    ax.set_xlabel("time (s) (curve stops at its runs' timeout)")
    ax_calls.set_xlim(0, calls_max)
    ax_calls.set_xlabel("simulator calls (curve stops where a run timed out)")
    for a in (ax, ax_calls):
        a.set_ylim(-0.02, 1.02)
        a.set_ylabel("fraction solved")
        a.grid(alpha=0.3)
    ax.set_title(title)
    ax_calls.set_title("the same, against simulator calls")
    ax.legend(fontsize=8, loc="upper left")
    return save_png(fig, path)  # names the rope in a corner, as every picture does


def _safe(name: str) -> str:
    """``name`` as a file name part: letters, digits, - _ . kept; a name that needed changing gets a
    short hash of itself, so that names that differ (``a/b``, ``a_b``) never share a file."""
    import hashlib

    kept = "".join(c if (c.isascii() and c.isalnum()) or c in "-_." else "_" for c in name)
    if kept == name and not name.startswith("."):
        return name
    return f"{kept.lstrip('.') or 'x'}-{hashlib.sha256(name.encode()).hexdigest()[:8]}"


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
        for plot in friction_plots(set_name, groups):
            sensitivity.append(
                _plot_curves(
                    plot.series,
                    plot.title,
                    out / f"friction_{_safe(set_name)}_{_safe(plot.planner)}_{plot.timeout_s:g}s.png",
                    friction_label,
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
    lines += discretisation_lines(store)
    robustness = robustness_table(store)
    if robustness:  # episodes in worlds apart from the model (docs/DESIGN.md section 15.7)
        lines += ["## Robustness: episodes in perturbed worlds", "", *robustness_markdown(robustness), ""]
        sensitivity.append(plot_robustness(robustness, out / "robustness.png"))
    lines += ["## Plots", ""] + [f"![{p.stem}]({p.name})" for p in plots + sensitivity]
    md = out / "report.md"
    md.write_text("\n".join(lines) + "\n")
    return ReportFiles(md, plots, sensitivity)
