"""Page times of `twisted browse` on a store with a 10,000-node planner tree (issue 35: under a second).

Builds a store whose one planner run has N search nodes (default 10,000: random ropes of 21 links in a
random tree, written through the store's own SearchRun), starts `twisted browse` on it in a subprocess
on a free port of 127.0.0.1, and times over HTTP: the search_nodes table (first page of 50 rows, 100
rows, a page from the middle), and the run's tree query (first and last page of 100 nodes), each
fetched once cold (no picture of it drawn yet; the server has answered two other pages, so its templates
are compiled) and then warm (repeats). Prints the figures; exits 1 when a page takes a second or more.

    python bench/browse_page.py [--nodes 10000] [--repeats 5] [--seed 0]
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LIMIT_S = 1.0


def _rope(rng: np.random.Generator) -> np.ndarray:
    """A random rope of 21 links of 4 cm, curled enough to cross itself now and then."""
    angles = np.cumsum(rng.normal(0.0, 0.7, 21))
    points = np.zeros((22, 3))
    points[1:, 0] = np.cumsum(0.04 * np.cos(angles))
    points[1:, 1] = np.cumsum(0.04 * np.sin(angles))
    points[:, 2] = rng.uniform(0.0, 0.02, 22)
    return points


def build_store(path: Path, nodes: int, seed: int) -> int:
    """A store with one planner run of ``nodes`` nodes; returns the run id."""
    from twisted.goals import state_goal
    from twisted.planner import Checkpoint, Node
    from twisted.sim import Curve
    from twisted.store import open_store
    from twisted.store.search import SearchRun
    from twisted.topology import parse_p_data, top

    rng = np.random.default_rng(seed)

    def node(index: int, parent: int | None) -> Node:
        straight = np.stack([np.arange(22) * 0.04, np.zeros(22), np.zeros(22)], axis=1)
        points = _rope(rng) if parent is not None else straight
        curve = None if parent is None else Curve(int(rng.integers(0, 21)), 0.05, 0.2, -0.1)
        iteration = index // 3
        return Node(index, parent, np.zeros(8), points, top(points), curve, iteration, index, 0.01 * index)

    def checkpoint(iteration: int) -> Checkpoint:
        return Checkpoint(iteration, 0.01 * iteration, 3 * iteration, {"seed": seed}, {})

    goal = state_goal(parse_p_data([[1, "O", 2, "+"], [2, "U", 1, "+"]]))
    with open_store(f"sqlite:///{path}") as store:
        parameters = {"planner": "bench", "seed": seed}
        recorder = SearchRun.create(store, goal, parameters, node(0, None), checkpoint(0))
        batch: list[Node] = []
        for index in range(1, nodes):
            batch.append(node(index, int(rng.integers(0, index))))
            if len(batch) == 1000 or index == nodes - 1:
                recorder.save(batch, checkpoint(batch[-1].iteration))
                batch = []
        return recorder.run_id


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _fetch(url: str) -> tuple[float, int, int]:
    """Seconds to fetch ``url`` whole, its size in bytes and how many SVG pictures it holds."""
    started = time.perf_counter()
    with urllib.request.urlopen(url, timeout=120) as response:
        body = response.read()
    return time.perf_counter() - started, len(body), body.count(b"<svg")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--nodes", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="browse-bench-") as folder:
        path = Path(folder) / "store.db"
        started = time.perf_counter()
        run_id = build_store(path, args.nodes, args.seed)
        built_s = time.perf_counter() - started
        print(f"store: {args.nodes:,} search nodes in run {run_id}, built in {built_s:.1f} s")
        port = _free_port()
        command = [sys.executable, "-m", "cli.main", "--db", f"sqlite:///{path}", "browse", f"--port={port}"]
        server = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        base = f"http://127.0.0.1:{port}/twisted"
        last = (args.nodes + 99) // 100  # the tree query's pages
        pages = {
            "search_nodes table, first page (50 rows)": f"{base}/search_nodes",
            "search_nodes table, 100 rows": f"{base}/search_nodes?_size=100",
            "search_nodes table, from the middle": f"{base}/search_nodes?_sort=id&_next={args.nodes // 2}",
            "run_tree query, first page (100 nodes)": f"{base}/run_tree?run_id={run_id}",
            f"run_tree query, last page ({last}/{last})": f"{base}/run_tree?run_id={run_id}&page={last}",
        }
        try:
            deadline = time.monotonic() + 120
            while True:
                try:
                    _fetch(f"http://127.0.0.1:{port}/-/versions.json")
                    break
                except OSError:
                    if server.poll() is not None or time.monotonic() > deadline:
                        print(server.stderr.read().decode() if server.stderr else "", file=sys.stderr)
                        return 2
                    time.sleep(0.3)
            for warm_up in (f"{base}/runs", f"{base}/eval_labels"):  # templates compiled, schema read
                _fetch(warm_up)
            load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
            print(f"machine load average (1, 5, 15 min): {load} on {os.cpu_count()} cores")
            worst = 0.0
            print(f"{'page':45s} {'cold s':>8s} {'warm median s':>14s} {'warm max s':>11s} {'kB':>7s} svg")
            for name, url in pages.items():
                cold, size, svgs = _fetch(url)
                warm = [_fetch(url)[0] for _ in range(args.repeats)]
                worst = max(worst, cold, *warm)
                print(
                    f"{name:45s} {cold:8.3f} {statistics.median(warm):14.3f} {max(warm):11.3f} "
                    f"{size / 1000:7.0f} {svgs:5d}"
                )
        finally:
            server.terminate()
            server.wait(timeout=60)
    verdict = "under" if worst < LIMIT_S else "NOT under"
    print(f"slowest page: {worst:.3f} s ({verdict} {LIMIT_S:.0f} s)")
    return 0 if worst < LIMIT_S else 1


if __name__ == "__main__":
    sys.exit(main())
