"""The collect loop of one worker, written once for the process workers and the Ray actors.

A worker owns one ``RopeSim`` and its view of D_Q (:class:`DQIndex`: the ids and crossing counts of
the collect configurations in the store; a start configuration is read when first sampled, then
cached). :meth:`CollectLoop.batch` fills one batch: it refreshes D_Q when ``refresh_seconds`` have
passed since the last look (or D_Q is empty), then samples a start configuration, applies a random
curve and counts it, until ``batch_size`` transitions are kept or the batch's time is up. What differs
between the two kinds of worker stays with them: a process worker draws every batch from one
generator and stops on its run's signals, deadline and shared :class:`Budget`; a Ray actor draws each
batch from its own generator (``SeedSequence([seed, run, worker, seq])``) and the driver decides when
to stop.

(On PostgreSQL two collectors' transactions may commit ids out of order; a configuration committed
late under a smaller id than one already seen joins a worker's D_Q only at the next run. Nothing is
lost from the store.)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from sqlalchemy import select

from twisted.collect.options import RUN_KIND, CollectError, CollectOptions
from twisted.store import Configuration, Store, open_store
from twisted.store.models import array_to_blob
from twisted.store.queries import (
    BatchRecord,
    KeptTransition,
    TryCount,
    add_configuration,
    batch_id,
    configuration_index,
    count_configurations,
)
from twisted.topology import EMPTY

if TYPE_CHECKING:  # twisted.sim (MuJoCo) is imported where the simulation runs
    from twisted.sim import RopeSim

CACHE_SIZE = 4096  # start configurations kept in memory per worker (then the cache starts over)

# a D_Q configuration as the loop uses it: q, state id, crossing count, (N_POINTS, 3) link points
StartConfiguration = tuple[np.ndarray, int, int, np.ndarray]


class DQIndex:
    """The configuration ids of D_Q grouped by crossing count, and the biased sampling rule."""

    def __init__(self, max_cross: int, cross_bias: float) -> None:
        self.max_cross = max_cross
        self.cross_bias = cross_bias
        self.by_cross: dict[int, list[int]] = {}
        self.last_id = 0

    def __len__(self) -> int:
        return sum(len(ids) for ids in self.by_cross.values())

    def add(self, ids: np.ndarray, crosses: np.ndarray) -> None:
        """Add configurations (ids ascending); those with ``cross >= max_cross`` cannot start a kept move."""
        for config_id, cross in zip(ids.tolist(), crosses.tolist(), strict=True):
            if cross < self.max_cross:
                self.by_cross.setdefault(cross, []).append(config_id)
            self.last_id = max(self.last_id, config_id)

    def cross_probabilities(self) -> dict[int, float]:
        """P(start crossing count = c) for the counts present: proportional to ``(1 + c) ** cross_bias``."""
        present = sorted(c for c, ids in self.by_cross.items() if ids)
        weights = np.array([(1.0 + c) ** self.cross_bias for c in present], dtype=np.float64)
        return dict(zip(present, (weights / weights.sum()).tolist(), strict=True))

    def sample(self, rng: np.random.Generator) -> int:
        """A start configuration id: crossing count by :meth:`cross_probabilities`, then uniform."""
        probabilities = self.cross_probabilities()
        if not probabilities:
            raise CollectError("D_Q is empty: no configuration with fewer than max_cross crossings")
        crosses = list(probabilities)
        cross = crosses[int(rng.choice(len(crosses), p=list(probabilities.values())))]
        ids = self.by_cross[cross]
        return ids[int(rng.integers(len(ids)))]


def ensure_root(store: Store, run_id: int, friction_scale: float = 1.0) -> int | None:
    """Put the straight rope into D_Q when D_Q is empty; returns its configuration id (None if not needed)."""
    from twisted.sim import RopeSim

    sim = RopeSim(friction_scale)
    sim.reset()
    p_data = sim.p_data()
    if p_data != EMPTY:
        raise CollectError(f"the straight rope should have no crossing, the simulator reads {p_data}")
    with store.exclusive_session("twisted.collect.root") as session:
        # one process at a time, so two collectors starting together add one root
        if count_configurations(session, RUN_KIND) > 0:
            return None
        return add_configuration(
            session, run_id=run_id, p_data=p_data, q=sim.state(), points=sim.link_points()
        ).id


class Budget:
    """``max_tries`` / ``max_kept`` shared by every worker, so that a run stops at exactly those numbers.

    A worker claims a try before it simulates a curve, and a kept slot before it keeps a transition; a
    curve whose transition finds no slot left is dropped as if never tried (the run ended before it).
    ``ctx`` is the multiprocessing context whose shared counters the workers use.
    """

    def __init__(self, ctx: Any, max_tries: int | None, max_kept: int | None) -> None:
        self.max_tries, self.max_kept = max_tries, max_kept
        self.tries = ctx.Value("q", 0)
        self.kept = ctx.Value("q", 0)

    def claim_try(self) -> bool:
        with self.tries.get_lock():
            if self.max_tries is not None and self.tries.value >= self.max_tries:
                return False
            self.tries.value += 1
            return True

    def claim_kept(self) -> bool:
        """A kept slot; without one the try claimed for this curve is given back."""
        with self.kept.get_lock():
            if self.max_kept is None or self.kept.value < self.max_kept:
                self.kept.value += 1
                return True
        with self.tries.get_lock():
            self.tries.value -= 1
        return False


class CollectLoop:
    """One worker's simulator and view of D_Q, filling batches of counted curves and kept transitions.

    It reads D_Q from the database at ``url``, which must therefore be reachable from the worker's
    machine; it never writes (the batches go to whoever commits them).
    """

    def __init__(self, url: str, run_id: int, worker: int, options: CollectOptions) -> None:
        from twisted.sim import RopeSim

        self.run_id, self.worker, self.options = run_id, worker, options
        self.sim: RopeSim = RopeSim(options.friction_scale)
        # create=False: a worker must never create an empty SQLite file where the database is missing
        self.store = open_store(url, create=False, upgrade=False)
        self.dq = DQIndex(options.max_cross, options.cross_bias)
        self._cache: dict[int, StartConfiguration] = {}
        self._last_refresh = -math.inf

    def close(self) -> None:
        self.store.close()

    def refresh(self) -> None:
        """Add the D_Q configurations committed since the last look (ids above the last one seen)."""
        with self.store.session() as session:
            self.dq.add(*configuration_index(session, after_id=self.dq.last_id, kind=RUN_KIND))
        self._last_refresh = time.monotonic()

    def _load(self, config_id: int) -> StartConfiguration:
        if config_id not in self._cache:
            if len(self._cache) > CACHE_SIZE:
                self._cache.clear()
            with self.store.session() as session:
                q, state_id, cross, points = session.execute(
                    select(
                        Configuration.q, Configuration.state_id, Configuration.cross, Configuration.points
                    ).where(Configuration.id == config_id)
                ).one()
            self._cache[config_id] = (
                np.frombuffer(q, dtype="<f8").astype(np.float64),
                state_id,
                cross,
                np.frombuffer(points, dtype="<f8").astype(np.float64).reshape(-1, 3),
            )
        return self._cache[config_id]

    def batch(
        self,
        seq: int,
        rng: np.random.Generator,
        seconds: float,
        *,
        go_on: Callable[[], bool] | None = None,
        budget: Budget | None = None,
    ) -> tuple[BatchRecord, bool]:
        """Batch ``seq``: random curves from D_Q until ``batch_size`` are kept or ``seconds`` have passed.

        Before each curve ``go_on()`` (when given) may end the batch, and the curve claims a try from
        ``budget`` (and a kept slot when it rises in crossings; a curve that gets none is not counted).
        Returns the batch (it may have tried nothing) and whether the worker may go on: False when
        ``go_on`` or the budget ended it.
        """
        from twisted.proposals import propose_curve

        started = time.monotonic()
        options = self.options
        if started - self._last_refresh >= options.refresh_seconds or len(self.dq) == 0:
            self.refresh()
        tries: dict[int, list[int]] = {}  # start cross -> [tried, kept, rejected]
        kept: list[KeptTransition] = []
        sim_seconds = 0.0
        more = True
        while len(kept) < options.batch_size and time.monotonic() - started < seconds:
            if (go_on is not None and not go_on()) or (budget is not None and not budget.claim_try()):
                more = False
                break
            config_id = self.dq.sample(rng)
            q, state_id, cross, points = self._load(config_id)
            curve = propose_curve(rng, points, options.across_share)
            t0 = time.perf_counter()
            self.sim.set_state(q)
            outcome = self.sim.apply(curve)
            p_data = self.sim.p_data() if outcome.ok else None
            sim_seconds += time.perf_counter() - t0
            rises = p_data is not None and cross < p_data.cross <= options.max_cross
            # one that removes crossings is kept with probability remove_share (no draw at 0, so a
            # collection without it draws what it always drew); labelled by the state reached alike
            if options.remove_share > 0.0 and p_data is not None and p_data.cross < cross:
                rises = bool(rng.random() < options.remove_share)
            if rises and budget is not None and not budget.claim_kept():
                more = False  # the run has its max_kept transitions: this curve is not part of it
                break
            counts = tries.setdefault(cross, [0, 0, 0])
            counts[0] += 1
            if p_data is None:
                counts[2] += 1
            elif rises:
                counts[1] += 1
                kept.append(
                    KeptTransition(
                        from_configuration_id=config_id,
                        from_state_id=state_id,
                        from_cross=cross,
                        link=curve.link,
                        z_max_m=curve.z_max_m,
                        x_m=curve.x_m,
                        y_m=curve.y_m,
                        q=array_to_blob(self.sim.state()),
                        points=array_to_blob(self.sim.link_points()),
                        p_data=p_data,
                        steps=outcome.steps,
                    )
                )
        record = BatchRecord(
            batch_id=batch_id(self.run_id, self.worker, seq),
            run_id=self.run_id,
            worker=self.worker,
            seq=seq,
            tries={c: TryCount(*counts) for c, counts in tries.items()},
            transitions=tuple(kept),
            sim_seconds=sim_seconds,
        )
        return record, more
