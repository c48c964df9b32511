"""Experiments a researcher can rerun (paper section 5): problem sets, eval runs, report, sensitivity,
discretisation.

- :mod:`~twisted.experiments.problems`: goal sets, drawn from our data by visit frequency (easy,
  medium, hard, unseen-3, 4, 5) or imported from a goal file / a list of knots; ``EvalInputError``.
- :mod:`~twisted.experiments.runner`: eval runs (``run_eval(store, url, EvalOptions(...))``). Tasks, one
  (goal, seed) each, are claimed, run with a planner and stored (:mod:`~twisted.experiments.leases`:
  ``run_task``); the one scheduler (:mod:`~twisted.experiments.scheduler`: ``schedule``, ``run_on``)
  keeps them in flight on a backend: ``ProcessBackend`` (local processes) or
  ``twisted.distributed.RayBackend``; the types they share are :mod:`~twisted.experiments.tasks`.
- :mod:`~twisted.experiments.improve`: expert iteration (``twisted improve``), its searches on the same
  backends.
- :mod:`~twisted.experiments.report`: success-vs-time curves, plots and ``report.md``.
- :mod:`~twisted.experiments.sensitivity`: friction sensitivity (an eval per scale, one plot per
  planner).
- :mod:`~twisted.experiments.discretise`: the discretisation experiment (rounded curves re-simulated).

The names below are the entry points the commands use; the rest is imported from the modules.
"""

from twisted.experiments.discretise import run_discretisation
from twisted.experiments.problems import (
    EvalInputError,
    import_problem_sets,
    make_problem_sets_in_store,
    parse_goal_file,
    save_goal_sets,
)
from twisted.experiments.report import write_report
from twisted.experiments.runner import EvalOptions, run_eval

__all__ = [
    "EvalInputError",
    "EvalOptions",
    "import_problem_sets",
    "make_problem_sets_in_store",
    "parse_goal_file",
    "run_discretisation",
    "run_eval",
    "save_goal_sets",
    "write_report",
]
