"""Curve proposals: the collector's (uniform random curves, curves aimed across another strand) and
the planner's scripted Cross move (:func:`cross_move_curve`) and curl (:func:`curl_move_curve`).

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
the move's sign are aimed at (the sign is what tells the two sides of b apart), nearer ones more
often. It is geometry only; whether it made the move is for the simulator to say (docs/DESIGN.md
section 8).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import numpy.typing as npt

from twisted.sim import CURVE_HIGH, CURVE_LOW, N_LINKS, Curve, sample_curve
from twisted.topology import cross2, projected_crossings

__all__ = [
    "CURVE_PROPOSALS",
    "across_curve",
    "cross_move_curve",
    "curl_move_aim",
    "curl_move_curve",
    "propose_curve",
    "segment_bounds",
]

CURVE_PROPOSALS = ("uniform", "across")

# How far beyond the aimed-at strand the grasped link is put down, and how far along it (m).
BEYOND_M = (0.03, 0.20)
ALONG_M = 0.03


def across_curve(rng: np.random.Generator, points: npt.ArrayLike) -> Curve:
    """A curve that carries a uniformly chosen link across another, non-adjacent link.

    ``points`` are the rope's 22 link points (m). The target is the other link's centre, moved to
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
    """What :func:`cross_move_curve` reads of a ``twisted.moves.Move`` of kind ``Cross``."""

    segment: int
    other_segment: int | None
    over: str | None
    sign: str | None


def segment_bounds(points: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Where the P-data segments of a rope lie: ``2k + 2`` rope parameters (link index + fraction along
    it), 0 at the head, one per crossing visit in walking order, ``N_LINKS`` at the tail; segment ``s``
    runs from entry ``s`` to entry ``s + 1``."""
    pts = np.asarray(points, dtype=np.float64)
    pc = projected_crossings(pts)
    visits = np.sort(np.concatenate([pc.i + pc.t, pc.j + pc.u]))
    return np.concatenate([[0.0], visits, [float(len(pts) - 1)]])


def cross_move_curve(rng: np.random.Generator, points: npt.ArrayLike, move: CrossMove) -> Curve:
    """A curve aimed at making ``move`` (a ``Cross``) from the rope with these 22 link points."""
    pts = np.asarray(points, dtype=np.float64)
    if move.other_segment is None or move.over not in ("O", "U") or move.sign not in ("+", "-"):
        raise ValueError(f"not a Cross move: {move}")
    bounds = segment_bounds(pts)
    if not 0 <= move.other_segment < len(bounds) - 1 or move.segment not in (0, len(bounds) - 2):
        raise ValueError(f"{move} does not fit a rope with {len(bounds) // 2 - 1} crossings")
    lo, hi = bounds[move.other_segment], bounds[move.other_segment + 1]
    pad = min(CROSS_END_PAD, 0.25 * (hi - lo))
    s = np.linspace(lo + pad, hi - pad, 40)
    link_of = np.clip(np.floor(s).astype(int), 0, N_LINKS - 1)
    along = pts[link_of + 1] - pts[link_of]
    at = pts[link_of] + (s - link_of)[:, None] * along
    head = move.segment == 0
    tip = pts[0] if head else pts[-1]
    towards = at[:, :2] - tip[:2]
    dist = np.hypot(towards[:, 0], towards[:, 1]) + 1e-9
    towards = towards / dist[:, None]
    # the rope's walking direction (head -> tail) along the tip's piece where it will cross b
    walk = -towards if head else towards
    d_over, d_under = (walk, along[:, :2]) if move.over == "O" else (along[:, :2], walk)
    signs = np.sign(cross2(d_over, d_under))
    fits = signs == (1 if move.sign == "+" else -1)
    weights = np.exp(-dist / CROSS_REACH_M) * (fits if fits.any() else 1.0)
    c = int(rng.choice(len(s), p=weights / weights.sum()))
    beyond = rng.uniform(*CROSS_BEYOND_M)
    lift = rng.uniform(*CROSS_LIFT_M)
    if move.over == "O":
        end = 0 if head else N_LINKS - 1
        link = end if rng.random() < CROSS_TIP_LINK_P else end + (1 if head else -1)
        target = at[c, :2] + beyond * towards[c]
    else:
        link = int(link_of[c])
        target = tip[:2] - beyond * towards[c]
    centre = 0.5 * (pts[link, :2] + pts[link + 1, :2])
    x, y = np.clip(target - centre, CURVE_LOW[2:], CURVE_HIGH[2:])
    return Curve(link, float(lift), float(x), float(y))


# -- the planner's scripted curl (R1) ---------------------------------------------------------------------

# How far along the rope the crossed point lies from the carried link (in links), how far past the
# crossed strand the link is put down (m), how high it is lifted (m), how sharply nearer pairs are
# preferred (m), how much of the segment next to its crossings is left out (in links), and how near
# the strand's line a link counts as on it (m).
CURL_GAP_LINKS = (2.0, 8.0)
CURL_BEYOND_M = (0.02, 0.06)
CURL_LIFT_M = (0.03, 0.07)
CURL_REACH_M = 0.05
CURL_END_PAD = 0.3
CURL_ON_LINE_M = 0.005


class CurlMove(Protocol):
    """What :func:`curl_move_curve` reads of a ``twisted.moves.Move`` of kind ``R1`` (read only)."""

    @property
    def kind(self) -> str: ...
    @property
    def segment(self) -> int: ...
    @property
    def over(self) -> str | None: ...
    @property
    def sign(self) -> str | None: ...


def _rope_at(pts: npt.NDArray[np.float64], s: npt.NDArray[np.float64]) -> tuple[np.ndarray, np.ndarray]:
    """Points (x, y) and unit walking directions of the rope at rope parameters ``s``."""
    link_of = np.clip(np.floor(s).astype(int), 0, N_LINKS - 1)
    along = pts[link_of + 1, :2] - pts[link_of, :2]
    at = pts[link_of, :2] + (s - link_of)[:, None] * along
    return at, along / np.maximum(np.hypot(along[:, 0], along[:, 1]), 1e-9)[:, None]


def curl_move_curve(rng: np.random.Generator, points: npt.ArrayLike, move: CurlMove) -> Curve:
    """A curve aimed at making ``move`` (an ``R1``) from the rope with these 22 link points (see
    :func:`curl_move_aim`)."""
    return curl_move_aim(rng, points, move)[0]


def curl_move_aim(rng: np.random.Generator, points: npt.ArrayLike, move: CurlMove) -> tuple[Curve, float]:
    """The curve of :func:`curl_move_curve` and the rope parameter of the point it carries its link
    across.

    A curl on segment k is closed by carrying one link of k, lifted, across another point of k a few
    links along (:data:`CURL_GAP_LINKS`): the carried piece is over at the new crossing and the rope
    between the two points is the loop. With the first visit over ("O") the carried link lies before
    the loop and is put down across the loop's far end; with "U" it lies after the loop and goes
    across its start. Of the (link, point) pairs of k, those where the carry gives the move's sign are
    drawn, nearer ones (a bend in the rope) more often, and the link is put down just past the strand,
    on the far side from where it lay. The stored searches' curls from 2 to 4 crossings were mostly
    of this shape; on a straight piece it rarely makes the curl (docs/DESIGN.md section 8).
    """
    pts = np.asarray(points, dtype=np.float64)
    if move.kind != "R1" or move.over not in ("O", "U") or move.sign not in ("+", "-"):
        raise ValueError(f"not an R1 move: {move}")
    bounds = segment_bounds(pts)
    if not 0 <= move.segment < len(bounds) - 1:
        raise ValueError(f"{move} does not fit a rope with {len(bounds) // 2 - 1} crossings")
    lo, hi = bounds[move.segment], bounds[move.segment + 1]
    pad = min(CURL_END_PAD, 0.25 * (hi - lo))
    links = np.arange(N_LINKS)
    centres_s = links + 0.5
    strand_s = np.linspace(lo + pad, hi - pad, 48)
    gap = strand_s[None, :] - centres_s[:, None]  # > 0: the point lies after the link
    if move.over == "U":
        gap = -gap
    ok = (gap >= CURL_GAP_LINKS[0]) & (gap <= CURL_GAP_LINKS[1])
    ok &= (centres_s[:, None] >= lo - 0.5) & (centres_s[:, None] <= hi + 0.5)
    if not ok.any():  # a short segment: the nearest pairs of it, whatever their gap
        ok = (gap > 0.5) & (centres_s[:, None] >= lo - 1.0) & (centres_s[:, None] <= hi + 1.0)
    if not ok.any():  # no point of the segment on the right side of any link: every pair
        ok = np.ones_like(gap, dtype=bool)
    at, walk = _rope_at(pts, strand_s)
    centres = 0.5 * (pts[links, :2] + pts[links + 1, :2])
    to = at[None, :, :] - centres[:, None, :]
    dist = np.hypot(to[..., 0], to[..., 1]) + 1e-9
    # the side of the strand the link starts on (+1: left of its walking direction); carried across,
    # the piece crosses it from that side, which gives the crossing's sign (module doc of
    # twisted.moves): over at a point of the first visit ("O") it is the piece after the link, coming
    # back, over at the second ("U") the piece before it, going on. A link within CURL_ON_LINE_M of
    # the strand's line (a straight piece) may start from either side.
    normal = np.stack([-walk[:, 1], walk[:, 0]], axis=-1)
    offset = np.einsum("lsk,sk->ls", -to, normal)
    want = 1 if move.sign == "+" else -1
    start = -want if move.over == "O" else want
    side = np.where(np.abs(offset) < CURL_ON_LINE_M, start, np.sign(offset))
    fits = ok & (side == start)
    # where no link lies on that side, any pair: on the tuning set's tree steps such carries made the
    # curl too (the crossing's side is the rope's to settle)
    weights = np.exp(-dist / CURL_REACH_M) * (fits if fits.any() else ok)
    flat = int(rng.choice(weights.size, p=(weights / weights.sum()).ravel()))
    link, c = divmod(flat, len(strand_s))
    target = at[c] - side[link, c] * rng.uniform(*CURL_BEYOND_M) * normal[c]
    x, y = np.clip(target - centres[link], CURVE_LOW[2:], CURVE_HIGH[2:])
    return Curve(int(link), float(rng.uniform(*CURL_LIFT_M)), float(x), float(y)), float(strand_s[c])
