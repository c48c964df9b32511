"""Entry point of the ``twisted`` console script.

Every ``cli/commands_*.py`` module adds its commands to the shared Typer ``app`` when imported.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys

import cli
from twisted import runtime

if "__mp_main__" in sys.modules:  # imported to start a worker process (multiprocessing)
    runtime.worker_process()
else:
    runtime.install()  # before anything slow is imported: a Ctrl-C during start-up exits 130 at once


def load_commands() -> None:
    for module in sorted(pkgutil.iter_modules(cli.__path__), key=lambda m: m.name):
        if module.name.startswith("commands_"):
            importlib.import_module(f"cli.{module.name}")


try:
    from cli.app import app

    load_commands()
except BaseException as exc:  # a signal during the imports (they may wrap it, e.g. in ImportError)
    code = runtime.exit_code(exc)
    if code is None:
        raise
    print(f"interrupted (exit {code}) while starting", file=sys.stderr)
    sys.exit(code)


def run() -> None:
    try:
        app()
    finally:  # the command has ended: a signal no longer changes its exit code (DESIGN 13)
        runtime.ignore_while_exiting()


if __name__ == "__main__":
    run()
