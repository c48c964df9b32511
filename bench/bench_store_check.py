"""What the damage check before a write costs (SQLite's quick_check; issue 37 item 9) on a large store.

    python bench/bench_store_check.py --from twisted.db --gb 1 [--work /tmp/store-check]

Copies ``--from`` (a store with collected data, e.g. after ``twisted collect``) into ``--work`` and
copies its configurations and transitions again and again (new ids, the same rows) until the file holds
about ``--gb`` GB, the size of a long collection. Then it times, on that file: opening it as a command
that only reads does (no check), as a command that writes does (``verify=True``: quick_check first),
and quick_check alone, each with the file's pages in the page cache ("warm", as after any recent use)
and after dropping them from the cache (``posix_fadvise(DONTNEED)``, "cold": only this file, the
machine's other caches are left alone). One core; prints a table and MB/s.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sqlite3
import tempfile
import time
from collections.abc import Callable
from pathlib import Path


def grow(path: Path, target_bytes: int) -> int:
    """Copy the configurations and transitions of ``path`` within it until the file is ``target_bytes``."""
    conn = sqlite3.connect(path, isolation_level=None)
    conn.execute("PRAGMA journal_mode = DELETE")  # one file: the size on disk is the size checked
    conn.execute("PRAGMA foreign_keys = OFF")
    top = conn.execute("SELECT max(id) FROM configurations").fetchone()[0] or 0
    columns = [row[1] for row in conn.execute("PRAGMA table_info(transitions)")]
    copied = 0
    while path.stat().st_size < target_bytes:
        copied += 1
        shift = copied * (top + 1)
        conn.execute("BEGIN")
        conn.execute(
            'INSERT INTO configurations (id, run_id, state_id, "cross", q, points, created_at) '
            'SELECT id + ?, run_id, state_id, "cross", q, points, created_at FROM configurations '
            "WHERE id <= ?",
            (shift, top),
        )
        shifted = {
            "id": "NULL",
            "batch_id": "NULL",
            "from_configuration_id": "from_configuration_id + ?",
            "to_configuration_id": "to_configuration_id + ?",
        }
        chosen = ", ".join(shifted.get(c, f'"{c}"') for c in columns)
        names = ", ".join(f'"{c}"' for c in columns)
        conn.execute(
            f"INSERT INTO transitions ({names}) SELECT {chosen} FROM transitions "
            "WHERE from_configuration_id <= ? AND to_configuration_id <= ?",
            (shift, shift, top, top),
        )
        conn.execute("COMMIT")
    conn.close()
    return copied


def drop_cache(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
        os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
    finally:
        os.close(fd)


def timed(action: Callable[[], object], path: Path, cold: bool, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        if cold:
            drop_cache(path)
        started = time.perf_counter()
        action()
        best = min(best, time.perf_counter() - started)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--from", dest="source", type=Path, required=True, help="a store with collected data")
    parser.add_argument("--gb", type=float, default=1.0, help="size to grow the copy to (GB)")
    parser.add_argument(
        "--work", type=Path, default=None, help="folder for the copy (default: a temporary one)"
    )
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    from twisted.store import open_store
    from twisted.store.db import _quick_check

    work = args.work or Path(tempfile.mkdtemp(prefix="store-check-"))
    work.mkdir(parents=True, exist_ok=True)
    path = work / "big.db"
    if not path.exists() or path.stat().st_size < args.gb * 0.95e9:
        shutil.copyfile(args.source, path)
        started = time.perf_counter()
        copies = grow(path, int(args.gb * 1e9))
        print(
            f"grew {path} to {path.stat().st_size / 1e9:.2f} GB ({copies} copies) in "
            f"{time.perf_counter() - started:.0f} s"
        )
    url = f"sqlite:///{path}"
    open_store(url).close()  # upgrade once (not what is measured)
    conn = sqlite3.connect(path)
    rows = {
        t: conn.execute(f"SELECT count(*) FROM {t}").fetchone()[0] for t in ("configurations", "transitions")
    }
    conn.close()
    size_mb = path.stat().st_size / 1e6
    print(
        f"{path}: {size_mb:,.0f} MB, {rows['configurations']:,} configurations, "
        f"{rows['transitions']:,} transitions"
    )

    def check_only() -> None:
        conn = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)
        try:
            _quick_check(conn, "bench")
        finally:
            conn.close()

    cases = {
        "open for reading (no check)": lambda: open_store(url, readonly=True).close(),
        "open for writing, verify=False": lambda: open_store(url).close(),
        "open for writing, verify=True": lambda: open_store(url, verify=True).close(),
        "quick_check alone": check_only,
    }
    print(f"\n{'case':34s} {'warm s':>8s} {'cold s':>8s} {'warm MB/s':>10s} {'cold MB/s':>10s}")
    for name, action in cases.items():
        warm = timed(action, path, cold=False, repeats=args.repeats)
        cold = timed(action, path, cold=True, repeats=args.repeats)
        print(f"{name:34s} {warm:8.2f} {cold:8.2f} {size_mb / warm:10,.0f} {size_mb / cold:10,.0f}")


if __name__ == "__main__":
    main()
