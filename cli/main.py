"""Entry point of the ``twisted`` console script.

Every ``cli/commands_*.py`` module adds its commands to the shared Typer ``app`` when imported.
"""

from __future__ import annotations

import importlib
import pkgutil

import cli
from cli.app import app


def load_commands() -> None:
    for module in sorted(pkgutil.iter_modules(cli.__path__), key=lambda m: m.name):
        if module.name.startswith("commands_"):
            importlib.import_module(f"cli.{module.name}")


load_commands()


def run() -> None:
    app()


if __name__ == "__main__":
    run()
