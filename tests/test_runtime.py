"""twisted.runtime: one way for every command to meet Ctrl-C and SIGTERM (exit 130 / 143)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from sqlalchemy import select

from twisted import runtime
from twisted.store import open_store
from twisted.store.experiments import EvalResult, ProblemRecord, save_problem_set
from twisted.topology import parse_p_data

REPO = Path(__file__).resolve().parents[1]
# a 3-crossing goal that random curves do not reach in seconds
THREE_CROSSINGS = '[[1,"O",4,"+"],[2,"U",5,"+"],[3,"O",6,"+"],[4,"U",1,"+"],[5,"O",2,"+"],[6,"U",3,"+"]]'


def _sigterm() -> None:
    """SIGTERM aimed at this (the main) thread; sent to the process it might reach another thread."""
    signal.pthread_kill(threading.get_ident(), signal.SIGTERM)


def _wait_for(seen: list[int]) -> None:
    deadline = time.monotonic() + 5
    while not seen and time.monotonic() < deadline:
        time.sleep(0.01)


def test_sigterm_as_interrupt_raises_keyboard_interrupt_and_restores_the_handler() -> None:
    before = signal.getsignal(signal.SIGTERM)
    runtime.received.clear()
    with pytest.raises(KeyboardInterrupt) as caught, runtime.sigterm_as_interrupt():
        _sigterm()
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
        _sigterm()
        _wait_for(seen)
    assert seen == [signal.SIGTERM]
    assert {s: signal.getsignal(s) for s in runtime.SIGNALS} == before


def test_signals_blocked_holds_signals_back_until_the_end() -> None:
    """What the worker processes inherit when they are started (they unblock once their handlers are set)."""
    seen: list[int] = []
    with runtime.stop_on_signals(seen.append):
        with runtime.signals_blocked():
            _sigterm()
            time.sleep(0.05)
            assert seen == []
        _wait_for(seen)
        assert seen == [signal.SIGTERM]


_CHILD_MASKS = """
import multiprocessing, signal
from twisted import runtime

def blocked(writer):
    writer.send(signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, []))

if __name__ == "__main__":
    ctx = multiprocessing.get_context("spawn")
    reader, writer = ctx.Pipe(duplex=False)  # no semaphore: nothing has started the resource tracker
    with runtime.signals_blocked():
        children = [ctx.Process(target=blocked, args=(writer,)) for _ in range(2)]
        for child in children:
            child.start()
    print([reader.recv() for _ in children])
    for child in children:
        child.join()
"""


def test_workers_started_under_signals_blocked_start_with_the_signals_blocked(tmp_path: Path) -> None:
    """In a fresh interpreter the first start() starts multiprocessing's resource tracker, which
    unblocks SIGINT/SIGTERM when it is up: before, the workers started after it were unprotected."""
    script = tmp_path / "masks.py"
    script.write_text(_CHILD_MASKS)
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "[True, True]"


def test_the_simulation_imports_mujoco_without_opengl() -> None:
    """MuJoCo's default GL (GLFW) starts a Python child at import, which a Ctrl-C in the first second
    killed with a traceback; pictures set MUJOCO_GL in their own child interpreter."""
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    code = "import sys, twisted.sim; print('mujoco' in sys.modules, 'glfw' in sys.modules)"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.split() == ["True", "False"]


def test_cpu_cores_are_the_cores_this_process_may_use_not_the_machines() -> None:
    """The default number of workers follows the CPU affinity (taskset, a container's cpuset), which can
    be fewer than the machine has: a child limited to one core counts one."""
    assert runtime.cpu_cores() == len(os.sched_getaffinity(0))
    code = "import os; os.sched_setaffinity(0, {min(os.sched_getaffinity(0))}); from twisted import runtime; "
    code += "print(runtime.cpu_cores())"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "1"


def test_a_process_is_alive_until_it_has_ended_and_been_reaped() -> None:
    child = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE)
    try:
        assert runtime.process_alive(os.getpid()) and runtime.process_alive(child.pid)
    finally:
        child.communicate(b"", timeout=60)
    assert not runtime.process_alive(child.pid)  # reaped: the pid names no process now
    assert not any(runtime.process_alive(pid) for pid in (0, -1, 2**22 + 12345, 2**40))


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_eval_stopped_by_a_signal_exits_128_plus_it(sqlite_url: str, signum: signal.Signals) -> None:
    """eval used to exit 130 for SIGTERM too (and print a stray "while starting" line after Ctrl-C)."""
    with open_store(sqlite_url) as store, store.session(write=True) as session:
        problems = [ProblemRecord(None, 0, parse_p_data(THREE_CROSSINGS), 0, "imported")]
        save_problem_set(session, "one", problems, source="imported")
    command = ["eval", "--set", "one", "--planner", "random-low", "--timeout", "300", "--parallel", "1"]
    process = subprocess.Popen(
        [sys.executable, "-m", "cli.main", "--db", sqlite_url, *command, "--workers", "1"],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and process.poll() is None:
            with open_store(sqlite_url) as store, store.session() as session:
                if session.scalars(select(EvalResult.plan_run_id)).first() is not None:
                    break  # the goal's planner is searching
            time.sleep(0.5)
        process.send_signal(signum)
        _, stderr = process.communicate(timeout=120)
    finally:
        process.kill()
    assert process.returncode == 128 + signum, stderr
    assert "interrupted: finished goals are stored" in stderr and "while starting" not in stderr
    with open_store(sqlite_url) as store, store.session() as session:
        assert session.scalars(select(EvalResult.status)).all() == ["interrupted"]
