"""Training data of the inverse model, read from the store once, in chunks.

Every kept transition (``Cross(s') > Cross(s)``: +1 and +2 crossing steps alike) becomes one
sample: the start configuration's link points, the curve, and the indices of the start and next
P-data states. States are few, so each distinct state is encoded once, in the four symmetry
variants (identity, mirror, reverse, both: :mod:`twisted.model.augment`), and a batch picks the
variant per sample. The train/validation split hashes the START configuration id with the seed,
so validation never contains a start configuration seen in training.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
import torch
from sqlalchemy import func, select

from twisted.model.augment import VARIANTS, apply_variant_p_data
from twisted.model.encoding import MAX_CROSSINGS, NEW_DIM, P_DATA_DIM, encode_new_visits, encode_p_data
from twisted.sim import N_POINTS
from twisted.store.db import Store
from twisted.store.models import Configuration, TopologicalState, Transition, blob_to_array
from twisted.topology import PData, parse_p_data

__all__ = [
    "NoTrainingDataError",
    "TransitionData",
    "encode_pairs",
    "encode_states",
    "load_transitions",
    "max_transition_id",
    "split_by_start",
    "transitions_from_samples",
]

CHUNK_SIZE = 4096


class NoTrainingDataError(RuntimeError):
    """The database holds no usable transitions (the message tells the user to collect first)."""


@dataclass
class TransitionData:
    """Samples as tensors; ``from_state``/``to_state`` index ``state_enc`` (S, 4 variants, P_DATA_DIM)."""

    transition_ids: npt.NDArray[np.int64]
    start_ids: npt.NDArray[np.int64]  # from_configuration_id
    from_cross: npt.NDArray[np.int64]
    to_cross: npt.NDArray[np.int64]
    points: torch.Tensor  # (N, 22, 3) world frame, metres
    curves: torch.Tensor  # (N, 4) link, z_max_m, x_m, y_m
    from_state: torch.Tensor  # (N,) long
    to_state: torch.Tensor  # (N,) long
    state_enc: torch.Tensor  # (S, 4, P_DATA_DIM)
    state_keys: list[str]
    pair: torch.Tensor  # (N,) long: index of (from_state, to_state) in pair_enc
    pair_enc: torch.Tensor  # (P, 4, NEW_DIM): where the new visits land, per symmetry variant

    def __len__(self) -> int:
        return len(self.transition_ids)

    def subset(self, index: npt.NDArray[np.int64]) -> TransitionData:
        t = torch.as_tensor(index, dtype=torch.long)
        return TransitionData(
            transition_ids=self.transition_ids[index],
            start_ids=self.start_ids[index],
            from_cross=self.from_cross[index],
            to_cross=self.to_cross[index],
            points=self.points[t],
            curves=self.curves[t],
            from_state=self.from_state[t],
            to_state=self.to_state[t],
            state_enc=self.state_enc,
            state_keys=self.state_keys,
            pair=self.pair[t],
            pair_enc=self.pair_enc,
        )

    def to(self, device: torch.device | str) -> TransitionData:
        return replace(
            self,
            points=self.points.to(device),
            curves=self.curves.to(device),
            from_state=self.from_state.to(device),
            to_state=self.to_state.to(device),
            state_enc=self.state_enc.to(device),
            pair=self.pair.to(device),
            pair_enc=self.pair_enc.to(device),
        )


def _usable() -> list:  # type: ignore[type-arg]
    # +1 and +2 steps alike; states beyond the encoding's limit cannot be targets.
    return [Transition.to_cross > Transition.from_cross, Transition.to_cross <= MAX_CROSSINGS]


def max_transition_id(store: Store) -> int | None:
    """The newest usable transition id (the data snapshot a training run reads), None if none."""
    with store.session() as session:
        return session.scalar(select(func.max(Transition.id)).where(*_usable()))


def load_transitions(
    store: Store,
    *,
    max_id: int | None = None,
    chunk_size: int = CHUNK_SIZE,
    progress: Callable[[int, int], None] | None = None,
) -> TransitionData:
    """All usable transitions with ``id <= max_id`` (all when None), read in chunks of ``chunk_size``.

    Arrays are allocated once from a COUNT and filled chunk by chunk, so the rows are never held
    twice. Raises :class:`NoTrainingDataError` when there is nothing to train on.
    """
    where = _usable() + ([Transition.id <= max_id] if max_id is not None else [])
    with store.session() as session:
        n = int(session.scalar(select(func.count()).select_from(Transition).where(*where)) or 0)
        if n == 0:
            raise NoTrainingDataError(
                f"the database {store.url.render_as_string(hide_password=True)} holds no transitions that "
                "add crossings: collect first (`twisted collect`), then train"
            )
        ids = np.empty(n, dtype=np.int64)
        start_ids = np.empty(n, dtype=np.int64)
        from_cross = np.empty(n, dtype=np.int64)
        to_cross = np.empty(n, dtype=np.int64)
        state_db_ids = np.empty((n, 2), dtype=np.int64)
        curves = np.empty((n, 4), dtype=np.float32)
        points = np.empty((n, N_POINTS, 3), dtype=np.float32)
        stmt = (
            select(
                Transition.id,
                Transition.from_configuration_id,
                Transition.from_cross,
                Transition.to_cross,
                Transition.from_state_id,
                Transition.to_state_id,
                Transition.link,
                Transition.z_max_m,
                Transition.x_m,
                Transition.y_m,
                Configuration.points,
            )
            .join(Configuration, Configuration.id == Transition.from_configuration_id)
            .where(*where)
            .order_by(Transition.id)
            .execution_options(yield_per=chunk_size)
        )
        i = 0
        for partition in session.execute(stmt).partitions():
            # rows committed after the COUNT (a collector is running, max_id None) are not ours
            for row in partition[: n - i]:
                ids[i], start_ids[i], from_cross[i], to_cross[i], state_db_ids[i, 0], state_db_ids[i, 1] = (
                    row[:6]
                )
                curves[i] = row[6:10]
                points[i] = blob_to_array(row[10], (N_POINTS, 3))
                i += 1
            if progress is not None:
                progress(i, n)
        ids, start_ids, from_cross, to_cross = ids[:i], start_ids[:i], from_cross[:i], to_cross[:i]
        state_db_ids, curves, points = state_db_ids[:i], curves[:i], points[:i]
        unique_states, inverse = np.unique(state_db_ids.reshape(-1), return_inverse=True)
        rows = session.execute(
            select(TopologicalState.id, TopologicalState.p_data).where(
                TopologicalState.id.in_(unique_states.tolist())
            )
        ).all()
    p_by_id = {sid: parse_p_data(p) for sid, p in rows}
    states = [p_by_id[sid] for sid in unique_states.tolist()]
    state_enc = encode_states(states)
    inverse = inverse.reshape(-1, 2)
    pair, pair_enc = encode_pairs(inverse, states)
    return TransitionData(
        transition_ids=ids,
        start_ids=start_ids,
        from_cross=from_cross,
        to_cross=to_cross,
        points=torch.from_numpy(points),
        curves=torch.from_numpy(curves),
        from_state=torch.as_tensor(inverse[:, 0], dtype=torch.long),
        to_state=torch.as_tensor(inverse[:, 1], dtype=torch.long),
        state_enc=state_enc,
        state_keys=[p.key for p in states],
        pair=pair,
        pair_enc=pair_enc,
    )


def encode_states(states: Sequence[PData]) -> torch.Tensor:
    """(S, 4, P_DATA_DIM): every state encoded in the four symmetry variants."""
    out = np.empty((len(states), len(VARIANTS), P_DATA_DIM), dtype=np.float32)
    for s, p in enumerate(states):
        for v in range(len(VARIANTS)):
            out[s, v] = encode_p_data(apply_variant_p_data(p, v))
    return torch.from_numpy(out)


def encode_pairs(index: npt.NDArray[np.int64], states: Sequence[PData]) -> tuple[torch.Tensor, torch.Tensor]:
    """For (N, 2) (from, to) state indices: (N,) pair index and (P, 4, NEW_DIM) new-visit encodings
    of every distinct pair in the four symmetry variants."""
    unique, inverse = np.unique(index, axis=0, return_inverse=True)
    out = np.empty((len(unique), len(VARIANTS), NEW_DIM), dtype=np.float32)
    for k, (a, b) in enumerate(unique.tolist()):
        for v in range(len(VARIANTS)):
            out[k, v] = encode_new_visits(
                apply_variant_p_data(states[a], v), apply_variant_p_data(states[b], v)
            )
    return torch.as_tensor(inverse.reshape(-1), dtype=torch.long), torch.from_numpy(out)


def transitions_from_samples(
    points: npt.ArrayLike,
    curves: npt.ArrayLike,
    p_from: Sequence[PData],
    p_to: Sequence[PData],
    start_ids: npt.ArrayLike | None = None,
) -> TransitionData:
    """:class:`TransitionData` from in-memory samples (benchmarks, tests); ids are 0..N-1 by default."""
    keys: dict[str, int] = {}
    states: list[PData] = []
    index = np.empty((len(p_from), 2), dtype=np.int64)
    for i, both in enumerate(zip(p_from, p_to, strict=True)):
        for j, p in enumerate(both):
            if p.key not in keys:
                keys[p.key] = len(states)
                states.append(p)
            index[i, j] = keys[p.key]
    n = len(p_from)
    ids = np.arange(n, dtype=np.int64)
    pair, pair_enc = encode_pairs(index, states)
    return TransitionData(
        transition_ids=ids,
        start_ids=ids.copy() if start_ids is None else np.asarray(start_ids, dtype=np.int64),
        from_cross=np.array([p.cross for p in p_from], dtype=np.int64),
        to_cross=np.array([p.cross for p in p_to], dtype=np.int64),
        points=torch.as_tensor(np.asarray(points), dtype=torch.float32),
        curves=torch.as_tensor(np.asarray(curves), dtype=torch.float32),
        from_state=torch.as_tensor(index[:, 0]),
        to_state=torch.as_tensor(index[:, 1]),
        state_enc=encode_states(states),
        state_keys=[p.key for p in states],
        pair=pair,
        pair_enc=pair_enc,
    )


def _mix64(x: npt.NDArray[np.uint64]) -> npt.NDArray[np.uint64]:
    """splitmix64 finaliser: a fixed, platform-independent hash of 64-bit integers."""
    with np.errstate(over="ignore"):
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return x ^ (x >> np.uint64(31))


def split_by_start(
    start_ids: npt.ArrayLike, val_fraction: float, seed: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """(train indices, validation indices): a start configuration falls wholly on one side."""
    ids = np.asarray(start_ids, dtype=np.int64).astype(np.uint64)
    with np.errstate(over="ignore"):
        h = _mix64(ids ^ _mix64(np.full_like(ids, np.uint64(seed & 0xFFFFFFFFFFFFFFFF))))
    u = (h >> np.uint64(11)).astype(np.float64) / float(1 << 53)
    val = u < val_fraction
    return np.flatnonzero(~val), np.flatnonzero(val)
