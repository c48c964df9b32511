"""``twisted collect`` on this machine: worker processes and one writer (docs/DESIGN.md section 7).

``workers`` simulation processes (each runs a :class:`~twisted.collect.loop.CollectLoop` with a
generator spawned from ``SeedSequence([seed, run_id])``) send their batches (every ``batch_size`` kept
transitions or ``batch_seconds``) to the main process, the ONE writer, which commits each batch in one
transaction under its idempotency id ``"<run>-<worker>-<seq>"`` and refreshes the run's counters with
it. ``max_tries`` / ``max_kept`` are claimed from a :class:`~twisted.collect.loop.Budget` shared by the
workers, so a run stops at exactly those numbers.

Stopping: at the deadline, at a limit, or on SIGINT/SIGTERM the workers finish their current curve and
send their last batch (a second signal stops at once, losing what is not committed). A worker leaves
as soon as the main process is gone (SIGKILL): nothing it makes could be committed.
"""

from __future__ import annotations

import multiprocessing
import queue as queue_module
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.synchronize import Event
from typing import Any

import numpy as np

from twisted.collect.driver import CollectRun
from twisted.collect.loop import Budget, CollectLoop
from twisted.collect.options import CollectOptions, CollectProgress, CollectSummary
from twisted.runtime import signals_blocked, worker_signals
from twisted.store import Store
from twisted.store.queries import BatchRecord

JOIN_S = 10.0  # how long the writer waits for a worker to end before terminating it


@dataclass(frozen=True)
class _WorkerSpec:
    worker: int
    url: str
    run_id: int
    seed: np.random.SeedSequence
    options: CollectOptions
    deadline: float  # time.time() at which to stop


def _worker_main(spec: _WorkerSpec, out: Any, stop: Event, budget: Budget) -> None:
    """Send batches to the writer until the deadline, ``stop``, SIGTERM, the budget or the writer's end."""
    terminated = worker_signals()  # Ctrl-C reaches the whole group: only the main process reacts to it
    parent = multiprocessing.parent_process()
    try:
        _worker_loop(spec, out, stop, terminated, parent, budget)
        out.put(("done", spec.worker, None))
    except BaseException:  # noqa: BLE001 - reported to the writer, which fails the run
        out.put(("error", spec.worker, traceback.format_exc()))
    if parent is not None and not parent.is_alive():
        out.cancel_join_thread()  # nobody reads the queue any more: do not hang on exit


def _worker_loop(
    spec: _WorkerSpec, out: Any, stop: Event, terminated: Callable[[], bool], parent: Any, budget: Budget
) -> None:
    def writer_gone() -> bool:
        return parent is not None and not parent.is_alive()

    def go_on() -> bool:
        return not (stop.is_set() or terminated() or time.time() >= spec.deadline or writer_gone())

    loop = CollectLoop(spec.url, spec.run_id, spec.worker, spec.options)
    rng = np.random.default_rng(spec.seed)
    try:
        seq, more = 0, True
        while more:
            record, more = loop.batch(seq, rng, spec.options.batch_seconds, go_on=go_on, budget=budget)
            if writer_gone():
                return  # the writer is gone (killed): nothing can be committed any more
            if record.tried:
                out.put(("batch", spec.worker, record))
                seq += 1
    finally:
        loop.close()


def _stop_workers(processes: list[Any], out: Any) -> None:
    for process in processes:
        process.join(timeout=JOIN_S)
        if process.is_alive():
            process.terminate()
            process.join(timeout=5)
    out.cancel_join_thread()


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
    ctx = multiprocessing.get_context("spawn")
    stop = ctx.Event()
    out = ctx.Queue()
    budget = Budget(ctx, options.max_tries, options.max_kept)
    processes: list[Any] = []
    url = store.url.render_as_string(hide_password=False)
    run = CollectRun(
        store, options, lost="uncommitted batches lost", on_progress=on_progress, on_stop=stop.set
    )
    with run.running(clean_up=lambda: _stop_workers(processes, out)):
        deadline = time.time() + options.hours * 3600.0
        seeds = np.random.SeedSequence([run.seed, run.run_id]).spawn(options.workers)
        with signals_blocked():
            for worker in range(options.workers if not stop.is_set() else 0):
                spec = _WorkerSpec(worker, url, run.run_id, seeds[worker], options, deadline)
                process = ctx.Process(
                    target=_worker_main, args=(spec, out, stop, budget), name=f"collect-{worker}"
                )
                process.start()
                processes.append(process)
        running = set(range(len(processes)))
        while running:
            try:
                kind, worker, payload = out.get(timeout=0.25)
            except queue_module.Empty:
                kind, worker, payload = "idle", -1, None
            if kind == "batch":
                record: BatchRecord = payload
                run.commit(record)
            elif kind in ("done", "error"):
                running.discard(worker)
                if kind == "error":
                    run.fail(f"worker {worker} failed:\n{payload}")
            else:
                for w in list(running):
                    if not processes[w].is_alive() and processes[w].exitcode not in (None, 0):
                        running.discard(w)
                        run.fail(f"worker {w} died (exit code {processes[w].exitcode})")
            run.tick(len(running), done=not running)
    return run.summary()
