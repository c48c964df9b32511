"""Curve proposals: the collector's (uniform random curves, curves aimed across another strand) and
the planner's scripted Cross move (:func:`cross_move_curve`).

A uniform curve (link, z_max, x, y all uniform) rarely adds a crossing once the rope has a few: most
displacements drag the link somewhere no other strand lies (the collector kept 3.5 % of them). An
*across* curve keeps the uniform link and ``z_max`` but aims the displacement at a point just beyond
another strand, on the far side from the grasped link: the dragged piece then has to cross that
strand (over it when lifted, or pushing it along when not), which is what makes a new crossing.

The proposal only changes which curves are tried. Every transition is still labelled by the state
the simulator reached (hindsight), so the data stays exactly what the inverse model needs: curves
that took ``q`` to ``s'``; a mixture with uniform curves (``across_share`` < 1) keeps every curve
possible.

A *Cross move curve* is aimed at one high-level move, ``Cross(end segment e, segment b, side, O/U)``
(:mod:`twisted.moves`): it finds segment b on the rope (between its two crossings along the rope),
picks a point of b near the tip of e, and carries a link across: for "O" the tip's own link, lifted
over b; for "U", which a lifted tip cannot make, the link of b at that point, lifted over the tip
(the same crossing seen from the other strand). Only points of b where such a crossing would get
the move's sign are aimed at (the sign is what tells the two sides of b apart; their share is
:func:`cross_fit`), nearer ones more often, and any point where there are none. It is geometry
only; whether it made the move is for the simulator to say (docs/DESIGN.md section 8).
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np
import numpy.typing as npt

from twisted.sim import CURVE_HIGH, CURVE_LOW, N_LINKS, Curve, sample_curve
from twisted.topology import cross2, projected_crossings

__all__ = [
    "CURVE_PROPOSALS",
    "across_curve",
    "cross_fit",
    "cross_move_curve",
    "propose_curve",
    "segment_bounds",
    "segment_points",
]

CURVE_PROPOSALS = ("uniform", "across")

# How far beyond the aimed-at strand the grasped link is put down, and how far along it (m).
BEYOND_M = (0.03, 0.20)
ALONG_M = 0.03


def across_curve(rng: np.random.Generator, points: npt.ArrayLike) -> Curve:
    """A curve that carries a uniformly chosen link across another, non-adjacent link.

    ``points`` are the rope's N_POINTS link points (m). The target is the other link's centre, moved to
    its far side (seen from the grasped link) by a uniform distance in :data:`BEYOND_M` and along it
    by up to :data:`ALONG_M`; the displacement is clipped to the curve range.
    """
    pts = np.asarray(points, dtype=np.float64)
    centres = 0.5 * (pts[1:, :2] + pts[:-1, :2])
    link = int(rng.integers(0, N_LINKS))
    others = [j for j in range(N_LINKS) if abs(j - link) >= 2]
    other = others[int(rng.integers(len(others)))]
    along = pts[other + 1, :2] - pts[other, :2]
    along = along / max(float(np.hypot(*along)), 1e-9)
    normal = np.array([-along[1], along[0]])
    side = 1.0 if float(np.dot(centres[link] - centres[other], normal)) >= 0 else -1.0
    beyond = rng.uniform(*BEYOND_M)
    shift = rng.uniform(-ALONG_M, ALONG_M)
    target = centres[other] - side * beyond * normal + shift * along
    x, y = np.clip(target - centres[link], CURVE_LOW[2:], CURVE_HIGH[2:])
    z = rng.uniform(CURVE_LOW[1], CURVE_HIGH[1])
    return Curve(link, float(z), float(x), float(y))


def propose_curve(rng: np.random.Generator, points: npt.ArrayLike | None, across_share: float) -> Curve:
    """An across curve with probability ``across_share`` (needs ``points``), else a uniform one."""
    if points is not None and across_share > 0 and rng.random() < across_share:
        return across_curve(rng, points)
    return sample_curve(rng)


# -- the planner's scripted Cross move -------------------------------------------------------------------

# How far past the crossed strand the carried link is put down (m), how high it is lifted (m), how
# sharply nearer points of b are preferred (m), and how much of b next to its crossings is left out
# (in links).
CROSS_BEYOND_M = (0.03, 0.12)
CROSS_LIFT_M = (0.03, 0.07)
CROSS_REACH_M = 0.1
CROSS_END_PAD = 0.3
# the tip's own link, or the next one, carries the tip over b
CROSS_TIP_LINK_P = 0.6


class CrossMove(Protocol):
    """What :func:`cross_move_curve` reads of a ``twisted.moves.Move`` of kind ``Cross`` (read-only, as a
    frozen ``Move`` has them)."""

    @property
    def segment(self) -> int: ...
    @property
    def other_segment(self) -> int | None: ...
    @property
    def over(self) -> str | None: ...
    @property
    def sign(self) -> str | None: ...


def segment_bounds(points: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Where the P-data segments of a rope lie: ``2k + 2`` rope parameters (link index + fraction along
    it), 0 at the head, one per crossing visit in walking order, ``N_LINKS`` at the tail; segment ``s``
    runs from entry ``s`` to entry ``s + 1``."""
    pts = np.asarray(points, dtype=np.float64)
    pc = projected_crossings(pts)
    visits = np.sort(np.concatenate([pc.i + pc.t, pc.j + pc.u]))
    return np.concatenate([[0.0], visits, [float(len(pts) - 1)]])


def segment_points(
    pts: npt.NDArray[np.float64], bounds: npt.NDArray[np.float64], segment: int, n: int = 40
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """``n`` points along P-data segment ``segment`` of a rope (``bounds``: :func:`segment_bounds`), clear
    of its crossings by :data:`CROSS_END_PAD` links (a quarter of a short segment): their rope
    parameters, links, points and the direction of their links (head to tail, not normalised)."""
    lo, hi = bounds[segment], bounds[segment + 1]
    pad = min(CROSS_END_PAD, 0.25 * (hi - lo))
    s = np.linspace(lo + pad, hi - pad, n)
    link_of = np.clip(np.floor(s).astype(int), 0, N_LINKS - 1)
    along = pts[link_of + 1] - pts[link_of]
    at = pts[link_of] + (s - link_of)[:, None] * along
    return s, link_of, at, along


class _CrossAim(NamedTuple):
    """Where a Cross move can be aimed on a rope: points ``at`` of the crossed segment b (rope parameter
    ``s``, on link ``link_of``), which end's tip moves (``head``) and where it lies, the unit vectors
    ``towards`` from the tip to each point and their distances ``dist``, and whether a straight
    approach to each point gives the move's sign (``fits``)."""

    s: npt.NDArray[np.float64]
    link_of: npt.NDArray[np.int64]
    at: npt.NDArray[np.float64]
    head: bool
    tip: npt.NDArray[np.float64]
    towards: npt.NDArray[np.float64]
    dist: npt.NDArray[np.float64]
    fits: npt.NDArray[np.bool_]


def _approach(
    tip: npt.NDArray[np.float64],
    head: bool,
    at: npt.NDArray[np.float64],
    along: npt.NDArray[np.float64],
    over: str,
    sign: str,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """From a tip at ``tip`` (x, y) of the head's (``head``) or the tail's end piece, to the points ``at``
    of a segment running along ``along``: the unit vectors toward them, their distances on the table, and
    whether a straight approach crosses there ``over`` / under with ``sign``."""
    towards = at[:, :2] - tip[:2]
    dist = np.hypot(towards[:, 0], towards[:, 1]) + 1e-9
    towards = towards / dist[:, None]
    # the rope's walking direction (head -> tail) along the tip's piece where it will cross the segment
    walk = -towards if head else towards
    d_over, d_under = (walk, along[:, :2]) if over == "O" else (along[:, :2], walk)
    fits = np.sign(cross2(d_over, d_under)) == (1 if sign == "+" else -1)
    return towards, dist, fits


def _cross_aim(pts: npt.NDArray[np.float64], move: CrossMove, bounds: npt.NDArray[np.float64]) -> _CrossAim:
    if move.other_segment is None or move.over not in ("O", "U") or move.sign not in ("+", "-"):
        raise ValueError(f"not a Cross move: {move}")
    if not 0 <= move.other_segment < len(bounds) - 1 or move.segment not in (0, len(bounds) - 2):
        raise ValueError(f"{move} does not fit a rope with {len(bounds) // 2 - 1} crossings")
    s, link_of, at, along = segment_points(pts, bounds, move.other_segment)
    head = move.segment == 0
    tip = pts[0] if head else pts[-1]
    towards, dist, fits = _approach(tip, head, at, along, move.over, move.sign)
    return _CrossAim(s, link_of, at, head, tip, towards, dist, fits)


def cross_fit(points: npt.ArrayLike, move: CrossMove, bounds: npt.NDArray[np.float64] | None = None) -> float:
    """The share of the points of ``move``'s crossed segment that a straight approach crosses with the
    move's sign: 0 when the tip lies on the wrong side of the whole segment, so that a straight carry
    makes the crossing with the other sign (DESIGN 8). ``bounds``: :func:`segment_bounds` of the points,
    when known."""
    pts = np.asarray(points, dtype=np.float64)
    aim = _cross_aim(pts, move, segment_bounds(pts) if bounds is None else bounds)
    return float(aim.fits.mean())


def cross_move_curve(rng: np.random.Generator, points: npt.ArrayLike, move: CrossMove) -> Curve:
    """A curve aimed at making ``move`` (a ``Cross``) from the rope with these N_POINTS link points."""
    pts = np.asarray(points, dtype=np.float64)
    aim = _cross_aim(pts, move, segment_bounds(pts))
    c = int(rng.choice(len(aim.s), p=_aim_weights(aim)))
    return _cross_curve(rng, pts, move, aim, c, rng.uniform(*CROSS_BEYOND_M))


def _aim_weights(aim: _CrossAim) -> npt.NDArray[np.float64]:
    """The probabilities of aiming at each point of b: nearer ones more often, only those that fit where
    any does."""
    weights = np.exp(-aim.dist / CROSS_REACH_M) * (aim.fits if aim.fits.any() else 1.0)
    return weights / weights.sum()


def _cross_curve(
    rng: np.random.Generator,
    pts: npt.NDArray[np.float64],
    move: CrossMove,
    aim: _CrossAim,
    c: int,
    beyond: float,
) -> Curve:
    """The curve that crosses point ``c`` of b, the carried link put down ``beyond`` (m) past it."""
    lift = rng.uniform(*CROSS_LIFT_M)
    if move.over == "O":
        end = 0 if aim.head else N_LINKS - 1
        link = end if rng.random() < CROSS_TIP_LINK_P else end + (1 if aim.head else -1)
        target = aim.at[c, :2] + beyond * aim.towards[c]
    else:
        link = int(aim.link_of[c])
        target = aim.tip[:2] - beyond * aim.towards[c]
    centre = 0.5 * (pts[link, :2] + pts[link + 1, :2])
    x, y = np.clip(target - centre, CURVE_LOW[2:], CURVE_HIGH[2:])
    return Curve(link, float(lift), float(x), float(y))
