"""Planner goals: one P-data state, or every state that ties a named knot.

A goal is a set of topological states; a search succeeds when it reaches any member. ``--goal`` gives a
set of one; ``--knot overhand [--crossings N]`` gives the states of N crossings (default: the knot's
crossing number, where they are made from its KnotInfo diagram) that really tie that knot: both
closures, under and over the table, are it (:func:`twisted.knots.states_tying`; knotoids are never
goals).

Goals are written as one line of text, the *goal spec*, wherever a goal must be stored or passed on:
the P-data key for a state (``[[1,"O",2,"+"],[2,"U",1,"+"]]``) or ``knot:<name>@<crossings>`` for a knot
(``knot:overhand@3``). Problem sets, evaluation results and planner runs store that text.

What a person types (``--goal``, ``--knot``, ``--crossings``) becomes a goal through :func:`make_goal`,
which also checks that the inverse model can encode it (:data:`twisted.rope.MAX_CROSSINGS`) and raises
:class:`PlanInputError` saying which input is wrong.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from twisted.rope import MAX_CROSSINGS, ROPE, ROPE_ENV
from twisted.topology import PData

__all__ = [
    "Goal",
    "GoalError",
    "KNOT_PREFIX",
    "PlanInputError",
    "check_goal",
    "crossing_number",
    "goal_from_spec",
    "knot_goal",
    "make_goal",
    "state_goal",
]

KNOT_PREFIX = "knot:"
# A knot goal at its crossing number is made from the knot's diagrams; at more crossings its states are
# enumerated, which stops here (5 crossings already take ~25 s to enumerate).
MAX_KNOT_CROSSINGS = 5
_KNOT_SPEC = re.compile(r"^knot:(?P<name>[^@\s]+)@(?P<crossings>\d+)$")


class GoalError(ValueError):
    """A goal the planner cannot take (bad P-data, unknown knot, no state of that knot); says why."""


class PlanInputError(ValueError):
    """A goal, run id or start configuration the planner cannot take; the message says why.

    Defined here, below the planner, because goal parsing (:func:`make_goal`) raises it first;
    :mod:`twisted.planner` raises it for runs, models and start configurations and re-exports it.
    """


@dataclass(frozen=True)
class Goal:
    """A set of goal states (sorted by key); ``knot`` names the knot they tie for a knot goal."""

    states: tuple[PData, ...]
    knot: str | None = None
    crossings: int | None = None  # for a knot goal: the crossing count its states were taken from

    def __post_init__(self) -> None:
        if not self.states:
            raise GoalError("a goal needs at least one state")
        keys = [p.key for p in self.states]
        if len(set(keys)) != len(keys) or keys != sorted(keys):
            raise ValueError("goal states must be unique and sorted by key (use state_goal / knot_goal)")

    def __contains__(self, p_data: object) -> bool:
        return isinstance(p_data, PData) and p_data.key in self.keys

    @cached_property
    def keys(self) -> frozenset[str]:
        """The members' P-data keys (computed once: the planner tests every new node against them)."""
        return frozenset(p.key for p in self.states)

    @property
    def cross(self) -> int:
        """The most crossings of a member: no state with more can lead to the goal."""
        return max(p.cross for p in self.states)

    @property
    def representative(self) -> PData:
        """The first member by key: where one state must stand for the goal."""
        return self.states[0]

    @property
    def spec(self) -> str:
        """The goal as one line of text (see the module docstring); :func:`goal_from_spec` reads it back."""
        if self.knot is not None:
            return f"{KNOT_PREFIX}{self.knot}@{self.crossings}"
        return self.states[0].key

    @property
    def cache_key(self) -> str:
        """The plan cache's goal key: the P-data key for one state; for a set its spec and a digest of its
        member keys (so that a changed catalogue or enumeration never reads another set's plans)."""
        if len(self.states) == 1 and self.knot is None:
            return self.states[0].key
        digest = hashlib.sha1("\n".join(p.key for p in self.states).encode()).hexdigest()[:16]
        return f"{self.spec}#{len(self.states)}:{digest}"

    @cached_property
    def knot_types(self) -> frozenset[str]:
        """The knot types a rope reaching this goal must tie when pulled tight (the pull test).

        A knot goal: the types its name stands for. A state goal: the knot that state ties (both closures
        agree), or no type at all when the state is a knotoid (it names no knot).
        """
        from twisted.knots import KNOTOID, identify, resolve_knot

        if self.knot is not None:
            return resolve_knot(self.knot)
        name = identify(self.states[0]).name
        return frozenset() if name == KNOTOID else frozenset({name})

    @cached_property
    def summands(self) -> frozenset[str]:
        """The summands of the composite knot types a knot goal names (granny: 3_1+ and 3_1-); empty for
        a prime knot, and for a state goal (it asks for one diagram, not for a knot tied in parts)."""
        types = self.knot_types if self.knot is not None else frozenset()
        return frozenset(part for t in types if "#" in t for part in t.split("#"))

    @property
    def knot_label(self) -> str | None:
        """What a pull test of this goal must tie, as stored: the knot name, else the state's knot type."""
        return self.knot if self.knot is not None else ",".join(sorted(self.knot_types)) or None

    def tightened_ties(self, knot_name: str | None) -> bool:
        """True when a tightened rope of knot type ``knot_name`` ties what this goal names."""
        return knot_name is not None and knot_name in self.knot_types

    @property
    def label(self) -> str:
        """What a person reads: the knot name and its crossing count, or the P-data key."""
        if self.knot is not None:
            return f"{self.knot} ({len(self.states)} states of {self.crossings} crossings)"
        return self.states[0].key


def _sorted(states: Iterable[PData]) -> tuple[PData, ...]:
    return tuple(sorted({p.key: p for p in states}.values(), key=lambda p: p.key))


def state_goal(p_data: PData) -> Goal:
    """The goal of reaching one state."""
    return Goal(_sorted([p_data]))


def crossing_number(name: str) -> int:
    """The least crossings of a rope that ties knot ``name`` (3 for the overhand knot, 6 for granny)."""
    from twisted.knots import least_crossings

    return least_crossings(name)


def knot_goal(name: str, crossings: int | None = None) -> Goal:
    """Every state of ``crossings`` crossings that really ties ``name`` (both closures are the knot).

    The default is the knot's crossing number (3 for the overhand knot, 4 for the figure-eight, 6 for
    6_1, granny and square, 7 for 7_1 ... 7_7 and 3_1#4_1): no rope with fewer crossings ties it
    (``twisted knots list``). There the states are cut from the knot's KnotInfo diagram (composites:
    joined from their summands'), nothing enumerated; above it they are enumerated, up to
    :data:`MAX_KNOT_CROSSINGS` (:func:`twisted.knots.states_tying`).
    """
    from twisted.knots import KNOTOID, MAX_BUILT_CROSSINGS, KnotNameError, resolve_knot, states_tying

    if name.strip().lower() == KNOTOID:
        raise GoalError("a knotoid is not a knot: give a knot name (see `twisted knots list`)")
    try:
        resolve_knot(name)
    except KnotNameError as exc:
        raise GoalError(str(exc)) from None
    if crossings is not None and not 1 <= crossings <= MAX_BUILT_CROSSINGS:
        raise GoalError(f"--crossings must be 1 to {MAX_BUILT_CROSSINGS} for a knot goal, got {crossings}")
    if crossings is None:
        crossings = crossing_number(name)
        if crossings == 0:
            raise GoalError(f"{name!r} is the straight rope itself: give a knot with crossings")
    try:
        found = states_tying(name, crossings, max_crossings=MAX_KNOT_CROSSINGS)
    except ValueError as exc:
        raise GoalError(str(exc)) from None
    states = [p for p in found if p.cross > 0]
    if not states:
        raise GoalError(f"no rope state with {crossings} crossings ties the knot {name!r}")
    return Goal(_sorted(states), knot=name, crossings=crossings)


def goal_from_spec(spec: str | Sequence[Any] | PData | Goal) -> Goal:
    """A goal from its spec: ``Goal``, P-data (text, list or PData) or ``knot:<name>@<crossings>``.

    Where people write goals (goal files) a knot may also be given as ``<name>`` or ``<name>@<crossings>``
    (``overhand``, ``figure-eight@4``): any text that does not start with ``[``.
    """
    from twisted.moves import parse_state
    from twisted.topology import PDataError

    if isinstance(spec, Goal):
        return spec
    if isinstance(spec, str) and not spec.strip().startswith("["):
        text = spec.strip()
        written = text if text.startswith(KNOT_PREFIX) else KNOT_PREFIX + text
        match = _KNOT_SPEC.match(written) or _KNOT_SPEC.match(written + "@0")
        if match is None:
            shown = spec if len(spec) <= 80 else f"{spec[:80]}... ({len(spec):,} characters)"
            raise GoalError(
                f"goal {shown!r} is neither P-data nor a knot: write a knot as <name>, <name>@<crossings> "
                "or knot:<name>@<crossings>, e.g. overhand@3"
            )
        digits = match["crossings"]
        if len(digits) > 4:  # int() of 4,300 digits and more raises ValueError; no rope has 10,000 crossings
            from twisted.knots import MAX_BUILT_CROSSINGS

            shown = digits if len(digits) <= 20 else f"{digits[:12]}... ({len(digits):,} digits)"
            raise GoalError(f"{shown} crossings: a knot goal has 1 to {MAX_BUILT_CROSSINGS}")
        crossings = int(digits)
        return knot_goal(match["name"], crossings if crossings > 0 else None)
    try:
        return state_goal(parse_state(spec, "goal"))
    except PDataError as exc:
        raise GoalError(str(exc)) from None


def check_goal(goal: str | Sequence[Any] | PData, max_cross: int = MAX_CROSSINGS) -> PData:
    """Parse ``goal``; check that a rope can have it and the model can encode it (else PlanInputError)."""
    from twisted.moves import parse_state
    from twisted.topology import PDataError

    try:
        p_data = parse_state(goal, "goal")
    except PDataError as exc:
        raise PlanInputError(str(exc)) from None
    if p_data.cross > max_cross:
        raise PlanInputError(
            f"goal {p_data.key} has {p_data.cross} crossings; the inverse model encodes at most {max_cross}"
        )
    if p_data.cross == 0:
        raise PlanInputError("goal [] (no crossing) is the straight rope itself: give a state with crossings")
    return p_data


def make_goal(
    goal: str | Sequence[Any] | PData | None = None,
    knot: str | None = None,
    crossings: int | None = None,
    max_cross: int = MAX_CROSSINGS,
) -> Goal:
    """The goal of a search: one P-data state (``goal``, or a ``knot:<name>@<n>`` spec) or a knot by name.

    Exactly one of ``goal`` and ``knot`` is given; ``crossings`` picks the knot's states of that many
    crossings (default: the knot's crossing number, see :func:`knot_goal`). Raises
    :class:`PlanInputError` saying which input is wrong.
    """
    if (goal is None) == (knot is None):
        raise PlanInputError("give exactly one goal: --goal P-DATA or --knot NAME")
    if crossings is not None and knot is None:
        raise PlanInputError("--crossings goes with --knot (a P-data goal has its own crossing count)")
    try:
        if knot is not None:
            found = knot_goal(knot, crossings)
        elif isinstance(goal, str) and goal.strip().startswith(KNOT_PREFIX):
            found = goal_from_spec(goal)
        else:
            assert goal is not None
            return state_goal(check_goal(goal, max_cross))
    except GoalError as exc:
        raise PlanInputError(str(exc)) from None
    if found.cross > max_cross:
        raise PlanInputError(
            f"knot goal {found.spec} has {found.cross} crossings; the model encodes at most {max_cross}, "
            "the rope's crossing limit: a rope that names a higher one "
            f"({ROPE_ENV}={ROPE.n_links}c{found.cross}, docs/DESIGN.md section 2.6), with a model trained "
            "on it, can plan it"
        )
    return found
