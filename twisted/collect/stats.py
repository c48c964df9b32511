"""What ``twisted stats`` prints about the collected data (read-only, safe beside a running collector)."""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, select

from twisted.collect.options import RUN_KIND
from twisted.store import Run, Store, Transition
from twisted.store.queries import acceptance_by_cross, collect_throughput, states_by_cross

# Random-curve statistics of the reference simulator (docs/DESIGN.md section 3.5): P(c -> c+1) per curve.
REFERENCE_PLUS_ONE_RATE = {0: 0.11, 1: 0.07, 2: 0.03}


def collection_stats(store: Store) -> dict[str, Any]:
    """What ``twisted stats`` prints, as plain data (read-only queries, safe beside a running collector).

    Keys: ``by_cross`` (per crossing count: visited states, configurations, kept transitions into and
    out of it), ``acceptance`` (per start crossing count: tried, kept, rejected, kept_rate, plus_one
    rate c -> c+1, and the reference's), ``runs`` (collect throughput per run).
    """
    with store.session() as session:
        states = {r["cross"]: r for r in states_by_cross(session)}
        into: dict[int, int] = {}
        out_of: dict[int, int] = {}
        plus_one: dict[int, int] = {}
        rows = session.execute(
            select(Transition.from_cross, Transition.to_cross, func.count(Transition.id))
            .join(Run, Run.id == Transition.run_id)
            .where(Run.kind == RUN_KIND)
            .group_by(Transition.from_cross, Transition.to_cross)
        ).all()
        for from_cross, to_cross, n in rows:
            into[to_cross] = into.get(to_cross, 0) + n
            out_of[from_cross] = out_of.get(from_cross, 0) + n
            if to_cross == from_cross + 1:
                plus_one[from_cross] = plus_one.get(from_cross, 0) + n
        acceptance = acceptance_by_cross(session)
        runs = collect_throughput(session)
        workers: dict[int, dict[str, Any]] = dict(
            session.execute(select(Run.id, Run.parameters).where(Run.kind == RUN_KIND)).all()
        )
    by_cross = [
        {
            "cross": c,
            "states": int(states[c]["visited_states"]) if c in states else 0,
            "configurations": int(states[c]["configurations"]) if c in states else 0,
            "transitions_in": into.get(c, 0),
            "transitions_out": out_of.get(c, 0),
        }
        for c in sorted(set(states) | set(into) | set(out_of))
    ]
    for row in acceptance:
        c, tried = int(row["from_cross"]), int(row["tried"] or 0)
        row["plus_one"] = plus_one.get(c, 0)
        row["plus_one_rate"] = plus_one.get(c, 0) / tried if tried else None
        row["reference_plus_one_rate"] = REFERENCE_PLUS_ONE_RATE.get(c)
    for row in runs:
        n_workers = int((workers.get(row["run_id"]) or {}).get("workers", 1) or 1)
        row["workers"] = n_workers
        per_hour = row["kept_per_hour"]
        row["kept_per_hour_per_worker"] = per_hour / n_workers if per_hour is not None else None
    return {"by_cross": by_cross, "acceptance": acceptance, "runs": runs}
