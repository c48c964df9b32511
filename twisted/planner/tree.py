"""The search tree ``T`` of Algorithm 1: reached configurations (``Node``) in creation order, indexed by
topological state (``SearchTree``); and the statistics key of a (node, requested next state) pair."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from twisted.topology import PData

__all__ = ["CINCH", "CinchAction", "Node", "SearchTree", "curve_row", "is_cinched", "pair_key"]


@dataclass(frozen=True)
class CinchAction:
    """What made a node that a cinch made (:func:`twisted.tighten.cinch`: the parent's rope pulled tight
    and let go), kept where a node's curve would be; the store writes its ``action``."""

    action: str = "cinch"


CINCH = CinchAction()


def is_cinched(node: Node) -> bool:
    """Whether ``node`` was made by a cinch, not a curve."""
    return getattr(node.curve, "action", "curve") == "cinch"


def curve_row(curve: Any) -> dict[str, Any]:
    """A step of a low-level plan as a row: its action, and the curve's parameters (None for a cinch)."""
    action = getattr(curve, "action", "curve")
    if action != "curve":
        return {"action": action, "link": None, "z_max_m": None, "x_m": None, "y_m": None}
    parameters = {"link": curve.link, "z_max_m": curve.z_max_m, "x_m": curve.x_m, "y_m": curve.y_m}
    return {"action": action, **parameters}


def pair_key(node_index: int, next_state_key: str) -> str:
    """The key of a (node, requested next state) pair in the ``pair`` statistics table; the state
    is given by its ``PData.key`` so that a caller asking for many nodes serialises it once."""
    return f"{node_index}|{next_state_key}"


@dataclass(eq=False, slots=True)
class Node:
    """A vertex of ``T``: a reached configuration ``q``, its state ``Top(q)``, the curve that made it."""

    index: int  # creation order in the run (0 = root)
    parent: int | None
    q: np.ndarray  # opaque simulator state (RopeSim.state())
    points: np.ndarray  # (N_POINTS, 3) link points, head first
    p_data: PData
    curve: Any | None  # twisted.sim.Curve; None for the root; CINCH for a cinched rope
    iteration: int  # iteration that created it (0 = root)
    sim_call: int  # number of the simulator call that produced it (0 = root)
    created_s: float = 0.0  # elapsed search time when it was created
    db_id: int | None = None  # row id once written to the store


class SearchTree:
    """``T``: the nodes in creation order, indexed by topological state."""

    def __init__(self) -> None:
        self.nodes: list[Node] = []
        self.by_state: dict[str, list[int]] = {}
        self.states: dict[str, PData] = {}  # insertion order = order of first reach

    def __len__(self) -> int:
        return len(self.nodes)

    def add(self, node: Node) -> Node:
        if node.index != len(self.nodes):
            raise ValueError(f"node index {node.index} breaks creation order (expected {len(self.nodes)})")
        self.nodes.append(node)
        key = node.p_data.key
        if key not in self.states:
            self.states[key] = node.p_data
            self.by_state[key] = []
        self.by_state[key].append(node.index)
        return node

    def truncate(self, size: int) -> None:
        """Forget the nodes created after the first ``size`` (an iteration that was not finished)."""
        while len(self.nodes) > size:
            node = self.nodes.pop()
            key = node.p_data.key
            self.by_state[key].pop()
            if not self.by_state[key]:
                del self.by_state[key]
                del self.states[key]

    def path(self, index: int) -> list[Node]:
        """The nodes from the root to node ``index``."""
        out = []
        cursor: int | None = index
        while cursor is not None:
            node = self.nodes[cursor]
            out.append(node)
            cursor = node.parent
        return out[::-1]
