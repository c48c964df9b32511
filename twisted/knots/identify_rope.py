"""What knot an open rope ties: both closures, and the knot when they agree (docs/DESIGN.md section 9).

:func:`identify` closes a rope state's diagram through its faces (P-data route), :func:`identify_points`
closes a rope's centreline points below and above the table (link-points route); both give a
:class:`RopeKnot`, whose name is ``"knotoid"`` (:data:`KNOTOID`) when the closures differ.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from twisted.knots.catalogue import KnotType, invariants
from twisted.knots.gauss import closed_gauss_code, gauss_code_from_polygon
from twisted.topology import PData, parse_p_data

__all__ = ["KNOTOID", "RopeKnot", "identify", "identify_points", "knot_type_name"]


KNOTOID = "knotoid"


@dataclass(frozen=True, slots=True)
class RopeKnot:
    """What an open rope ties: its two closures, and the knot when they agree.

    ``under``: the ends lowered below the table and joined there (the closing arc passes under
    everything); ``over``: the ends lifted and joined above everything. When both closures are the
    same knot, pulling the ends apart cannot change it (the ends can be led out either way), and the
    rope ties that knot: :attr:`name` is its catalogue name (``"unknown"`` outside the catalogue).
    When they differ the diagram is a proper knotoid (Turaev 2012): an end lies inside a loop and what
    the rope becomes depends on which way the end leaves; :attr:`name` is ``"knotoid"`` and no knot
    is tied.
    """

    under: KnotType
    over: KnotType

    @property
    def is_knot(self) -> bool:
        """True when both closures are the same knot (by their invariants)."""
        return self.under == self.over

    @property
    def name(self) -> str:
        """The knot's name when both closures agree, else ``"knotoid"`` (the store's ``knot_type``)."""
        return self.under.name if self.is_knot else KNOTOID

    @property
    def knot(self) -> KnotType | None:
        """The knot tied (both closures), None for a knotoid."""
        return self.under if self.is_knot else None

    def describe(self) -> str:
        """``3_1+`` for a knot, ``knotoid: under 3_1-, over 0_1`` otherwise."""
        if self.is_knot:
            return self.name
        return f"{KNOTOID}: under {self.under.name}, over {self.over.name}"

    def to_dict(self) -> dict[str, object]:
        """JSON-ready: name, both closures with their invariants."""

        def one(k: KnotType) -> dict[str, object]:
            return {
                "knot_type": k.name,
                "alexander": list(k.alexander),
                "determinant": k.determinant,
                "jones": [list(t) for t in k.jones],
                "writhe": k.writhe,
            }

        return {
            "knot_type": self.name,
            "is_knot": self.is_knot,
            "under": one(self.under),
            "over": one(self.over),
        }


@lru_cache(maxsize=1 << 16)
def identify(p: PData) -> RopeKnot:
    """What rope state ``p`` ties: both closures (under and over the table) through its faces, named."""
    q = parse_p_data(p)
    return RopeKnot(invariants(closed_gauss_code(q)), invariants(closed_gauss_code(q, over=True)))


def identify_points(points: npt.ArrayLike, depth_m: float = 1.0) -> RopeKnot:
    """What a rope with these centreline points (head first, shape (N, 3)) ties: both closures.

    For the under closure both ends are lowered ``depth_m`` below the rope's lowest point (and the
    table) and joined there by a straight segment; for the over closure they are lifted ``depth_m``
    above its highest point. Each closed polygon is projected to the table (its vertical segments
    project to the tips themselves).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2:
        raise ValueError(f"points must have shape (N>=2, 3), got {pts.shape}")
    low = min(float(pts[:, 2].min()), 0.0) - depth_m
    high = float(pts[:, 2].max()) + depth_m

    def closed(z: float) -> KnotType:
        tail = np.array([pts[-1, 0], pts[-1, 1], z])
        head = np.array([pts[0, 0], pts[0, 1], z])
        return invariants(gauss_code_from_polygon(np.vstack([pts, tail, head])))

    return RopeKnot(closed(low), closed(high))


def knot_type_name(p: PData) -> str:
    """Shorthand for ``identify(p).name``: the knot, or ``"knotoid"`` (the store's ``knot_type``)."""
    return identify(p).name
