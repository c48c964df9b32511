"""Which plan steps succeed: follow_plan steps per crossing level and kind of move, from eval runs.

    python bench/step_moves.py --db sqlite:///collect.db --set v26-4 --label z-now [--level 3] [--detail]
        [--by origin|free]

For every finished evaluation result it reads the plan run's ``pair`` statistics (per node and
requested next state: the steps tried and those that reached it, DESIGN 8) and the tree's nodes, and
names each request by the move that makes it (``twisted.moves.explains``, the move the plan named).
Steps are grouped by the crossings of the state they start from and by a class of move that means the
same in every state: R1 on an end segment or an inner one, Cross of a tip over the other end segment
or over an inner one, R2. ``--detail`` groups by the move itself instead (segment numbers are those of
the state the move starts from, so one move there can name different physical acts in two states).
``--by origin`` splits each group by where its node came from: ``arrived`` (its parent is in another
state: a step or an expansion that changed the state), ``same`` (a curve from a node in the same state
that changed only the configuration) or ``root``. ``--by free`` splits it by the node's free rope: the
links from each end to its first crossing, summed (``twisted.proposals.segment_bounds``), in the bins
of :data:`FREE_BINS`. Prints steps tried, steps that reached their state, the distinct (node, next
state) pairs, goals and runs per group; --json writes the figures.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

import numpy as np
from sqlalchemy import select

from twisted.moves import Move, explains
from twisted.planner.tree import Node
from twisted.proposals import segment_bounds
from twisted.rope import N_LINKS
from twisted.store import open_store
from twisted.store.experiments import FINISHED_STATUSES, EvalResult, ProblemSet
from twisted.store.search import SearchRunInfo, StoredNode, load_run
from twisted.topology import PData, parse_p_data


def move_class(move: Move, p_data: PData) -> str:
    """The kind of ``move`` from ``p_data`` in words that mean the same in every state."""
    ends = (0, 2 * p_data.cross)
    if move.kind == "Cross":
        return f"Cross tip over {'other end' if move.other_segment in ends else 'inner'} segment"
    if move.kind == "R1":
        return f"R1 on {'end' if move.segment in ends else 'inner'} segment"
    return "R2"


def add_run_selection(ap: argparse.ArgumentParser, required: bool = False) -> None:
    """``--db``, and ``--set`` / ``--label`` (repeatable; all when not given, unless ``required``): which
    evaluation runs a bench reads (:func:`finished_runs`, :func:`stored_pairs`)."""
    default = "" if required else "; default all"
    ap.add_argument("--db", required=True, help="store with evaluation results")
    ap.add_argument(
        "--set", action="append", dest="sets", required=required, help=f"problem set (repeatable{default})"
    )
    ap.add_argument(
        "--label",
        action="append",
        dest="labels",
        required=required,
        help=f"result label (repeatable{default})",
    )


def finished_runs(
    store: Any, sets: Sequence[str] | None, labels: Sequence[str] | None
) -> list[tuple[int, str]]:
    """(plan run id, goal key) of the finished evaluation results toward ``sets`` under ``labels`` (all when
    None or empty), in run order."""
    with store.session() as session:
        q = (
            select(EvalResult.plan_run_id, EvalResult.goal_key)
            .join(ProblemSet, ProblemSet.id == EvalResult.set_id)
            .where(EvalResult.status.in_(FINISHED_STATUSES), EvalResult.plan_run_id.is_not(None))
            .order_by(EvalResult.plan_run_id)
        )
        if sets:
            q = q.where(ProblemSet.name.in_(sets))
        if labels:
            q = q.where(EvalResult.planner.in_(labels))
        return [(int(run_id), str(goal_key)) for run_id, goal_key in session.execute(q).all()]


def stored_pairs(
    store: Any,
    sets: Sequence[str] | None,
    labels: Sequence[str] | None,
    on_run: Callable[[SearchRunInfo], None] | None = None,
) -> Iterator[tuple[int, str, StoredNode, PData, Move | None, float, float]]:
    """Every (node, requested next state) pair of the finished evaluation runs toward ``sets`` under
    ``labels`` (all when None or empty), from the runs' ``pair`` statistics: run id, goal key, the node,
    the next state, the move that explains the step (None when no one move does), steps tried and
    reached. Runs made before the pair statistics were kept are skipped. ``on_run``, when given, is
    called with each run (its whole tree loaded) before its pairs are yielded."""
    for run_id, goal_key in finished_runs(store, sets, labels):
        info = load_run(store, run_id)
        if info is None or info.checkpoint is None or "pair" not in info.checkpoint.stats:
            continue  # a run made before the pair statistics were kept
        if on_run is not None:
            on_run(info)
        nodes = {node.seq: node for node in info.nodes}
        for key, (tried, reached) in info.checkpoint.stats["pair"].items():
            seq, next_key = key.split("|", 1)
            node = nodes[int(seq)]
            next_state = parse_p_data(json.loads(next_key))
            yield run_id, goal_key, node, next_state, explains(node.p_data, next_state), tried, reached


# A plan step of a stored search as the benches simulate it: (node, next state, move, goal key)
StepPair = tuple[Node, PData, Move, str]


def step_groups(
    store: Any,
    sets: Sequence[str] | None,
    labels: Sequence[str] | None,
    levels: Sequence[int],
    wanted: Callable[[Move, PData], bool] | None = None,
    on_run: Callable[[SearchRunInfo], None] | None = None,
) -> dict[int, list[StepPair]]:
    """The distinct adding plan steps of :func:`stored_pairs` (one move explains them and it adds
    crossings) whose node has a crossing count in ``levels`` and, when ``wanted`` is given, whose move and
    node's state it accepts, grouped by that count in the order met; the node as the planner's ``Node``."""
    groups: dict[int, list[StepPair]] = defaultdict(list)
    seen = set()
    for run_id, goal_key, stored, nxt, move, _, _ in stored_pairs(store, sets, labels, on_run):
        if move is None or move.remove or stored.p_data.cross not in levels:
            continue
        if wanted is not None and not wanted(move, stored.p_data):
            continue
        if (run_id, stored.seq, nxt.key) in seen:
            continue
        seen.add((run_id, stored.seq, nxt.key))
        node = Node(stored.seq, None, stored.q, stored.points, stored.p_data, None, 0, 0)
        groups[stored.p_data.cross].append((node, nxt, move, goal_key))
    return groups


def segment_link(
    rng: np.random.Generator, points: Any, segment: int, bounds: np.ndarray | None = None
) -> int:
    """A whole link inside P-data ``segment`` of the rope with these link points, uniformly drawn (the
    middle link when none is); ``bounds``: ``segment_bounds`` of the points, when known."""
    bounds = segment_bounds(points) if bounds is None else bounds
    lo, hi = bounds[segment], bounds[segment + 1]
    inside = [link for link in range(N_LINKS) if lo + 0.3 < link + 0.5 < hi - 0.3]
    return int(rng.choice(inside)) if inside else int(np.clip((lo + hi) / 2, 0, N_LINKS - 1))


J = TypeVar("J")
R = TypeVar("R")


def pool_map(fn: Callable[[J], R], jobs: Sequence[J], workers: int) -> list[R]:
    """``fn`` over ``jobs`` in order: in this process when ``workers`` is 1 or less, else in that many
    forkserver processes (as the planner's pool, ``twisted.sim.pool``; ``fn`` must be a module's top-level
    function, and the calling script must start its work under ``if __name__ == "__main__"``)."""
    if workers <= 1:
        return [fn(job) for job in jobs]
    import multiprocessing

    ctx = multiprocessing.get_context("forkserver")
    with ctx.Pool(workers) as pool:
        return pool.map(fn, jobs, chunksize=8)


# --by free: upper bounds (links) of the free-rope bins
FREE_BINS = (2.0, 4.0, 6.0, 10.0, float("inf"))


def free_rope(points: Any) -> float:
    """Links of rope from each end to its first crossing, summed (the whole rope without crossings)."""
    bounds = segment_bounds(points)
    if len(bounds) == 2:  # no crossing: one segment, head to tail
        return float(bounds[1] - bounds[0])
    return float(bounds[1] - bounds[0] + bounds[-1] - bounds[-2])


def split_name(by: str | None, node: StoredNode, parent: PData | None, free: float) -> str:
    """The ``--by`` part of a group's name for a step from ``node`` (whose parent is in ``parent`` and
    whose free rope is ``free``)."""
    if by == "origin":
        return "root" if parent is None else "same" if parent == node.p_data else "arrived"
    if by == "free":
        upper = next(b for b in FREE_BINS if free <= b)
        lower = max([0.0, *(b for b in FREE_BINS if b < upper)])
        return f"free {lower:g}-{upper:g}" if upper != float("inf") else f"free > {lower:g}"
    return ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_selection(ap)
    ap.add_argument("--level", type=int, action="append", help="only steps from states of N crossings")
    ap.add_argument("--detail", action="store_true", help="group by the move itself, not its class")
    ap.add_argument(
        "--by", choices=("origin", "free"), help="split each group by the node's origin or its free rope"
    )
    ap.add_argument("--json", help="write the figures to this file")
    args = ap.parse_args()

    groups: dict[tuple[int, str], dict[str, Any]] = defaultdict(
        lambda: {"steps": 0.0, "reached": 0.0, "pairs": 0, "goals": set(), "runs": set()}
    )
    parents: dict[int, PData] = {}  # --by origin: the state of each node's parent in the run being read

    def note_parents(info: SearchRunInfo) -> None:
        nodes = {node.seq: node for node in info.nodes}
        parents.clear()
        parents.update({n.seq: nodes[n.parent_seq].p_data for n in info.nodes if n.parent_seq is not None})

    free_by_level: dict[int, list[float]] = defaultdict(list)  # --by free: each pair's node
    with open_store(args.db) as store:
        pairs = stored_pairs(store, args.sets, args.labels, note_parents if args.by == "origin" else None)
        for run_id, goal_key, node, _, move, tried, reached in pairs:
            level = node.p_data.cross
            if args.level and level not in args.level:
                continue
            if move is None:
                continue
            name = str(move) if args.detail else move_class(move, node.p_data)
            if args.by:
                free = 0.0
                if args.by == "free":
                    free = free_rope(node.points)
                    free_by_level[level].append(free)
                name = f"{name}, {split_name(args.by, node, parents.get(node.seq), free)}"
            g = groups[(level, name)]
            g["steps"] += tried
            g["reached"] += reached
            g["pairs"] += 1
            g["goals"].add(goal_key)
            g["runs"].add(run_id)

    print(f"{'from':>4} {'move':60} {'steps':>7} {'reached':>8} {'rate':>6}", end="")
    print(f" {'pairs':>6} {'goals':>5} {'runs':>5}")
    figures = []
    for (level, name), g in sorted(groups.items(), key=lambda item: (item[0][0], -item[1]["steps"])):
        rate = g["reached"] / g["steps"] if g["steps"] else 0.0
        print(
            f"{level:>4} {name:60} {int(g['steps']):>7,} {int(g['reached']):>8,} {rate:>6.1%} "
            f"{g['pairs']:>6,} {len(g['goals']):>5} {len(g['runs']):>5}"
        )
        figures.append(
            {
                "level": level,
                "move": name,
                "steps": g["steps"],
                "reached": g["reached"],
                "pairs": g["pairs"],
                "goals": len(g["goals"]),
                "runs": len(g["runs"]),
            }
        )
    if args.by == "free":
        print(
            "median free rope (links) of the pairs' nodes: "
            + ", ".join(f"{np.median(f):.1f} from {level}" for level, f in sorted(free_by_level.items()))
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(figures, f, indent=1)


if __name__ == "__main__":
    main()
