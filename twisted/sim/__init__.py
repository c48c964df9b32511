"""The MuJoCo rope simulator: ``f(q, c) -> q'`` for a curve ``c``, link points and P-data.

``RopeSim`` is one rope (state in, curve in, state out, deterministic); ``SimPool`` runs many
``(state, curve)`` jobs on worker processes; ``simulate`` is the same job in-process.

The simulation never draws, so ``mujoco`` is imported without OpenGL (``MUJOCO_GL=disable`` unless
the user set it): its default, GLFW, starts a Python child at import to probe its library (0.2 s
per process, and a Ctrl-C arriving then killed that child with a traceback on the command's
stderr). Pictures are drawn by a child interpreter that sets ``MUJOCO_GL`` itself
(:func:`twisted.render.gl_top_views`).
"""

import os

os.environ.setdefault("MUJOCO_GL", "disable")

from twisted.rope import N_LINKS, N_POINTS  # noqa: E402
from twisted.sim.pool import SimPool, SimResult, simulate  # noqa: E402
from twisted.sim.rope import CURVE_HIGH, CURVE_LOW, Curve, CurveOutcome, Pin, RopeSim, sample_curve  # noqa: E402

__all__ = [
    "CURVE_HIGH",
    "CURVE_LOW",
    "Curve",
    "CurveOutcome",
    "N_LINKS",
    "N_POINTS",
    "Pin",
    "RopeSim",
    "SimPool",
    "SimResult",
    "sample_curve",
    "simulate",
]
