"""Collection and evaluation on a Ray cluster (``twisted collect --ray``, ``twisted eval --ray``).

The same work as :mod:`twisted.collect` and :mod:`twisted.experiments`, the same database and schema, but
the simulators run in Ray workers that may sit on other machines. Ray (and psycopg for PostgreSQL) are
optional extras: ``pip install 'twisted-knots[distributed]'``; ray is imported only when used.

Cluster. ``address=None`` joins the cluster that ``ray start`` runs on this machine (or ``RAY_ADDRESS``)
and otherwise starts a local one for the duration of the command; ``"auto"`` insists on an existing
cluster, ``"local"`` always starts a new one, and ``host:port`` / ``ray://host:10001`` name one. When
Ray is already initialised in this process (tests, notebooks) that connection is used and left open.

Collect. One :class:`CollectWorker` actor per CPU of the cluster (or ``workers``), each owning one
``RopeSim``. The driver asks every actor for one batch at a time (``run_batch(seq, seconds)``): the
actor samples start configurations from D_Q (which it reads from the database, refreshed between
batches), simulates random curves for up to ``batch_seconds`` or ``batch_size`` kept transitions, and

- ``writer="driver"`` (the default for SQLite, which wants one writer): returns the batch to the driver,
  which commits it;
- ``writer="workers"`` (the default for PostgreSQL): commits the batch itself and returns its counts.

Every batch has the idempotency id ``"<run>-<worker>-<seq>"`` (``collect_batches`` primary key) and its
own generator seeded from ``(seed, run, worker, seq)``. A batch is committed in one transaction, so a
worker that dies loses at most its in-flight batch. Ray restarts a dead actor (``max_restarts`` times)
and re-runs the in-flight call with the same seq: if the first attempt had committed before dying, the
retry's batch id is already stored and it is a no-op, so nothing is stored twice. When the restarts are
spent the run goes on with the remaining workers. The summary's counters are read back from the
database, so they are what was committed.

Eval. :class:`RayBackend` is the eval scheduler's Ray backend: each (goal, seed) of
:func:`twisted.experiments.runner.run_eval` becomes one Ray task (``run_task``, ``num_cpus = workers``)
that writes its own result row, as the local processes do; Ctrl-C cancels the tasks (their planners
checkpoint) and a rerun continues.

SQLite with Ray works on one machine (the database file must be readable at the same path by every
worker); for a cluster of several machines use PostgreSQL (README: "Collecting on a Ray cluster").
"""

from __future__ import annotations

import logging
import math
import os
import secrets
import signal
import socket
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
from sqlalchemy import func, select, update

from twisted.collect import (
    RUN_KIND,
    CollectError,
    CollectOptions,
    CollectProgress,
    CollectSummary,
    DQIndex,
    ensure_root,
    make_batch,
    record_curve,
    stop_on_signals,
)
from twisted.store import CollectBatch, Configuration, Run, Store, Transition, open_store
from twisted.store.db import sqlite_path
from twisted.store.queries import (
    BatchRecord,
    KeptTransition,
    add_collect_batch,
    batch_id,
    configuration_index,
    end_run,
    mark_stale_runs,
    start_run,
)

RAY_MISSING = (
    "--ray needs Ray, an optional extra that is not installed: pip install 'twisted-knots[distributed]'"
)
WRITERS = ("auto", "driver", "workers")
# How long the driver waits, after the deadline, for batches in flight (they last batch_seconds, plus
# an actor restart when one just died) before it gives up on them.
FINAL_WAIT_S = 30.0


class DistributedError(RuntimeError):
    """Ray is missing or unreachable, or the options do not fit the cluster; the message says what to do."""


def import_ray() -> Any:
    """The ``ray`` module, or :class:`DistributedError` saying how to install it."""
    try:
        import ray
    except ImportError as exc:
        raise DistributedError(RAY_MISSING) from exc
    return ray


@contextmanager
def ray_cluster(address: str | None = None, *, num_cpus: int | None = None) -> Iterator[Any]:
    """Connect to (or start) a Ray cluster for the block; yields the ``ray`` module.

    ``address``: None = the cluster ``ray start`` runs here (or ``RAY_ADDRESS``), else a new local one;
    ``"auto"`` = an existing cluster only; ``"local"`` = a new local cluster (``num_cpus`` CPUs); or an
    address. A Ray connection this process already has is used and left open.
    """
    ray = import_ray()
    if ray.is_initialized():
        yield ray
        return
    kwargs: dict[str, Any] = {"logging_level": logging.WARNING, "log_to_driver": True}
    if (
        address not in (None, "auto", "local")
        and "RAY_AUTH_MODE" not in os.environ
        and _auth_token_available()
    ):
        # Ray (>= 2.5x) enables token authentication by itself for "auto" but not for an explicit
        # address: without this, `--ray HEAD:6379` is refused by a cluster that `ray start` secured.
        os.environ["RAY_AUTH_MODE"] = "token"
    if address in (None, "local"):
        # Only a cluster we start takes these (connecting to one with them is an error in Ray).
        kwargs["include_dashboard"] = False
        if address == "local" and num_cpus is not None:
            kwargs["num_cpus"] = num_cpus
    try:
        ray.init(address=address, **kwargs)
    except (ConnectionError, ValueError, RuntimeError) as exc:
        where = "an existing Ray cluster" if address in (None, "auto") else f"the Ray cluster at {address!r}"
        raise DistributedError(
            f"cannot connect to {where}: {exc}. Start one with `ray start --head` (and `ray start "
            "--address HEAD:6379` on the other machines), or give no address for a local cluster; a "
            "cluster that uses token authentication also needs its token here (~/.ray/auth_token of "
            "the head, or RAY_AUTH_TOKEN)"
        ) from exc
    try:
        yield ray
    finally:
        ray.shutdown()


def _auth_token_available() -> bool:
    """Whether a Ray authentication token is at hand (environment or ~/.ray/auth_token)."""
    if os.environ.get("RAY_AUTH_TOKEN") or os.environ.get("RAY_AUTH_TOKEN_PATH"):
        return True
    return os.path.exists(os.path.join(os.path.expanduser("~"), ".ray", "auth_token"))


def cluster_cpus(ray: Any) -> int:
    """Total CPUs of the connected cluster (at least 1)."""
    return max(1, int(ray.cluster_resources().get("CPU", 1)))


def worker_url(store: Store) -> str:
    """The URL workers open: SQLite paths made absolute (Ray workers run in another directory)."""
    path = sqlite_path(store.url)
    url = store.url if path is None else store.url.set(database=str(path.resolve()))
    return url.render_as_string(hide_password=False)


def choose_writer(store: Store, writer: str) -> str:
    """``"driver"`` or ``"workers"``: who commits the batches (``auto``: workers on PostgreSQL only)."""
    if writer not in WRITERS:
        raise DistributedError(f"writer must be one of {', '.join(WRITERS)}, got {writer!r}")
    if writer == "auto":
        return "workers" if store.dialect == "postgresql" else "driver"
    if writer == "workers" and store.dialect == "sqlite":
        raise DistributedError(
            "workers cannot write to SQLite (it takes one writer): use writer='driver' or PostgreSQL"
        )
    return writer


# --- the collect actor -------------------------------------------------------------------------------


@dataclass(frozen=True)
class BatchReport:
    """What a :class:`CollectWorker` returns for one batch.

    ``record`` is the batch itself when the driver commits; when the worker committed it, ``stored``
    says whether it was new (False: the id was already stored by an earlier attempt) and
    ``new_crosses`` lists the crossing counts of the configurations it added.
    """

    batch_id: str
    worker: int
    seq: int
    tried: int
    kept: int
    rejected: int
    sim_seconds: float
    host: str
    pid: int
    record: BatchRecord | None = None
    stored: bool | None = None
    new_crosses: tuple[int, ...] = ()


class CollectWorker:
    """A Ray actor that owns one ``RopeSim`` and simulates one batch of random curves per call.

    It reads D_Q (ids and crossing counts, then start configurations on demand) from the database at
    ``url``, which must therefore be reachable from its machine. With ``write=True`` it commits its
    batches itself (PostgreSQL).
    """

    def __init__(
        self, url: str, run_id: int, worker: int, seed: int, options: CollectOptions, write: bool
    ) -> None:
        from twisted.sim import RopeSim

        self.run_id, self.worker, self.seed, self.options, self.write = run_id, worker, seed, options, write
        self.sim = RopeSim(options.friction_scale)
        # create=False: a worker must never create an empty SQLite file where the database is missing
        self.store = open_store(url, create=False, upgrade=False)
        self.dq = DQIndex(options.max_cross, options.cross_bias)
        self.cache: dict[int, tuple[np.ndarray, int, int, np.ndarray]] = {}
        self.last_refresh = -math.inf

    def location(self) -> tuple[str, int]:
        """(host name, process id) of this actor."""
        return socket.gethostname(), os.getpid()

    def _refresh(self) -> None:
        with self.store.session() as session:
            self.dq.add(*configuration_index(session, after_id=self.dq.last_id, kind=RUN_KIND))
        self.last_refresh = time.monotonic()

    def _load(self, config_id: int) -> tuple[np.ndarray, int, int, np.ndarray]:
        """(q, state id, crossing count, link points) of a D_Q configuration, cached."""
        if config_id not in self.cache:
            if len(self.cache) > 4096:
                self.cache.clear()
            with self.store.session() as session:
                q, state_id, cross, points = session.execute(
                    select(
                        Configuration.q, Configuration.state_id, Configuration.cross, Configuration.points
                    ).where(Configuration.id == config_id)
                ).one()
            self.cache[config_id] = (
                np.frombuffer(q, dtype="<f8").astype(np.float64),
                state_id,
                cross,
                np.frombuffer(points, dtype="<f8").astype(np.float64).reshape(-1, 3),
            )
        return self.cache[config_id]

    def run_batch(self, seq: int, seconds: float) -> BatchReport:
        """Simulate curves for up to ``seconds`` (or ``batch_size`` kept); commit or return the batch."""
        from twisted.proposals import propose_curve

        started = time.monotonic()
        if started - self.last_refresh >= self.options.refresh_seconds or len(self.dq) == 0:
            self._refresh()
        # One generator per batch: a batch replays from (seed, run, worker, seq) and the same D_Q, and
        # a retried batch draws the same curves as the attempt it replaces.
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, self.run_id, self.worker, seq]))
        tries: dict[int, list[int]] = {}  # start cross -> [tried, kept, rejected]
        kept: list[KeptTransition] = []
        sim_seconds = 0.0
        max_cross = self.options.max_cross
        while len(kept) < self.options.batch_size and time.monotonic() - started < seconds:
            config_id = self.dq.sample(rng)
            q, state_id, cross, points = self._load(config_id)
            curve = propose_curve(rng, points, self.options.across_share)
            t0 = time.perf_counter()
            self.sim.set_state(q)
            outcome = self.sim.apply(curve)
            p_data = self.sim.p_data() if outcome.ok else None
            sim_seconds += time.perf_counter() - t0
            record_curve(
                tries, kept, self.sim, config_id, state_id, cross, curve, p_data, max_cross, outcome.steps
            )
        record = make_batch(self.run_id, self.worker, seq, tries, kept, sim_seconds)
        host, pid = self.location()
        report = BatchReport(
            record.batch_id,
            self.worker,
            seq,
            record.tried,
            record.kept,
            record.rejected,
            sim_seconds,
            host,
            pid,
        )
        if not self.write or record.tried == 0:
            return replace(report, record=record if record.tried else None)
        with self.store.session() as session:
            new = add_collect_batch(session, record)
        return replace(report, stored=new is not None, new_crosses=tuple(cross for _, cross in new or ()))

    def __del__(self) -> None:
        store = getattr(self, "store", None)
        if store is not None:
            store.close()


def _ray_errors(ray: Any) -> tuple[tuple[type[BaseException], ...], tuple[type[BaseException], ...]]:
    """(errors that mean "the worker is gone", errors raised by our own code inside it)."""
    exc = ray.exceptions
    gone = tuple(
        getattr(exc, name)
        for name in ("RayActorError", "WorkerCrashedError", "NodeDiedError", "ObjectLostError")
        if hasattr(exc, name)
    )
    return gone, (exc.RayTaskError,)


# --- collect driver -----------------------------------------------------------------------------------


def collect_on_ray(
    store: Store,
    options: CollectOptions,
    address: str | None = None,
    *,
    workers: int | None = None,
    writer: str = "auto",
    max_restarts: int = 1,
    on_progress: Callable[[CollectProgress], None] | None = None,
) -> CollectSummary:
    """Run one collection (a ``runs`` row of kind "collect") with Ray actors; returns how it ended.

    ``workers``: actors to start (None: one per CPU of the cluster; ``options.workers`` is ignored).
    ``writer``: who commits (``auto``: the workers on PostgreSQL, the driver on SQLite).
    ``max_restarts``: times Ray restarts a dead actor (re-running its in-flight batch) before the run
    goes on without it. Stops at the deadline, ``max_kept``/``max_tries`` or SIGINT/SIGTERM (a second
    signal stops at once) like :func:`twisted.collect.collect`.
    """
    options.validate()
    if workers is not None and (isinstance(workers, bool) or workers < 1):
        raise CollectError(f"--workers must be a positive number, got {workers!r}")
    if max_restarts < 0:
        raise DistributedError(f"max_restarts must be >= 0, got {max_restarts}")
    mode = choose_writer(store, writer)
    with ray_cluster(address) as ray:
        cpus = cluster_cpus(ray)
        n_workers = workers or cpus
        if n_workers > cpus:
            raise DistributedError(
                f"--workers {n_workers} is more than the {cpus} CPUs of the Ray cluster: each worker "
                "takes one CPU; give fewer workers or add machines (`ray start --address ...`)"
            )
        options = replace(options, workers=n_workers)
        nodes = sum(1 for node in ray.nodes() if node.get("Alive"))
        return _collect(ray, store, options, address, mode, max_restarts, nodes, on_progress)


def _collect(
    ray: Any,
    store: Store,
    options: CollectOptions,
    address: str | None,
    mode: str,
    max_restarts: int,
    nodes: int,
    on_progress: Callable[[CollectProgress], None] | None,
) -> CollectSummary:
    gone_errors, task_errors = _ray_errors(ray)
    seed = options.seed if options.seed is not None else secrets.randbits(63)
    with store.session(write=True) as session:
        mark_stale_runs(session, RUN_KIND)
        parameters = asdict(options) | {
            "seed": seed,
            "dq_sampling": "P(c) ~ (1+c)**cross_bias, uniform within c",
            "ray": {"address": address, "nodes": nodes, "writer": mode, "max_restarts": max_restarts},
        }
        run_id = start_run(session, RUN_KIND, parameters, seed=seed).id
    started = time.monotonic()
    total_s = options.hours * 3600.0
    deadline = started + total_s
    progress = CollectProgress(run_id=run_id, elapsed_s=0.0, total_s=total_s, workers=options.workers)
    status, message = "finished", None
    notes: list[str] = []
    signals: list[int] = []
    sim_seconds = commit_seconds = 0.0
    stop = False
    stopping_since: float | None = None
    dead: set[int] = set()
    actors: list[Any] = []
    pending: dict[Any, tuple[int, int]] = {}  # object ref -> (worker, seq)
    url = worker_url(store)

    def on_signal(signum: int) -> None:
        nonlocal stop
        signals.append(signum)
        stop = True
        if len(signals) > 1:
            raise KeyboardInterrupt  # a second signal: stop now, without waiting for the workers

    def submit(worker: int, seq: int) -> None:
        seconds = min(options.batch_seconds, deadline - time.monotonic())
        pending[actors[worker].run_batch.remote(seq, seconds)] = (worker, seq)

    try:
        with stop_on_signals(on_signal):
            ensure_root(store, run_id, options.friction_scale)
            actor_class = ray.remote(num_cpus=1, max_restarts=max_restarts, max_task_retries=max_restarts)(
                CollectWorker
            )
            for worker in range(options.workers):
                actors.append(
                    actor_class.options(name=None).remote(
                        url, run_id, worker, seed, options, mode == "workers"
                    )
                )
            for worker in range(options.workers):
                submit(worker, 0)
            last_report = last_wall_update = 0.0
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1, timeout=0.25)
                for ref in ready:
                    worker, seq = pending.pop(ref)
                    try:
                        report: BatchReport = ray.get(ref)
                    except gone_errors as exc:
                        dead.add(worker)
                        notes.append(
                            f"worker {worker} died, lost its batch {batch_id(run_id, worker, seq)} in flight "
                            f"({type(exc).__name__}: {str(exc).strip().splitlines()[0][:300]})"
                        )
                        continue  # the run goes on with the others
                    except task_errors as exc:
                        if status != "failed":
                            status, message = "failed", f"worker {worker} failed:\n{exc}"
                        stop = True
                        continue
                    new_crosses: Sequence[int] | None = None
                    if report.record is not None:
                        t0 = time.monotonic()
                        with store.session(write=True) as session:
                            new = add_collect_batch(session, report.record, wall_seconds=t0 - started)
                        commit_seconds += time.monotonic() - t0
                        new_crosses = None if new is None else [cross for _, cross in new]
                    elif report.stored:
                        new_crosses = report.new_crosses
                    if new_crosses is not None:
                        progress.tried += report.tried
                        progress.kept += report.kept
                        progress.rejected += report.rejected
                        progress.batches += 1
                        sim_seconds += report.sim_seconds
                    if options.max_kept is not None and progress.kept >= options.max_kept:
                        stop = True
                    if options.max_tries is not None and progress.tried >= options.max_tries:
                        stop = True
                    if not stop and time.monotonic() < deadline:
                        submit(worker, seq + 1)
                now = time.monotonic()
                if mode == "workers" and now - last_wall_update >= 5.0:
                    # The workers update the counters; keep the wall time current for the views.
                    with store.session() as session:
                        session.execute(
                            update(Run).where(Run.id == run_id).values(wall_seconds=now - started)
                        )
                    last_wall_update = now
                if stopping_since is None and (stop or now >= deadline):
                    stopping_since = now
                if pending and stopping_since is not None and now - stopping_since > FINAL_WAIT_S:
                    notes.append(f"gave up waiting for {len(pending)} batches in flight")
                    pending.clear()
                progress.elapsed_s = now - started
                progress.stopping = stop or now >= deadline
                progress.workers = len({w for w, _ in pending.values()})
                if on_progress is not None and (progress.elapsed_s - last_report >= 0.2 or not pending):
                    on_progress(progress)
                    last_report = progress.elapsed_s
            if len(dead) == options.workers and status != "failed":
                status, message = "failed", "every worker died"
    except KeyboardInterrupt:
        status, message = "interrupted", "stopped at once by a second signal (batches in flight lost)"
    except BaseException as exc:
        status, message = "failed", f"{type(exc).__name__}: {exc}"
        raise
    finally:
        for actor in actors:
            ray.kill(actor, no_restart=True)
        if signals and status == "finished":
            status, message = "interrupted", f"stopped by {signal.Signals(signals[0]).name}"
        if notes:
            message = "; ".join(([message] if message else []) + notes)
        wall_seconds = time.monotonic() - started
        with store.session(write=True) as session:
            end_run(session, run_id, status, message, wall_seconds=wall_seconds)
    summary = _summary_from_store(store, run_id, status, seed, options.workers, message, commit_seconds)
    summary.signum = signals[0] if signals else None
    return summary


def _summary_from_store(
    store: Store, run_id: int, status: str, seed: int, workers: int, message: str | None, commit_s: float
) -> CollectSummary:
    """The run's summary from what is committed (workers may have committed batches never reported)."""
    with store.session() as session:
        run = session.get(Run, run_id)
        assert run is not None
        batches = session.scalar(select(func.count()).where(CollectBatch.run_id == run_id)) or 0
        by_cross = dict(
            session.execute(
                select(Transition.to_cross, func.count(Transition.id))
                .where(Transition.run_id == run_id)
                .group_by(Transition.to_cross)
                .order_by(Transition.to_cross)
            ).all()
        )
        return CollectSummary(
            run_id=run_id,
            status=status,
            seed=seed,
            workers=workers,
            tried=run.tried,
            kept=run.kept,
            rejected=run.rejected,
            batches=int(batches),
            wall_seconds=run.wall_seconds,
            sim_seconds=run.sim_seconds,
            message=message,
            kept_by_to_cross={int(c): int(n) for c, n in by_cross.items()},
            commit_seconds=commit_s,
        )


# --- eval -------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RayBackend:
    """The eval backend that runs each (goal, seed) as a Ray task (``run_eval(..., backend=RayBackend())``).

    Each task takes ``workers`` CPUs (the planner's simulator processes); ``parallel`` caps the tasks in
    flight (0: as many as the cluster's CPUs allow). A task whose worker died is retried
    ``max_retries`` times (the planner resumes from its checkpoint); after that its result row is
    marked ``interrupted`` so that a rerun picks it up.
    """

    address: str | None = None
    max_retries: int = 1
    name = "Ray"
    min_parallel = 0

    @contextmanager
    def open(self, store: Store, db_url: str, workers: int, parallel: int) -> Iterator[_RayTaskPool]:
        """Connect to (or start) the cluster; a pool of Ray tasks for the block."""
        with ray_cluster(self.address) as ray:
            cpus = cluster_cpus(ray)
            if workers > cpus:
                raise DistributedError(
                    f"--workers {workers} is more than the {cpus} CPUs of the Ray cluster (one task per goal "
                    "takes --workers CPUs)"
                )
            url = worker_url(store) if sqlite_path(store.url) is not None else db_url
            in_flight = parallel or max(1, cpus // workers)
            parameters = {"ray": {"address": self.address, "cpus": cpus}}
            yield _RayTaskPool(ray, store, url, workers, self.max_retries, in_flight, parameters)


class _RayTaskPool:
    """Eval tasks in flight as Ray tasks (the :class:`twisted.experiments.runner.TaskPool` of Ray)."""

    def __init__(
        self,
        ray: Any,
        store: Store,
        url: str,
        workers: int,
        max_retries: int,
        in_flight: int,
        parameters: dict[str, Any],
    ) -> None:
        from twisted.experiments.runner import run_task

        self.ray, self.store, self.url = ray, store, url
        self.in_flight, self.parameters = in_flight, parameters
        self._remote = ray.remote(num_cpus=workers, max_retries=max_retries)(run_task)
        gone_errors, task_errors = _ray_errors(ray)
        self._lost = (*gone_errors, *task_errors)
        self._pending: dict[Any, Any] = {}  # object ref -> EvalTask

    @property
    def running(self) -> int:
        return len(self._pending)

    def submit(self, task: Any) -> None:
        self._pending[self._remote.remote(self.url, task)] = task

    def wait(self, timeout_s: float) -> list[Any]:
        from twisted.experiments.runner import TaskOutcome, free_row

        outcomes = []
        ready, _ = self.ray.wait(list(self._pending), num_returns=1, timeout=timeout_s)
        for ref in ready:
            task = self._pending.pop(ref)
            try:
                outcomes.append(self.ray.get(ref))
            except self._lost as exc:
                text = f"Ray task lost ({type(exc).__name__}): {str(exc).strip().splitlines()[0][:300]}"
                free_row(self.store, task, text)  # the worker died holding the row: free it for a rerun
                outcomes.append(TaskOutcome(task.goal_key, task.seed, "failed", message=text))
        return outcomes

    def cancel_all(self) -> list[Any]:
        """Ask the tasks to stop (KeyboardInterrupt in the task: the planner checkpoints), wait for them."""
        from twisted.experiments.runner import CANCEL_WAIT_S, POLL_S, TaskOutcome

        for ref in self._pending:
            self.ray.cancel(ref, force=False)
        outcomes = []
        deadline = time.monotonic() + CANCEL_WAIT_S
        while self._pending and time.monotonic() < deadline:
            ready, _ = self.ray.wait(list(self._pending), num_returns=1, timeout=POLL_S)
            for ref in ready:
                task = self._pending.pop(ref)
                try:
                    outcomes.append(self.ray.get(ref))
                except Exception:  # noqa: BLE001 - cancelled before it started, or died: nothing stored
                    outcomes.append(TaskOutcome(task.goal_key, task.seed, "interrupted"))
        for ref in self._pending:
            self.ray.cancel(ref, force=True)
        self._pending.clear()
        return outcomes


def resolve_address(use_ray: bool, address: str | None) -> str | None:
    """The cluster address from the CLI's ``--ray [ADDRESS]`` (flag + optional value).

    Raises :class:`DistributedError` for an ADDRESS without ``--ray``. ``None`` means "the cluster
    ``ray start`` runs here, else a local one" (see :func:`ray_cluster`).
    """
    if address is not None and not use_ray:
        raise DistributedError(f"unexpected argument {address!r}: a Ray address goes after --ray")
    if address is not None and not address.strip():
        raise DistributedError(
            "--ray: the address is empty (give host:port, ray://host:10001, auto or local)"
        )
    return address
