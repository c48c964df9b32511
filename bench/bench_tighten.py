"""Pull test against the catalogue: does a rope pulled tight tie what `identify` said its state ties?

Takes up to --per-class configurations of each class from a database (collected configurations and the
nodes of planner trees; classes: every knot type that both closures agree on, and the knotoids by their
(under, over) closures), pulls each tight (twisted.tighten) and prints, per class, what the
tightened ropes tie, the agreement rate and the time per pull test.

    python bench/bench_tighten.py --db sqlite:////tmp/copy.db [--per-class 40] [--seed 0]

Agreement for a real knot: the tightened rope ties the same knot. For a knotoid: "agree" counts the
tightened ropes that are the unknot (the end left its loop); others tie the other closure (the end
left over or under the strand around it); the column "closure" counts the ropes that tighten to
either closure.
--db opens (and so migrates) the database: point it at a copy.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter, defaultdict

import numpy as np

from twisted.knots import identify
from twisted.tighten import tighten, tightening_sim
from twisted.topology import parse_p_data


def _rows(url: str) -> list[tuple[str, bytes, str]]:
    from sqlalchemy import select

    from twisted.store import Configuration, TopologicalState, open_store
    from twisted.store.search_tree import SearchNode

    out: list[tuple[str, bytes, str]] = []
    with open_store(url) as store, store.session() as session:
        for source, table in (("collect", Configuration), ("tree", SearchNode)):
            rows = session.execute(
                select(TopologicalState.key, table.q)
                .join(table, table.state_id == TopologicalState.id)
                .where(TopologicalState.knot_type != "0_1")
            ).all()
            out.extend((key, q, source) for key, q in rows)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--db", required=True, help="database URL (a copy: opening migrates it)")
    parser.add_argument("--per-class", type=int, default=40, help="configurations per class")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sample")
    args = parser.parse_args()

    by_class: dict[str, list[tuple[str, bytes]]] = defaultdict(list)
    for key, q, _source in _rows(args.db):
        k = identify(parse_p_data(key))
        label = k.name if k.is_knot else f"knotoid under {k.under.name} over {k.over.name}"
        by_class[label].append((key, q))
    rng = np.random.default_rng(args.seed)
    sim = tightening_sim()
    head = f"{'class':<34} {'n':>4} {'agree':>6} {'closure':>7}  {'tightened to':<40} ms/test"
    print(head)
    for label in sorted(by_class):
        pool = by_class[label]
        picks = rng.choice(len(pool), size=min(args.per_class, len(pool)), replace=False)
        outcomes: Counter[str] = Counter()
        agree, closure, wall = 0, 0, 0.0
        for i in picks:
            key, q = pool[int(i)]
            before = identify(parse_p_data(key))
            t0 = time.perf_counter()
            result = tighten(sim, np.frombuffer(q, dtype="<f8"))
            wall += time.perf_counter() - t0
            after = result.knot_name if result.ok else "rejected"
            outcomes[str(after)] += 1
            if before.is_knot:
                agree += after == before.name
            else:
                agree += after == "0_1"
            closure += after in (before.under.name, before.over.name)
        shown = ", ".join(f"{name} {n}" for name, n in outcomes.most_common())
        rate = agree / max(len(picks), 1)
        ms = 1000 * wall / max(len(picks), 1)
        either = closure / max(len(picks), 1)
        print(f"{label:<34} {len(picks):>4} {rate:>6.0%} {either:>7.0%}  {shown:<40} {ms:6.0f}")
    print("agree: a knot tightens to itself; a knotoid tightens to the unknot")
    print("closure: the tightened rope ties one of the state's two closures (under or over)")


if __name__ == "__main__":
    main()
