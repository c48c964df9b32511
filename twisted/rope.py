"""The rope every layer agrees on: its links and length (:data:`ROPE`), and the crossing limit.

Written once here, at the bottom of the layers, so that the simulator, the planner (which must not
load MuJoCo to know the link count), the inverse model's encoding and the goal checks read the
same numbers instead of keeping copies.

- :class:`RopeProfile` is the chain of capsule links the simulator builds (``twisted.sim.mjcf``):
  ``n_links`` links, ``link_spacing_m`` from centre to centre; its ``n_points`` centreline points
  are the two tips and the joints between links. :data:`ROPE` is the one rope in use: 21 links
  0.04 m apart (the paper's) unless the environment variable ``TWISTED_ROPE`` names another
  (``"31"``: 31 links at 0.04 m; ``"31x0.03"``: 31 links at 0.03 m; :func:`parse_rope`). It is read
  once, when this module is imported: every constant below is bound from it and imported by value
  across the layers, so a process runs one rope from start to end. An invalid value does not stop
  the import: the default is kept and the reason is in :data:`ROPE_ENV_ERROR`, which the CLI (and
  :func:`check_rope_env`) turns into an error before anything is opened.
- :data:`MAX_CROSSINGS` is the most crossings a state may have anywhere in the pipeline, the rope's
  crossing limit (6 unless ``TWISTED_ROPE`` names another, ``"31c7"``): the
  inverse model encodes P-data of fixed size up to it (``twisted.model.encoding``), so collection
  keeps transitions up to it, a goal above it is refused and the RL environment fails a curve
  that goes past it.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

__all__ = [
    "DEFAULT_MAX_CROSSINGS",
    "DEFAULT_ROPE",
    "DEFAULT_SPACING_M",
    "LINK_SPACING_M",
    "MAX_CROSSINGS",
    "MAX_CROSSING_LIMIT",
    "MAX_LINKS",
    "MAX_ROPE_LENGTH_M",
    "MAX_SPACING_M",
    "MIN_CROSSING_LIMIT",
    "MIN_LINKS",
    "MIN_SPACING_M",
    "N_LINKS",
    "N_POINTS",
    "ROPE",
    "ROPE_ENV",
    "ROPE_ENV_ERROR",
    "ROPE_LENGTH_M",
    "RopeProfile",
    "check_rope_env",
    "parse_rope",
]

ROPE_ENV = "TWISTED_ROPE"

# The model encodes states of up to 6 crossings unless the rope names another limit (docs/DESIGN.md
# section 6.1: the reference truncated to 3).
DEFAULT_MAX_CROSSINGS = 6


@dataclass(frozen=True)
class RopeProfile:
    """A rope of ``n_links`` equal links, ``link_spacing_m`` apart (centre to centre)."""

    n_links: int
    link_spacing_m: float
    # the most crossings a state of this rope may have anywhere in the pipeline (MAX_CROSSINGS below):
    # the inverse model's input has room for this many, so a model is made for one limit as for one rope
    max_crossings: int = DEFAULT_MAX_CROSSINGS

    def __post_init__(self) -> None:
        if self.n_links < 2:
            raise ValueError(f"a rope has at least 2 links, got {self.n_links}")
        if not self.link_spacing_m > 0:
            raise ValueError(f"link spacing must be a positive length in metres, got {self.link_spacing_m}")
        if not 1 <= self.max_crossings <= 100:
            raise ValueError(f"a crossing limit is a count from 1 to 100, got {self.max_crossings}")

    @property
    def n_points(self) -> int:
        """Centreline points: the head tip, the joints between links, the tail tip."""
        return self.n_links + 1

    @property
    def length_m(self) -> float:
        """The rope's length (links times spacing)."""
        return self.n_links * self.link_spacing_m

    @property
    def name(self) -> str:
        """The profile in words, for messages and figures: ``"21 links x 0.04 m (0.84 m)"``."""
        name = f"{self.n_links} links x {self.link_spacing_m:g} m ({self.length_m:.2f} m)"
        if self.max_crossings != DEFAULT_MAX_CROSSINGS:
            name += f", states of up to {self.max_crossings} crossings"
        return name

    @property
    def env_value(self) -> str:
        """What ``TWISTED_ROPE`` holds to run this rope: ``"31"``, ``"31x0.03"`` at another spacing,
        ``"31c7"`` with another crossing limit."""
        value = str(self.n_links)
        if self.link_spacing_m != DEFAULT_SPACING_M:
            value += f"x{self.link_spacing_m:g}"
        if self.max_crossings != DEFAULT_MAX_CROSSINGS:
            value += f"c{self.max_crossings}"
        return value


DEFAULT_SPACING_M = 0.04
DEFAULT_ROPE = RopeProfile(n_links=21, link_spacing_m=DEFAULT_SPACING_M)  # the paper's rope

# The ropes TWISTED_ROPE may name. The capsules themselves are fixed (twisted.sim.mjcf: radius 0.01 m,
# a 0.03 m cylinder, 0.05 m from cap to cap); only their number and spacing change.
# - At least 11 links, and at least 2 x c - 1 for a crossing limit c: a goal may have c crossings (6
#   unless the rope names another), 2 x c visits along the rope; with fewer links than that, several
#   visits must share a link and such states can hardly be laid out.
# - A crossing limit of 3 to 8: fewer crossings tie no knot; the knot table (twisted.knots) goes to 7
#   crossings and its composites, and every crossing more widens the model's input and the states
#   collection must cover.
# - At most 0.05 m apart: beyond it a gap opens between neighbouring capsules through which another
#   strand (0.02 m thick) could slip, and the rope would no longer be a rope for the topology.
# - At least 0.025 m apart: closer, neighbours overlap by more than half a capsule and the joint
#   limits (110 degrees) no longer keep a link from folding onto its neighbour's body.
# - At most 1.4 m long (and so at most 56 links): the simulator rejects a rope that leaves the
#   1.2 m workspace radius (twisted.sim.simulator.WORKSPACE_RADIUS_M) and a curve moves a link up to
#   0.5 m: half the straight rope (0.7 m) plus 0.5 m is the workspace's edge.
MIN_LINKS = 11
MAX_LINKS = 56
MIN_SPACING_M = 0.025
MAX_SPACING_M = 0.05
MIN_CROSSING_LIMIT = 3
MAX_CROSSING_LIMIT = 8
MAX_ROPE_LENGTH_M = 1.4


def parse_rope(value: str) -> RopeProfile:
    """The rope a ``TWISTED_ROPE`` value names: ``"LINKS"`` (0.04 m apart) or ``"LINKSxSPACING"``
    (spacing in metres), each optionally followed by ``cCROSSINGS``, the crossing limit (6 unless
    given): e.g. ``"31"``, ``"31x0.03"`` or ``"31c7"``; an empty value is the default rope.

    Raises ValueError saying which value is wrong and why (not an integer, out of range, ...).
    """
    given = value
    value = value.strip()
    if not value:
        return DEFAULT_ROPE
    form = "give LINKS or LINKSxSPACING, optionally followed by cCROSSINGS, e.g. 31, 31x0.03 or 31c7"
    value = value.lower()
    head, c_sep, crossings_text = value.rpartition("c")
    max_crossings = DEFAULT_MAX_CROSSINGS
    # a limit after what reads as a rope (digits, an "x", a spacing), not a "c" inside a misspelt value
    if c_sep and head.strip()[:1].isdigit() and not any(ch.isalpha() and ch not in "xe" for ch in head):
        value = head
        try:
            max_crossings = int(crossings_text.strip())
        except ValueError:
            raise ValueError(
                f"{ROPE_ENV}={given!r}: the crossing limit {crossings_text.strip()!r} is not an integer "
                f"({form})"
            ) from None
        if not MIN_CROSSING_LIMIT <= max_crossings <= MAX_CROSSING_LIMIT:
            raise ValueError(
                f"{ROPE_ENV}={given!r}: a crossing limit of {max_crossings} is out of range (give "
                f"{MIN_CROSSING_LIMIT} to {MAX_CROSSING_LIMIT})"
            )
    links_text, sep, spacing_text = value.partition("x")
    try:
        n_links = int(links_text.strip())
    except ValueError:
        raise ValueError(
            f"{ROPE_ENV}={given!r}: the link count {links_text.strip()!r} is not an integer ({form})"
        ) from None
    spacing = DEFAULT_SPACING_M
    if sep:
        try:
            spacing = float(spacing_text.strip())
        except ValueError:
            raise ValueError(
                f"{ROPE_ENV}={given!r}: the spacing {spacing_text.strip()!r} is not a number of metres "
                f"({form})"
            ) from None
        if not (math.isfinite(spacing) and spacing > 0):
            raise ValueError(f"{ROPE_ENV}={given!r}: the spacing must be a positive length in metres")
    if not MIN_LINKS <= n_links <= MAX_LINKS:
        raise ValueError(
            f"{ROPE_ENV}={given!r}: {n_links} links is out of range (give {MIN_LINKS} to {MAX_LINKS} links)"
        )
    if not MIN_SPACING_M <= spacing <= MAX_SPACING_M:
        raise ValueError(
            f"{ROPE_ENV}={given!r}: links {spacing:g} m apart is out of range (give {MIN_SPACING_M} to "
            f"{MAX_SPACING_M} m: the capsules are fixed, 0.05 m from cap to cap)"
        )
    if n_links < 2 * max_crossings - 1:
        raise ValueError(
            f"{ROPE_ENV}={given!r}: {n_links} links cannot lay out {max_crossings} crossings "
            f"({2 * max_crossings} visits along the rope): give at least {2 * max_crossings - 1} links or a "
            "lower crossing limit"
        )
    rope = RopeProfile(n_links, spacing, max_crossings)
    if rope.length_m > MAX_ROPE_LENGTH_M + 1e-9:
        raise ValueError(
            f"{ROPE_ENV}={given!r}: a rope of {rope.name} is longer than {MAX_ROPE_LENGTH_M} m, the most the "
            "simulator's 1.2 m workspace holds: give fewer links or a shorter spacing"
        )
    return rope


def _rope_from_env() -> tuple[RopeProfile, str | None]:
    try:
        return parse_rope(os.environ.get(ROPE_ENV, "")), None
    except ValueError as exc:
        return DEFAULT_ROPE, str(exc)


ROPE, ROPE_ENV_ERROR = _rope_from_env()


def check_rope_env() -> None:
    """Raise ValueError (the reason) when ``TWISTED_ROPE`` holds a value that names no rope."""
    if ROPE_ENV_ERROR is not None:
        raise ValueError(ROPE_ENV_ERROR)


N_LINKS = ROPE.n_links
N_POINTS = ROPE.n_points
LINK_SPACING_M = ROPE.link_spacing_m
ROPE_LENGTH_M = ROPE.length_m  # 0.84 m by default

# The most crossings a state may have anywhere: the rope's limit (6 unless TWISTED_ROPE names another).
MAX_CROSSINGS = ROPE.max_crossings
