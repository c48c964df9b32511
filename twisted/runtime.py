"""Signals and stopping, written once for every command (docs/DESIGN.md section 13).

Every long job meets SIGINT (Ctrl-C) and SIGTERM alike: it saves what can be resumed and the command
exits 128 + signal (130 / 143). A signal reaches a job in one of three ways:

- as ``KeyboardInterrupt`` (:func:`install`, :func:`sigterm_as_interrupt`): whatever runs unwinds
  (open transactions roll back) and the job's ``except KeyboardInterrupt`` checkpoints (train,
  rl train, eval); :data:`received` remembers which signal it was, for :func:`exit_code`;
- as a stop request that the planner checks between steps (:class:`StopSignals`): the unfinished
  iteration is discarded, nothing is cut half-way;
- as a callback (:func:`stop_on_signals`): collect lets its workers finish their curve and commit.

Worker processes leave the signals to the process that started them (:func:`worker_process`,
:func:`worker_signals`, :func:`signals_blocked`). Standard library only: the CLI installs its handler
from here before anything slow is imported.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any

SIGNALS = (signal.SIGINT, signal.SIGTERM)

# the signals that install() / sigterm_as_interrupt() turned into KeyboardInterrupt, last one last
received: list[int] = []


def signal_exit_code(signum: int) -> int:
    """The shell's convention for a command stopped by a signal: 128 + signal (SIGINT 130, SIGTERM 143)."""
    return 128 + signum


def signal_name(signum: int) -> str:
    """``"SIGINT"``, ``"SIGTERM"``, ..."""
    return signal.Signals(signum).name


def _interrupt(signum: int, _frame: FrameType | None) -> None:
    received.append(signum)
    raise KeyboardInterrupt  # what Python raises for Ctrl-C; unwinds (and rolls back) whatever runs


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def install() -> None:
    """SIGINT and SIGTERM raise KeyboardInterrupt from now on (main thread only)."""
    for signum in SIGNALS:
        signal.signal(signum, _interrupt)


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Inside the block SIGTERM raises KeyboardInterrupt like Ctrl-C; the previous handler comes back after.

    Outside the main thread (where Python delivers no signal) it does nothing.
    """
    if not _main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def exit_code(exc: BaseException) -> int | None:
    """128 + signal when ``exc`` ended a command because of a signal (an import may wrap it), else None."""
    if received:
        return signal_exit_code(received[-1])
    if isinstance(exc, KeyboardInterrupt):
        return signal_exit_code(signal.SIGINT)
    return None


@contextlib.contextmanager
def stop_on_signals(on_signal: Callable[[int], None]) -> Iterator[None]:
    """Route SIGINT/SIGTERM to ``on_signal`` for the block (main thread only); restore afterwards."""
    if not _main_thread():
        yield
        return
    previous = {sig: signal.getsignal(sig) for sig in SIGNALS}

    def handler(signum: int, _frame: FrameType | None) -> None:
        on_signal(signum)

    for sig in previous:
        signal.signal(sig, handler)
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


# --- worker processes -------------------------------------------------------------------------------------


@contextlib.contextmanager
def signals_blocked() -> Iterator[None]:
    """SIGINT and SIGTERM held back (delivered at the end) while worker processes are started.

    A child inherits the mask, so a Ctrl-C to the process group cannot kill a worker that has not yet
    set its own handlers (it used to fail a collect run: "worker died (exit code -2)"); the worker
    unblocks them once it has (:func:`worker_signals`). This process gets its signals as soon as the
    block ends.

    multiprocessing's resource tracker is started first: when the first ``start()`` starts it, it
    unblocks SIGINT and SIGTERM once it is up (CPython's ``ensure_running``), and the workers started
    after it would lose the block.
    """
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, set(SIGNALS))
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def worker_signals() -> Callable[[], bool]:
    """Signal set-up of a worker process started under :func:`signals_blocked`; returns "SIGTERM came".

    Ctrl-C reaches the whole process group: only the parent reacts (it tells the workers to stop), so
    the worker ignores SIGINT; a SIGTERM aimed at the worker itself only asks it to stop at its next
    check. The signals are unblocked once the handlers are in place.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    terminated: list[int] = []
    signal.signal(signal.SIGTERM, lambda signum, _frame: terminated.append(signum))
    signal.pthread_sigmask(signal.SIG_UNBLOCK, set(SIGNALS))
    return lambda: bool(terminated)


def worker_process() -> None:
    """For a worker process that a command starts (it imports ``cli.main`` to bootstrap).

    Ctrl-C reaches the whole process group, but it is the command's process that stops the workers (a
    worker killed by it would lose its job, and a pool waits for that result for ever): ignore it. And
    leave as soon as the command's process is gone (SIGKILL): the results have nowhere to go, and
    writing them into the closed pipe only prints BrokenPipeError tracebacks.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_with_parent, name="twisted-exit-with-parent", daemon=True).start()


def _exit_with_parent() -> None:
    import multiprocessing
    import multiprocessing.connection

    deadline = time.monotonic() + 30  # the parent is known once the bootstrap has read it
    while (parent := multiprocessing.parent_process()) is None:
        if time.monotonic() > deadline:
            return  # not a multiprocessing child after all (a forkserver preloading its main module)
        time.sleep(0.02)
    multiprocessing.connection.wait([parent.sentinel])
    os._exit(0)


def cpu_cores() -> int:
    """The CPU cores this process may use (the default number of worker processes)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on every platform
        return os.cpu_count() or 1


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` of this host still runs (one of another user counts: it exists)."""
    if pid <= 0:
        return False  # 0 and -n would ask about process groups
    try:
        os.kill(pid, 0)
    except (ProcessLookupError, OverflowError):
        return False
    except PermissionError:
        return True
    return True


# --- the planner's stop request ------------------------------------------------------------------------


class StopRequested(BaseException):
    """Raised by :class:`StopSignals` inside a blocking wait on the worker pool or during the set-up."""


_MAX_TIMER_S = 1e8  # a longer set-up budget is no budget (setitimer overflows near 1e308)


class StopSignals:
    """Turns SIGINT / SIGTERM into a stop request that the search checks between steps.

    The handler only sets a flag, except while the search waits on the worker pool
    (:meth:`interruptible`): Ctrl-C also kills the workers' current jobs, whose results would then
    never come, so the wait is cut short by raising :class:`StopRequested`. The unfinished iteration
    is discarded either way; a store transaction is never interrupted half-way.
    """

    def __init__(self) -> None:
        self.signum: int | None = None
        self.timed_out = False  # the time budget of a set-up section ran out
        self._waiting = False

    def __call__(self) -> bool:
        return self.signum is not None

    @property
    def exit_code(self) -> int:
        """Shell convention 128 + signal: 130 for Ctrl-C (SIGINT), 143 for SIGTERM."""
        return signal_exit_code(self.signum or 0)

    @contextlib.contextmanager
    def interruptible(self) -> Iterator[None]:
        """A section (a wait on worker processes) that a stop signal may cut short."""
        self._waiting = True
        try:
            if self.signum is not None:
                raise StopRequested
            yield
        finally:
            self._waiting = False

    @contextlib.contextmanager
    def setup(self, budget_s: float | None = None) -> Iterator[None]:
        """The set-up before a search (goal enumeration, imports, loading the model, starting workers).

        Nothing in it can be checkpointed, so a stop signal, or ``budget_s`` seconds passing (the
        set-up counts toward the search's timeout), ends it at once with :class:`StopRequested`; then
        :attr:`signum` or :attr:`timed_out` says which. An error that a signal caused inside code that
        wraps it (an import turns KeyboardInterrupt into ImportError) is reported as StopRequested too.
        """
        armed = budget_s is not None and budget_s < _MAX_TIMER_S
        previous = signal.signal(signal.SIGALRM, self._alarm) if armed else None
        if armed:
            assert budget_s is not None
            signal.setitimer(signal.ITIMER_REAL, max(budget_s, 1e-3))
        self._waiting = True
        try:
            if self.signum is not None:
                raise StopRequested
            yield
        except StopRequested:
            raise
        except BaseException as exc:
            if self.signum is not None or self.timed_out:
                raise StopRequested from exc
            raise
        finally:
            self._waiting = False
            if armed:
                signal.setitimer(signal.ITIMER_REAL, 0)
                signal.signal(signal.SIGALRM, previous)

    @contextlib.contextmanager
    def deferred(self) -> Iterator[None]:
        """Inside :meth:`setup`, a section that a stop signal or the deadline does not cut short (checks of
        the input, whose errors must win); they take effect when it ends."""
        waiting, self._waiting = self._waiting, False
        try:
            yield
        finally:
            self._waiting = waiting
        if waiting and (self.signum is not None or self.timed_out):
            raise StopRequested

    def _alarm(self, signum: int, frame: Any) -> None:
        self.timed_out = True
        if self._waiting:
            self._waiting = False
            raise StopRequested

    def _handler(self, signum: int, frame: Any) -> None:
        self.signum = signum
        if self._waiting:
            self._waiting = False
            raise StopRequested

    @contextlib.contextmanager
    def installed(self) -> Iterator[StopSignals]:
        """Handle SIGINT and SIGTERM for the duration of the block (main thread only)."""
        previous = {s: signal.signal(s, self._handler) for s in SIGNALS}
        try:
            yield self
        finally:
            for s, h in previous.items():
                signal.signal(s, h)
