"""Self-supervised data collection with the D_Q reset scheme (docs/DESIGN.md section 7).

``D_Q`` is the set of configurations in the store added by ``collect`` runs (the straight rope is put in
as the root when there is none). Each iteration a worker

1. samples a start configuration q from D_Q, biased toward more crossings: among the crossing counts
   ``c < max_cross`` present in D_Q it picks ``c`` with probability proportional to
   ``(1 + c) ** cross_bias``, then a configuration uniformly among those with ``c`` crossings. The
   default ``cross_bias = 1`` weighs a count by ``1 + c`` (the planner's prioritise-crosses weight);
   0 is uniform over the counts present. Weighing counts rather than configurations keeps the one
   straight rope (the only 0-crossing configuration) in use, and a steeper bias (e.g. ``2 ** c``) was
   measured to halve the kept rate: random curves from 4-5 crossings are kept 1-3 % of the time
   against 5-8 % from 1-3 crossings;
2. applies a random curve ``c_t``: with probability ``across_share`` one aimed across another strand
   of q (:func:`twisted.proposals.across_curve`), else a uniform one (``twisted.sim.sample_curve``);
3. keeps the transition ``(q, s, c_t, q', s')`` when the simulation is valid and
   ``Cross(s) < Cross(s') <= max_cross``; q' joins D_Q once committed.

Processes: ``workers`` simulation processes (each owns a ``RopeSim`` and a generator spawned from
``SeedSequence([seed, run_id])``) send small batches (every ``batch_size`` kept transitions or
``batch_seconds``) to the main process, the ONE writer, which commits each batch in one transaction
under its idempotency id ``"<run>-<worker>-<seq>"`` and refreshes the run's counters with it. Workers
pick up newly committed configurations (``id`` above the last seen) every ``refresh_seconds``. (On
PostgreSQL two collectors' transactions may commit ids out of order; a configuration committed late
under a smaller id then joins a worker's D_Q only at the next run. Nothing is lost from the store.)

Stopping: at the deadline, at ``max_kept``/``max_tries``, or on SIGINT/SIGTERM the workers finish their
current curve, send their last batch, and the run is marked ``finished`` (deadline/limits) or
``interrupted`` (signal). After SIGKILL at most the batches not yet committed are lost; the run stays
``running`` until the next collect on the same host marks it ``interrupted``. Running collect again
always starts a NEW run that continues the same D_Q (every collect configuration in the store), not
the straight rope. Several collectors may write one database at the same time.

Replay: every random choice comes from the seeded per-worker generators, but which configurations are
in D_Q when a worker samples depends on commit timing across processes, so a multi-process run is not
bit-for-bit replayable; each transition's curve and start configuration are stored, and replaying a
stored transition in ``RopeSim`` is exact.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import queue as queue_module
import secrets
import signal
import time
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from multiprocessing.synchronize import Event
from types import FrameType
from typing import TYPE_CHECKING, Any

import numpy as np
from sqlalchemy import select

from twisted.store import Configuration, Store, open_store
from twisted.store.models import array_to_blob
from twisted.store.queries import (
    BatchRecord,
    KeptTransition,
    TryCount,
    add_collect_batch,
    add_configuration,
    batch_id,
    configuration_index,
    count_configurations,
    end_run,
    mark_stale_runs,
    start_run,
)
from twisted.topology import EMPTY, PData

if TYPE_CHECKING:  # twisted.sim (MuJoCo) is imported where the simulation runs
    from twisted.sim import Curve, RopeSim

RUN_KIND = "collect"
MAX_ENCODED_CROSS = 6  # the inverse model encodes goals of up to 6 crossings
MAX_HOURS = 1e5  # more is a typo (and overflows the clock arithmetic near 1e308)
ACROSS_SHARE = 0.8  # bench/bench_collect_curves.py: kept per hour per core, uniform vs across curves


class CollectError(ValueError):
    """Invalid collection options or an unusable D_Q; the message says which and why."""


@dataclass(frozen=True)
class CollectOptions:
    """What one ``twisted collect`` run does (stored in ``runs.parameters``)."""

    hours: float
    workers: int = 1
    seed: int | None = None
    batch_size: int = 20
    batch_seconds: float = 2.0
    max_cross: int = MAX_ENCODED_CROSS
    cross_bias: float = 1.0
    max_kept: int | None = None
    max_tries: int | None = None
    friction_scale: float = 1.0
    refresh_seconds: float = 2.0
    # share of curves aimed across another strand (twisted.proposals); the rest are uniform
    across_share: float = ACROSS_SHARE

    def validate(self) -> None:
        """Raise :class:`CollectError` naming the first bad option."""

        def positive(name: str, value: float | int | None, allow_none: bool = False) -> None:
            if value is None and allow_none:
                return
            if value is None or isinstance(value, bool) or not math.isfinite(value) or value <= 0:
                raise CollectError(f"--{name.replace('_', '-')} must be a positive number, got {value!r}")

        positive("hours", self.hours)
        if self.hours > MAX_HOURS:
            raise CollectError(f"--hours must be at most {MAX_HOURS:g} (about 11 years), got {self.hours!r}")
        positive("workers", self.workers)
        positive("batch_size", self.batch_size)
        positive("batch_seconds", self.batch_seconds)
        positive("refresh_seconds", self.refresh_seconds)
        positive("friction_scale", self.friction_scale)
        if self.friction_scale > 100:
            raise CollectError(f"--friction-scale must be at most 100, got {self.friction_scale!r}")
        if not (math.isfinite(self.cross_bias) and 0 <= self.cross_bias <= 10):
            raise CollectError(f"--cross-bias must be between 0 and 10, got {self.cross_bias!r}")
        if not (math.isfinite(self.across_share) and 0 <= self.across_share <= 1):
            raise CollectError(f"--across-share must be between 0 and 1, got {self.across_share!r}")
        positive("max_kept", self.max_kept, allow_none=True)
        positive("max_tries", self.max_tries, allow_none=True)
        if not 1 <= self.max_cross <= 20:
            raise CollectError(f"--max-cross must be between 1 and 20, got {self.max_cross}")
        if self.seed is not None and not 0 <= self.seed < 2**63:
            raise CollectError(f"--seed must be in 0..2**63-1, got {self.seed}")


@dataclass
class CollectProgress:
    """Counters of the running collection (what was committed so far), for a progress display."""

    run_id: int
    elapsed_s: float
    total_s: float
    tried: int = 0
    kept: int = 0
    rejected: int = 0
    batches: int = 0
    workers: int = 0
    stopping: bool = False

    @property
    def kept_per_hour(self) -> float:
        return self.kept * 3600.0 / self.elapsed_s if self.elapsed_s > 0 else 0.0


@dataclass
class CollectSummary:
    """How a collection run ended."""

    run_id: int
    status: str  # finished | interrupted | failed
    seed: int
    workers: int
    tried: int
    kept: int
    rejected: int
    batches: int
    wall_seconds: float
    sim_seconds: float
    message: str | None = None
    kept_by_to_cross: dict[int, int] = field(default_factory=dict)
    commit_seconds: float = 0.0  # the writer's time spent committing batches
    signum: int | None = None  # the signal that stopped it (interrupted)

    @property
    def kept_per_hour(self) -> float:
        return self.kept * 3600.0 / self.wall_seconds if self.wall_seconds > 0 else 0.0

    @property
    def kept_per_hour_per_worker(self) -> float:
        return self.kept_per_hour / max(1, self.workers)


# --- D_Q sampling ---------------------------------------------------------------------------------------


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


# --- worker process ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _WorkerSpec:
    worker: int
    url: str
    run_id: int
    seed: np.random.SeedSequence
    options: CollectOptions
    deadline: float  # time.time() at which to stop


class Budget:
    """``max_tries`` / ``max_kept`` shared by every worker, so that a run stops at exactly those numbers.

    A worker claims a try before it simulates a curve, and a kept slot before it keeps a transition; a
    curve whose transition finds no slot left is dropped as if never tried (the run ended before it).
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


@contextmanager
def signals_blocked() -> Iterator[None]:
    """SIGINT and SIGTERM held back (delivered at the end) while worker processes are started.

    A child inherits the mask, so a Ctrl-C to the process group cannot kill a worker that has not yet
    set its own handlers (it used to fail the run: "worker died (exit code -2)"); the worker unblocks
    them once it has. The main process gets its signals as soon as the block ends.
    """
    blocked = {signal.SIGINT, signal.SIGTERM}
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, blocked)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _worker_main(spec: _WorkerSpec, out: Any, stop: Event, budget: Budget) -> None:
    """Simulate curves from D_Q and send batches to the writer until the deadline, ``stop`` or the budget."""
    # Ctrl-C reaches the whole process group: only the main process reacts (it sets ``stop``).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    terminated = []
    signal.signal(signal.SIGTERM, lambda *_: terminated.append(True))
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})  # see signals_blocked
    parent = multiprocessing.parent_process()
    try:
        _worker_loop(spec, out, stop, terminated, parent, budget)
        out.put(("done", spec.worker, None))
    except BaseException:  # noqa: BLE001 - reported to the writer, which fails the run
        out.put(("error", spec.worker, traceback.format_exc()))
    if parent is not None and not parent.is_alive():
        out.cancel_join_thread()  # nobody reads the queue any more: do not hang on exit


def make_batch(
    run_id: int,
    worker: int,
    seq: int,
    tries: dict[int, list[int]],
    kept: list[KeptTransition],
    sim_seconds: float,
) -> BatchRecord:
    """The batch ``seq`` of a worker from its per-crossing try counts and kept transitions."""
    return BatchRecord(
        batch_id=batch_id(run_id, worker, seq),
        run_id=run_id,
        worker=worker,
        seq=seq,
        tries={c: TryCount(*counts) for c, counts in tries.items()},
        transitions=tuple(kept),
        sim_seconds=sim_seconds,
    )


def record_curve(
    tries: dict[int, list[int]],
    kept: list[KeptTransition],
    sim: RopeSim,
    config_id: int,
    state_id: int,
    cross: int,
    curve: Curve,
    p_data: PData | None,
    max_cross: int,
    steps: int,
) -> None:
    """Count one simulated random curve and keep its transition when it adds crossings.

    ``tries[cross]`` is ``[tried, kept, rejected]`` for starts with ``cross`` crossings (created on
    first use). ``p_data is None`` means the simulation failed (rejected). A transition is kept, in
    ``kept``, when the end state has more crossings than the start and at most ``max_cross``; its
    end configuration and link points are read from ``sim``, which must still hold the rope as the
    curve left it. Shared by the local workers and the Ray actors so both count and keep alike.
    """
    counts = tries.setdefault(cross, [0, 0, 0])  # tried, kept, rejected
    counts[0] += 1
    if p_data is None:
        counts[2] += 1
    elif cross < p_data.cross <= max_cross:
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
                q=array_to_blob(sim.state()),
                points=array_to_blob(sim.link_points()),
                p_data=p_data,
                steps=steps,
            )
        )


def _worker_loop(
    spec: _WorkerSpec, out: Any, stop: Event, terminated: list[bool], parent: Any, budget: Budget
) -> None:
    from twisted.proposals import propose_curve
    from twisted.sim import RopeSim

    options = spec.options
    rng = np.random.default_rng(spec.seed)
    sim = RopeSim(options.friction_scale)
    store = open_store(spec.url, create=False, upgrade=False)
    dq = DQIndex(options.max_cross, options.cross_bias)
    cache: dict[int, tuple[np.ndarray, int, int, np.ndarray]] = {}

    def refresh() -> None:
        with store.session() as session:
            dq.add(*configuration_index(session, after_id=dq.last_id, kind=RUN_KIND))

    def load(config_id: int) -> tuple[np.ndarray, int, int, np.ndarray]:
        if config_id not in cache:
            if len(cache) > 4096:
                cache.clear()
            with store.session() as session:
                row = session.execute(
                    select(
                        Configuration.q, Configuration.state_id, Configuration.cross, Configuration.points
                    ).where(Configuration.id == config_id)
                ).one()
            q, points = (np.frombuffer(b, dtype="<f8").astype(np.float64) for b in (row[0], row[3]))
            cache[config_id] = (q, row[1], row[2], points.reshape(-1, 3))
        return cache[config_id]

    seq = 0
    tries: dict[int, list[int]] = {}
    kept: list[KeptTransition] = []
    sim_seconds = 0.0
    batch_started = last_refresh = time.monotonic()

    def flush() -> None:
        nonlocal seq, tries, kept, sim_seconds, batch_started
        if tries:
            record = make_batch(spec.run_id, spec.worker, seq, tries, kept, sim_seconds)
            out.put(("batch", spec.worker, record))
            seq += 1
        tries, kept, sim_seconds = {}, [], 0.0
        batch_started = time.monotonic()

    try:
        refresh()
        while not stop.is_set() and not terminated and time.time() < spec.deadline:
            if parent is not None and not parent.is_alive():
                return  # the writer is gone (killed): nothing can be committed any more
            if not budget.claim_try():
                break
            config_id = dq.sample(rng)
            q, state_id, cross, points = load(config_id)
            curve = propose_curve(rng, points, options.across_share)
            started = time.perf_counter()
            sim.set_state(q)
            outcome = sim.apply(curve)
            p_data = sim.p_data() if outcome.ok else None
            sim_seconds += time.perf_counter() - started
            if p_data is not None and cross < p_data.cross <= options.max_cross and not budget.claim_kept():
                break  # the run has its max_kept transitions: this curve is not part of it
            record_curve(
                tries, kept, sim, config_id, state_id, cross, curve, p_data, options.max_cross, outcome.steps
            )
            now = time.monotonic()
            if len(kept) >= options.batch_size or now - batch_started >= options.batch_seconds:
                flush()
            if now - last_refresh >= options.refresh_seconds:
                refresh()
                last_refresh = now
        flush()
    finally:
        store.close()


# --- the writer (main process) ------------------------------------------------------------------------


@contextmanager
def stop_on_signals(on_signal: Callable[[int], None]) -> Iterator[None]:
    """Route SIGINT/SIGTERM to ``on_signal`` while collecting (main thread only); restore afterwards."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}

    def handler(signum: int, _frame: FrameType | None) -> None:
        on_signal(signum)

    for sig in previous:
        signal.signal(sig, handler)
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def collect(
    store: Store,
    options: CollectOptions,
    on_progress: Callable[[CollectProgress], None] | None = None,
) -> CollectSummary:
    """Run one collection (a new ``runs`` row of kind "collect") and return how it ended.

    Blocks until the deadline, a limit, or SIGINT/SIGTERM (the first signal stops gracefully: workers
    flush, everything received is committed, the run is marked interrupted; a second one stops at once).
    """
    options.validate()
    seed = options.seed if options.seed is not None else secrets.randbits(63)
    signals: list[int] = []
    finishing = False
    ctx = multiprocessing.get_context("spawn")
    stop = ctx.Event()

    def on_signal(signum: int) -> None:
        signals.append(signum)
        stop.set()
        if len(signals) > 1 and not finishing:
            raise KeyboardInterrupt  # a second signal: stop now, without waiting for the workers

    # handled from before the run exists to after it is ended, so no signal can leave it 'running'
    with stop_on_signals(on_signal):
        with store.session(write=True) as session:
            mark_stale_runs(session, RUN_KIND)
            parameters = asdict(options) | {
                "seed": seed,
                "dq_sampling": "P(c) ~ (1+c)**cross_bias, uniform within c",
            }
            run_id = start_run(session, RUN_KIND, parameters, seed=seed).id
        started = time.monotonic()
        total_s = options.hours * 3600.0
        progress = CollectProgress(run_id=run_id, elapsed_s=0.0, total_s=total_s, workers=options.workers)
        status, message = "finished", None
        sim_seconds = commit_seconds = 0.0
        kept_by_to_cross: dict[int, int] = {}
        out = ctx.Queue()
        budget = Budget(ctx, options.max_tries, options.max_kept)
        processes: list[Any] = []
        url = store.url.render_as_string(hide_password=False)

        try:
            ensure_root(store, run_id, options.friction_scale)
            deadline = time.time() + total_s
            seeds = np.random.SeedSequence([seed, run_id]).spawn(options.workers)
            with signals_blocked():
                for worker in range(options.workers if not stop.is_set() else 0):
                    spec = _WorkerSpec(worker, url, run_id, seeds[worker], options, deadline)
                    process = ctx.Process(
                        target=_worker_main, args=(spec, out, stop, budget), name=f"collect-{worker}"
                    )
                    process.start()
                    processes.append(process)
            running = set(range(len(processes)))
            last_report = 0.0
            while running:
                try:
                    kind, worker, payload = out.get(timeout=0.25)
                except queue_module.Empty:
                    kind, worker, payload = "idle", -1, None
                if kind == "batch":
                    record: BatchRecord = payload
                    commit_started = time.monotonic()
                    with store.session(write=True) as session:
                        new = add_collect_batch(session, record, wall_seconds=commit_started - started)
                    commit_seconds += time.monotonic() - commit_started
                    if new is not None:
                        progress.tried += record.tried
                        progress.kept += len(record.transitions)
                        progress.rejected += record.rejected
                        progress.batches += 1
                        sim_seconds += record.sim_seconds
                        for _, to_cross in new:
                            kept_by_to_cross[to_cross] = kept_by_to_cross.get(to_cross, 0) + 1
                elif kind in ("done", "error"):
                    running.discard(worker)
                    if kind == "error" and status != "failed":
                        status, message = "failed", f"worker {worker} failed:\n{payload}"
                        stop.set()
                else:
                    for w in list(running):
                        if not processes[w].is_alive() and processes[w].exitcode not in (None, 0):
                            running.discard(w)
                            status = "failed"
                            message = f"worker {w} died (exit code {processes[w].exitcode})"
                            stop.set()
                if options.max_kept is not None and progress.kept >= options.max_kept:
                    stop.set()
                if options.max_tries is not None and progress.tried >= options.max_tries:
                    stop.set()
                progress.elapsed_s = time.monotonic() - started
                progress.stopping = stop.is_set()
                progress.workers = len(running)
                if on_progress is not None and (progress.elapsed_s - last_report >= 0.2 or not running):
                    on_progress(progress)
                    last_report = progress.elapsed_s
        except KeyboardInterrupt:
            status, message = "interrupted", "stopped at once by a second signal (uncommitted batches lost)"
        except BaseException as exc:
            status, message = "failed", f"{type(exc).__name__}: {exc}"
            raise
        finally:
            finishing = True  # a further signal no longer cuts the clean-up short
            stop.set()
            for process in processes:
                process.join(timeout=10)
                if process.is_alive():
                    process.terminate()
                    process.join(timeout=5)
            out.cancel_join_thread()
            if signals and status == "finished":
                status = "interrupted"
                message = f"stopped by {signal.Signals(signals[0]).name}"
            wall_seconds = time.monotonic() - started
            with store.session(write=True) as session:
                end_run(session, run_id, status, message, wall_seconds=wall_seconds)
    return CollectSummary(
        run_id=run_id,
        status=status,
        seed=seed,
        workers=options.workers,
        tried=progress.tried,
        kept=progress.kept,
        rejected=progress.rejected,
        batches=progress.batches,
        wall_seconds=wall_seconds,
        sim_seconds=sim_seconds,
        message=message,
        kept_by_to_cross=dict(sorted(kept_by_to_cross.items())),
        commit_seconds=commit_seconds,
        signum=signals[0] if signals else None,
    )


def default_workers() -> int:
    """The CPU cores this process may use (the default number of collect workers)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


# --- statistics ---------------------------------------------------------------------------------------

# Random-curve statistics of the reference simulator (docs/DESIGN.md section 3.5): P(c -> c+1) per curve.
REFERENCE_PLUS_ONE_RATE = {0: 0.11, 1: 0.07, 2: 0.03}


def collection_stats(store: Store) -> dict[str, Any]:
    """What ``twisted stats`` prints, as plain data (read-only queries, safe beside a running collector).

    Keys: ``by_cross`` (per crossing count: visited states, configurations, kept transitions into and
    out of it), ``acceptance`` (per start crossing count: tried, kept, rejected, kept_rate, plus_one
    rate c -> c+1, and the reference's), ``runs`` (collect throughput per run).
    """
    from sqlalchemy import func

    from twisted.store import Run, Transition
    from twisted.store.queries import acceptance_by_cross, collect_throughput, states_by_cross

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
