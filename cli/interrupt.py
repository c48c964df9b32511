"""Ctrl-C and SIGTERM wherever a command does not handle them itself: exit 130 / 143, no traceback.

Installed first thing by ``cli.main`` (before the heavy imports), so a signal during start-up is never
lost: a shell starts background jobs with SIGINT ignored, and Python keeps it ignored. Long commands
(plan, collect) install their own handlers while they work, which checkpoint before exiting.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from types import FrameType

SIGNALS = (signal.SIGINT, signal.SIGTERM)

received: list[int] = []  # the signals that arrived while this handler was installed


def _handler(signum: int, _frame: FrameType | None) -> None:
    received.append(signum)
    raise KeyboardInterrupt  # what Python raises for Ctrl-C; unwinds (and rolls back) whatever runs


def install() -> None:
    """Handle SIGINT and SIGTERM (main thread only)."""
    for signum in SIGNALS:
        signal.signal(signum, _handler)


def exit_code(exc: BaseException) -> int | None:
    """128 + signal when ``exc`` ended a command because of a signal (an import may wrap it), else None."""
    if received:
        return 128 + received[-1]
    if isinstance(exc, KeyboardInterrupt):
        return 128 + signal.SIGINT
    return None


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
