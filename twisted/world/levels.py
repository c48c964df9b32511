"""Perturbation levels: named, validated sets of ranges a world's physics and noise are drawn from.

A level (docs/DESIGN.md section 15.2) says how far the world's rope may be from the planner's model:
ranges of multipliers on the model's sliding friction, joint stiffness, joint damping and link mass,
a range of link radii in metres, and the noise of the actions (a grasp one link off with a
probability, Gaussian noise on the carry target and the lift height) and of the observations
(Gaussian noise on every link point). ``none`` is the model itself; ``mild`` is TWISTED's own
sensitivity test (friction x0.95-1.05); ``moderate`` and ``strong`` are ours.

A level is written as its name, optionally followed by overrides:
``moderate,friction=0.5:2,observation_noise_m=0.003`` (a range ``lo:hi`` or one value). Every value is
checked against :data:`BOUNDS`; a level that makes no sense is a :class:`LevelError`, which the CLI
turns into exit 2 before anything is opened.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

from twisted.sim.mjcf import LINK_HALF_LENGTH_M, LINK_RADIUS_M


class LevelError(ValueError):
    """A perturbation level that is unknown or makes no sense (the message says which value and why)."""


Range = tuple[float, float]


@dataclass(frozen=True)
class Level:
    """The ranges a world is drawn from. Multipliers apply to the planner's rope (``RopeParams()``)."""

    name: str
    friction: Range = (1.0, 1.0)  # x sliding (and torsional, rolling) friction
    stiffness: Range = (1.0, 1.0)  # x joint stiffness
    damping: Range = (1.0, 1.0)  # x joint damping
    mass: Range = (1.0, 1.0)  # x link mass (through the density)
    radius_m: Range = (LINK_RADIUS_M, LINK_RADIUS_M)  # link radius in metres
    grasp_off_by_one_p: float = 0.0  # probability that the gripper takes a neighbour of the asked link
    carry_noise_m: float = 0.0  # standard deviation of the carry target's x and y, metres
    lift_noise_m: float = 0.0  # standard deviation of the lift height, metres
    observation_noise_m: float = 0.0  # standard deviation of every observed coordinate, metres

    def to_dict(self) -> dict[str, Any]:
        """What an episode stores: the name and every range (JSON)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Level:
        """Inverse of :meth:`to_dict`, checked (a stored level is input like any other)."""
        if not isinstance(data, dict) or set(data) != {f.name for f in fields(cls)}:
            names = [f.name for f in fields(cls)]
            raise LevelError(f"a stored level has the fields {names}, got {data!r:.200}")
        values: dict[str, Any] = {}
        for f in fields(cls):
            v = data[f.name]
            if f.name == "name":
                values["name"] = str(v)
            elif f.name in _RANGES:
                if not (isinstance(v, list) and len(v) == 2):
                    raise LevelError(f"stored level: {f.name} must be a [low, high] pair, got {v!r:.80}")
                values[f.name] = (_number(f.name, v[0]), _number(f.name, v[1]))
            else:
                values[f.name] = _number(f.name, v)
        return check_level(cls(**values))


_RANGES = ("friction", "stiffness", "damping", "mass", "radius_m")

# What makes sense, each bound with its reason. Radius: under 5 mm the 0.04 m spaced capsules (cylinder
# half-length 0.015 m) leave gaps a strand can pass through; over 15 mm they overlap most of their
# neighbour. Noise: a gripper or a camera off by more than a few centimetres is not a robot to plan for.
BOUNDS: dict[str, tuple[float, float, str]] = {
    "friction": (0.05, 10.0, "a multiplier of the model's friction"),
    "stiffness": (0.05, 20.0, "a multiplier of the model's joint stiffness"),
    "damping": (0.05, 20.0, "a multiplier of the model's joint damping"),
    "mass": (0.1, 10.0, "a multiplier of the model's link mass"),
    "radius_m": (0.02 - LINK_HALF_LENGTH_M, 0.015, "a link radius in metres (capsules touch, never swallow)"),
    "grasp_off_by_one_p": (0.0, 0.5, "a probability"),
    "carry_noise_m": (0.0, 0.05, "a standard deviation in metres"),
    "lift_noise_m": (0.0, 0.02, "a standard deviation in metres"),
    "observation_noise_m": (0.0, 0.02, "a standard deviation in metres"),
}

LEVELS: dict[str, Level] = {
    "none": Level("none"),
    "mild": Level("mild", friction=(0.95, 1.05)),
    # A real rope and gripper against the model: friction of a cord on a table known to some tens of
    # percent, bending stiffness and damping to a factor of two, mass to a quarter, the thickness to a
    # millimetre; a gripper that lands half a centimetre off and takes the wrong link one time in twenty;
    # a camera that places a link point to 2 mm (docs/DESIGN.md section 15.2).
    "moderate": Level(
        "moderate",
        friction=(0.7, 1.4),
        stiffness=(0.5, 2.0),
        damping=(0.5, 2.0),
        mass=(0.8, 1.25),
        radius_m=(0.009, 0.011),
        grasp_off_by_one_p=0.05,
        carry_noise_m=0.005,
        lift_noise_m=0.003,
        observation_noise_m=0.002,
    ),
    "strong": Level(
        "strong",
        friction=(0.5, 2.0),
        stiffness=(0.25, 4.0),
        damping=(0.25, 4.0),
        mass=(0.6, 1.6),
        radius_m=(0.008, 0.012),
        grasp_off_by_one_p=0.15,
        carry_noise_m=0.015,
        lift_noise_m=0.008,
        observation_noise_m=0.005,
    ),
}


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise LevelError(f"{name}: a number is needed, got {value!r:.80}")
    v = float(value)
    if not math.isfinite(v):
        raise LevelError(f"{name}: a finite number is needed, got {value!r:.80}")
    return v


def check_level(level: Level) -> Level:
    """``level`` when every value lies within :data:`BOUNDS` and every range is ordered; else LevelError."""
    for name, (low, high, what) in BOUNDS.items():
        value = getattr(level, name)
        values: tuple[float, ...] = tuple(value) if name in _RANGES else (value,)
        for v in values:
            _number(name, v)
            if not low <= v <= high:
                raise LevelError(f"{name} = {v:g} makes no sense: {what} in [{low:g}, {high:g}]")
        if values != tuple(sorted(values)):
            raise LevelError(f"{name}: the range {values[0]:g}:{values[-1]:g} runs backwards (low:high)")
    return level


def parse_level(text: str) -> Level:
    """``NAME`` or ``NAME,key=value,...`` (``value``: ``lo:hi`` for a range, or one number) -> Level."""
    name, *overrides = [part.strip() for part in str(text).split(",")]
    if name not in LEVELS:
        raise LevelError(f"unknown perturbation level {name!r}: one of {', '.join(LEVELS)}")
    level = LEVELS[name]
    known = {f.name for f in fields(Level)} - {"name"}
    changes: dict[str, Any] = {}
    for item in overrides:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or key not in known:
            raise LevelError(f"{item!r}: an override is KEY=VALUE with KEY one of {', '.join(sorted(known))}")
        try:
            numbers = [float(v) for v in value.split(":")]
        except ValueError:
            raise LevelError(f"{key}: {value!r} is not a number (a range is written low:high)") from None
        if key in _RANGES:
            if len(numbers) not in (1, 2):
                raise LevelError(f"{key}: a range is low:high or one value, got {value!r}")
            changes[key] = (numbers[0], numbers[-1])
        else:
            if len(numbers) != 1:
                raise LevelError(f"{key}: one value is needed, got {value!r}")
            changes[key] = numbers[0]
    if changes:
        level = replace(level, name=text.strip(), **changes)
    return check_level(level)
