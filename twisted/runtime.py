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


def ignore_while_exiting() -> None:
    """The command has ended (its exit code chosen, its results stored and printed): SIGINT and SIGTERM
    are ignored while the interpreter shuts down (a second or two of garbage collection). Python puts
    the default handlers back as it finalizes, so a Ctrl-C there killed the process (130 in a shell)
    without a word after it had done everything, a solved run stored as solved (issue 62, item 11)."""
    if _main_thread():
        for signum in SIGNALS:
            signal.signal(signum, signal.SIG_IGN)


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
    writing them into the closed pipe only prints BrokenPipeError tracebacks. The thread below notices
    the parent's end within milliseconds, but a result written in those milliseconds met the closed pipe
    first (seen once in CI's load): SIGPIPE's default action ends the worker quietly at that write too.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)
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


# ---- output files: what a command may write (docs/security.md) ------------------------------------------

# the files SQLite keeps beside a database: none of them is ever an output
STORE_SUFFIXES = ("", "-wal", "-shm", "-journal")
KERNEL_FILE_SYSTEMS = ("/proc", "/sys", "/dev")


def store_files(database: str | os.PathLike[str] | None) -> tuple[str, ...]:
    """The real paths of a SQLite database file and its -wal, -shm and -journal files (None: none)."""
    if database is None:
        return ()
    real = os.path.realpath(database)
    return tuple(real + suffix for suffix in STORE_SUFFIXES)


def _too_long(path: str) -> bool:
    """Whether a name in ``path`` passes 255 bytes or the whole 4095 (what Linux file systems take)."""
    raw = os.fsencode(path)
    return len(raw) > 4095 or any(len(part) > 255 for part in raw.split(b"/"))


def _same(a: str, b: str) -> bool:
    """Whether ``a`` and ``b`` are one file (a hard link too); False when either is missing."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def output_problem(
    path: str | os.PathLike[str],
    *,
    protected: tuple[str, ...] = (),
    force: bool = False,
    append: bool = False,
) -> str | None:
    """Why a command must not write the file ``path`` (None: it may); nothing is created.

    Refused: a folder; a path below /proc, /sys or /dev; a path whose real location (after symbolic
    links and ``..``) is one of ``protected`` (the open database and its -wal/-shm/-journal files,
    :func:`store_files`) whatever ``force`` says; a missing folder (it is not created); a folder or
    file without write permission; and an existing file unless ``force`` (or ``append``, for a log
    that is added to, when it is a regular file).
    """
    text = os.fspath(path)
    if not text or "\0" in text:
        return "is not a file name"
    real = os.path.realpath(text)
    if _too_long(real):
        return "is too long a file name (255 bytes a name, 4095 a path)"
    if real in protected or (os.path.exists(real) and any(_same(real, p) for p in protected)):
        return "is the database this command has open (or its -wal/-shm/-journal file): give another path"
    if any(real == root or real.startswith(root + "/") for root in KERNEL_FILE_SYSTEMS):
        return "is on a kernel file system (/proc, /sys, /dev), not a place for files: give another path"
    if os.path.isdir(real):
        return "is a directory: give a file name"
    folder = os.path.dirname(real) or "."
    if not os.path.isdir(folder):
        shown = os.path.dirname(text) or "."
        return f"the folder {shown} does not exist (it is not created: make it first)"
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"cannot write there (no permission in {os.path.dirname(text) or '.'})"
    if os.path.lexists(text):
        if append and os.path.isfile(real):
            return None if os.access(real, os.W_OK) else "cannot write there (the file is read-only)"
        if not os.path.isfile(real):
            return "exists and is not a regular file: give another path"
        if not force:
            return "exists: give --force to write over it, or another path"
        if not os.access(real, os.W_OK):
            return "cannot write there (the file is read-only)"
    return None


def output_folder_problem(
    path: str | os.PathLike[str], *, marker: str, protected: tuple[str, ...] = (), force: bool = False
) -> str | None:
    """Why a command must not write its files into the folder ``path`` (None: it may); nothing is created.

    The folder may be missing when the folder above it exists (the command makes that one level). One
    that holds ``marker`` (e.g. ``report.md``) is written over only with ``force``; the open database
    and its -wal/-shm files are never written (:func:`output_problem` on ``marker``).
    """
    text = os.fspath(path)
    if not text or "\0" in text:
        return "is not a folder name"
    real = os.path.realpath(text)
    if _too_long(os.path.join(real, marker)):
        return "is too long a folder name (255 bytes a name, 4095 a path)"
    if any(real == root or real.startswith(root + "/") for root in KERNEL_FILE_SYSTEMS):
        return "is on a kernel file system (/proc, /sys, /dev), not a place for files: give another folder"
    if os.path.lexists(text) and not os.path.isdir(real):
        return "exists and is not a folder: give a folder"
    if not os.path.isdir(real):
        above = os.path.dirname(real) or "."
        if not os.path.isdir(above):
            return f"the folder above it, {os.path.dirname(text) or '.'}, does not exist (it is not created)"
        if not os.access(above, os.W_OK | os.X_OK):
            return f"cannot create it (no permission in {os.path.dirname(text) or '.'})"
        return None
    if not os.access(real, os.W_OK | os.X_OK):
        return "cannot write there (no permission)"
    return output_problem(os.path.join(text, marker), protected=protected, force=force)


# ---- names: set names, labels, model names (docs/security.md) -------------------------------------------


def name_problem(text: str, limit: int = 64) -> str | None:
    """Why ``text`` cannot name a set, label or model (None: it can).

    Names end up in report.md tables, file names and the terminal: refused are control characters
    (terminal escapes, newlines, tabs, NUL), other invisible format characters, blanks at either
    end, an empty or blank name, and more than ``limit`` characters.
    """
    import unicodedata

    if not text.strip():
        return "is empty or blank"
    if len(text) > limit:
        return f"has {len(text):,} characters, more than {limit}"
    bad = next((c for c in text if unicodedata.category(c)[0] in "CZ" and c != " "), None)
    if bad is not None:
        return f"holds the control or invisible character U+{ord(bad):04X}: use letters, digits and - _ . /"
    if text != text.strip():
        return "starts or ends with a blank"
    return None
