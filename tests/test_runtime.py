"""twisted.runtime: one way for every command to meet Ctrl-C and SIGTERM (exit 130 / 143)."""

from __future__ import annotations

import os
import signal
import time

import pytest

from twisted import runtime


def _wait_for(seen: list[int]) -> None:
    deadline = time.monotonic() + 5
    while not seen and time.monotonic() < deadline:
        time.sleep(0.01)


def test_sigterm_as_interrupt_raises_keyboard_interrupt_and_restores_the_handler() -> None:
    before = signal.getsignal(signal.SIGTERM)
    runtime.received.clear()
    with pytest.raises(KeyboardInterrupt) as caught, runtime.sigterm_as_interrupt():
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)  # cut short by the handler
    assert signal.getsignal(signal.SIGTERM) is before
    assert runtime.exit_code(caught.value) == 143
    runtime.received.clear()
    assert runtime.exit_code(KeyboardInterrupt()) == 130  # a plain Ctrl-C
    assert runtime.exit_code(ValueError()) is None


def test_stop_on_signals_calls_back_and_restores_the_handlers() -> None:
    before = {s: signal.getsignal(s) for s in runtime.SIGNALS}
    seen: list[int] = []
    with runtime.stop_on_signals(seen.append):
        os.kill(os.getpid(), signal.SIGTERM)
        _wait_for(seen)
    assert seen == [signal.SIGTERM]
    assert {s: signal.getsignal(s) for s in runtime.SIGNALS} == before


def test_signals_blocked_holds_signals_back_until_the_end() -> None:
    seen: list[int] = []
    with runtime.stop_on_signals(seen.append):
        with runtime.signals_blocked():
            os.kill(os.getpid(), signal.SIGTERM)
            assert seen == []
        _wait_for(seen)
        assert seen == [signal.SIGTERM]


def test_cpu_cores_is_positive() -> None:
    assert runtime.cpu_cores() >= 1
