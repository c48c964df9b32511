"""Ctrl-C and SIGTERM wherever a command does not handle them itself: exit 130 / 143, no traceback.

Installed first thing by ``cli.main`` (before the heavy imports), so a signal during start-up is never
lost: a shell starts background jobs with SIGINT ignored, and Python keeps it ignored. Long commands
(plan, collect) install their own handlers while they work, which checkpoint before exiting.
"""

from __future__ import annotations

import signal
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
