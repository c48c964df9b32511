"""Page times of `twisted browse` on a store with a 10,000-node planner tree (issue 35: under a second),
and a link check of its pages in headless Chromium (issue 63: the browser tells a run's story).

Times (the default): builds a store whose one planner run has N search nodes (default 10,000: random
ropes of 21 links in a random tree, written through the store's own SearchRun), starts `twisted browse`
on it in a subprocess on a free port of 127.0.0.1, and times over HTTP: the search_nodes table (first
page of 50 rows, 100 rows, a page from the middle), the run's tree query (first and last page of 100
nodes), the run's page (first and last page of 50 nodes) and the front page, each fetched once cold
(no picture of it drawn yet; the server has answered two other pages, so its templates are compiled)
and then warm (repeats). Prints the figures; exits 1 when a page takes a second or more.

    python bench/browse_page.py [--nodes 10000] [--repeats 5] [--seed 0]

Links (``--crawl``): serves ``--db`` (a copy of it is served; default: a small store built here with a
solved planner run, its pull test and a collected trefoil), opens the front page, every run page and
every canned query (with its example) in headless Chromium (``chromium --headless --dump-dom``: the
page as the browser built it), and fetches every link and picture on them; prints each page's links and
the broken ones, and exits 1 when one is broken. ``--shots DIR`` also saves screenshots (PNG) of the
front page, the first solved run's page and knots_tied.

    python bench/browse_page.py --crawl [--db sqlite:///twisted.db] [--shots DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.parse
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
    from twisted.store.search_tree import SearchRun
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


def build_story_store(path: Path) -> None:
    """A small store with a story: a solved planner run (a one-crossing goal) with its pull test, and a
    collected trefoil."""
    from twisted.planner import PlannerOptions, start_search
    from twisted.planner.runs import replay
    from twisted.sim import SimPool
    from twisted.store import open_store
    from twisted.store.queries import add_configuration, start_run
    from twisted.topology import parse_p_data, top

    t = np.linspace(0.25, 2 * np.pi - 0.25, 22)  # an open trefoil, 21 links
    trefoil = np.stack([0.05 * (np.sin(t) + 2 * np.sin(2 * t)), 0.05 * (np.cos(t) - 2 * np.cos(2 * t)),
                        0.02 - 0.01 * np.sin(3 * t)], axis=1)  # fmt: skip
    with open_store(f"sqlite:///{path}") as store:
        with SimPool(1) as pool:
            goal = parse_p_data([[1, "O", 2, "+"], [2, "U", 1, "+"]])
            result = start_search(store, goal, PlannerOptions(planner="random-low", seed=0), pool).run(400)
        replay(store, result.run_id, tighten=True)
        with store.session(write=True) as session:
            collect_id = start_run(session, "collect", {}).id
            add_configuration(session, run_id=collect_id, p_data=top(trefoil), q=np.zeros(4), points=trefoil)


class _Links:
    """Every ``href`` and ``src`` of one origin in an HTML text."""

    def __init__(self, base: str) -> None:
        self.base = base

    def __call__(self, page: str, html: str) -> set[str]:
        found = set()
        for raw in re.findall(r'(?:href|src)="([^"#]+)"', html):
            url = urllib.parse.urljoin(page, raw.replace("&amp;", "&"))
            if url.startswith(self.base + "/"):
                found.add(url)
        return found


def _dom(chromium: str, url: str) -> str:
    """The page as headless Chromium built it."""
    command = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--dump-dom", url]
    return subprocess.run(command, capture_output=True, text=True, timeout=120, check=True).stdout


def _status(url: str) -> int:
    try:
        with urllib.request.urlopen(url, timeout=120) as response:
            response.read()
            return int(response.status)
    except urllib.error.HTTPError as exc:
        return int(exc.code)


def crawl(base: str, chromium: str, shots: Path | None) -> int:
    """Open the story pages in Chromium, check every link and picture on them; the count of broken ones."""
    from twisted.browse.queries import QUERIES

    runs = json.loads(urllib.request.urlopen(f"{base}/twisted/runs.json?_shape=array&_size=max").read())
    front = _dom(chromium, f"{base}/")
    examples = sorted({u for u in _Links(base)(f"{base}/", front) if "/twisted/" in u and "?" in u})
    pages = [f"{base}/", *(f"{base}/-/twisted/runs/{r['id']}" for r in runs)]
    pages += [f"{base}/twisted/{name}" for name in QUERIES] + examples
    links, checked, broken = _Links(base), {}, []
    for page in pages:
        found = links(page, _dom(chromium, page))
        for url in sorted(found - set(checked)):
            checked[url] = _status(url)
        bad = [(page, url, checked[url]) for url in sorted(found) if checked[url] != 200]
        broken += bad
        print(f"{page[len(base):][:70]:70s} {len(found):4d} links, {len(bad)} broken")
    for page, url, status in broken:
        print(f"broken: {url[len(base):]} ({status}) on {page[len(base):]}")
    print(f"{len(pages)} pages opened in Chromium, {len(checked)} links fetched, {len(broken)} broken")
    if shots is not None:
        solved = [r["id"] for r in runs if r["message"] == "solved"] or [r["id"] for r in runs]
        named = {"runs.png": "/", "run.png": f"/-/twisted/runs/{solved[0]}"}
        named["knots_tied.png"] = "/twisted/knots_tied"
        for name, address in named.items():
            command = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                       "--window-size=1400,1600", f"--screenshot={shots / name}", base + address]  # fmt: skip
            subprocess.run(command, capture_output=True, timeout=120, check=True)
            print(f"screenshot: {shots / name} ({address})")
    return len(broken)


def _serve(url: str) -> tuple[subprocess.Popen[bytes], str]:
    port = _free_port()
    command = [sys.executable, "-m", "cli.main", "--db", url, "browse", f"--port={port}"]
    server = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    base = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 120
    while True:
        try:
            _fetch(f"{base}/-/versions.json")
            return server, base
        except OSError:
            if server.poll() is not None or time.monotonic() > deadline:
                server.kill()
                raise SystemExit(server.stderr.read().decode() if server.stderr else "no start") from None
            time.sleep(0.3)


def crawl_main(db: str | None, shots: Path | None) -> int:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        print("headless Chromium is needed: apt-get install -y chromium", file=sys.stderr)
        return 2
    if shots is not None:
        shots.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="browse-crawl-") as folder:
        path = Path(folder) / "store.db"
        if db is None:
            build_story_store(path)
        else:
            from twisted.store.db import parse_url, sqlite_path

            source = sqlite_path(parse_url(db))
            if source is None:
                print(f"--db {db}: give an SQLite file", file=sys.stderr)
                return 2
            shutil.copyfile(source, path)  # served from a copy: an older schema is upgraded there only
        server, base = _serve("sqlite:///" + urllib.parse.quote(str(path)))
        try:
            broken = crawl(base, chromium, shots)
        finally:
            server.terminate()
            server.wait(timeout=60)
    return 1 if broken else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--nodes", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--crawl", action="store_true", help="check the story pages' links in Chromium")
    parser.add_argument("--db", help="--crawl: the store to serve (a copy); default: a small one built here")
    parser.add_argument("--shots", type=Path, help="--crawl: save screenshots into this folder")
    args = parser.parse_args()
    if args.crawl:
        return crawl_main(args.db, args.shots)
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
        last_50 = (args.nodes + 49) // 50  # the run page's
        root = f"http://127.0.0.1:{port}"
        pages = {
            "search_nodes table, first page (50 rows)": f"{base}/search_nodes",
            "search_nodes table, 100 rows": f"{base}/search_nodes?_size=100",
            "search_nodes table, from the middle": f"{base}/search_nodes?_sort=id&_next={args.nodes // 2}",
            "run_tree query, first page (100 nodes)": f"{base}/run_tree?run_id={run_id}",
            f"run_tree query, last page ({last}/{last})": f"{base}/run_tree?run_id={run_id}&page={last}",
            "run page, first page (50 nodes, plan first)": f"{root}/-/twisted/runs/{run_id}",
            f"run page, last page ({last_50}/{last_50})": f"{root}/-/twisted/runs/{run_id}?page={last_50}",
            "front page": f"{root}/",
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
