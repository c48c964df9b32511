"""Checks shared by the collect tests on Ray and PostgreSQL: what a correct collect database looks like."""

from __future__ import annotations

import numpy as np
from sqlalchemy import func, select

from twisted.sim import Curve, RopeSim
from twisted.store import CollectBatch, Configuration, Run, TopologicalState, Transition, open_store
from twisted.topology import parse_p_data


def check_collect_rows(url: str) -> None:
    """Counters equal committed rows, no transition or batch twice, one root, every move adds crossings."""
    with open_store(url) as store, store.session() as session:
        for run in session.scalars(select(Run).where(Run.kind == "collect")):
            n = session.scalar(select(func.count(Transition.id)).where(Transition.run_id == run.id))
            kept, tried, rejected = session.execute(
                select(
                    func.coalesce(func.sum(CollectBatch.kept), 0),
                    func.coalesce(func.sum(CollectBatch.tried), 0),
                    func.coalesce(func.sum(CollectBatch.rejected), 0),
                ).where(CollectBatch.run_id == run.id)
            ).one()
            assert (run.kept, run.tried, run.rejected) == (n, tried, rejected) and kept == n
        curves = session.execute(
            select(
                Transition.from_configuration_id,
                Transition.link,
                Transition.z_max_m,
                Transition.x_m,
                Transition.y_m,
            )
        ).all()
        assert len(curves) == len(set(curves)), "a transition was stored twice"
        targets = list(session.scalars(select(Transition.to_configuration_id)))
        assert len(targets) == len(set(targets))
        assert session.scalar(select(func.count(Configuration.id))) == len(targets) + 1, "one root"
        assert not session.scalar(
            select(func.count(Transition.id)).where(Transition.to_cross <= Transition.from_cross)
        )


def replay_some(url: str, n: int = 3) -> None:
    """Stored transitions replay exactly in the simulator (the workers stored what they simulated)."""
    sim = RopeSim()
    with open_store(url) as store, store.session() as session:
        for t in session.scalars(select(Transition).order_by(Transition.id).limit(n)):
            start = session.get(Configuration, t.from_configuration_id)
            end = session.get(Configuration, t.to_configuration_id)
            state = session.get(TopologicalState, t.to_state_id)
            assert start is not None and end is not None and state is not None
            sim.set_state(start.q_array())
            assert sim.apply(Curve(t.link, t.z_max_m, t.x_m, t.y_m)).ok
            assert np.array_equal(sim.state(), end.q_array())
            assert sim.p_data() == parse_p_data(state.p_data)
