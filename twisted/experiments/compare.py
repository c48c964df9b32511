"""Two evaluation labels compared run by run: the same goals, seeds, timeout and friction.

``twisted compare A B`` answers the question the evaluations of DESIGN 8 ask (does A spend fewer
simulator calls than B?) from the stored results alone. Runs are paired by (set, goal, seed,
timeout, friction scale); a run that only one label has is counted but not compared. Per label:
runs, solved, the median time to solve, the calls to solve (the simulation that produced the goal
node, the planner's own count where the run kept no tree) and every call of every run, the whole
timeout of the unsolved runs included. Between the labels: the calls per goal on the runs both
solved, the median of the per-run ratios A / B there, how often A took fewer, and the ratio of all
calls per solved goal, the figure that charges a label for the runs it did not solve.

Both ratios come with a 95 % interval from a bootstrap over goals (:func:`ratio_intervals`): the
runs of one goal under different seeds share the goal's difficulty, so whole goals, with all their
paired runs, are drawn with replacement (``BOOTSTRAP_DRAWS`` times, from a generator seeded with
``BOOTSTRAP_SEED``, so the interval is the same at every call), and the interval is the 2.5th to
97.5th percentile of the ratio over the draws. With one goal there is no interval.
"""

from __future__ import annotations

import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import select

from twisted.experiments.problems import EvalInputError
from twisted.experiments.report import ResultRow, load_results
from twisted.store.experiments import ProblemSet

__all__ = [
    "BOOTSTRAP_DRAWS",
    "BOOTSTRAP_SEED",
    "Comparison",
    "LabelFigures",
    "compare_in_store",
    "compare_labels",
    "pair_runs",
    "ratio_intervals",
]

RunKey = tuple[str, str, int, float, float]  # set, goal, seed, timeout, friction scale
Interval = tuple[float, float]

BOOTSTRAP_DRAWS = 2000
BOOTSTRAP_SEED = 0


@dataclass(frozen=True)
class LabelFigures:
    """One label over the paired runs."""

    label: str
    runs: int
    solved: int
    median_time_s: float | None  # over the solved runs
    calls_to_solve: float | None  # mean over the solved runs
    all_calls: int  # every call of every paired run

    @property
    def all_calls_per_solved(self) -> float | None:
        return self.all_calls / self.solved if self.solved else None


@dataclass(frozen=True)
class Comparison:
    """Label ``a`` against label ``b`` on the runs both have (one set, or all of them: ``scope``)."""

    scope: str
    a: LabelFigures
    b: LabelFigures
    only_a: int  # runs of a without a partner in b
    only_b: int
    both_solved: int
    calls_both_a: float | None  # mean calls to solve over the runs both solved
    calls_both_b: float | None
    median_ratio: float | None  # median of a's / b's calls to solve, runs both solved
    a_fewer: int  # runs both solved where a took fewer calls
    # 95 % intervals of calls_both_ratio and all_calls_ratio, goals resampled (None: one goal, or no
    # draw where the ratio is defined)
    calls_both_interval: Interval | None = None
    all_calls_interval: Interval | None = None

    @property
    def calls_both_ratio(self) -> float | None:
        """a's calls per goal over b's on the runs both solved."""
        if self.calls_both_a is None or not self.calls_both_b:
            return None
        return self.calls_both_a / self.calls_both_b

    @property
    def all_calls_ratio(self) -> float | None:
        """a's all calls per solved goal over b's (below 1: a spends fewer)."""
        pa, pb = self.a.all_calls_per_solved, self.b.all_calls_per_solved
        return pa / pb if pa is not None and pb else None

    def to_dict(self) -> dict[str, object]:
        out: dict[str, object] = {
            "scope": self.scope,
            "only_a": self.only_a,
            "only_b": self.only_b,
            "both_solved": self.both_solved,
            "calls_both_a": self.calls_both_a,
            "calls_both_b": self.calls_both_b,
            "calls_both_ratio": self.calls_both_ratio,
            "median_ratio": self.median_ratio,
            "a_fewer": self.a_fewer,
            "all_calls_ratio": self.all_calls_ratio,
            "calls_both_interval": _listed(self.calls_both_interval),
            "all_calls_interval": _listed(self.all_calls_interval),
        }
        for side, f in (("a", self.a), ("b", self.b)):
            out[side] = {
                "label": f.label,
                "runs": f.runs,
                "solved": f.solved,
                "median_time_s": f.median_time_s,
                "calls_to_solve": f.calls_to_solve,
                "all_calls": f.all_calls,
                "all_calls_per_solved": f.all_calls_per_solved,
            }
        return out


def _listed(interval: Interval | None) -> list[float] | None:
    return None if interval is None else list(interval)


def _key(r: ResultRow) -> RunKey:
    return (r.set_name, r.goal_key, r.seed, r.timeout_s, r.friction_scale)


def _calls_to_solve(r: ResultRow) -> int:
    if r.sim_calls_to_solve is not None:
        return r.sim_calls_to_solve
    return r.sim_calls or 0


def pair_runs(
    rows: Iterable[ResultRow], a: str, b: str
) -> tuple[dict[RunKey, ResultRow], dict[RunKey, ResultRow]]:
    """The finished runs of ``a`` and of ``b``, by run key."""
    by_label: dict[str, dict[RunKey, ResultRow]] = {a: {}, b: {}}
    for r in rows:
        if r.planner in by_label:
            by_label[r.planner][_key(r)] = r
    return by_label[a], by_label[b]


def _figures(label: str, runs: Sequence[ResultRow]) -> LabelFigures:
    solved = [r for r in runs if r.solved]
    times = [r.time_to_solve_s for r in solved if r.time_to_solve_s is not None]
    return LabelFigures(
        label,
        len(runs),
        len(solved),
        statistics.median(times) if times else None,
        statistics.fmean(_calls_to_solve(r) for r in solved) if solved else None,
        sum(r.sim_calls or 0 for r in runs),
    )


def _interval(numerator: np.ndarray, denominator: np.ndarray) -> Interval | None:
    defined = denominator > 0
    if not defined.any():
        return None
    ratios = numerator[defined] / denominator[defined]
    low, high = np.percentile(ratios, [2.5, 97.5])
    return float(low), float(high)


def ratio_intervals(
    ra: dict[RunKey, ResultRow],
    rb: dict[RunKey, ResultRow],
    draws: int = BOOTSTRAP_DRAWS,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[Interval | None, Interval | None]:
    """95 % intervals of the calls-per-goal ratio on the runs both solved and of the all-calls ratio,
    over the runs both labels have, by a bootstrap over goals (see the module docstring)."""
    keys = sorted(set(ra) & set(rb))
    goals = sorted({(k[0], k[1]) for k in keys})
    if len(goals) < 2:
        return None, None
    index = {goal: i for i, goal in enumerate(goals)}
    # per goal: calls to solve of a and b on the runs both solved; all calls and solved runs of each
    sums = np.zeros((6, len(goals)))
    for k in keys:
        i, x, y = index[(k[0], k[1])], ra[k], rb[k]
        if x.solved and y.solved:
            sums[0, i] += _calls_to_solve(x)
            sums[1, i] += _calls_to_solve(y)
        sums[2, i] += x.sim_calls or 0
        sums[3, i] += x.solved
        sums[4, i] += y.sim_calls or 0
        sums[5, i] += y.solved
    rng = np.random.default_rng(seed)
    drawn = rng.integers(0, len(goals), size=(draws, len(goals)))
    weights = np.zeros((draws, len(goals)))
    np.add.at(weights, (np.arange(draws)[:, None], drawn), 1.0)
    both_a, both_b, all_a, solved_a, all_b, solved_b = (weights @ sums.T).T  # each (draws,)
    both = _interval(both_a, both_b)
    per_a = np.divide(all_a, solved_a, out=np.full(draws, np.nan), where=solved_a > 0)
    per_b = np.divide(all_b, solved_b, out=np.full(draws, np.nan), where=solved_b > 0)
    usable = np.isfinite(per_a) & np.isfinite(per_b)
    every = _interval(per_a[usable], per_b[usable])
    return both, every


def _compare(
    scope: str, ra: dict[RunKey, ResultRow], rb: dict[RunKey, ResultRow], a: str, b: str
) -> Comparison:
    keys = sorted(set(ra) & set(rb))
    both = [k for k in keys if ra[k].solved and rb[k].solved]
    ca = [_calls_to_solve(ra[k]) for k in both]
    cb = [_calls_to_solve(rb[k]) for k in both]
    ratios = [x / y for x, y in zip(ca, cb, strict=True) if y > 0]
    return Comparison(
        scope,
        _figures(a, [ra[k] for k in keys]),
        _figures(b, [rb[k] for k in keys]),
        len(set(ra) - set(rb)),
        len(set(rb) - set(ra)),
        len(both),
        statistics.fmean(ca) if ca else None,
        statistics.fmean(cb) if cb else None,
        statistics.median(ratios) if ratios else None,
        sum(x < y for x, y in zip(ca, cb, strict=True)),
        *ratio_intervals(ra, rb),
    )


def compare_labels(
    rows: Iterable[ResultRow], a: str, b: str, *, seeds: Iterable[int] | None = None
) -> list[Comparison]:
    """One comparison per set both labels ran on (in the order of ``rows``), then one over all runs
    (left out when there is one set and no run elsewhere).

    Raises :class:`EvalInputError` when a label has no finished run (among ``seeds``, if given) or
    the two share none.
    """
    if a == b:
        raise EvalInputError(f"compare needs two different labels, got {a!r} twice")
    wanted = None if seeds is None else set(seeds)
    rows = [r for r in rows if wanted is None or r.seed in wanted]
    ra, rb = pair_runs(rows, a, b)
    for label, runs in ((a, ra), (b, rb)):
        if not runs:
            labels = sorted({r.planner for r in rows})
            raise EvalInputError(
                f"label {label!r} has no finished results"
                + (" with these seeds" if wanted is not None else "")
                + f" (labels with results: {', '.join(labels) or 'none'})"
            )
    shared = set(ra) & set(rb)
    if not shared:
        raise EvalInputError(f"labels {a!r} and {b!r} share no run (set, goal, seed, timeout, friction)")
    sets = list(dict.fromkeys(k[0] for k in ra if k in shared))
    out = [
        _compare(
            name,
            {k: r for k, r in ra.items() if k[0] == name},
            {k: r for k, r in rb.items() if k[0] == name},
            a,
            b,
        )
        for name in sets
    ]
    if len(sets) > 1 or any(k[0] not in sets for k in (*ra, *rb)):
        out.append(_compare("all", ra, rb, a, b))  # also where runs of other sets went unpaired
    return out


def compare_in_store(
    store: Any,
    a: str,
    b: str,
    *,
    sets: Sequence[str] | None = None,
    seeds: Iterable[int] | None = None,
) -> list[Comparison]:
    """:func:`compare_labels` on the stored results (of ``sets`` only, if given; each must exist)."""
    with store.session() as session:
        known = set(session.scalars(select(ProblemSet.name)))
        missing = [name for name in sets or () if name not in known]
        if missing:
            raise EvalInputError(f"--set {missing[0]}: no such problem set")
        rows = load_results(session, sets)
    return compare_labels(rows, a, b, seeds=seeds)
