"""Label policy: what the results of an evaluation are stored under (``eval_results.planner``), and
that results under one label were made with the same planner options.

Finished results count as done for every later evaluation under the same label, so an evaluation
with another model or K must not be added under it. The options compared are the model and those an
evaluation sets (the planner options declared for ``twisted eval``, :mod:`twisted.planner.options`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from sqlalchemy import select

from twisted.experiments.problems import EvalInputError
from twisted.store.experiments import EvalResult, EvalRun, ProblemSetRecord

__all__ = ["check_label_options", "default_label", "result_options"]


def result_options() -> tuple[str, ...]:
    """The options that change what a result is: the planner kind, the model and the planner options an
    evaluation sets."""
    from twisted.planner.options import result_options as planner_options

    return ("planner", "model_id", *(name for name in planner_options() if name != "planner"))


def default_label(planner: str, options: Mapping[str, Any]) -> str:
    """The planner kind, plus ``-<heuristic>`` when the options choose one."""
    return planner if options.get("heuristic") is None else f"{planner}-{options['heuristic']}"


def _shown(stored: Any) -> str:
    """A stored planner option; evaluations before the defaults were stored left them out."""
    return "unrecorded (the default of its day)" if stored is None else str(stored)


def check_label_options(
    session: Any, record: ProblemSetRecord, label: str, options: Mapping[str, Any]
) -> None:
    """Refuse (EvalInputError) to add results under ``label`` that were made with other planner options.

    An option missing from a stored evaluation was the default of its day (unknown), except one added
    after evaluations stored every option's value: that one ran with the value runs had before it
    existed. An evaluation made with an option since removed differs from every new one.
    """
    from twisted.planner.options import removed_in, specs

    here = (EvalResult.set_id == record.id) & (EvalResult.planner == label)
    runs = select(EvalResult.eval_run_id).where(here)
    q = select(EvalRun.parameters).where(EvalRun.id.in_(runs))  # no DISTINCT: PostgreSQL's json has no "="
    compared = result_options()
    ours = {key: options.get(key) for key in compared}
    added = {spec.name: spec.before for spec in specs() if spec.before_in_evals}
    for (parameters,) in session.execute(q):
        theirs = {key: (parameters or {}).get(key, added.get(key)) for key in compared}
        differ = [
            f"{key} {_shown(theirs[key])} (now {ours[key]})" for key in compared if theirs[key] != ours[key]
        ]
        differ += removed_in(parameters or {})
        if differ:
            raise EvalInputError(
                f"--label {label}: the results on set {record.name!r} under this label were made with "
                f"{', '.join(differ)}; give another --label"
            )
