"""Friction sensitivity (paper section 5.3, Figure 8): one planner on one set at several friction scales.

``friction_scale`` is part of every result's key, so the experiment is one eval per scale
(``twisted sensitivity run``: :func:`check_scales`, then :func:`twisted.experiments.runner.run_eval`
for each; finished results of a scale are reused) and one more kind of plot: for every (set,
planner, timeout) with results at more than one scale, success against time with one line per scale
(:func:`friction_plots`, drawn by :func:`twisted.experiments.report.write_report`).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from twisted.experiments.problems import EvalInputError

__all__ = ["DEFAULT_SCALES", "FrictionPlot", "check_scales", "friction_label", "friction_plots"]

DEFAULT_SCALES = (0.95, 1.0, 1.05)  # the paper's 95 %, 100 %, 105 %
MIN_SCALE, MAX_SCALE = 0.01, 100.0

# (planner, friction scale, timeout) -> the results of that series
Series = Mapping[tuple[str, float, float], Sequence[Any]]


def check_scales(scales: Sequence[float] | None) -> list[float]:
    """The friction scales to evaluate (none given: :data:`DEFAULT_SCALES`); each must lie in 0.01 .. 100."""
    for scale in scales or []:
        if not MIN_SCALE <= scale <= MAX_SCALE:
            raise EvalInputError(f"--scales: {scale:g} is not a friction factor in 0.01 .. 100")
    return list(scales or DEFAULT_SCALES)


@dataclass(frozen=True)
class FrictionPlot:
    """One friction plot of a set: a planner and timeout with results at several scales."""

    set_name: str
    planner: str
    timeout_s: float
    series: Series  # one line per friction scale

    @property
    def title(self) -> str:
        return f"set {self.set_name}, {self.planner}: friction sensitivity"


def friction_label(planner: str, friction: float, timeout_s: float) -> str:
    """A line of a friction plot is named by its scale alone."""
    return f"friction {friction * 100:.0f}%"


def friction_plots(set_name: str, series: Series) -> list[FrictionPlot]:
    """The friction plots of one set's series: one per (planner, timeout) evaluated at several scales."""
    by_planner: dict[tuple[str, float], dict[tuple[str, float, float], Sequence[Any]]] = defaultdict(dict)
    for key, rows in series.items():
        by_planner[(key[0], key[2])][key] = rows
    return [
        FrictionPlot(set_name, planner, timeout_s, sub)
        for (planner, timeout_s), sub in sorted(by_planner.items())
        if len(sub) > 1
    ]
