"""The rope every layer agrees on: its links and length (:data:`ROPE`), and the crossing limit.

Written once here, at the bottom of the layers, so that the simulator, the planner (which must not
load MuJoCo to know the link count), the inverse model's encoding and the goal checks read the
same numbers instead of keeping copies.

- :class:`RopeProfile` is the chain of capsule links the simulator builds (``twisted.sim.mjcf``):
  ``n_links`` links, ``link_spacing_m`` from centre to centre; its ``n_points`` centreline points
  are the two tips and the joints between links. :data:`ROPE` is the one rope in use.
- :data:`MAX_CROSSINGS` is the most crossings a state may have anywhere in the pipeline: the
  inverse model encodes P-data of fixed size up to it (``twisted.model.encoding``), so collection
  keeps transitions up to it, a goal above it is refused and the RL environment fails a curve
  that goes past it.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["LINK_SPACING_M", "MAX_CROSSINGS", "N_LINKS", "N_POINTS", "ROPE", "ROPE_LENGTH_M", "RopeProfile"]


@dataclass(frozen=True)
class RopeProfile:
    """A rope of ``n_links`` equal links, ``link_spacing_m`` apart (centre to centre)."""

    n_links: int
    link_spacing_m: float

    def __post_init__(self) -> None:
        if self.n_links < 2:
            raise ValueError(f"a rope has at least 2 links, got {self.n_links}")
        if not self.link_spacing_m > 0:
            raise ValueError(f"link spacing must be a positive length in metres, got {self.link_spacing_m}")

    @property
    def n_points(self) -> int:
        """Centreline points: the head tip, the joints between links, the tail tip."""
        return self.n_links + 1

    @property
    def length_m(self) -> float:
        """The rope's length (links times spacing)."""
        return self.n_links * self.link_spacing_m


ROPE = RopeProfile(n_links=21, link_spacing_m=0.04)
N_LINKS = ROPE.n_links
N_POINTS = ROPE.n_points
LINK_SPACING_M = ROPE.link_spacing_m
ROPE_LENGTH_M = ROPE.length_m  # 0.84 m

# The model encodes goals of up to 6 crossings (docs/DESIGN.md section 6.1: the reference truncated to 3).
MAX_CROSSINGS = 6
