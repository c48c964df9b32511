"""Mirror and Reverse: the two symmetries of the rope used to augment the training data.

* **Mirror** reflects the world y -> -y: link points and the action's y flip, every P-data sign
  flips (:meth:`PData.mirror`). Physics (a horizontal table, gravity along -z) is symmetric under
  this reflection, up to chaos.
* **Reverse** walks the rope tail -> head: link k becomes link 20 - k, the point order reverses,
  P-data positions are renumbered p -> 2n+1-p (:meth:`PData.reverse`); the action's displacement
  stays the same because the gripper moves the same physical link the same way.

The point/curve functions work on numpy arrays and torch tensors alike (last axis = coordinates,
the point axis second to last). :data:`VARIANTS` numbers the four combinations so that a batch
can pick one per sample: bit 0 = mirror, bit 1 = reverse (they commute).

:func:`mirror_state` / :func:`reverse_state` apply the same symmetries to a simulator state, so
that the tests can check the augmentations against physics.
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
import numpy.typing as npt
import torch

from twisted.sim import N_LINKS, RopeSim
from twisted.sim.mjcf import joint_names
from twisted.topology import PData

__all__ = [
    "VARIANTS",
    "apply_variant",
    "apply_variant_p_data",
    "mirror_curve",
    "mirror_p_data",
    "mirror_points",
    "mirror_state",
    "reverse_curve",
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
    """Link points (..., 22, 3) reflected y -> -y."""
    return _negate(points, 1)


def mirror_curve(curve: ArrayT) -> ArrayT:
    """Curves (..., 4) = (link, z_max_m, x_m, y_m) reflected: y -> -y."""
    return _negate(curve, 3)


def mirror_p_data(p: PData) -> PData:
    return p.mirror()


def reverse_points(points: ArrayT) -> ArrayT:
    """Link points (..., 22, 3) walked tail -> head."""
    if isinstance(points, torch.Tensor):
        return points.flip(-2)
    return np.array(points[..., ::-1, :], copy=True)


def reverse_curve(curve: ArrayT) -> ArrayT:
    """Curves (..., 4): the same physical link, renumbered k -> 20 - k; displacement unchanged."""
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


def apply_variant(
    points: torch.Tensor, curve: torch.Tensor, variant: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-sample augmentation of a batch: points (B, 22, 3), curves (B, 4), variant (B,) in 0..3."""
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
    """The same physical rope with its links renumbered k -> 20 - k (head and tail swapped).

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
