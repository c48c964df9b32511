"""Logging of a command, configured once per command (docs/DESIGN.md section 13.3).

The modules log through ``logging.getLogger(__name__)``; this module decides where it goes:

* the console (stderr, a Rich handler): WARNING and above; everything down to DEBUG with
  ``--verbose``. What a command prints today (tables, progress bars, summaries) stays as it is, so
  INFO lines there would only repeat it;
* ``--log-file PATH`` (appended, plain text, one timestamped line per record): INFO and above of
  twisted's own loggers (DEBUG with ``--verbose``) and WARNING and above of the libraries. This is
  the record a long ``collect``, ``train`` or ``eval`` leaves to read afterwards.
"""

from __future__ import annotations

import logging
from pathlib import Path

from rich.console import Console
from rich.logging import RichHandler

# the loggers of this project (everything else is a library: WARNING and above only)
OWN_LOGGERS = ("twisted", "cli")
FILE_FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"

_installed: list[logging.Handler] = []  # the handlers of the command that runs (tests run many)


def configure(console: Console, verbose: bool = False, log_file: Path | None = None) -> None:
    """Route log records to ``console`` (stderr) and ``log_file`` for the command about to run.

    Replaces what an earlier call installed; the file is opened at its first record (appending).
    """
    close()
    own_level = logging.DEBUG if verbose else logging.INFO
    root = logging.getLogger()
    root.setLevel(logging.WARNING)
    for name in OWN_LOGGERS:
        logging.getLogger(name).setLevel(own_level)
    screen = RichHandler(
        console=console, level=logging.DEBUG if verbose else logging.WARNING, show_path=False
    )
    _installed.append(screen)
    if log_file is not None:
        file = logging.FileHandler(log_file, mode="a", encoding="utf-8", delay=True)
        file.setFormatter(logging.Formatter(FILE_FORMAT))
        _installed.append(file)
    for handler in _installed:
        root.addHandler(handler)


def close() -> None:
    """Remove (and close) the handlers :func:`configure` installed."""
    root = logging.getLogger()
    for handler in _installed:
        root.removeHandler(handler)
        handler.close()
    _installed.clear()
