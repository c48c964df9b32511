"""Kinematic drag prediction: which state a curve leaves the rope in, guessed without the simulator.

A curve grasps one link, lifts it and carries it along a straight line (``twisted.sim``). Here the rope
on either side of the grasped link follows the way a chain pulled over a table does, with nothing
else: a point moves only when the link to its neighbour nearer the gripper is stretched, and then
just enough, along that link, to keep its length (follow-the-leader). The carried piece hangs from
the gripper: a point's height is the gripper's lift less half its distance along the rope.

The predicted state comes from the predicted centreline: a crossing the rope had before (the same
pair of links, give or take one) keeps its over strand; a new one is over where the piece was carried
higher (on a tie, the earlier link); the signs follow from the directions as in ``Top``.

It is wrong more often than right (friction, pushing, stiffness and the drop at release are all left
out; ``bench/drag_steps.py`` measures it), but in a batch it costs well under a millisecond a curve
where a simulated curve costs about 40 ms, and curves it predicts to make a plan step from 3 crossings
made it several times as often as the planner's own (DESIGN 8). :class:`DragPool` holds a
node's pool of random curves with their predicted states, so that those predicted to make a given step
can be picked out (``bench/drag_steps.py``). Used by the planner, to simulate such curves first, it
solved no more tuning goals and was not kept (DESIGN 8; log, 2026-12-05).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from twisted.rope import LINK_SPACING_M, N_LINKS
from twisted.sim import CURVE_HIGH, CURVE_LOW, Curve
from twisted.sim.rope import MIN_LIFT_M
from twisted.topology import PData, crossing_signs, p_data_of, projected_crossings, segment_hits

__all__ = ["DragPool", "crossing_counts", "drag", "predicted_states"]

FloatArray = npt.NDArray[np.float64]

# Drop of the hanging piece's height per metre along the rope from the grasped link, and the number of
# straight sub-moves a carry is split into.
HANG_SLOPE = 0.5
SUBSTEPS = 10


def drag(
    points: npt.ArrayLike, curves: npt.ArrayLike, substeps: int = SUBSTEPS
) -> tuple[FloatArray, FloatArray]:
    """Follow-the-leader positions after each curve, batched.

    ``points``: the rope's link points (N_POINTS, 3 or 2), head first; ``curves``: (M, 4) rows
    ``[link, z_max_m, x_m, y_m]``. Returns the predicted table positions (M, N_POINTS, 2) and each point's
    greatest height during the carry (M, N_POINTS)."""
    p0 = np.asarray(points, dtype=np.float64)[:, :2]
    c = np.asarray(curves, dtype=np.float64).reshape(-1, 4)
    n, m = len(p0), len(c)
    link = np.clip(np.round(c[:, 0]).astype(int), 0, n - 2)
    lift = np.maximum(c[:, 1], 0.0) + MIN_LIFT_M
    idx = np.arange(n)
    grasped = (idx == link[:, None]) | (idx == link[:, None] + 1)
    before, after = idx < link[:, None], idx > link[:, None] + 1
    along = np.abs(idx - (link[:, None] + 0.5)) * LINK_SPACING_M
    p = np.repeat(p0[None], m, axis=0)
    high = np.zeros((m, n))
    for s in np.linspace(0.0, 1.0, substeps + 1)[1:]:
        p[grasped] = (p0[None] + s * c[:, None, 2:4])[grasped]
        for k in range(n - 2, -1, -1):  # the head side follows the point after it
            _follow(p, k, k + 1, before[:, k])
        for k in range(1, n):  # the tail side follows the point before it
            _follow(p, k, k - 1, after[:, k])
        high = np.maximum(high, lift[:, None] * np.sin(np.pi * s) - HANG_SLOPE * along)
    return p, np.maximum(high, 0.0)


def _follow(p: FloatArray, k: int, leader: int, moving: npt.NDArray[np.bool_]) -> None:
    v = p[:, k] - p[:, leader]
    d = np.hypot(v[:, 0], v[:, 1])
    pull = moving & (d > LINK_SPACING_M)
    p[pull, k] = p[pull, leader] + v[pull] * (LINK_SPACING_M / d[pull])[:, None]


def crossing_counts(xy: FloatArray) -> npt.NDArray[np.int64]:
    """The number of crossings of each predicted centreline (M, N_POINTS, 2), batched."""
    start, d = xy[:, :-1], xy[:, 1:] - xy[:, :-1]
    i, j = np.triu_indices(d.shape[1], k=2)
    hit, _, _ = segment_hits(start[:, i], d[:, i], start[:, j], d[:, j])
    return hit.sum(axis=1)


def _old_over(points: FloatArray) -> dict[tuple[int, int], bool]:
    pc = projected_crossings(points)
    return {(int(i), int(j)): bool(o) for i, j, o in zip(pc.i, pc.j, pc.i_over, strict=True)}


def _state(xy: FloatArray, high: FloatArray, old: dict[tuple[int, int], bool]) -> PData:
    """The P-data of one predicted centreline (see the module docstring for the over strands)."""
    pc = projected_crossings(np.column_stack([xy, np.zeros(len(xy))]))
    over = np.empty(len(pc), dtype=bool)
    for c, (i, j) in enumerate(zip(pc.i.tolist(), pc.j.tolist(), strict=True)):
        kept = next(
            (old[(a, b)] for a in (i, i - 1, i + 1) for b in (j, j - 1, j + 1) if (a, b) in old), None
        )
        over[c] = kept if kept is not None else max(high[i], high[i + 1]) >= max(high[j], high[j + 1])
    d = xy[1:] - xy[:-1]
    return p_data_of(replace(pc, i_over=over, sign=crossing_signs(d[pc.i], d[pc.j], over)))


def predicted_states(points: npt.ArrayLike, curves: npt.ArrayLike) -> list[PData]:
    """The state each curve (rows ``[link, z_max_m, x_m, y_m]``) is predicted to leave the rope in."""
    pts = np.asarray(points, dtype=np.float64)
    xy, high = drag(pts, curves)
    old = _old_over(pts)
    return [_state(xy[m], high[m], old) for m in range(len(xy))]


class DragPool:
    """A rope's pool of ``size`` uniform random curves (drawn from ``rng``) with their predicted results;
    each predicted state is computed once, when first asked for."""

    def __init__(self, points: npt.ArrayLike, size: int, rng: np.random.Generator) -> None:
        self.points = np.asarray(points, dtype=np.float64)
        self.curves = np.column_stack(
            [
                rng.integers(0, N_LINKS, size),
                rng.uniform(CURVE_LOW[1], CURVE_HIGH[1], size),
                rng.uniform(CURVE_LOW[2:], CURVE_HIGH[2:], (size, 2)),
            ]
        )
        self.xy, self.high = drag(self.points, self.curves)
        self.counts = crossing_counts(self.xy)
        self._old = _old_over(self.points)
        self._states: dict[int, PData] = {}

    def reaching(self, state: PData) -> list[int]:
        """Indices of the pool's curves predicted to reach ``state``, in pool order."""
        out = []
        for m in np.flatnonzero(self.counts == state.cross).tolist():
            if m not in self._states:
                self._states[m] = _state(self.xy[m], self.high[m], self._old)
            if self._states[m] == state:
                out.append(m)
        return out

    def curve(self, m: int) -> Curve:
        return Curve.from_array(self.curves[m])
