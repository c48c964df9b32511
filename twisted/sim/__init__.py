"""The MuJoCo rope simulator: ``f(q, c) -> q'`` for a curve ``c``, link points and P-data.

``RopeSim`` is one rope (state in, curve in, state out, deterministic); ``SimPool`` runs many
``(state, curve)`` jobs on worker processes; ``simulate`` is the same job in-process.
"""

from twisted.sim.mjcf import N_LINKS, N_POINTS
from twisted.sim.pool import SimPool, SimResult, simulate
from twisted.sim.rope import CURVE_HIGH, CURVE_LOW, Curve, CurveOutcome, RopeSim, sample_curve

__all__ = [
    "CURVE_HIGH",
    "CURVE_LOW",
    "Curve",
    "CurveOutcome",
    "N_LINKS",
    "N_POINTS",
    "RopeSim",
    "SimPool",
    "SimResult",
    "sample_curve",
    "simulate",
]
