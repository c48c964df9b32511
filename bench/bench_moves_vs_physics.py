"""How much of what the simulated rope did is one high-level move?

    python bench/bench_moves_vs_physics.py --db sqlite:///twisted.db [--show 30]

Over the kept transitions in the store (table ``transitions`` joined to ``topological_states`` by
``from_state_id`` / ``to_state_id``) whose crossing count grew by 1 or 2, prints the share whose end state
is one move (R1, R2 or Cross) from the start state, per crossing change and per move kind, and lists the
unexplained (start, end) pairs with a reason: the number of moves the shortest plan needs (e.g. two moves
made by one curve), an R3 slide (a strand slid across a crossing, which reorders visits and is not one of
the planner's moves) next to one move, or how many crossings of the start the curve undid or changed.
"""

from __future__ import annotations

import argparse
from collections import Counter
from dataclasses import dataclass

from sqlalchemy import func, select
from sqlalchemy.orm import aliased

from twisted.diagram import diagram
from twisted.moves import explains, plans, sub_states, successor_states
from twisted.store import TopologicalState, Transition, open_store
from twisted.topology import PData, PDataError, parse_p_data


@dataclass
class Pair:
    start: PData
    end: PData
    count: int


def load_pairs(url: str) -> list[Pair]:
    """Distinct (start, end) state pairs of the kept transitions, with how often each occurred."""
    start_state = aliased(TopologicalState)
    end_state = aliased(TopologicalState)
    query = (
        select(start_state.key, end_state.key, func.count(Transition.id))
        .join(start_state, start_state.id == Transition.from_state_id)
        .join(end_state, end_state.id == Transition.to_state_id)
        .group_by(start_state.key, end_state.key)
    )
    with open_store(url, create=False) as store, store.session() as session:
        rows = session.execute(query).all()
    return [Pair(parse_p_data(a), parse_p_data(b), int(n)) for a, b, n in rows]


def r3_slides(p: PData) -> list[PData]:
    """States one R3 move away (diagnostic only: the planner has no R3).

    R3 slides a strand across a crossing through a triangular face whose three sides are middle
    segments k (between visits k and k+1); it is possible when one of the three strands passes over
    both of its triangle crossings, and it swaps the visits k and k+1 of every side, keeping each
    crossing's O/U and sign.
    """
    out = []
    last = 2 * p.cross
    for face in diagram(p).faces:
        sides = [s.segment for s in face.sides]
        if len(sides) != 3 or len(set(sides)) != 3 or 0 in sides or last in sides:
            continue
        if not any(p.visits[k - 1].over == "O" and p.visits[k].over == "O" for k in sides):
            continue
        perm = list(range(last + 1))
        for k in sides:
            perm[k], perm[k + 1] = k + 1, k
        moved = [[perm[v.position], v.over, perm[v.partner], v.sign] for v in p.visits]
        try:  # sides that share a crossing (adjacent segments) give no valid slide
            slid = parse_p_data(moved)
            diagram(slid)
        except PDataError:
            continue
        out.append(slid)
    return out


def why_not_one_move(start: PData, end: PData) -> str:
    """A short reason why no single move takes ``start`` to ``end``."""
    for name, p in (("start", start), ("end", end)):
        try:
            diagram(p)
        except PDataError:
            return f"{name} state cannot be drawn in the plane (a Top artefact)"
    found = plans(start, end, limit=1)
    if found:
        kinds = "+".join(m.kind for m in found[0].moves)
        return f"{found[0].length} moves ({kinds}) made by one curve"
    if any(explains(s, end) for s in r3_slides(start)) or any(
        end in r3_slides(t) for t in successor_states(start)
    ):
        return "an R3 slide and one move"
    if start in sub_states(end):
        return "every crossing of the start is kept, but no sequence of moves makes the end"
    common = max(s.cross for s in sub_states(start) & sub_states(end))
    lost = start.cross - common
    return f"the curve undid or changed {lost} crossing{'s' * (lost > 1)} of the start"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--db", required=True, help="database URL of a store with collected transitions")
    parser.add_argument(
        "--show", type=int, default=30, help="unexplained pairs to list (most frequent first)"
    )
    args = parser.parse_args()

    pairs = load_pairs(args.db)
    by_delta: Counter[int] = Counter()
    from_cross: Counter[int] = Counter()
    explained_from_cross: Counter[int] = Counter()
    explained_by_delta: Counter[int] = Counter()
    by_kind: Counter[str] = Counter()
    reasons: Counter[str] = Counter()
    unexplained: list[tuple[Pair, str]] = []
    for pair in pairs:
        delta = pair.end.cross - pair.start.cross
        by_delta[delta] += pair.count
        if delta not in (1, 2):
            continue
        try:
            move = explains(pair.start, pair.end)
        except PDataError:
            move = None
        from_cross[pair.start.cross] += pair.count
        if move is not None:
            explained_by_delta[delta] += pair.count
            explained_from_cross[pair.start.cross] += pair.count
            by_kind[move.kind] += pair.count
        else:
            reason = why_not_one_move(pair.start, pair.end)
            reasons[reason] += pair.count
            unexplained.append((pair, reason))

    total = sum(by_delta.values())
    considered = by_delta[1] + by_delta[2]
    explained = explained_by_delta[1] + explained_by_delta[2]
    print(f"kept transitions: {total} ({len(pairs)} distinct state pairs)")
    for delta in sorted(by_delta):
        extra = ""
        if delta in (1, 2):
            share = explained_by_delta[delta] / by_delta[delta]
            extra = f", one move explains {explained_by_delta[delta]} ({share:.1%})"
        print(f"  crossings {delta:+d}: {by_delta[delta]}{extra}")
    if considered:
        print(
            f"share of +1/+2 transitions explained by one move: {explained}/{considered}"
            f" = {explained / considered:.2%}"
        )
        print("  by move kind: " + ", ".join(f"{k} {n}" for k, n in by_kind.most_common()))
        print(
            "  by start crossing count: "
            + ", ".join(f"{c}: {explained_from_cross[c]}/{n}" for c, n in sorted(from_cross.items()))
        )
    if reasons:
        print("unexplained, by reason:")
        for reason, n in reasons.most_common():
            print(f"  {n:6d}  {reason}")
        print(f"most frequent unexplained pairs (up to {args.show}):")
        for pair, reason in sorted(unexplained, key=lambda x: -x[0].count)[: args.show]:
            print(f"  {pair.count:5d}  {pair.start.key} -> {pair.end.key}: {reason}")


if __name__ == "__main__":
    main()
