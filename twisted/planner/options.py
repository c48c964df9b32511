"""The planner's options, each declared once: name, type, default, bounds, help, the commands that take it,
and the value a run stored before the option existed ran with.

:class:`PlannerOptions` is the one declaration (a field per option, its :func:`option` metadata). From it
come the checks (:meth:`PlannerOptions.validate`), the stored form (``to_dict``/``from_dict``),
:data:`OPTIONS_BEFORE`, the command-line options of ``twisted plan`` and ``twisted eval``
(:func:`specs`, read by ``cli/options.py``) and the options an evaluation's results must agree on
(:func:`result_options`). Options that were removed are listed in :data:`REMOVED_OPTIONS` with the
value that behaves like the planner without them: a stored run or evaluation that used another value
is refused, not silently continued with other behaviour.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from twisted.rope import N_LINKS  # the rope's link count, without loading MuJoCo
from twisted.store.boundary import shown as quoted  # one quoting of a given or stored value

__all__ = [
    "HEURISTICS",
    "N_LINKS",
    "OPTIONS_BEFORE",
    "PLANNERS",
    "REMOVED_OPTIONS",
    "OptionSpec",
    "PlannerOptions",
    "removed_in",
    "result_options",
    "specs",
]

PLANNERS = ("twisted", "random-low", "low-level-only", "sac")
HEURISTICS = ("rnd", "crs", "ucb")
MAX_SEED = 2**63 - 1
EVALUATED = ("plan", "eval")  # the options an evaluation sets (and its results must agree on)


@dataclass(frozen=True)
class OptionSpec:
    """One planner option as declared (see :func:`option`); ``name`` and ``type`` come from the field."""

    name: str
    type: type
    default: Any
    help: str
    bounds: tuple[float, float] = (0.0, 1.0)  # numbers only: the least and the most value
    low_open: bool = False  # the bounds are (low, high] instead of [low, high]
    must: str = ""  # what a value must be, in words (default: the bounds)
    choices: tuple[str, ...] = ()
    commands: tuple[str, ...] = ()  # the commands that take it as --NAME ("plan", "eval", "sensitivity")
    # what a run stored before the option existed ran with (None: every stored run has it)
    before: Any = None
    # evaluations stored before it existed (they stored every other option's value) ran with ``before``
    before_in_evals: bool = False

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    def check(self, value: Any) -> str | None:
        """Why ``value`` is not allowed, in words; None when it is. The type is checked too: a value read
        back from the store (a run's parameters) passes this same check as one from the command line.
        None is allowed where it is the default."""
        if value is None and self.default is None:
            return None
        if self.choices:
            listed = ", ".join(self.choices)
            allowed = isinstance(value, str) and value in self.choices
            return None if allowed else f"must be one of {listed}, got {quoted(value)}"
        if self.type is bool:
            return None if isinstance(value, bool) else f"must be true or false, got {quoted(value)}"
        wanted = numbers.Integral if self.type is int else numbers.Real
        if isinstance(value, bool) or not isinstance(value, wanted):
            return f"must be {'an integer' if self.type is int else 'a number'}, got {quoted(value)}"
        low, high = self.bounds
        number = int(value) if isinstance(value, numbers.Integral) else float(value)  # an int of any size
        nan = isinstance(number, float) and math.isnan(number)
        if nan or not ((low < number if self.low_open else low <= number) and number <= high):
            shown = "2**63-1" if high == MAX_SEED else f"{high:g}"
            must = self.must or f"lie in {'(' if self.low_open else '['}{low:g}, {shown}]"
            return f"must {must}, got {quoted(value)}"
        return None


def option(default: Any, help: str, **spec: Any) -> Any:
    """A field of :class:`PlannerOptions`: its default and the rest of its :class:`OptionSpec`."""
    return dataclasses.field(default=default, metadata={"help": help, **spec})


@dataclass(frozen=True)
class PlannerOptions:
    """Algorithm options; the defaults are the paper's values except ``k``, ``p_expand``,
    ``k_expand``, ``retry_weight``, ``cross_move``, ``r1_room`` and ``cinch``, which measured searches set
    (DESIGN 8)."""

    planner: str = option(
        "twisted",
        "twisted (inverse model) | sac (SAC+HER policy) | random-low (random curves, same plans) | "
        "low-level-only (random curves from random nodes).",
        choices=PLANNERS,
        commands=EVALUATED + ("sensitivity",),
    )
    heuristic: str = option(
        "crs", "State choice: rnd | crs | ucb.", choices=HEURISTICS, commands=EVALUATED + ("sensitivity",)
    )
    seed: int = option(0, "Seed of the search.", bounds=(0, MAX_SEED), commands=("plan",))
    k: int = option(
        3, "Curves sampled per plan step (K; the paper's 6).", bounds=(1, 1000), commands=EVALUATED
    )
    p_expand: float = option(
        0.01, "RandomExpand probability after a failed iteration (p; the paper's 0.05).", commands=EVALUATED
    )
    k_expand: int = option(
        25, "Random curves per RandomExpand (k; the paper's 100).", bounds=(1, 100_000), commands=EVALUATED
    )
    plan_limit: int = option(
        100, "High-level plans kept per reached state.", bounds=(1, 100_000), commands=("plan",)
    )
    ucb_c: float = option(
        0.7, "Exploration weight of the ucb heuristic (rewards lie in [0, 1]).", bounds=(0, 1e6)
    )
    retry_weight: float = option(
        0.1,
        "Node choice: weight retry_weight**n for a node already asked n times for the plan's next state "
        "(1: the paper's uniform choice).",
        low_open=True,
        commands=EVALUATED,
        before=1.0,
    )
    cross_move: float = option(
        0.67,
        "Share of the K curves of a plan step toward a Cross move that are scripted (the tip, or the "
        "crossed strand, carried across; planner twisted) instead of drawn from the model (0: all from "
        "the model).",
        must="be a share of the K curves in [0, 1]",
        commands=EVALUATED,
        before=0.0,
        before_in_evals=True,
    )
    r1_room: float = option(
        8.0,
        "Room for R1 curls: a node whose segment for the curl is shorter than this many links gets "
        "weight (length / r1_room)^2, and a plan that starts with a curl, and its state, the weight of "
        "the best node for it (0: off).",
        bounds=(0, N_LINKS),
        must=f"be a number of links in [0, {N_LINKS}]",
        commands=EVALUATED,
        before=0.0,
        before_in_evals=True,
    )
    cinch: bool = option(
        True,
        "Toward a granny or a square: a rope that ties an overhand is pulled tight and let go once before "
        "a step starts from it, and the steps start from such tight ropes, and from ropes made from them, "
        "where a state has any (--no-cinch: never).",
        commands=EVALUATED,
        before=False,
        before_in_evals=True,
    )
    same_state: bool = option(
        True,
        "Keep curves whose rope stays in its parent's state (the model moving the rope to where its next "
        "curve works); --no-same-state: only curves that change the state enter the tree (a cinch always "
        "does), so every plan's curve is a move.",
        commands=EVALUATED,
        before=True,
        before_in_evals=True,
    )
    tighten: bool = option(
        False,
        "Success means: reached a goal state AND the rope pulled tight (both ends held, lifted a little, "
        "pulled apart) ties the goal's knot; a reached state that fails the pull test does not end the "
        "search. Each pull test is stored with the run.",
        commands=EVALUATED,
        before=False,
        before_in_evals=True,
    )

    def validate(self) -> None:
        """Raise ValueError naming the option that is out of range."""
        for spec in specs():
            problem = spec.check(getattr(self, spec.name))
            if problem is not None:
                raise ValueError(f"{spec.name} {problem}")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PlannerOptions:
        """The options a run stored; one missing ran with its :data:`OPTIONS_BEFORE` value. Raises
        ValueError when the run used an option that was removed (:func:`removed_in`)."""
        removed = removed_in(data)
        if removed:
            raise ValueError(f"it was searched with {'; '.join(removed)}")
        known = {k: v for k, v in data.items() if k in cls.__dataclass_fields__}
        return cls(**{**OPTIONS_BEFORE, **known})


def specs() -> tuple[OptionSpec, ...]:
    """The declaration of every option, in field order."""
    return _SPECS


_SPECS = tuple(
    OptionSpec(name=f.name, type=type(f.default), default=f.default, **f.metadata)
    for f in dataclasses.fields(PlannerOptions)
)
# what a run stored before an option existed ran with (PlannerOptions.from_dict)
OPTIONS_BEFORE = {spec.name: spec.before for spec in _SPECS if spec.before is not None}

# options that were removed: the value with which a run behaved as the planner now does, and why it went
# (the measurement is in docs/DESIGN.md section 8 and the experiment log)
REMOVED_OPTIONS: dict[str, tuple[Any, str]] = {
    "state_prior": (
        0.0,
        "--state-prior was removed (17 % more calls per solved goal on the sets it was not tuned on)",
    ),
    "feasibility": (
        0.0,
        "--feasibility was removed (a learned feasibility of plan steps solved 2 of 10 final-u5 goals "
        "against 3 without)",
    ),
    "penultimate_curves": (
        0,
        "--penultimate-curves was removed (6 more curves for a step that reached the state before a plan's "
        "last solved 3 of 10 tune-u5 goals, as without)",
    ),
}


def removed_in(stored: Mapping[str, Any]) -> list[str]:
    """The removed options ``stored`` (a run's or an evaluation's parameters) used with a value that
    behaves otherwise than the planner now does, in words."""
    return [
        f"{name} {stored[name]} ({why})"
        for name, (neutral, why) in REMOVED_OPTIONS.items()
        if stored.get(name) not in (None, neutral)
    ]


def result_options() -> tuple[str, ...]:
    """The planner options an evaluation sets (``twisted eval``); results stored under one label must
    agree on them (with the model, see :mod:`twisted.experiments.labels`)."""
    return tuple(spec.name for spec in _SPECS if "eval" in spec.commands)
