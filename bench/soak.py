"""Kill-loop soak: `collect` and `plan --resume` killed at random moments, then the store is checked.

    python bench/soak.py --kills 100 [--backend sqlite|postgresql] [--plan-share 0.5] [--seed 0]

Each cycle starts the real CLI in its own process group and, after a random delay (0.2-4 s: from
start-up to the middle of the work), sends it one of

- SIGKILL to the main process (a crash: nothing can be flushed; its workers must notice and go),
- SIGINT to the whole group (Ctrl-C in a terminal),
- SIGTERM to the main process (`kill PID`),

and records the exit code (expected: -9, 130, 143; or the normal end if the work finished first) and
any traceback. Collect cycles run `collect --hours 1`; plan cycles run one fixed-seed search
(`--seed S --max-iterations M --checkpoint-every 0`) and continue it with `plan --resume RUN` after
each kill until it ends, then start the next identical run. At the end:

- SQLite: ``PRAGMA integrity_check`` and ``PRAGMA foreign_key_check`` (PostgreSQL enforces keys);
- collect: counters equal committed rows, no batch or transition twice, one root
  (``tests/collect_checks.py``);
- plan: every run's tree rows are ``seq`` 0..n-1 once each, and each finished run's tree (states,
  parents, curves, iterations, simulator calls) equals that of one uninterrupted run with the same
  seed and iteration cap;
- no run is left ``running``.

Prints the figures and exits 1 if any check failed. PostgreSQL: a throwaway server is started
(``tests/postgres_server.py``); the reference run goes to a second database on it.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import create_engine, text
from sqlalchemy.engine import make_url

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

GOAL = '[[1,"O",4,"+"],[2,"U",5,"+"],[3,"O",6,"+"],[4,"U",1,"+"],[5,"O",2,"+"],[6,"U",3,"+"]]'
SIGNALS = (signal.SIGKILL, signal.SIGINT, signal.SIGTERM)
EXPECTED = {signal.SIGKILL: -9, signal.SIGINT: 130, signal.SIGTERM: 143}


def cli(url: str, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "cli.main", "--db", url, *args],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def children(pid: int) -> list[int]:
    """Every descendant of ``pid`` (from /proc)."""
    parent_of: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parent_of[int(entry.name)] = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
    found, frontier = [], [pid]
    while frontier:
        current = frontier.pop()
        kids = [p for p, parent in parent_of.items() if parent == current]
        found += kids
        frontier += kids
    return found


def alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


class Soak:
    def __init__(self, url: str, rng: np.random.Generator, workers: int) -> None:
        self.url = url
        self.rng = rng
        self.workers = workers
        self.kills: Counter[str] = Counter()
        self.codes: Counter[str] = Counter()
        self.problems: list[str] = []

    def kill_at_random(self, proc: subprocess.Popen[str], phase: str, normal_codes: tuple[int, ...]) -> bool:
        """Wait a random moment, send a random signal; True when it was killed (not finished first)."""
        deadline = time.monotonic() + float(self.rng.uniform(0.2, 4.0))
        while time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.01)
        signum = SIGNALS[int(self.rng.integers(len(SIGNALS)))]
        descendants = children(proc.pid)
        killed = proc.poll() is None
        if killed:
            if signum == signal.SIGINT:
                os.killpg(proc.pid, signum)
            else:
                os.kill(proc.pid, signum)
        try:
            _, err = proc.communicate(timeout=90)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            _, err = proc.communicate()
            self.problems.append(f"{phase}: did not stop within 90 s of {signum.name}")
        name = signum.name if killed else "none (finished first)"
        self.kills[f"{phase} {name}"] += 1
        self.codes[f"{phase} {name} -> {proc.returncode}"] += 1
        expected = (EXPECTED[signum],) if killed else normal_codes
        if proc.returncode not in expected:
            self.problems.append(f"{phase} {name}: exit {proc.returncode}, expected {expected}: {err[-600:]}")
        if "Traceback" in err:
            self.problems.append(f"{phase} {name}: a traceback on stderr: {err[-1500:]}")
        deadline = time.monotonic() + 30
        while any(alive(p) for p in descendants) and time.monotonic() < deadline:
            time.sleep(0.1)
        left = [p for p in descendants if alive(p)]
        if left:
            self.problems.append(f"{phase} {name}: processes {left} outlived it")
            for p in left:
                os.kill(p, signal.SIGKILL)
        return killed

    def collect(self, kills: int) -> None:
        for _ in range(kills):
            seed = str(int(self.rng.integers(2**62)))
            proc = cli(
                self.url,
                "collect",
                "--hours",
                "1",
                "--workers",
                str(self.workers),
                "--batch-size",
                "2",
                "--seed",
                seed,
            )
            self.kill_at_random(proc, "collect", (0,))
        # a clean last run marks the SIGKILLed ones interrupted (what the next collect on a host does)
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "cli.main",
                "--db",
                self.url,
                "collect",
                "--hours",
                "0.01",
                "--workers",
                "1",
                "--max-tries",
                "5",
            ],
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=300,
        )
        if done.returncode != 0:
            self.problems.append(f"the closing collect failed: {done.stderr[-800:]}")

    def plan(self, kills: int, common: list[str]) -> list[int]:
        """Kill fixed-seed searches ``kills`` times (resuming each to its end); the finished run ids."""
        finished: list[int] = []
        run_id: int | None = None
        done_kills = 0
        while done_kills < kills or run_id is not None:
            args = ["plan", "--goal", GOAL] if run_id is None else ["plan", "--resume", str(run_id)]
            proc = cli(self.url, *args, *common)
            if done_kills >= kills:  # no kills left: let the run end
                out, err = proc.communicate(timeout=900)
                self.codes[f"plan resumed to its end -> {proc.returncode}"] += 1
                if proc.returncode != 3 or "Traceback" in err:
                    self.problems.append(
                        f"plan --resume {run_id} to the end: exit {proc.returncode}: {err[-800:]}"
                    )
                finished.append(run_id)  # type: ignore[arg-type]
                run_id = None
                break
            killed = self.kill_at_random(proc, "plan", (3,))
            done_kills += killed
            newest = self.newest_plan_run()
            if not killed:
                finished.append(run_id if run_id is not None else newest)  # type: ignore[arg-type]
                run_id = None
            elif run_id is None and newest is not None and newest not in finished:
                run_id = newest  # killed after the run was created: continue it
        return finished

    def newest_plan_run(self) -> int | None:
        with engine(self.url).connect() as conn:
            value = conn.execute(text("SELECT MAX(id) FROM runs WHERE kind = 'plan'")).scalar()
        return None if value is None else int(value)


@functools.cache
def engine(url: str) -> Any:
    return create_engine(url)


def tree(url: str, run_id: int) -> list[tuple[Any, ...]]:
    """A run's tree without times: (seq, parent seq, state, curve, iteration, simulator call)."""
    with engine(url).connect() as conn:
        return [
            tuple(row)
            for row in conn.execute(
                text(
                    "SELECT n.seq, p.seq, s.key, n.link, n.z_max_m, n.x_m, n.y_m, n.iteration, n.sim_call "
                    "FROM search_nodes n LEFT JOIN search_nodes p ON p.id = n.parent_id "
                    "JOIN topological_states s ON s.id = n.state_id WHERE n.run_id = :r ORDER BY n.seq"
                ),
                {"r": run_id},
            )
        ]


def checks(url: str, sqlite: bool, finished: list[int], reference: list[tuple[Any, ...]]) -> list[str]:
    from tests.collect_checks import check_collect_rows

    failed = []
    with engine(url).connect() as conn:
        if sqlite:
            integrity = conn.execute(text("PRAGMA integrity_check")).scalars().all()
            if integrity != ["ok"]:
                failed.append(f"integrity_check: {integrity[:5]}")
            broken = conn.execute(text("PRAGMA foreign_key_check")).all()
            if broken:
                failed.append(f"foreign_key_check: {broken[:5]}")
        running = conn.execute(text("SELECT id, kind FROM runs WHERE status = 'running'")).all()
        if running:
            failed.append(f"runs left running: {running}")
        twice = conn.execute(
            text(
                "SELECT run_id, worker, seq, COUNT(*) FROM collect_batches GROUP BY run_id, worker, seq "
                "HAVING COUNT(*) > 1"
            )
        ).all()
        if twice:
            failed.append(f"collect batches twice: {twice[:5]}")
        gaps = conn.execute(
            text(
                "SELECT run_id, COUNT(*), COUNT(DISTINCT seq), MIN(seq), MAX(seq) FROM search_nodes "
                "GROUP BY run_id HAVING COUNT(*) != COUNT(DISTINCT seq) OR MIN(seq) != 0 "
                "OR MAX(seq) != COUNT(*) - 1"
            )
        ).all()
        if gaps:
            failed.append(f"search trees with a duplicated or missing row: {gaps}")
    try:
        check_collect_rows(url)
    except AssertionError as exc:
        failed.append(f"collect rows: {exc}")
    for run_id in finished:
        if tree(url, run_id) != reference:
            failed.append(f"run {run_id}'s tree differs from the uninterrupted run's")
    return failed


def database_urls(backend: str, workdir: Path) -> tuple[list[str], Any]:
    """Two fresh databases (the soak's, the reference's) and what to close at the end."""
    if backend == "sqlite":
        return [f"sqlite:///{workdir / 'soak.db'}", f"sqlite:///{workdir / 'reference.db'}"], None
    from tests.postgres_server import PostgresServer

    server = PostgresServer()  # its own temporary folder (the server runs as another user)
    server.__enter__()
    admin = make_url(server.url)
    with create_engine(admin, isolation_level="AUTOCOMMIT").connect() as conn:
        for name in ("soak", "reference"):
            conn.execute(text(f'CREATE DATABASE "{name}"'))
    return [
        admin.set(database=n).render_as_string(hide_password=False) for n in ("soak", "reference")
    ], server


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--kills", type=int, default=100, help="kills in all (collect and plan)")
    parser.add_argument("--backend", choices=("sqlite", "postgresql"), default="sqlite")
    parser.add_argument("--plan-share", type=float, default=0.5, help="share of the kills that hit plan")
    parser.add_argument("--seed", type=int, default=0, help="seed of the moments, signals and collect seeds")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--planner", default="random-low", help="the plan runs' planner (twisted: the model)")
    parser.add_argument("--iterations", type=int, default=25, help="--max-iterations of each plan run")
    parser.add_argument(
        "--workdir", default=None, help="keep the databases here (default: a temporary folder)"
    )
    args = parser.parse_args()

    started = time.monotonic()
    workdir = Path(args.workdir or tempfile.mkdtemp(prefix="twisted-soak-"))
    workdir.mkdir(parents=True, exist_ok=True)
    (url, reference_url), server = database_urls(args.backend, workdir)
    try:
        soak = Soak(url, np.random.default_rng(args.seed), args.workers)
        plan_kills = round(args.kills * args.plan_share)
        soak.collect(args.kills - plan_kills)
        common = [
            "--planner",
            args.planner,
            "--seed",
            "7",
            "--max-iterations",
            str(args.iterations),
            "--workers",
            str(args.workers),
            "--checkpoint-every",
            "0",
            "--timeout",
            "100000",
        ]
        finished = soak.plan(plan_kills, common)
        reference_run = subprocess.run(
            [
                sys.executable,
                "-m",
                "cli.main",
                "--db",
                reference_url,
                "plan",
                "--goal",
                GOAL,
                *common,
                "--json",
            ],
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=900,
        )
        reference = tree(reference_url, int(json.loads(reference_run.stdout)["run_id"]))
        failed = checks(url, args.backend == "sqlite", finished, reference) + soak.problems
    finally:
        for cached in (url, reference_url):
            engine(cached).dispose()
        if server is not None:
            server.__exit__(None, None, None)

    print(
        f"soak on {args.backend}: {sum(soak.kills.values())} cycles in {time.monotonic() - started:.0f} s "
        f"({args.workers} workers, seed {args.seed}; databases in {workdir})"
    )
    for what, n in sorted(soak.kills.items()):
        print(f"  {what}: {n}")
    print("exit codes:")
    for what, n in sorted(soak.codes.items()):
        print(f"  {what}: {n}")
    print(
        f"plan runs finished through kills and resumes: {len(finished)}, each compared with one "
        f"uninterrupted run of {len(reference)} nodes ({args.planner}, seed 7, {args.iterations} iterations)"
    )
    print(
        "checks: integrity_check, foreign_key_check (SQLite), collect rows (counters = rows, no batch or "
        "transition twice, one root), tree rows 0..n-1 once, trees equal the reference, no run left running"
    )
    if failed:
        print(f"FAILED ({len(failed)}):")
        for line in failed:
            print(f"  - {line}")
        sys.exit(1)
    print("all checks passed")


if __name__ == "__main__":
    main()
