"""Curve actions as plain results, in-process or in a pool of worker processes.

Each worker process owns one :class:`RopeSim`, built once when the worker starts; a job is a
``(state, curve)`` pair and the answer a :class:`SimResult`. Because :meth:`RopeSim.apply`
depends only on the state and the curve, a pool gives exactly the results of :func:`simulate`
in-process, in the order of the jobs.
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.pool
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from types import TracebackType

import numpy as np
import numpy.typing as npt

from twisted.sim.simulator import Curve, RopeSim
from twisted.topology import PData

Job = tuple[npt.ArrayLike, Curve]


@dataclass(frozen=True, slots=True)
class SimResult:
    """Outcome of one curve from one state; ``state``/``points``/``p_data`` are None when not ok."""

    ok: bool
    reason: str | None
    state: npt.NDArray[np.float64] | None
    points: npt.NDArray[np.float64] | None
    p_data: PData | None
    steps: int


def simulate(sim: RopeSim, state: npt.ArrayLike, curve: Curve) -> SimResult:
    """Apply ``curve`` to the rope in ``state`` on ``sim`` and read the result."""
    sim.set_state(state)
    outcome = sim.apply(curve)
    if not outcome.ok:
        return SimResult(False, outcome.reason, None, None, None, outcome.steps)
    return SimResult(True, None, sim.state(), sim.link_points(), sim.p_data(), outcome.steps)


_worker_sim: RopeSim | None = None


def _init_worker(friction_scale: float, timestep_s: float | None) -> None:
    global _worker_sim
    _worker_sim = RopeSim(friction_scale) if timestep_s is None else RopeSim(friction_scale, timestep_s)


def _run_job(job: Job) -> SimResult:
    assert _worker_sim is not None, "worker used before its initializer ran"
    state, curve = job
    return simulate(_worker_sim, state, curve)


class SimPool:
    """Run many curve jobs on ``workers`` processes (``workers <= 1``: in this process).

    Use as a context manager or call :meth:`close`. Workers are started with ``forkserver``
    (``spawn`` where unavailable) so that no parent state, threads or open databases are
    inherited; each builds its own :class:`RopeSim` once.
    """

    def __init__(
        self, workers: int = 1, friction_scale: float = 1.0, timestep_s: float | None = None
    ) -> None:
        if workers < 0:
            raise ValueError(f"workers must be >= 0, got {workers}")
        self.workers = workers
        self.friction_scale = friction_scale
        self._pool: multiprocessing.pool.Pool | None = None
        self._sim: RopeSim | None = None
        if workers <= 1:
            self._sim = RopeSim(friction_scale) if timestep_s is None else RopeSim(friction_scale, timestep_s)
        else:
            method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
            ctx = multiprocessing.get_context(method)
            self._pool = ctx.Pool(workers, initializer=_init_worker, initargs=(friction_scale, timestep_s))

    def imap(self, jobs: Sequence[Job], chunksize: int | None = None) -> Iterator[SimResult]:
        """Results one by one in job order (for progress bars)."""
        if self._pool is None:
            assert self._sim is not None
            for state, curve in jobs:
                yield simulate(self._sim, state, curve)
            return
        if chunksize is None:
            # a few chunks per worker: low IPC overhead, still balanced (action costs vary ~3x)
            chunksize = max(1, min(16, len(jobs) // (4 * self.workers)))
        yield from self._pool.imap(_run_job, jobs, chunksize=chunksize)

    def run(self, jobs: Sequence[Job]) -> list[SimResult]:
        """Simulate every ``(state, curve)`` job; results in the order of ``jobs``."""
        return list(self.imap(jobs))

    def close(self) -> None:
        """Stop the worker processes (idempotent)."""
        if self._pool is not None:
            self._pool.close()
            self._pool.join()
            self._pool = None

    def __enter__(self) -> SimPool:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc_type is not None and self._pool is not None:
            self._pool.terminate()  # do not wait for queued jobs after an error
            self._pool.join()
            self._pool = None
        self.close()
