"""Curve proposals of the collector: uniform random curves, and curves aimed across another strand.

A uniform curve (link, z_max, x, y all uniform) rarely adds a crossing once the rope has a few: most
displacements drag the link somewhere no other strand lies (the collector kept 3.5 % of them). An
*across* curve keeps the uniform link and ``z_max`` but aims the displacement at a point just beyond
another strand, on the far side from the grasped link: the dragged piece then has to cross that
strand (over it when lifted, or pushing it along when not), which is what makes a new crossing.

The proposal only changes which curves are tried. Every transition is still labelled by the state
the simulator reached (hindsight), so the data stays exactly what the inverse model needs: curves
that took ``q`` to ``s'``; a mixture with uniform curves (``across_share`` < 1) keeps every curve
possible.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from twisted.sim import CURVE_HIGH, CURVE_LOW, N_LINKS, Curve, sample_curve

__all__ = ["CURVE_PROPOSALS", "across_curve", "propose_curve"]

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
