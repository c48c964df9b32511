"""Training data of the inverse model, read from the store once, in chunks.

Two sources of samples (:data:`SOURCES`):

* ``collect``: every kept transition (``Cross(s') > Cross(s)``: +1 and +2 crossing steps alike);
* ``search``: every edge of the planner trees ``T`` in ``search_nodes`` that adds crossings: the
  parent node's configuration, the curve, and the state the child reached. Each reached state is a
  goal this curve achieves (hindsight), with exactly the planner's distribution of configurations.

A sample is the start configuration's link points, the curve, and the indices of the start and next
P-data states. States are few, so each distinct state is encoded once, in the four symmetry
variants (identity, mirror, reverse, both: :mod:`twisted.model.augment`), and a batch picks the
variant per sample; so is each distinct (start, next) pair: where the new visits land and the move
that makes the step (the first in :func:`twisted.moves.successors` order, :func:`twisted.moves.explains`,
in each variant's own frame: the planner passes the first move of its plans, so training labels match
what inference is given). The train/validation split hashes the START configuration with the seed,
so validation never contains a start configuration seen in training: a transition's start is its
``from_configuration_id``; a tree edge's is its parent node (key ``-node id``), except that an edge
from a tree's root takes the run's start configuration (the D_Q straight rope for runs from it), so
that both sources put one configuration on one side. A held-out problem set (``hold_out_sets``:
the sets a model is then evaluated on) leaves out the trees of runs whose goal is one of its goals,
and every sample of either source that reaches one of its goal states (for a knot goal, any state
of that knot at its crossing count), so that a model has never been shown a curve into a goal it is
then evaluated on.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
import torch
from sqlalchemy import func, select
from sqlalchemy.orm import Session, aliased

from twisted.goals import Goal, make_goal
from twisted.model.augment import VARIANTS, apply_variant_p_data
from twisted.model.config import SOURCES
from twisted.model.encoding import (
    MAX_CROSSINGS,
    MOVE_DIM,
    NEW_DIM,
    P_DATA_DIM,
    encode_move,
    encode_new_visits,
    encode_p_data,
)
from twisted.moves import explains
from twisted.sim import N_POINTS
from twisted.store.db import Store
from twisted.store.experiments import Problem, ProblemSet
from twisted.store.models import Configuration, Run, TopologicalState, Transition, blob_to_array
from twisted.store.search_tree import SearchNode, SearchRunRow
from twisted.topology import PData, parse_p_data

__all__ = [
    "NoTrainingDataError",
    "TransitionData",
    "UnknownProblemSetError",
    "check_hold_out_sets",
    "encode_pairs",
    "encode_states",
    "load_samples",
    "load_transitions",
    "load_tree_edges",
    "max_search_node_id",
    "max_transition_id",
    "split_by_start",
    "transitions_from_samples",
]

CHUNK_SIZE = 4096
COLLECT, SEARCH = 0, 1


class NoTrainingDataError(RuntimeError):
    """The database holds no usable transitions (the message tells the user to collect first)."""


@dataclass
class TransitionData:
    """Samples as tensors; ``from_state``/``to_state`` index ``state_enc`` (S, 4 variants, P_DATA_DIM).

    ``transition_ids`` are transition ids for ``source`` 0 (collect) and search node ids for 1 (search).
    """

    transition_ids: npt.NDArray[np.int64]
    start_ids: npt.NDArray[np.int64]  # the split key: the start configuration (see the module docstring)
    from_cross: npt.NDArray[np.int64]
    to_cross: npt.NDArray[np.int64]
    points: torch.Tensor  # (N, N_POINTS, 3) world frame, metres
    curves: torch.Tensor  # (N, 4) link, z_max_m, x_m, y_m
    from_state: torch.Tensor  # (N,) long
    to_state: torch.Tensor  # (N,) long
    state_enc: torch.Tensor  # (S, 4, P_DATA_DIM)
    state_keys: list[str]
    pair: torch.Tensor  # (N,) long: index of (from_state, to_state) in pair_enc
    pair_enc: torch.Tensor  # (P, 4, NEW_DIM): where the new visits land, per symmetry variant
    move_enc: torch.Tensor  # (P, 4, MOVE_DIM): the move that makes the step, per symmetry variant
    source: npt.NDArray[np.int64]  # index into SOURCES

    def __len__(self) -> int:
        return len(self.transition_ids)

    def count_by_source(self) -> dict[str, int]:
        """Samples per source name."""
        counts = np.bincount(self.source, minlength=len(SOURCES))
        return {name: int(counts[i]) for i, name in enumerate(SOURCES)}

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
            move_enc=self.move_enc,
            source=self.source[index],
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
            move_enc=self.move_enc.to(device),
        )


def _usable(removing: bool = False) -> list:  # type: ignore[type-arg]
    # +1 and +2 steps alike (and -1, -2 with ``removing``); states beyond the encoding's limit
    # cannot be targets, nor starts (a removing move's segments are those of the state it starts from).
    if removing:
        return [
            Transition.to_cross != Transition.from_cross,
            Transition.to_cross <= MAX_CROSSINGS,
            Transition.from_cross <= MAX_CROSSINGS,
        ]
    return [Transition.to_cross > Transition.from_cross, Transition.to_cross <= MAX_CROSSINGS]


def max_transition_id(store: Store, *, removing: bool = False) -> int | None:
    """The newest usable transition id (the data snapshot a training run reads), None if none;
    ``removing``: transitions that remove crossings count as usable too."""
    with store.session() as session:
        return session.scalar(select(func.max(Transition.id)).where(*_usable(removing)))


@dataclass
class _Rows:
    """Samples as read from the store, before the states are encoded."""

    ids: npt.NDArray[np.int64]
    start_ids: npt.NDArray[np.int64]
    from_cross: npt.NDArray[np.int64]
    to_cross: npt.NDArray[np.int64]
    state_db_ids: npt.NDArray[np.int64]  # (N, 2) topological_states ids of (from, to)
    curves: npt.NDArray[np.float32]
    points: npt.NDArray[np.float32]
    source: int

    @classmethod
    def empty(cls, n: int, source: int) -> _Rows:
        return cls(
            np.empty(n, dtype=np.int64),
            np.empty(n, dtype=np.int64),
            np.empty(n, dtype=np.int64),
            np.empty(n, dtype=np.int64),
            np.empty((n, 2), dtype=np.int64),
            np.empty((n, 4), dtype=np.float32),
            np.empty((n, N_POINTS, 3), dtype=np.float32),
            source,
        )

    def head(self, n: int) -> _Rows:
        return _Rows(
            self.ids[:n],
            self.start_ids[:n],
            self.from_cross[:n],
            self.to_cross[:n],
            self.state_db_ids[:n],
            self.curves[:n],
            self.points[:n],
            self.source,
        )


def _no_data(store: Store, sources: Sequence[str]) -> NoTrainingDataError:
    what = " or ".join({"collect": "transitions", "search": "planner tree edges"}[s] for s in sources)
    return NoTrainingDataError(
        f"the database {store.url.render_as_string(hide_password=True)} holds no {what} that add crossings: "
        "collect first (`twisted collect`), then train"
    )


def load_transitions(
    store: Store,
    *,
    max_id: int | None = None,
    chunk_size: int = CHUNK_SIZE,
    progress: Callable[[int, int], None] | None = None,
    removing: bool = False,
) -> TransitionData:
    """All usable transitions with ``id <= max_id`` (all when None), read in chunks of ``chunk_size``;
    with ``removing`` those that remove crossings too.

    Arrays are allocated once from a COUNT and filled chunk by chunk, so the rows are never held
    twice. Raises :class:`NoTrainingDataError` when there is nothing to train on.
    """
    return load_samples(
        store, ("collect",), max_id=max_id, chunk_size=chunk_size, progress=progress, removing=removing
    )


def load_tree_edges(
    store: Store, *, max_node_id: int | None = None, hold_out_sets: Sequence[str] = ()
) -> TransitionData:
    """Every planner tree edge adding crossings (up to :data:`MAX_CROSSINGS`), node id <= ``max_node_id``,
    except in the trees of runs towards a goal of one of ``hold_out_sets`` and those reaching one of
    its goal states."""
    return load_samples(store, ("search",), max_node_id=max_node_id, hold_out_sets=hold_out_sets)


class UnknownProblemSetError(ValueError):
    """A held-out problem set that the database does not have."""


def check_hold_out_sets(store: Store, names: Sequence[str]) -> None:
    """Raise :class:`UnknownProblemSetError` naming every set of ``names`` the store lacks."""
    if not names:
        return
    with store.session() as session:
        known = set(session.scalars(select(ProblemSet.name).where(ProblemSet.name.in_(list(names)))))
        missing = [n for n in names if n not in known]
        if missing:
            have = sorted(session.scalars(select(ProblemSet.name)))
            raise UnknownProblemSetError(
                f"no problem set named {', '.join(repr(n) for n in missing)} in the database "
                f"(it has: {', '.join(have) or 'none'})"
            )


def load_samples(
    store: Store,
    sources: Sequence[str] = ("collect",),
    *,
    max_id: int | None = None,
    max_node_id: int | None = None,
    hold_out_sets: Sequence[str] = (),
    chunk_size: int = CHUNK_SIZE,
    progress: Callable[[int, int], None] | None = None,
    removing: bool = False,
) -> TransitionData:
    """Samples of the given :data:`SOURCES`: transitions up to ``max_id`` (those that remove
    crossings too with ``removing``), tree edges that add crossings up to ``max_node_id`` (None: all)
    outside the trees of runs towards a goal of ``hold_out_sets``, and none of either source that
    reaches one of their goal states.
    Raises :class:`NoTrainingDataError` when there are none."""
    unknown = [s for s in sources if s not in SOURCES]
    if unknown or not sources:
        raise ValueError(f"sources must be among {', '.join(SOURCES)}, got {', '.join(sources) or 'none'}")
    parts: list[_Rows] = []
    with store.session() as session:
        goals = _held_out_goals(session, hold_out_sets) if hold_out_sets else []
        goal_states = _goal_state_ids(session, goals)
        if "collect" in sources:
            parts.append(_read_transitions(session, max_id, chunk_size, progress, goal_states, removing))
        if "search" in sources:
            parts.append(_read_tree_edges(session, max_node_id, goals, goal_states))
        n = sum(len(p.ids) for p in parts)
        if n == 0:
            raise _no_data(store, sources)
        state_db_ids = np.concatenate([p.state_db_ids for p in parts])
        unique_states, inverse = np.unique(state_db_ids.reshape(-1), return_inverse=True)
        rows = session.execute(
            select(TopologicalState.id, TopologicalState.p_data).where(
                TopologicalState.id.in_(unique_states.tolist())
            )
        ).all()
    p_by_id = {sid: parse_p_data(p) for sid, p in rows}
    states = [p_by_id[sid] for sid in unique_states.tolist()]
    inverse = inverse.reshape(-1, 2)
    pair, pair_enc, move_enc = encode_pairs(inverse, states)
    return TransitionData(
        transition_ids=np.concatenate([p.ids for p in parts]),
        start_ids=np.concatenate([p.start_ids for p in parts]),
        from_cross=np.concatenate([p.from_cross for p in parts]),
        to_cross=np.concatenate([p.to_cross for p in parts]),
        points=torch.from_numpy(np.concatenate([p.points for p in parts])),
        curves=torch.from_numpy(np.concatenate([p.curves for p in parts])),
        from_state=torch.as_tensor(inverse[:, 0], dtype=torch.long),
        to_state=torch.as_tensor(inverse[:, 1], dtype=torch.long),
        state_enc=encode_states(states),
        state_keys=[p.key for p in states],
        pair=pair,
        pair_enc=pair_enc,
        move_enc=move_enc,
        source=np.concatenate([np.full(len(p.ids), p.source, dtype=np.int64) for p in parts]),
    )


def _read_transitions(
    session: Session,
    max_id: int | None,
    chunk_size: int,
    progress: Callable[[int, int], None] | None,
    held_out_states: Sequence[int] = (),
    removing: bool = False,
) -> _Rows:
    where = _usable(removing) + ([Transition.id <= max_id] if max_id is not None else [])
    if held_out_states:
        where.append(Transition.to_state_id.not_in(list(held_out_states)))
    n = int(session.scalar(select(func.count()).select_from(Transition).where(*where)) or 0)
    out = _Rows.empty(n, COLLECT)
    if n == 0:
        return out
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
            out.ids[i], out.start_ids[i], out.from_cross[i], out.to_cross[i] = row[:4]
            out.state_db_ids[i] = row[4:6]
            out.curves[i] = row[6:10]
            out.points[i] = blob_to_array(row[10], (N_POINTS, 3))
            i += 1
        if progress is not None:
            progress(i, n)
    return out.head(i)


def _straight_rope_configuration(session: Session) -> int:
    """The D_Q configuration of the straight rope (the collect root), 0 when there is none."""
    found = session.scalar(
        select(func.min(Configuration.id))
        .join(Run, Run.id == Configuration.run_id)
        .where(Run.kind == "collect", Configuration.cross == 0)
    )
    return int(found or 0)


def _read_tree_edges(
    session: Session,
    max_node_id: int | None,
    held_out_goals: Sequence[Goal] = (),
    held_out_states: Sequence[int] = (),
) -> _Rows:
    parent = aliased(SearchNode)
    where = [
        SearchNode.parent_id.is_not(None),
        SearchNode.link.is_not(None),
        SearchNode.cross > parent.cross,
        SearchNode.cross <= MAX_CROSSINGS,
    ] + ([SearchNode.id <= max_node_id] if max_node_id is not None else [])
    if held_out_goals:
        where.append(SearchNode.run_id.not_in(_held_out_runs(session, held_out_goals)))
    if held_out_states:
        where.append(SearchNode.state_id.not_in(list(held_out_states)))
    stmt = (
        select(
            SearchNode.id,
            parent.id,
            parent.seq,
            SearchRunRow.start_configuration_id,
            parent.cross,
            SearchNode.cross,
            parent.state_id,
            SearchNode.state_id,
            SearchNode.link,
            SearchNode.z_max_m,
            SearchNode.x_m,
            SearchNode.y_m,
            parent.points,
        )
        .join(parent, parent.id == SearchNode.parent_id)
        .join(SearchRunRow, SearchRunRow.run_id == SearchNode.run_id)
        .where(*where)
        .order_by(SearchNode.id)
    )
    rows = session.execute(stmt).all()
    out = _Rows.empty(len(rows), SEARCH)
    straight = _straight_rope_configuration(session)
    for i, row in enumerate(rows):
        node_id, parent_id, parent_seq, run_start = row[:4]
        out.ids[i] = node_id
        if parent_seq == 0:
            out.start_ids[i] = run_start if run_start is not None else straight
        else:
            out.start_ids[i] = -parent_id
        out.from_cross[i], out.to_cross[i] = row[4:6]
        out.state_db_ids[i] = row[6:8]
        out.curves[i] = row[8:12]
        out.points[i] = blob_to_array(row[12], (N_POINTS, 3))
    return out


def _held_out_goals(session: Session, set_names: Sequence[str]) -> list[Goal]:
    """The goals of the named problem sets."""
    specs = session.scalars(
        select(Problem.goal_key)
        .join(ProblemSet, ProblemSet.id == Problem.set_id)
        .where(ProblemSet.name.in_(list(set_names)))
    ).all()
    return [make_goal(spec) for spec in specs]


def _goal_state_ids(session: Session, goals: Sequence[Goal]) -> list[int]:
    """The stored states (ids) that are members of ``goals``: a P-data goal's state, every member
    state of a knot goal."""
    keys = sorted({key for goal in goals for key in goal.keys})
    if not keys:
        return []
    return sorted(session.scalars(select(TopologicalState.id).where(TopologicalState.key.in_(keys))).all())


def _held_out_runs(session: Session, goals: Sequence[Goal]) -> list[int]:
    """The planner runs towards one of ``goals``: the same P-data goal, or for a knot goal
    (``knot:<name>@<crossings>``) the same knot from the same crossing count."""
    state_keys = [g.representative.key for g in goals if g.knot is None]
    knots = {(g.knot, g.cross) for g in goals if g.knot is not None}
    runs = set(
        session.scalars(
            select(SearchRunRow.run_id)
            .join(TopologicalState, TopologicalState.id == SearchRunRow.goal_state_id)
            .where(SearchRunRow.goal_knot.is_(None), TopologicalState.key.in_(state_keys))
        )
    )
    for knot, cross in knots:
        runs.update(
            session.scalars(
                select(SearchRunRow.run_id).where(
                    SearchRunRow.goal_knot == knot, SearchRunRow.goal_cross == cross
                )
            )
        )
    return sorted(runs)


def max_search_node_id(store: Store) -> int | None:
    """The newest search node id (the tree snapshot a training run reads), None if there is none."""
    with store.session() as session:
        return session.scalar(select(func.max(SearchNode.id)))


def encode_states(states: Sequence[PData]) -> torch.Tensor:
    """(S, 4, P_DATA_DIM): every state encoded in the four symmetry variants."""
    out = np.empty((len(states), len(VARIANTS), P_DATA_DIM), dtype=np.float32)
    for s, p in enumerate(states):
        for v in range(len(VARIANTS)):
            out[s, v] = encode_p_data(apply_variant_p_data(p, v))
    return torch.from_numpy(out)


def encode_pairs(
    index: npt.NDArray[np.int64], states: Sequence[PData]
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """For (N, 2) (from, to) state indices: (N,) pair index, and the (P, 4, NEW_DIM) new-visit and
    (P, 4, MOVE_DIM) move encodings of every distinct pair in the four symmetry variants (the move:
    :func:`twisted.moves.explains` of the transformed pair; zeros when no single move makes it)."""
    unique, inverse = np.unique(index.reshape(-1, 2), axis=0, return_inverse=True)
    new = np.empty((len(unique), len(VARIANTS), NEW_DIM), dtype=np.float32)
    moves = np.empty((len(unique), len(VARIANTS), MOVE_DIM), dtype=np.float32)
    for k, (a, b) in enumerate(unique.tolist()):
        for v in range(len(VARIANTS)):
            p_from, p_to = apply_variant_p_data(states[a], v), apply_variant_p_data(states[b], v)
            new[k, v] = encode_new_visits(p_from, p_to)
            moves[k, v] = encode_move(explains(p_from, p_to))
    return (
        torch.as_tensor(inverse.reshape(-1), dtype=torch.long),
        torch.from_numpy(new),
        torch.from_numpy(moves),
    )


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
    pair, pair_enc, move_enc = encode_pairs(index, states)
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
        move_enc=move_enc,
        source=np.full(n, COLLECT, dtype=np.int64),
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
