"""What the inverse model sees and predicts, in ONE place used by training and inference.

* :func:`encode_p_data` turns a P-data state into a fixed-size vector (up to
  :data:`MAX_CROSSINGS` crossings; a longer state is an :class:`EncodingError`, never truncated).
* :func:`preprocess` turns link points (B, N_POINTS, 3) into the network's geometric input. It moves the
  rope into a *canonical frame*: centred on the mean of its points in the table plane and rotated
  about z so that the head->tail vector points along +x. Physics is invariant under translations
  and rotations about the vertical, so the model never has to learn them; the price is that the
  action's planar displacement must be expressed in the same frame (:func:`curve_to_target`) and
  rotated back at inference (:func:`target_to_curve`).
* :func:`encode_move` turns the abstract move (R1 / R2 / Cross, its segments, sides, over/under
  and sign, :class:`twisted.moves.Move`) into a vector, and :func:`move_link_features` marks the
  links on the move's segments, so the link scorer sees where the new crossings are to appear.
* The crossing features are computed from the points themselves (which segment crosses which,
  over or under, with which sign), so they stay consistent with any augmentation of the points.

Targets live in a normalised space: ``z`` in [-1, 1] over [0, z_max high], and the canonical
displacement divided by the range half-width (0.5 m), so it lies in the disc of radius sqrt(2).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import torch

from twisted.moves import Move
from twisted.rope import MAX_CROSSINGS, ROPE_LENGTH_M
from twisted.sim import CURVE_HIGH, CURVE_LOW, N_LINKS, N_POINTS
from twisted.topology import PData, Visit

__all__ = [
    "CROSSING_DIM",
    "EncodingError",
    "GEOMETRY_DIM",
    "LINK_TOKEN_DIM",
    "MAX_CROSSINGS",
    "MAX_VISITS",
    "MOVE_DIM",
    "MOVE_KINDS",
    "MOVE_LINK_DIM",
    "NEW_DIM",
    "NEW_LINK_DIM",
    "P_DATA_DIM",
    "Preprocessed",
    "curve_to_target",
    "curve_valid",
    "encode_move",
    "encode_new_visits",
    "encode_p_data",
    "link_segments",
    "move_link_features",
    "new_visit_link_features",
    "new_visits",
    "preprocess",
    "target_to_curve",
]

MAX_VISITS = 2 * MAX_CROSSINGS
# per visit: present, over(+1)/under(-1), sign +-1, partner one-hot, (partner - position) / MAX_VISITS
VISIT_DIM = 4 + MAX_VISITS
P_DATA_DIM = MAX_VISITS * VISIT_DIM + MAX_CROSSINGS + 1  # + one-hot of Cross(s) in 0..MAX_CROSSINGS

N_SEGMENTS = N_LINKS
_PAIR_I, _PAIR_J = np.triu_indices(N_SEGMENTS, k=2)  # non-adjacent segment pairs, as in Top
N_PAIRS = len(_PAIR_I)
CROSSING_DIM = 2 * N_PAIRS  # per pair: crossed * (+1 if the earlier segment is over else -1), crossed * sign
VISIT_GEOMETRY_DIM = 5 * MAX_VISITS  # per visit slot: present, arc position, x, y, over
GEOMETRY_DIM = 3 * N_POINTS + CROSSING_DIM + VISIT_GEOMETRY_DIM
# per link: centre (3), planar direction (2), index / 20, crossing-matrix row (2 x 21), visit slots on it
LINK_TOKEN_DIM = 3 + 2 + 1 + 2 * N_SEGMENTS + MAX_VISITS

XY_SCALE_M = 0.5 * ROPE_LENGTH_M  # half the rope length: canonical points lie in about [-1, 1]
Z_REST_M = 0.01  # a link lying on the table (its radius)
Z_SCALE_M = 0.01  # one radius: a strand lying on another sits about one unit up

Z_LOW, Z_HIGH = float(CURVE_LOW[1]), float(CURVE_HIGH[1])
XY_HALF_M = float(CURVE_HIGH[2])  # displacement range is [-XY_HALF_M, XY_HALF_M] on x and y
assert np.allclose(-CURVE_LOW[2:], CURVE_HIGH[2:]), "displacement range must be symmetric"


class EncodingError(ValueError):
    """An input the model cannot encode (for example P-data with too many crossings)."""


def encode_p_data(p: PData) -> npt.NDArray[np.float32]:
    """Fixed-size float32 vector of a P-data state with at most :data:`MAX_CROSSINGS` crossings."""
    if p.cross > MAX_CROSSINGS:
        raise EncodingError(
            f"P-data {p.to_json()} has {p.cross} crossings; the inverse model encodes at most {MAX_CROSSINGS}"
        )
    out = np.zeros(P_DATA_DIM, dtype=np.float32)
    for v in p.visits:
        base = (v.position - 1) * VISIT_DIM
        out[base] = 1.0
        out[base + 1] = 1.0 if v.over == "O" else -1.0
        out[base + 2] = 1.0 if v.sign == "+" else -1.0
        out[base + 3] = (v.partner - v.position) / MAX_VISITS
        out[base + 4 + v.partner - 1] = 1.0
    out[MAX_VISITS * VISIT_DIM + p.cross] = 1.0
    return out


# ---- where the next state's new crossings go ----------------------------------------------------

MAX_NEW_VISITS = 4  # a +2 step adds two crossings: four visits
N_STATE_SEGMENTS = MAX_VISITS + 1  # segments between visits of a state, numbered 0..2n
NEW_VISIT_DIM = 1 + N_STATE_SEGMENTS + 2  # present, segment of the current state (one-hot), over, sign
NEW_DIM = 1 + MAX_NEW_VISITS * NEW_VISIT_DIM  # + "aligned" flag
NEW_LINK_DIM = 3 * MAX_NEW_VISITS  # per link: lies on that segment, x over, x sign


def _without(p: PData, removed: set[int]) -> PData:
    """``p`` with the visits at positions ``removed`` (whole crossings) taken out and renumbered."""
    keep = [v for v in p.visits if v.position not in removed]
    rank = {v.position: r + 1 for r, v in enumerate(keep)}
    return PData(tuple(Visit(rank[v.position], v.over, rank[v.partner], v.sign) for v in keep))


def new_visits(p_from: PData, p_to: PData) -> list[Visit] | None:
    """The visits that ``p_to`` adds to ``p_from``, each with ``position`` = the SEGMENT of ``p_from``
    (0..2n, between its visits) where it lands, or None when ``p_to`` is not ``p_from`` plus new
    crossings (a move that also changed existing crossings).

    Found by deleting each set of ``Cross(p_to) - Cross(p_from)`` crossings from ``p_to`` and
    comparing with ``p_from``; the first match (in crossing order) is used.
    """
    added = p_to.cross - p_from.cross
    if added <= 0 or 2 * added > MAX_NEW_VISITS:
        return None
    crossings = [(v.position, v.partner) for v in p_to.visits if v.over == "O"]
    for chosen in itertools.combinations(crossings, added):
        removed = {q for pair in chosen for q in pair}
        if _without(p_to, removed) == p_from:
            out = []
            for v in p_to.visits:
                if v.position in removed:
                    segment = sum(1 for q in range(1, v.position) if q not in removed)
                    out.append(Visit(segment, v.over, v.partner, v.sign))
            return out
    return None


def encode_new_visits(p_from: PData, p_to: PData) -> npt.NDArray[np.float32]:
    """(NEW_DIM,) float32: aligned flag, then per new visit: present, segment one-hot, over, sign."""
    out = np.zeros(NEW_DIM, dtype=np.float32)
    found = new_visits(p_from, p_to)
    if found is None:
        return out
    out[0] = 1.0
    for k, v in enumerate(found):
        base = 1 + k * NEW_VISIT_DIM
        out[base] = 1.0
        out[base + 1 + v.position] = 1.0
        out[base + 1 + N_STATE_SEGMENTS] = 1.0 if v.over == "O" else -1.0
        out[base + 2 + N_STATE_SEGMENTS] = 1.0 if v.sign == "+" else -1.0
    return out


def new_visit_link_features(pre: Preprocessed, new: torch.Tensor) -> torch.Tensor:
    """(B, N_LINKS, NEW_LINK_DIM): for each link and new visit, whether the link lies on the segment of
    the current rope where that visit lands (x its over/under, x its sign).

    A link's segment is the number of current crossing visits before its middle along the rope.
    """
    link_segment = link_segments(pre)
    slots = new[:, 1:].reshape(len(new), MAX_NEW_VISITS, NEW_VISIT_DIM)
    present = slots[..., 0]
    segment = slots[..., 1 : 1 + N_STATE_SEGMENTS].argmax(dim=2)
    over = slots[..., 1 + N_STATE_SEGMENTS]
    sign = slots[..., 2 + N_STATE_SEGMENTS]
    on = (link_segment[:, :, None] == segment[:, None, :]).to(new.dtype) * present[:, None, :]
    return torch.cat([on, on * over[:, None, :], on * sign[:, None, :]], dim=2)


# ---- the abstract move that should take the rope to the next state -----------------------------

MOVE_KINDS = ("R1", "R2", "Cross")
# known flag, kind one-hot, segment one-hot, side, other segment one-hot, other side, over, sign
MOVE_DIM = 1 + len(MOVE_KINDS) + 2 * N_STATE_SEGMENTS + 4
MOVE_LINK_DIM = 4  # per link: on the move's segment, x its side, on its other segment, x that side


def _side(side: str | None) -> float:
    return 0.0 if side is None else (1.0 if side == "L" else -1.0)


def encode_move(move: Move | None) -> npt.NDArray[np.float32]:
    """(MOVE_DIM,) float32 of an R1 / R2 / Cross move (:class:`twisted.moves.Move`); zeros when None
    (a transition no single move explains). Sides: L +1, R -1; over: O +1, U -1; sign +1 / -1; the
    kind's one-hot entry is -1 for a removing move (``move.remove``), whose segments are those of
    the state it starts from, like an adding move's."""
    out = np.zeros(MOVE_DIM, dtype=np.float32)
    if move is None:
        return out
    if not 0 <= move.segment < N_STATE_SEGMENTS or not (
        move.other_segment is None or 0 <= move.other_segment < N_STATE_SEGMENTS
    ):
        raise EncodingError(f"move {move} starts from more than {MAX_CROSSINGS - 1} crossings")
    out[0] = 1.0
    # a removing move (twisted.moves.removals) is told apart by its kind entry: -1 instead of +1
    out[1 + MOVE_KINDS.index(move.kind)] = -1.0 if move.remove else 1.0
    base = 1 + len(MOVE_KINDS)
    out[base + move.segment] = 1.0
    if move.other_segment is not None:
        out[base + N_STATE_SEGMENTS + move.other_segment] = 1.0
    tail = base + 2 * N_STATE_SEGMENTS
    out[tail] = _side(move.side)
    out[tail + 1] = _side(move.other_side)
    out[tail + 2] = 0.0 if move.over is None else (1.0 if move.over == "O" else -1.0)
    out[tail + 3] = 0.0 if move.sign is None else (1.0 if move.sign == "+" else -1.0)
    return out


def link_segments(pre: Preprocessed) -> torch.Tensor:
    """(B, N_LINKS) long: the segment of the current state each link lies on (visits before its middle)."""
    mids = torch.arange(N_LINKS, dtype=pre.visit_arcs.dtype, device=pre.visit_arcs.device) + 0.5
    return (pre.visit_arcs[:, None, :] < mids[None, :, None]).sum(dim=2)  # inf never counts


def move_link_features(pre: Preprocessed, move: torch.Tensor) -> torch.Tensor:
    """(B, N_LINKS, MOVE_LINK_DIM): for each link, whether it lies on the move's segment (and that side),
    and on its other segment (and that side): where the move says the new crossings go."""
    base = 1 + len(MOVE_KINDS)
    tail = base + 2 * N_STATE_SEGMENTS
    segment = move[:, base : base + N_STATE_SEGMENTS].argmax(dim=1)
    other = move[:, base + N_STATE_SEGMENTS : tail]
    known, has_other = move[:, 0], other.sum(dim=1)
    link_segment = link_segments(pre)
    on = (link_segment == segment[:, None]).to(move.dtype) * known[:, None]
    on_other = (link_segment == other.argmax(dim=1)[:, None]).to(move.dtype) * has_other[:, None]
    return torch.stack([on, on * move[:, tail, None], on_other, on_other * move[:, tail + 1, None]], dim=2)


@dataclass
class Preprocessed:
    """The geometric input of a batch in the canonical frame (see the module docstring)."""

    features: torch.Tensor  # (B, GEOMETRY_DIM) whole-rope features
    link_tokens: torch.Tensor  # (B, N_LINKS, LINK_TOKEN_DIM) per-link features
    visit_arcs: torch.Tensor  # (B, MAX_VISITS) position of each crossing visit along the rope (inf: none)
    centre: torch.Tensor  # (B, 2) world xy of the canonical origin (m)
    cos: torch.Tensor  # (B,) rotation world -> canonical is by -angle
    sin: torch.Tensor  # (B,)


@dataclass
class Crossings:
    """Crossings of the projected rope, batched (see :func:`crossing_features`)."""

    pairs: torch.Tensor  # (B, CROSSING_DIM)
    visits: torch.Tensor  # (B, VISIT_GEOMETRY_DIM)
    per_link: torch.Tensor  # (B, N_LINKS, 2 * N_LINKS + MAX_VISITS)
    arcs: torch.Tensor  # (B, MAX_VISITS) segment + t of each visit in P-data order, inf when absent


# The torch twin of twisted.topology.cross2 / projected_crossings: the encoder runs batched on the
# model's device (GPU too) and keeps every segment pair as a fixed-size feature, hit or not, so the numpy
# function (one rope, hits only) cannot be reused here.
def _cross2(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def crossing_features(points: torch.Tensor) -> Crossings:
    """Crossings of the projected rope, batched, by the same test as :func:`twisted.topology.top`.

    * ``pairs``: per non-adjacent segment pair, crossed x (+1 if the earlier segment is over,
      else -1) and crossed x sign.
    * ``visits``: per visit slot 1..12, the visits in the order P-data numbers them: present,
      position along the rope / N_LINKS, planar location, over (+1) / under (-1). This ties the
      P-data's visit numbers to places on the rope.
    * ``per_link``: per link (segment) k, its row of the crossing matrix (with every other
      segment: +1 over / -1 under where they cross, and the sign) and which visit slots lie on it.

    Rotation/translation invariant except the locations, so it runs on canonical points.
    """
    batch = points.shape[0]
    start = points[:, :-1]
    d = points[:, 1:] - points[:, :-1]
    i = torch.as_tensor(_PAIR_I, device=points.device)
    j = torch.as_tensor(_PAIR_J, device=points.device)
    di, dj = d[:, i, :2], d[:, j, :2]
    w = start[:, j, :2] - start[:, i, :2]
    denom = _cross2(di, dj)
    ok = denom.abs() > 1e-12
    safe = torch.where(ok, denom, torch.ones_like(denom))
    t = _cross2(w, dj) / safe
    u = _cross2(w, di) / safe
    hit = ok & (t >= 0) & (t < 1) & (u >= 0) & (u < 1)
    zi = start[:, i, 2] + t * d[:, i, 2]
    zj = start[:, j, 2] + u * d[:, j, 2]
    i_over = zi >= zj
    d_over = torch.where(i_over[..., None], di, dj)
    d_under = torch.where(i_over[..., None], dj, di)
    sign = torch.where(_cross2(d_over, d_under) > 0, 1.0, -1.0).to(points.dtype)
    hit_f = hit.to(points.dtype)
    over_f = torch.where(i_over, 1.0, -1.0).to(points.dtype)
    pairs = torch.cat([hit_f * over_f, hit_f * sign], dim=1)

    inf = torch.full_like(t, math.inf)
    param = torch.cat([torch.where(hit, i + t, inf), torch.where(hit, j + u, inf)], dim=1)
    order = param.argsort(dim=1)[:, :MAX_VISITS]
    arc = param.gather(1, order)
    present = torch.isfinite(arc)
    loc = start[:, i, :2] + t[..., None] * di
    loc2 = torch.cat([loc, loc], dim=1).gather(1, order[..., None].expand(-1, -1, 2))
    over2 = torch.cat([over_f, -over_f], dim=1).gather(1, order)
    p = present.to(points.dtype)
    arc0 = torch.where(present, arc, 0.0)
    visits = torch.stack([p, arc0 / N_LINKS, p * loc2[..., 0], p * loc2[..., 1], p * over2], dim=2)

    over_matrix = points.new_zeros(batch, N_SEGMENTS, N_SEGMENTS)
    sign_matrix = points.new_zeros(batch, N_SEGMENTS, N_SEGMENTS)
    over_matrix[:, i, j] = hit_f * over_f
    over_matrix[:, j, i] = -hit_f * over_f
    sign_matrix[:, i, j] = hit_f * sign
    sign_matrix[:, j, i] = hit_f * sign
    segment = arc0.floor().long().clamp(0, N_SEGMENTS - 1)
    on_segment = torch.nn.functional.one_hot(segment, N_SEGMENTS).to(points.dtype) * p[..., None]
    per_link = torch.cat([over_matrix, sign_matrix, on_segment.transpose(1, 2)], dim=2)
    return Crossings(pairs=pairs, visits=visits.flatten(1), per_link=per_link, arcs=arc)


def preprocess(points: torch.Tensor | npt.ArrayLike) -> Preprocessed:
    """Canonical-frame geometric features of link points, shape (B, N_POINTS, 3) or (N_POINTS, 3) (metres)."""
    pts = torch.as_tensor(points, dtype=torch.float32)
    if pts.ndim == 2:
        pts = pts[None]
    if pts.ndim != 3 or pts.shape[1:] != (N_POINTS, 3):
        raise EncodingError(f"link points must have shape (B, {N_POINTS}, 3), got {tuple(pts.shape)}")
    centre = pts[:, :, :2].mean(dim=1)
    axis = pts[:, -1, :2] - pts[:, 0, :2]
    angle = torch.atan2(axis[:, 1], axis[:, 0])  # atan2(0, 0) = 0: a closed rope keeps the world frame
    cos, sin = torch.cos(angle), torch.sin(angle)
    xy = rotate(pts[:, :, :2] - centre[:, None], cos[:, None], -sin[:, None])
    canon = torch.cat([xy / XY_SCALE_M, (pts[:, :, 2:] - Z_REST_M) / Z_SCALE_M], dim=2)
    cx = crossing_features(canon)
    features = torch.cat([canon.flatten(1), cx.pairs, cx.visits], dim=1)
    direction = canon[:, 1:, :2] - canon[:, :-1, :2]
    direction = direction / direction.norm(dim=2, keepdim=True).clamp_min(1e-6)
    index = torch.arange(N_LINKS, dtype=pts.dtype, device=pts.device) / (N_LINKS - 1)
    index = index.expand(pts.shape[0], -1)[..., None]
    link_tokens = torch.cat([0.5 * (canon[:, 1:] + canon[:, :-1]), direction, index, cx.per_link], dim=2)
    return Preprocessed(
        features=features, link_tokens=link_tokens, visit_arcs=cx.arcs, centre=centre, cos=cos, sin=sin
    )


def rotate(xy: torch.Tensor, cos: torch.Tensor, sin: torch.Tensor) -> torch.Tensor:
    """Rotate planar vectors (..., 2) by the angle whose cosine/sine are given (broadcast)."""
    x, y = xy[..., 0], xy[..., 1]
    return torch.stack([cos * x - sin * y, sin * x + cos * y], dim=-1)


def curve_to_target(curve: torch.Tensor, pre: Preprocessed) -> tuple[torch.Tensor, torch.Tensor]:
    """World curves (B, 4) = (link, z_max_m, x_m, y_m) -> (link (B,) long, target (B, 3) normalised)."""
    link = curve[:, 0].round().long()
    z = 2.0 * (curve[:, 1] - Z_LOW) / (Z_HIGH - Z_LOW) - 1.0
    xy = rotate(curve[:, 2:4], pre.cos, -pre.sin) / XY_HALF_M
    return link, torch.cat([z[:, None], xy], dim=1)


def target_to_curve(link: torch.Tensor, target: torch.Tensor, pre: Preprocessed) -> torch.Tensor:
    """Inverse of :func:`curve_to_target`: world curves (B, 4) as float tensor."""
    z = Z_LOW + 0.5 * (target[:, 0] + 1.0) * (Z_HIGH - Z_LOW)
    xy = rotate(target[:, 1:3] * XY_HALF_M, pre.cos, pre.sin)
    return torch.cat([link.to(target.dtype)[:, None], z[:, None], xy], dim=1)


def curve_valid(curve: torch.Tensor) -> torch.Tensor:
    """(B,) bool: the world curve lies inside CURVE_LOW..CURVE_HIGH (link checked by the caller)."""
    low = torch.as_tensor(CURVE_LOW[1:], dtype=curve.dtype, device=curve.device)
    high = torch.as_tensor(CURVE_HIGH[1:], dtype=curve.dtype, device=curve.device)
    return ((curve[:, 1:] >= low) & (curve[:, 1:] <= high)).all(dim=1)
