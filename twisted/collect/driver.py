"""The driver's side of a collect run, written once for the process workers and the Ray actors.

:class:`CollectRun` owns what does not depend on where the workers run: the ``runs`` row (from before
the first signal can arrive to after the run is ended, so no signal leaves it ``running``), SIGINT /
SIGTERM (the first asks the workers to stop, a second one stops at once), committing a batch and
counting it, the progress display, the stop at ``max_kept`` / ``max_tries``, the log lines, and the
summary, which is read back from the database so that it is what was committed.
"""

from __future__ import annotations

import logging
import secrets
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict
from typing import Any

from sqlalchemy import func, select

from twisted.collect.loop import ensure_root
from twisted.collect.options import RUN_KIND, CollectOptions, CollectProgress, CollectSummary
from twisted.runtime import signal_name, stop_on_signals
from twisted.store import CollectBatch, Run, Store, Transition
from twisted.store.queries import BatchRecord, add_collect_batch, end_run, mark_stale_runs, start_run

log = logging.getLogger(__name__)

PROGRESS_EVERY_S = 0.2  # on_progress calls
LOG_EVERY_S = 60.0  # the periodic INFO line


class CollectRun:
    """One collect run as the driver sees it; use :meth:`running` around the back-end's work.

    ``on_stop`` is called whenever a stop is requested (a signal, a limit, a failure, the end), for a
    back-end whose workers watch something of their own (an event); ``lost`` says what a second
    signal loses (it ends the run at once). ``parameters`` are stored with the options.
    """

    def __init__(
        self,
        store: Store,
        options: CollectOptions,
        *,
        lost: str,
        on_progress: Callable[[CollectProgress], None] | None = None,
        on_stop: Callable[[], None] | None = None,
        parameters: dict[str, Any] | None = None,
    ) -> None:
        self.store, self.options = store, options
        self.seed = options.seed if options.seed is not None else secrets.randbits(63)
        self.lost, self.on_progress, self.on_stop = lost, on_progress, on_stop
        self.parameters = parameters or {}
        self.run_id = 0
        self.started = time.monotonic()
        self.progress = CollectProgress(run_id=0, elapsed_s=0.0, total_s=options.hours * 3600.0)
        self.status = "finished"
        self.message: str | None = None
        self.notes: list[str] = []  # added to the message (a worker lost on the way)
        self.signals: list[int] = []
        self.stop_requested = False
        self.commit_seconds = 0.0
        self.wall_seconds = 0.0
        self._finishing = False
        self._last_report = self._last_log = 0.0

    # --- the run's life ----------------------------------------------------------------------------------

    @contextmanager
    def running(self, clean_up: Callable[[], None]) -> Iterator[CollectRun]:
        """Start the run (and put the root into an empty D_Q), yield, then stop the workers and end it.

        ``clean_up`` stops the back-end's workers; it runs whatever happened, before the run is ended.
        A second signal (KeyboardInterrupt) ends the run ``interrupted``; another error ends it
        ``failed`` and is raised.
        """
        with stop_on_signals(self._on_signal):
            self._start()
            try:
                ensure_root(self.store, self.run_id, self.options.friction_scale)
                yield self
            except KeyboardInterrupt:
                self.status = "interrupted"
                self.message = f"stopped at once by a second signal ({self.lost})"
            except BaseException as exc:
                self.status, self.message = "failed", f"{type(exc).__name__}: {exc}"
                raise
            finally:
                self._finishing = True  # a further signal no longer cuts the clean-up short
                self.request_stop()
                clean_up()
                self._end()

    def _start(self) -> None:
        with self.store.session(write=True) as session:
            mark_stale_runs(session, RUN_KIND)
            parameters = (
                asdict(self.options)
                | {"seed": self.seed, "dq_sampling": "P(c) ~ (1+c)**cross_bias, uniform within c"}
                | self.parameters
            )
            self.run_id = start_run(session, RUN_KIND, parameters, seed=self.seed).id
        self.started = time.monotonic()
        self.progress.run_id, self.progress.workers = self.run_id, self.options.workers
        log.info(
            "collect run %d started: seed %d, %d workers, %g h, options %s",
            self.run_id,
            self.seed,
            self.options.workers,
            self.options.hours,
            parameters,
        )

    def _on_signal(self, signum: int) -> None:
        self.signals.append(signum)
        self.request_stop()
        if len(self.signals) > 1 and not self._finishing:
            raise KeyboardInterrupt  # a second signal: stop now, without waiting for the workers

    def request_stop(self) -> None:
        self.stop_requested = True
        if self.on_stop is not None:
            self.on_stop()

    def fail(self, message: str) -> None:
        """A worker failed: the run fails (the first failure's message is kept) and stops."""
        if self.status != "failed":
            self.status, self.message = "failed", message
        self.request_stop()

    def _end(self) -> None:
        if self.signals and self.status == "finished":
            self.status, self.message = "interrupted", f"stopped by {signal_name(self.signals[0])}"
        if self.notes:
            self.message = "; ".join(([self.message] if self.message else []) + self.notes)
        self.wall_seconds = time.monotonic() - self.started
        with self.store.session(write=True) as session:
            end_run(session, self.run_id, self.status, self.message, wall_seconds=self.wall_seconds)
        p = self.progress
        level = {"finished": logging.INFO, "interrupted": logging.WARNING}.get(self.status, logging.ERROR)
        log.log(
            level,
            "collect run %d %s%s: kept %d of %d tried (%d rejected), %d batches in %.1f s%s",
            self.run_id,
            self.status,
            f" by {signal_name(self.signals[0])}" if self.signals else "",
            p.kept,
            p.tried,
            p.rejected,
            p.batches,
            self.wall_seconds,
            f": {self.message}" if self.message else "",
        )

    # --- batches and progress ------------------------------------------------------------------------

    def commit(self, record: BatchRecord) -> bool:
        """Commit a batch in one transaction and count it; False when its id was already stored."""
        t0 = time.monotonic()
        with self.store.session(write=True) as session:
            new = add_collect_batch(session, record, wall_seconds=t0 - self.started)
        self.commit_seconds += time.monotonic() - t0
        if new is not None:
            self.count(record.batch_id, record.tried, record.kept, record.rejected)
        return new is not None

    def count(self, batch_id: str, tried: int, kept: int, rejected: int) -> None:
        """A committed batch (by :meth:`commit` or by a worker): into the progress; stop at a limit."""
        p = self.progress
        p.tried += tried
        p.kept += kept
        p.rejected += rejected
        p.batches += 1
        log.debug(
            "collect batch %s committed: kept %d of %d tried (%d rejected)", batch_id, kept, tried, rejected
        )
        options = self.options
        if (options.max_kept is not None and p.kept >= options.max_kept) or (
            options.max_tries is not None and p.tried >= options.max_tries
        ):
            self.request_stop()

    def tick(self, workers: int, *, done: bool, stopping: bool = False) -> None:
        """Update the progress (``workers`` still at work) and show it; log a line every minute."""
        p = self.progress
        p.elapsed_s = time.monotonic() - self.started
        p.stopping = self.stop_requested or stopping
        p.workers = workers
        if self.on_progress is not None and (p.elapsed_s - self._last_report >= PROGRESS_EVERY_S or done):
            self.on_progress(p)
            self._last_report = p.elapsed_s
        if p.elapsed_s - self._last_log >= LOG_EVERY_S:
            self._last_log = p.elapsed_s
            log.info(
                "collect run %d: kept %d of %d tried in %.0f s (%.0f kept/h), %d batches, %d workers%s",
                self.run_id,
                p.kept,
                p.tried,
                p.elapsed_s,
                p.kept_per_hour,
                p.batches,
                workers,
                ", stopping" if p.stopping else "",
            )

    def summary(self) -> CollectSummary:
        """How the run ended, with its counters read back from what is committed."""
        run_id = self.run_id
        with self.store.session() as session:
            run = session.get(Run, run_id)
            assert run is not None
            batches = session.scalar(select(func.count()).where(CollectBatch.run_id == run_id)) or 0
            by_cross = session.execute(
                select(Transition.to_cross, func.count(Transition.id))
                .where(Transition.run_id == run_id)
                .group_by(Transition.to_cross)
                .order_by(Transition.to_cross)
            ).all()
            return CollectSummary(
                run_id=run_id,
                status=self.status,
                seed=self.seed,
                workers=self.options.workers,
                tried=run.tried,
                kept=run.kept,
                rejected=run.rejected,
                batches=int(batches),
                wall_seconds=run.wall_seconds,
                sim_seconds=run.sim_seconds,
                message=self.message,
                kept_by_to_cross={int(c): int(n) for c, n in by_cross},
                commit_seconds=self.commit_seconds,
                signum=self.signals[0] if self.signals else None,
            )
