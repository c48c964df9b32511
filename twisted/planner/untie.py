"""Untie and retie: searches from any stored rope to any goal, the straight rope ``[]`` included.

A search *both ways* is Algorithm 1 with three parts swapped (:func:`both_ways_parts`), all small:

- its high level plans with adding and removing moves (:func:`twisted.moves.plans_both_ways`, through
  the plan cache under a key of its own), so a state with more crossings than the goal, or with a
  crossing the goal lacks, has plans too;
- its growth is :class:`twisted.planner.strategies.BothWays`: a result enters ``T`` whenever it has no
  more crossings than the start or the goal, whichever has more (the paper's rule "Cross does not
  drop" would forbid every untying step);
- the curves of a removing step come from the proposer ``removal_curves`` names: ``model`` (the
  inverse model, conditioned on the removing move, which it encodes apart from the adding one; the
  shipped model has never seen one) or ``random`` (uniform random curves, the ``random-low``
  baseline's). Adding steps are served as in any search.

Where a search starts: the straight rope, a stored configuration (``--start-config``), or the end
configuration of a stored run (:func:`run_end`: the goal node of a solved run), which ``twisted untie``
and ``twisted plan --from-run`` use. What a both-ways run asked for is stored with its parameters
(:data:`PARAMETERS`), so a resumed run continues both ways with the same proposer.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from twisted.goals import Goal, PlanInputError, make_goal, state_goal
from twisted.moves import sub_states
from twisted.planner.options import MAX_SEED, OptionSpec
from twisted.planner.strategies import BothWays, RandomCurves
from twisted.topology import EMPTY, PData, parse_p_data

__all__ = [
    "PARAMETERS",
    "REMOVAL_CURVES",
    "RunEnd",
    "accepted_configuration",
    "both_ways_needed",
    "both_ways_parts",
    "check_start",
    "check_untie_run",
    "make_any_goal",
    "run_end",
]

# proposers of a removing step's curves (see the module docstring)
REMOVAL_CURVES = ("model", "random")
DEFAULT_REMOVAL_CURVES = "random"
# runs.parameters keys of a both-ways search (beside the planner options and the model id)
PARAMETERS = ("both_ways", "removal_curves", "from_run")
_ID = (0, MAX_SEED)
# what a run stores beside its planner options, declared as they are: --removal-curves is checked by
# this declaration on the command line (check_start) and in a stored run (stored_options)
REMOVAL_SPEC = OptionSpec(
    "removal_curves", str, DEFAULT_REMOVAL_CURVES, "Curves of a removing step.", choices=REMOVAL_CURVES
)
STORED = (
    REMOVAL_SPEC,
    OptionSpec("both_ways", bool, False, "The search also removes crossings."),
    OptionSpec("from_run", int, None, "The run whose end the search started from.", bounds=_ID),
    OptionSpec("model_id", int, None, "The inverse model or SAC policy sampled.", bounds=_ID),
    OptionSpec("start_configuration_id", int, None, "The stored start configuration.", bounds=_ID),
)


def both_ways_parts(parameters: Mapping[str, Any], goal: Goal, start: PData) -> dict[str, Any]:
    """The parts a run's parameters (``runs.parameters``) make a search both ways with, as keyword
    arguments of :func:`twisted.planner.strategies.default_parts` (``growth``, ``removal``): none for a
    search that adds crossings only (a run stored before removing moves existed is one). ``start``: the
    state of the tree's root. Raises :class:`PlanInputError` on a proposer that does not exist."""
    if not parameters.get("both_ways"):
        return {}
    removal_curves = parameters.get("removal_curves", DEFAULT_REMOVAL_CURVES)
    problem = REMOVAL_SPEC.check(removal_curves)
    if problem is not None:
        raise PlanInputError(f"removal_curves {problem}")
    removal = RandomCurves() if removal_curves == "random" else None
    return {"growth": BothWays(goal, start), "removal": removal}


def both_ways_needed(start: PData, goal: Goal) -> bool:
    """Whether a search from ``start`` needs removing moves: the goal has no more crossings, or
    ``start`` has a crossing no goal state has (it is no sub-state of any), so adding moves alone
    never lead there."""
    if all(g.cross <= start.cross for g in goal.states):
        return True
    return not any(start in sub_states(g) for g in goal.states if g.cross > start.cross)


def make_any_goal(
    goal: str | None, knot: str | None = None, crossings: int | None = None, *, other_start: bool = False
) -> Goal:
    """:func:`twisted.goals.make_goal`, and with ``other_start`` (a search that does not start from
    the straight rope) the straight rope ``[]`` as well: the goal of untying."""
    if (
        other_start
        and goal is not None
        and knot is None
        and crossings is None
        and goal.strip().startswith("[")
    ):
        try:
            parsed = parse_p_data(goal)
        except ValueError:
            parsed = None
        if parsed == EMPTY:
            return state_goal(EMPTY)
    return make_goal(goal, knot, crossings)


class RunEnd:
    """Where a stored run ended: its goal node's configuration (``q``, link points, state)."""

    def __init__(self, run_id: int, node_seq: int, q: np.ndarray, points: np.ndarray, p_data: PData) -> None:
        self.run_id = run_id
        self.node_seq = node_seq
        self.q = q
        self.points = points
        self.p_data = p_data


def run_end(store: Any, run_id: int) -> RunEnd:
    """The end configuration of stored planner run ``run_id``: the node that solved it.

    Raises :class:`PlanInputError` when there is no such run or it did not reach its goal.
    """
    from twisted.store.search import load_run, solution_path

    info = load_run(store, run_id, with_nodes=False)
    if info is None:
        raise PlanInputError(f"run {run_id} is not a planner run in this database (see `twisted runs`)")
    path = solution_path(store, run_id)
    if not path:
        raise PlanInputError(
            f"run {run_id} did not reach its goal (outcome: {info.outcome}): it has no end configuration "
            "to start from; give a solved run"
        )
    end = path[-1]
    q, points = np.asarray(end.q), np.asarray(end.points)
    accepted_configuration(q, points, "search_nodes", end.id)
    return RunEnd(run_id, end.seq, q, points, end.p_data)


def accepted_configuration(q: np.ndarray, points: np.ndarray, table: str, row: int) -> None:
    """A stored configuration a search may start from: finite arrays of the rope profile's sizes
    (:func:`twisted.store.boundary.check_configuration`), a state the simulator takes (its length, and
    in the workspace, on the table, without deep penetration: ``RopeSim.invalid_reason``) and whose
    link points are the stored ones. StoredValueError naming the field otherwise, before any run exists."""
    from twisted.rope import N_POINTS, ROPE
    from twisted.sim import RopeSim
    from twisted.store.boundary import StoredValueError, check_configuration

    check_configuration(q, points, N_POINTS, table, row)
    sim = RopeSim()
    if q.shape != (sim.state_size,):
        problem = f"holds {q.size} floats; a state of the rope in use ({ROPE.name}) has {sim.state_size}"
        raise StoredValueError(table, row, "q", problem)
    with np.errstate(all="ignore"):  # a stored 1e300 overflows: the reason says so, not a warning
        sim.set_state(q)
        reason = sim.invalid_reason()
    if reason is not None:
        raise StoredValueError(table, row, "q", f"the simulator refuses it: {reason}")
    off = float(np.max(np.abs(sim.link_points() - points)))
    if off > 1e-6:
        raise StoredValueError(table, row, "points", f"are not the link points of its q ({off:.3g} m off)")


def check_untie_run(store: Any, run_id: int) -> None:
    """``twisted untie --resume RUN_ID``: PlanInputError unless ``run_id`` is an untie run (a search from a
    run's end to the straight rope), so that a tying search is not continued under the untie command."""
    from twisted.store.search import load_run

    info = load_run(store, run_id, with_nodes=False)
    if info is None:
        raise PlanInputError(f"--resume {run_id}: there is no planner run {run_id} in this database")
    if info.parameters.get("from_run") is None or info.goal.states != (EMPTY,):
        start = info.parameters.get("from_run")
        started = "the straight rope or a configuration" if start is None else f"the end of run {start}"
        raise PlanInputError(
            f"--resume {run_id}: run {run_id} is not an untie run (it searches from {started} to "
            f"{info.goal.label}); continue it with `twisted plan --resume {run_id}`"
        )


def check_start(
    resume: bool, start_config: int | None, from_run: int | None, removal_curves: str | None
) -> None:
    """What can be checked of a search's start without the store (PlanInputError when it is wrong)."""
    if from_run is not None and start_config is not None:
        raise PlanInputError("give one start: --start-config ID or --from-run RUN_ID, not both")
    if from_run is not None and resume:
        raise PlanInputError("--from-run cannot change the start of a resumed run")
    if removal_curves is not None:
        problem = REMOVAL_SPEC.check(removal_curves)
        if problem is not None:
            raise PlanInputError(f"--removal-curves {problem}")
        if resume:
            raise PlanInputError("--removal-curves cannot change a resumed run (it keeps its own)")
