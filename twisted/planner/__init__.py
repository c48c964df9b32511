"""The planner: TWISTED (Algorithm 1 of the paper), its baselines, and searches kept in the store.

- :mod:`twisted.planner.options`: ``PlannerOptions``, every option declared once (type, default, bounds,
  help, the commands that take it, the value runs had before it existed); ``PLANNERS``, ``HEURISTICS``.
- :mod:`twisted.planner.tree`: the tree ``T`` (``Node``, ``SearchTree``).
- :mod:`twisted.planner.strategies`: the parts a search is built from: state, plan and node selection,
  curve proposers, goal tests, what enters the tree (adding moves or both ways) and the iteration
  itself (Algorithm 1 or the low-level-only baseline) (``Parts``, ``default_parts``).
- :mod:`twisted.planner.search`: Algorithm 1's loop. ``Twisted`` (the search), the protocols of what it
  composes (``Pool``, ``SearchRecorder``), its checkpoint and result. The stop signals it checks between
  steps are :class:`twisted.runtime.StopSignals`.
- :mod:`twisted.planner.session`: searches from the store. ``run_search`` (one call from a
  ``SearchRequest`` to a stored ``SearchResult``: what every caller uses); ``start_search``,
  ``resume_search``, ``replay``; ``choose_run`` (new run or resume, with the options of each);
  ``search_parts`` (the parts, with the pull test when asked for); ``curve_sampler`` (the inverse
  model or a SAC policy for a planner kind); ``high_level`` (plans through the plan cache).

Goals and their parsing (``make_goal``, ``check_goal``, ``PlanInputError``) live in :mod:`twisted.goals`;
the inverse model's sampler ``ModelCurves`` in :mod:`twisted.model.sampler`. See docs/DESIGN.md section 8.
"""

from twisted.goals import PlanInputError
from twisted.planner import search, session
from twisted.planner.search import *  # noqa: F403
from twisted.planner.session import *  # noqa: F403

__all__ = ["PlanInputError", *search.__all__, *session.__all__]
