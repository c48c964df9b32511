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
import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import update

from twisted.collect import (
    CollectError,
    CollectLoop,
    CollectOptions,
    CollectProgress,
    CollectRun,
    CollectSummary,
)
from twisted.experiments.tasks import TaskKind
from twisted.store import Run, Store
from twisted.store.db import sqlite_path
from twisted.store.queries import BatchRecord, add_collect_batch, batch_id

log = logging.getLogger(__name__)

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
        # A token left here by an earlier `ray start` must not be sent to a cluster without tokens,
        # though: the driver connects, and every worker dies at once without saying why.
        if cluster_uses_tokens(address) is False:
            raise DistributedError(token_mismatch_message(address))
        os.environ["RAY_AUTH_MODE"] = "token"
    starts_here = address == "local" or (address is None and _starts_a_local_cluster())
    if starts_here:
        # Only a cluster we start takes these (connecting to one with them is an error in Ray).
        kwargs.update(include_dashboard=False, dashboard_host=LOOPBACK, _node_ip_address=LOOPBACK)
        if address == "local" and num_cpus is not None:
            kwargs["num_cpus"] = num_cpus
    try:
        with _loopback_node(ray) if starts_here else _nothing():
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
    return os.path.exists(RAY_TOKEN_FILE.expanduser())


# Where Ray keeps the token that `ray start`, `ray get-auth-token --generate` and every new local cluster
# (ray.init without an address) write when none exists: ray._private.authentication
# .authentication_token_setup._get_default_token_path() (Ray 2.5x), Path.home() / ".ray" / "auth_token".
RAY_TOKEN_FILE = Path("~/.ray/auth_token")
# Asks the cluster's GCS for a key without sending a token (RAY_AUTH_MODE=disabled in its environment):
# a cluster that uses tokens refuses with AuthenticationError, one that does not answers.
_TOKEN_PROBE = """
import sys
from ray._raylet import GcsClient
from ray.exceptions import AuthenticationError
try:
    GcsClient(address=sys.argv[1]).internal_kv_get(b"twisted-probe", namespace=None, timeout=10)
except AuthenticationError:
    print("token")
except Exception:
    print("unknown")
else:
    print("none")
"""
PROBE_TIMEOUT_S = 30.0


def cluster_uses_tokens(address: str) -> bool | None:
    """Whether the Ray cluster at ``host:port`` asks for a token; None when that cannot be told (a Ray
    Client address ``ray://``, a host that does not answer, an older Ray)."""
    if "://" in address:
        return None
    host, _, port = address.rpartition(":")
    if not port.isdigit():
        return None
    try:  # a quick look first: Ray's client waits ~40 s for a host that does not answer
        socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), timeout=3).close()
    except (OSError, ValueError):
        return None
    env = {k: v for k, v in os.environ.items() if k not in ("RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH")}
    env.update(RAY_AUTH_MODE="disabled", RAY_py_gcs_connect_timeout_s="5")
    try:
        done = subprocess.run(
            [sys.executable, "-c", _TOKEN_PROBE, address],
            env=env,
            capture_output=True,
            text=True,
            timeout=PROBE_TIMEOUT_S,
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    answer = done.stdout.strip().splitlines()[-1:] or ["unknown"]
    return {"token": True, "none": False}.get(answer[0])


def token_mismatch_message(address: str) -> str:
    """What to do when a token is at hand here but the cluster at ``address`` uses none."""
    where = (
        "RAY_AUTH_TOKEN / RAY_AUTH_TOKEN_PATH"
        if os.environ.get("RAY_AUTH_TOKEN") or os.environ.get("RAY_AUTH_TOKEN_PATH")
        else f"{RAY_TOKEN_FILE.expanduser()} (written by an earlier `ray start` or local Ray cluster)"
    )
    return (
        f"the Ray cluster at {address!r} does not use token authentication, but a Ray token is set here "
        f"({where}); with it every worker would die at once. Either start the cluster with tokens "
        "(RAY_AUTH_MODE=token on every `ray start`, with this token), or run this command with "
        "RAY_AUTH_MODE=disabled, or move the token away. A cluster without tokens runs code for anyone "
        "who reaches its ports: keep it on a private network (docs/distributed.md)"
    )


# A local cluster started by twisted serves this machine only: its node address is the loopback one.
LOOPBACK = "127.0.0.1"
# Ray (Linux) replaces a loopback node address by the machine's network address unless it is told that
# clusters are off (the flag it sets itself on Windows and macOS); the processes of a node whose address
# is 127.0.0.1 then listen on 127.0.0.1 only (GCS, raylet, workers, agents).
_NO_CLUSTER_FLAG = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"


@contextmanager
def _loopback_node(ray: Any) -> Iterator[None]:
    """While ``ray.init`` starts a local cluster: its node address is 127.0.0.1 (Ray's own processes
    started meanwhile inherit the flag)."""
    constants: Any = getattr(getattr(ray, "_private", None), "ray_constants", None)
    saved_flag = getattr(constants, "ENABLE_RAY_CLUSTER", None)
    saved_env = os.environ.get(_NO_CLUSTER_FLAG)
    os.environ[_NO_CLUSTER_FLAG] = "0"
    if saved_flag is not None:
        constants.ENABLE_RAY_CLUSTER = False  # read at import; get_node_ip_address() reads it per call
    try:
        yield
    finally:
        if saved_flag is not None:
            constants.ENABLE_RAY_CLUSTER = saved_flag
        if saved_env is None:
            os.environ.pop(_NO_CLUSTER_FLAG, None)
        else:
            os.environ[_NO_CLUSTER_FLAG] = saved_env


@contextmanager
def _nothing() -> Iterator[None]:
    yield


def _starts_a_local_cluster() -> bool:
    """Whether ``ray.init()`` without an address starts a new cluster here (no RAY_ADDRESS, no cluster of
    `ray start` on this machine) rather than joining one."""
    try:
        from ray._private.services import canonicalize_bootstrap_address
    except ImportError:
        return False
    try:
        return canonicalize_bootstrap_address(None) is None  # type: ignore[arg-type]
    except Exception:  # noqa: BLE001 - Ray's own lookup failed: let ray.init decide and report
        return False


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
    """A Ray actor that runs the collect loop (:class:`twisted.collect.CollectLoop`) one batch per call.

    It reads D_Q from the database at ``url``, which must therefore be reachable from its machine. With
    ``write=True`` it commits its batches itself (PostgreSQL).
    """

    def __init__(
        self, url: str, run_id: int, worker: int, seed: int, options: CollectOptions, write: bool
    ) -> None:
        self.run_id, self.worker, self.seed, self.write = run_id, worker, seed, write
        self.loop = CollectLoop(url, run_id, worker, options)

    def location(self) -> tuple[str, int]:
        """(host name, process id) of this actor."""
        return socket.gethostname(), os.getpid()

    def run_batch(self, seq: int, seconds: float) -> BatchReport:
        """Simulate curves for up to ``seconds`` (or ``batch_size`` kept); commit or return the batch."""
        # One generator per batch: a batch replays from (seed, run, worker, seq) and the same D_Q, and
        # a retried batch draws the same curves as the attempt it replaces.
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, self.run_id, self.worker, seq]))
        record, _ = self.loop.batch(seq, rng, seconds)
        host, pid = self.location()
        report = BatchReport(
            record.batch_id,
            self.worker,
            seq,
            record.tried,
            record.kept,
            record.rejected,
            record.sim_seconds,
            host,
            pid,
        )
        if not self.write or record.tried == 0:
            return replace(report, record=record if record.tried else None)
        with self.loop.store.session() as session:
            new = add_collect_batch(session, record)
        return replace(report, stored=new is not None, new_crosses=tuple(cross for _, cross in new or ()))

    def __del__(self) -> None:
        loop = getattr(self, "loop", None)
        if loop is not None:
            loop.close()


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
    ray_parameters = {"address": address, "nodes": nodes, "writer": mode, "max_restarts": max_restarts}
    run = CollectRun(
        store,
        options,
        lost="batches in flight lost",
        on_progress=on_progress,
        parameters={"ray": ray_parameters},
    )
    dead: set[int] = set()
    actors: list[Any] = []
    pending: dict[Any, tuple[int, int]] = {}  # object ref -> (worker, seq)
    url = worker_url(store)

    def kill_actors() -> None:
        for actor in actors:
            ray.kill(actor, no_restart=True)

    with run.running(clean_up=kill_actors):
        deadline = run.started + options.hours * 3600.0

        def submit(worker: int, seq: int) -> None:
            seconds = min(options.batch_seconds, deadline - time.monotonic())
            pending[actors[worker].run_batch.remote(seq, seconds)] = (worker, seq)

        actor_class = ray.remote(num_cpus=1, max_restarts=max_restarts, max_task_retries=max_restarts)(
            CollectWorker
        )
        for worker in range(options.workers):
            actors.append(
                actor_class.options(name=None).remote(
                    url, run.run_id, worker, run.seed, options, mode == "workers"
                )
            )
        for worker in range(options.workers):
            submit(worker, 0)
        last_wall_update = 0.0
        stopping_since: float | None = None
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=0.25)
            for ref in ready:
                worker, seq = pending.pop(ref)
                try:
                    report: BatchReport = ray.get(ref)
                except gone_errors as exc:
                    dead.add(worker)
                    run.notes.append(
                        f"worker {worker} died, lost its batch {batch_id(run.run_id, worker, seq)} in flight "
                        f"({type(exc).__name__}: {str(exc).strip().splitlines()[0][:300]})"
                    )
                    log.warning("collect run %d: %s", run.run_id, run.notes[-1])
                    continue  # the run goes on with the others
                except task_errors as exc:
                    run.fail(f"worker {worker} failed:\n{exc}")
                    continue
                if report.record is not None:
                    run.commit(report.record)
                elif report.stored:
                    run.count(report.batch_id, report.tried, report.kept, report.rejected)
                if not run.stop_requested and time.monotonic() < deadline:
                    submit(worker, seq + 1)
            now = time.monotonic()
            if mode == "workers" and now - last_wall_update >= 5.0:
                # The workers update the counters; keep the wall time current for the views.
                with store.session() as session:
                    session.execute(
                        update(Run).where(Run.id == run.run_id).values(wall_seconds=now - run.started)
                    )
                last_wall_update = now
            if stopping_since is None and (run.stop_requested or now >= deadline):
                stopping_since = now
            if pending and stopping_since is not None and now - stopping_since > FINAL_WAIT_S:
                run.notes.append(f"gave up waiting for {len(pending)} batches in flight")
                pending.clear()
            run.tick(len({w for w, _ in pending.values()}), done=not pending, stopping=now >= deadline)
        if len(dead) == options.workers:
            run.fail("every worker died")
    return run.summary()


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
    def open(
        self, store: Store, db_url: str, workers: int, parallel: int, kind: TaskKind | None = None
    ) -> Iterator[_RayTaskPool]:
        """Connect to (or start) the cluster; a pool of Ray tasks of ``kind`` (default: an evaluation's
        tasks) for the block."""
        from twisted.experiments.leases import EVAL_TASKS

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
            options = {"num_cpus": workers, "max_retries": self.max_retries}
            yield _RayTaskPool(ray, store, url, kind or EVAL_TASKS, options, in_flight, parameters)


class _RayTaskPool:
    """Tasks in flight as Ray tasks (the :class:`twisted.experiments.scheduler.TaskPool` of Ray)."""

    def __init__(
        self,
        ray: Any,
        store: Store,
        url: str,
        kind: TaskKind,
        options: dict[str, Any],
        in_flight: int,
        parameters: dict[str, Any],
    ) -> None:
        """``kind.run`` becomes a Ray task with ``options`` (its CPUs and retries)."""
        self.ray, self.store, self.url, self.kind = ray, store, url, kind
        self.in_flight, self.parameters = in_flight, parameters
        self._remote = ray.remote(**options)(kind.run)
        gone_errors, task_errors = _ray_errors(ray)
        self._lost = (*gone_errors, *task_errors)
        self._pending: dict[Any, Any] = {}  # object ref -> task

    @property
    def running(self) -> int:
        return len(self._pending)

    def submit(self, task: Any) -> None:
        self._pending[self._remote.remote(self.url, task)] = task

    def wait(self, timeout_s: float) -> list[Any]:
        outcomes = []
        ready, _ = self.ray.wait(list(self._pending), num_returns=1, timeout=timeout_s)
        for ref in ready:
            task = self._pending.pop(ref)
            try:
                outcomes.append(self.ray.get(ref))
            except self._lost as exc:
                text = f"Ray task lost ({type(exc).__name__}): {str(exc).strip().splitlines()[0][:300]}"
                outcomes.append(self.kind.lost(self.store, task, "failed", text))  # an eval frees its row
        return outcomes

    def cancel_all(self) -> list[Any]:
        """Ask the tasks to stop (KeyboardInterrupt in the task: the planner checkpoints), wait for them."""
        from twisted.experiments.scheduler import CANCEL_WAIT_S, POLL_S

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
                    outcomes.append(self.kind.lost(self.store, task, "interrupted", "cancelled"))
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
        hint = ""
        if address.strip().isdigit():  # `--seeds 2 3`: the option takes one argument
            stray = address.strip()
            hint = f"; several seeds go in one argument: --seeds '<seeds> {stray}' or comma-separated"
        raise DistributedError(f"unexpected argument {address!r}: a Ray address goes after --ray{hint}")
    if address is not None and not address.strip():
        raise DistributedError(
            "--ray: the address is empty (give host:port, ray://host:10001, auto or local)"
        )
    return address
