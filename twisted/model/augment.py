"""Mirror and Reverse: the two symmetries of the rope used to augment the training data.

* **Mirror** reflects the world y -> -y: link points and the action's y flip, every P-data sign
  flips (:meth:`PData.mirror`). Physics (a horizontal table, gravity along -z) is symmetric under
  this reflection, up to chaos.
* **Reverse** walks the rope tail -> head: link k becomes link N_LINKS - 1 - k, the point order reverses,
  P-data positions are renumbered p -> 2n+1-p (:meth:`PData.reverse`); the action's displacement
  stays the same because the gripper moves the same physical link the same way.

The point/curve functions work on numpy arrays and torch tensors alike (last axis = coordinates,
the point axis second to last). :func:`mirror_move` / :func:`reverse_move` transform an abstract
move (:class:`twisted.moves.Move`) so that it makes the transformed state from the transformed
start. :data:`VARIANTS` numbers the four combinations so that a batch
can pick one per sample: bit 0 = mirror, bit 1 = reverse (they commute).

:func:`mirror_state` / :func:`reverse_state` apply the same symmetries to a simulator state, so
that the tests can check the augmentations against physics.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TypeVar

import numpy as np
import numpy.typing as npt
import torch

from twisted.moves import Move
from twisted.sim import N_LINKS, RopeSim
from twisted.sim.mjcf import joint_names
from twisted.topology import PData

__all__ = [
    "VARIANTS",
    "apply_variant",
    "apply_variant_move",
    "apply_variant_p_data",
    "mirror_curve",
    "mirror_move",
    "mirror_p_data",
    "mirror_points",
    "mirror_state",
    "reverse_curve",
    "reverse_move",
    "reverse_p_data",
    "reverse_points",
    "reverse_state",
]

ArrayT = TypeVar("ArrayT", np.ndarray, torch.Tensor)

VARIANTS = ("identity", "mirror", "reverse", "mirror+reverse")
MIRROR, REVERSE = 1, 2


def _negate(a: ArrayT, index: int) -> ArrayT:
    """A copy of ``a`` with the last-axis component ``index`` negated."""
    out = a.clone() if isinstance(a, torch.Tensor) else np.array(a, copy=True)
    out[..., index] = -out[..., index]
    return out


def mirror_points(points: ArrayT) -> ArrayT:
    """Link points (..., N_POINTS, 3) reflected y -> -y."""
    return _negate(points, 1)


def mirror_curve(curve: ArrayT) -> ArrayT:
    """Curves (..., 4) = (link, z_max_m, x_m, y_m) reflected: y -> -y."""
    return _negate(curve, 3)


def mirror_p_data(p: PData) -> PData:
    return p.mirror()


def reverse_points(points: ArrayT) -> ArrayT:
    """Link points (..., N_POINTS, 3) walked tail -> head."""
    if isinstance(points, torch.Tensor):
        return points.flip(-2)
    return np.array(points[..., ::-1, :], copy=True)


def reverse_curve(curve: ArrayT) -> ArrayT:
    """Curves (..., 4): the same physical link, renumbered k -> N_LINKS - 1 - k; displacement unchanged."""
    out = curve.clone() if isinstance(curve, torch.Tensor) else np.array(curve, copy=True)
    out[..., 0] = (N_LINKS - 1) - out[..., 0]
    return out


def reverse_p_data(p: PData) -> PData:
    return p.reverse()


def apply_variant_p_data(p: PData, variant: int) -> PData:
    """P-data under variant 0..3 (bit 0 mirror, bit 1 reverse)."""
    if variant & MIRROR:
        p = p.mirror()
    if variant & REVERSE:
        p = p.reverse()
    return p


def _other(side: str | None) -> str | None:
    return None if side is None else ("R" if side == "L" else "L")


def _other_sign(sign: str | None) -> str | None:
    return None if sign is None else ("-" if sign == "+" else "+")


def mirror_move(move: Move) -> Move:
    """The move that makes the mirrored state from the mirrored start: sides and signs flip,
    segments and over/under are kept (a reflection of the table keeps which strand is on top)."""
    return replace(
        move, side=_other(move.side), other_side=_other(move.other_side), sign=_other_sign(move.sign)
    )


def reverse_move(move: Move, p_from: PData) -> Move:
    """The move that makes the reversed state from the reversed start ``p_from.reverse()``.

    Segments renumber k -> 2n - k and every side flips (the rope is walked the other way); signs
    are kept. R1: the curl's first visit is the old second one, so over/under flips. R2: the piece
    met first is now the old second piece (its over/under), and its first new visit is the old
    second crossing when the pieces ran parallel (sides differ: the sign flips) and the old first
    one when nested (sides agree: the sign is kept). Cross: the head's tip becomes the tail's.
    """
    last = 2 * p_from.cross
    if move.kind == "R1":
        return replace(move, segment=last - move.segment, side=_other(move.side), over=_flip_over(move.over))
    if move.kind == "R2":
        assert move.other_segment is not None
        return Move(
            "R2",
            last - move.other_segment,
            side=_other(move.other_side),
            sign=move.sign if move.side == move.other_side else _other_sign(move.sign),
            over=_flip_over(move.over),
            other_segment=last - move.segment,
            other_side=_other(move.side),
        )
    assert move.other_segment is not None
    return replace(
        move,
        segment=last - move.segment,
        other_segment=last - move.other_segment,
        other_side=_other(move.other_side),
    )


def _flip_over(over: str | None) -> str | None:
    return None if over is None else ("U" if over == "O" else "O")


def apply_variant_move(move: Move, p_from: PData, variant: int) -> Move:
    """``move`` (from state ``p_from``) under variant 0..3, in the order of :func:`apply_variant_p_data`."""
    if variant & MIRROR:
        move, p_from = mirror_move(move), p_from.mirror()
    if variant & REVERSE:
        move = reverse_move(move, p_from)
    return move


def apply_variant(
    points: torch.Tensor, curve: torch.Tensor, variant: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-sample augmentation of a batch: points (B, N_POINTS, 3), curves (B, 4), variant (B,) in 0..3."""
    mirror = (variant & MIRROR).bool()
    reverse = (variant & REVERSE).bool()
    points = torch.where(mirror[:, None, None], mirror_points(points), points)
    curve = torch.where(mirror[:, None], mirror_curve(curve), curve)
    points = torch.where(reverse[:, None, None], reverse_points(points), points)
    curve = torch.where(reverse[:, None], reverse_curve(curve), curve)
    return points, curve


# ---- the same symmetries on a simulator state (qpos then qvel, see RopeSim.state) ---------------


def _state_layout(sim: RopeSim) -> tuple[int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Addresses of the root free joint and of every (yaw, pitch) hinge, by name."""
    m = sim.model
    root = m.joint("root")
    yaw = [m.joint(joint_names(i)[0]) for i in range(N_LINKS - 1)]
    pitch = [m.joint(joint_names(i)[1]) for i in range(N_LINKS - 1)]
    return (
        int(root.qposadr[0]),
        int(root.dofadr[0]),
        np.array([int(j.qposadr[0]) for j in yaw]),
        np.array([int(j.qposadr[0]) for j in pitch]),
        np.array([int(j.dofadr[0]) for j in yaw]),
        np.array([int(j.dofadr[0]) for j in pitch]),
    )


def mirror_state(sim: RopeSim, state: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The rope state reflected y -> -y.

    Every link frame has its local x along the rope (mjcf.py), so the reflection S = diag(1,-1,1)
    maps a link frame R to S R S: the root's quaternion (w, x, y, z) becomes (w, -x, y, -z), its
    position and linear velocity flip y, its body-frame angular velocity (a pseudovector) becomes
    (-wx, wy, -wz); a yaw hinge (about local z) flips, a pitch hinge (about local y) is kept.
    """
    q = np.array(state, dtype=np.float64, copy=True)
    nq = sim.model.nq
    pos, dof, yaw_q, _pitch_q, yaw_v, _pitch_v = _state_layout(sim)
    qpos, qvel = q[:nq], q[nq:]
    qpos[pos + 1] *= -1.0
    qpos[pos + 4] *= -1.0  # quaternion x
    qpos[pos + 6] *= -1.0  # quaternion z
    qpos[yaw_q] *= -1.0
    qvel[dof + 1] *= -1.0
    qvel[dof + 3] *= -1.0
    qvel[dof + 5] *= -1.0
    qvel[yaw_v] *= -1.0
    return q


def reverse_state(sim: RopeSim, state: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The same physical rope with its links renumbered k -> N_LINKS - 1 - k (head and tail swapped).

    The middle link stays the root but turns by pi about its local z (its x axis must point to
    the new tail): quaternion q -> q * (0, 0, 0, 1), body-frame angular velocity (wx, wy, wz) ->
    (-wx, -wy, wz). Joint j (between links j and j+1) becomes joint 19 - j; a joint on the tail
    half rotates its child, on the head half its parent, so renumbering keeps the yaw and flips
    the pitch (Rz(pi)^T Rz(yaw) Ry(pitch) Rz(pi) = Rz(yaw) Ry(-pitch)).
    """
    q = np.array(state, dtype=np.float64, copy=True)
    nq = sim.model.nq
    pos, dof, yaw_q, pitch_q, yaw_v, pitch_v = _state_layout(sim)
    qpos, qvel = q[:nq], q[nq:]
    w, x, y, z = qpos[pos + 3 : pos + 7].copy()
    qpos[pos + 3 : pos + 7] = (-z, y, -x, w)  # (w, x, y, z) * (0, 0, 0, 1)
    qvel[dof + 3] *= -1.0
    qvel[dof + 4] *= -1.0
    qpos[yaw_q] = qpos[yaw_q[::-1]].copy()
    qpos[pitch_q] = -qpos[pitch_q[::-1]]
    qvel[yaw_v] = qvel[yaw_v[::-1]].copy()
    qvel[pitch_v] = -qvel[pitch_v[::-1]]
    return q
