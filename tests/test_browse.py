"""`twisted browse` (issue 35): the store in Datasette with rope and knot pictures.

A tiny store (a real planner run that reaches a one-crossing goal, and a collected rope that ties a
trefoil) is served by the real command in a subprocess on a free port of 127.0.0.1; the runs table,
the tree query and the knots-tied query are fetched over HTTP and must carry their SVG pictures; the
server is then stopped. The pictures themselves are checked against the P-data they draw, and the
command's input checks (port, extra, PostgreSQL) exit 2 before anything starts.
"""

from __future__ import annotations

import hashlib
import json
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from twisted.browse.svg import KNOT_WORDS, blob_points, gauss_svg, knot_words, rope_svg
from twisted.knots.catalogue import CATALOGUE
from twisted.render import crossing_geometry, rope_pieces
from twisted.store import open_store
from twisted.store.queries import add_configuration, start_run
from twisted.topology import parse_p_data, top

ONE = parse_p_data([[1, "O", 2, "+"], [2, "U", 1, "+"]])
ROOT = Path(__file__).resolve().parents[1]


def _trefoil_rope() -> np.ndarray:
    """22 link points of an open trefoil (the standard parametrisation, ends left apart), 3 crossings."""
    t = np.linspace(0.25, 2 * np.pi - 0.25, 22)
    x = 0.05 * (np.sin(t) + 2 * np.sin(2 * t))
    y = 0.05 * (np.cos(t) - 2 * np.cos(2 * t))
    return np.stack([x, y, 0.02 - 0.01 * np.sin(3 * t)], axis=1)


# ------------------------------------------------------------------ the pictures


def test_rope_picture_draws_the_crossings_of_its_state() -> None:
    points = _trefoil_rope()
    p = top(points)
    assert p.cross == 3
    svg = rope_svg(points.astype("<f8").tobytes())
    assert svg is not None and svg.startswith("<svg") and svg.endswith("</svg>")
    labels = re.findall(r">(\d+[OU][+-])</text>", svg)
    assert sorted(labels) == sorted(f"{v.position}{v.over}{v.sign}" for v in p.visits)
    # the rope broken at each under-crossing (a piece shorter than the gap, at an end, is left out)
    assert svg.count("<polyline") == len(rope_pieces(points, crossing_geometry(points))) >= p.cross
    assert p.key.replace('"', "&quot;") in svg  # the state is the tooltip


def test_gauss_picture_has_one_arc_per_crossing() -> None:
    p = top(_trefoil_rope())
    svg = gauss_svg(p.key)
    assert svg.count("<path") == p.cross and svg.count("<polygon") == p.cross  # arcs and arrow heads
    assert re.findall(r">(\d+[OU])</text>", svg) == [f"{v.position}{v.over}" for v in p.visits]
    assert gauss_svg("[]").count("<path") == 0


def test_only_link_points_are_drawn() -> None:
    good = _trefoil_rope().astype("<f8").tobytes()
    assert blob_points(good) is not None
    assert blob_points(good[:-8]) is None  # not a whole number of points
    assert blob_points(b"") is None and blob_points("text") is None
    assert blob_points(np.full((22, 3), np.nan).tobytes()) is None
    assert rope_svg(b"\x00" * 7) is None


def test_every_catalogue_knot_has_words() -> None:
    assert set(CATALOGUE) <= set(KNOT_WORDS)
    assert "trefoil" in (knot_words("3_1+") or "")
    assert knot_words("nonsense") is None and knot_words(3) is None


# ------------------------------------------------------------------ the command's checks


def _cli(*args: str) -> tuple[int, str]:
    from cli.main import app

    result = CliRunner().invoke(app, list(args))
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    return result.exit_code, " ".join(result.output.split())


@pytest.mark.parametrize("port", ["0", "65536", "-3", "http"])
def test_a_bad_port_exits_2(sqlite_url: str, port: str) -> None:
    code, out = _cli("--db", sqlite_url, "browse", "--port", port)
    assert code == 2 and "'--port'" in out
    assert not Path(sqlite_url.removeprefix("sqlite:///")).exists()


def test_a_port_in_use_exits_2(sqlite_url: str) -> None:
    pytest.importorskip("datasette")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        code, out = _cli("--db", sqlite_url, "browse", "--port", str(port))
    assert code == 2 and f"--port {port}: cannot listen on 127.0.0.1:{port}" in out
    assert not Path(sqlite_url.removeprefix("sqlite:///")).exists()


def test_without_datasette_the_message_names_the_extra(
    sqlite_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "datasette", None)  # as if not installed: find_spec gives None
    code, out = _cli("--db", sqlite_url, "browse")
    assert code == 2 and "pip install 'twisted-knots[browse]'" in out


def test_postgresql_and_missing_stores_are_refused(tmp_path: Path) -> None:
    pytest.importorskip("datasette")
    code, out = _cli("--db", "postgresql+psycopg://nobody@127.0.0.1:1/none", "browse", "--port", "1")
    assert code == 2 and "only an SQLite store can be browsed" in out
    code, out = _cli("--db", f"sqlite:///{tmp_path / 'none.db'}", "browse", "--port", str(_free_port()))
    assert code == 2 and "does not exist" in out
    assert not (tmp_path / "none.db").exists()


# ------------------------------------------------------------------ the server


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int, int]:
    """(file, plan run id, collect run id): a solved planner run with its pull test, a collected
    trefoil, and a run that starts from the trefoil (`_untie_run`)."""
    pytest.importorskip("datasette")
    from twisted.planner import PlannerOptions, start_search
    from twisted.planner.runs import replay
    from twisted.sim import SimPool

    path = tmp_path_factory.mktemp("browse") / "store.db"
    with open_store(f"sqlite:///{path}") as opened:
        with SimPool(1) as pool:
            search = start_search(opened, ONE, PlannerOptions(planner="random-low", seed=0), pool)
            result = search.run(max_iterations=400)
        assert result.solved  # deterministic for this seed (tests/test_render.py)
        replay(opened, result.run_id, tighten=True)  # the pull test `plan --tighten` stores
        rope = _trefoil_rope()
        with opened.session(write=True) as session:
            collect_id = start_run(session, "collect", {}).id
            add_configuration(session, run_id=collect_id, p_data=top(rope), q=np.zeros(4), points=rope)
        _untie_run(opened, result.run_id)
    return path, result.run_id, collect_id


def _untie_run(opened: object, from_run: int) -> int:
    """A stored search that starts from the trefoil rope (as `untie` does from a run's end): its root and
    one child keep the trefoil, one child is the straight rope."""
    from twisted.goals import state_goal
    from twisted.planner import Checkpoint, Node
    from twisted.sim import Curve
    from twisted.store.search_tree import SearchRun

    trefoil, straight = _trefoil_rope(), np.stack([np.arange(22) * 0.04, np.zeros(22), np.zeros(22)], axis=1)

    def node(seq: int, parent: int | None, points: np.ndarray) -> Node:
        curve = None if parent is None else Curve(3, 0.05, 0.1, 0.1)
        return Node(seq, parent, np.zeros(8), points, top(points), curve, seq, seq, 0.01 * seq)

    def checkpoint(iteration: int) -> Checkpoint:
        return Checkpoint(iteration, 0.01 * iteration, iteration, {"seed": 0}, {})

    parameters = {"planner": "random-low", "from_run": from_run, "both_ways": True}
    root = node(0, None, trefoil)
    recorder = SearchRun.create(opened, state_goal(top(straight)), parameters, root, checkpoint(0))
    recorder.save([node(1, 0, trefoil + 0.001), node(2, 0, straight)], checkpoint(1))
    return int(recorder.run_id)


def _start(url: str) -> tuple[str, subprocess.Popen[str]]:
    """`twisted --db URL browse` on a free port, answering: (base URL, the process)."""
    port = _free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "cli.main", "--db", url, "browse", "--port", str(port)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    base = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 120  # start-up on a busy machine; not a speed check
    while True:
        assert proc.poll() is None, proc.communicate()[0]
        try:
            # the port listens before the app is up (bound first): a request waits in its queue
            with urllib.request.urlopen(f"{base}/-/versions.json", timeout=30):
                return base, proc
        except (urllib.error.URLError, ConnectionError, TimeoutError):
            if time.monotonic() > deadline:
                proc.kill()
                raise AssertionError("twisted browse did not start") from None
            time.sleep(0.3)


def _stop(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.fixture(scope="module")
def server(store: tuple[Path, int, int]) -> Iterator[tuple[str, subprocess.Popen[str], str]]:
    """`twisted browse` on a free port: (base URL, the process, the file's digest before serving)."""
    path = store[0]
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    base, proc = _start(f"sqlite:///{path}")
    try:
        yield base, proc, digest
    finally:
        _stop(proc)


def _get(
    url: str, data: bytes | None = None, headers: dict[str, str] | None = None
) -> tuple[int, str, bytes]:
    try:
        request = urllib.request.Request(url, data=data, headers=headers or {})
        with urllib.request.urlopen(request, timeout=60) as response:
            return response.status, response.headers.get("Content-Type", ""), response.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.headers.get("Content-Type", ""), exc.read()


def _page(url: str) -> str:
    status, _, body = _get(url)
    assert status == 200, body[:2000]
    return body.decode()


def test_the_runs_table_links_a_plan_run_to_its_tree_and_pictures(server, store) -> None:
    base, _, _ = server
    _, plan_id, collect_id = store
    html = _page(f"{base}/twisted/runs")
    assert f"/twisted/run_tree?run_id={plan_id}" in html
    assert f"/-/twisted/runs/{plan_id}/plan.gif" in html
    assert f"/twisted/configurations?run_id={collect_id}" in html
    status, content_type, gif = _get(f"{base}/-/twisted/runs/{plan_id}/plan.gif")
    assert status == 200 and content_type == "image/gif" and gif[:6] == b"GIF89a"
    status, _, body = _get(f"{base}/-/twisted/runs/{collect_id}/plan.png")
    assert status == 404 and b"not a planner run" in body


def test_the_tree_query_draws_every_node(server, store) -> None:
    base, _, _ = server
    path, plan_id, _ = store
    with open_store(f"sqlite:///{path}", readonly=True) as opened:
        from twisted.store.search_tree import load_run, solution_path

        info = load_run(opened, plan_id)
        assert info is not None
        nodes, plan = info.nodes, solution_path(opened, plan_id)
    html = _page(f"{base}/twisted/run_tree?run_id={plan_id}")
    assert html.count('class="twisted-rope"') == len(nodes) > 1
    assert len(re.findall(r"<td class=\"col-on_plan[^>]*>plan</td>", html)) == len(plan)
    assert _page(f"{base}/twisted/run_tree?run_id={plan_id}&page=2").count("<svg") == 0


def test_the_knots_tied_query_shows_the_trefoil(server, store) -> None:
    base, _, _ = server
    _, _, collect_id = store
    html = _page(f"{base}/twisted/knots_tied")
    assert "3_1-" in html and "trefoil (overhand knot), left-handed" in html
    assert html.count('class="twisted-rope"') == 1
    key = top(_trefoil_rope()).key
    states = _page(f"{base}/twisted/topological_states")
    assert urllib.parse.urlencode({"key": key}).replace("&", "&amp;") in states  # its link to the ropes
    reached = _page(f"{base}/twisted/state_reached_by?{urllib.parse.urlencode({'key': key})}")
    # the collected trefoil and the two trefoil nodes of the run that starts from it
    assert reached.count('class="twisted-rope"') == 3 and f">{collect_id}</a>" in reached


def test_states_show_their_gauss_diagram_and_full_drawing(server) -> None:
    base, _, _ = server
    html = _page(f"{base}/twisted/topological_states")
    assert html.count('class="twisted-gauss"') == html.count('class="twisted-rope"') >= 3  # each has a rope
    status, content_type, svg = _get(f"{base}/-/twisted/state.svg?{urllib.parse.urlencode({'key': ONE.key})}")
    assert status == 200 and content_type == "image/svg+xml" and b"<svg" in svg[:1000]
    assert _get(f"{base}/-/twisted/state.svg?key=nonsense")[0] == 400


def test_the_other_canned_queries_answer(server) -> None:
    base, _, _ = server
    columns = {"states_most_reached": "p_data", "pull_tests": "pulled_points", "eval_labels": "label"}
    for name, column in {**columns, "eval_goals.json?set_name=x&label=y": "plan_run_id"}.items():
        if "?" not in name:
            name += ".json"
        status, _, body = _get(f"{base}/twisted/{name}")
        assert status == 200 and column in json.loads(body)["columns"]  # the SQL runs on this schema
    assert len(json.loads(_page(f"{base}/twisted/states_most_reached.json"))["rows"]) >= 3


# ------------------------------------------------------------------ hostile stores and requests (issue 62)

# '#' ends a file: URI's path, '?' starts its parameters, '%' escapes, ' ' is not allowed: written
# unescaped after "file:", this name opens the file "odd " read-write (the decoy beside it)
ODD_NAME = "odd #x?mode=rw&y= %41.db"
DECOY = "odd "
WRITES = [
    "with x as (select 1) delete from runs",
    "with x as (select 1) update runs set message = 'written'",
    "with x as (select 1) insert into runs (kind, parameters, started_at, pid) select kind, parameters, "
    "started_at, pid from runs",
]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _plant(path: Path, collect_id: int) -> None:
    """A rope of 1,000 random links in the first planner node of the straight state, and a run's
    parameters nested 200,000 deep."""
    import sqlite3

    conn = sqlite3.connect(path)
    try:
        (node_id,) = conn.execute(
            "SELECT n.id FROM search_nodes n JOIN topological_states s ON s.id = n.state_id "
            "WHERE s.key = '[]' ORDER BY n.id LIMIT 1"
        ).fetchone()
        rope = np.random.default_rng(0).uniform(-0.3, 0.3, (1001, 3)).astype("<f8")
        conn.execute("UPDATE search_nodes SET points = ? WHERE id = ?", (rope.tobytes(), node_id))
        deep = "[" * 200_000 + "]" * 200_000
        conn.execute("UPDATE runs SET parameters = ? WHERE id = ?", (deep, collect_id))
        conn.commit()
    finally:
        conn.close()


@pytest.fixture(scope="module")
def hostile(
    store: tuple[Path, int, int], tmp_path_factory: pytest.TempPathFactory
) -> Iterator[tuple[str, subprocess.Popen[str], Path]]:
    """The store copied under ODD_NAME with `_plant`'s rows, a decoy store beside it (the file an
    unescaped URI would open), served: (base URL, the process, the file)."""
    import shutil
    import sqlite3

    folder = tmp_path_factory.mktemp("odd")
    path = folder / ODD_NAME
    shutil.copyfile(store[0], path)
    _plant(path, store[2])
    shutil.copyfile(store[0], folder / DECOY)
    with sqlite3.connect(folder / DECOY) as conn:
        conn.execute("UPDATE runs SET message = 'decoy'")
    conn.close()
    base, proc = _start(f"sqlite:///{urllib.parse.quote(str(path))}")
    try:
        yield base, proc, path
    finally:
        _stop(proc)


@pytest.mark.parametrize("name", ["a#b.db", "r.db?mode=rw&x=", "p%41 q.db", "sp ace.db"])
def test_the_served_file_is_exactly_the_store_and_sqlite_refuses_writes(tmp_path: Path, name: str) -> None:
    pytest.importorskip("datasette")
    import sqlite3

    from twisted.browse.server import DATABASE, datasette_app

    path = tmp_path / name
    for file in (path, tmp_path / "a", tmp_path / "r.db", tmp_path / "p"):  # the decoys first, if any
        with sqlite3.connect(file) as conn:
            conn.execute("CREATE TABLE runs (id INTEGER PRIMARY KEY, message TEXT)")
            conn.execute("INSERT INTO runs (message) VALUES (?)", (file.name,))
        conn.close()
    digest = _digest(path)
    conn = datasette_app(path, f"sqlite:///{path}").get_database(DATABASE).connect()
    try:
        assert conn.execute("SELECT message FROM runs").fetchall() == [(name,)]
        assert conn.execute("PRAGMA query_only").fetchone() == (1,)
        for sql in [*WRITES[:2], "with x as (select 1) insert into runs (message) values ('w')"]:
            with pytest.raises(sqlite3.OperationalError, match="readonly|read-only"):
                conn.execute(sql)
    finally:
        conn.close()
    assert _digest(path) == digest


def test_sql_that_writes_is_refused_and_nothing_is_written(hostile) -> None:
    base, _, path = hostile
    digests = _digest(path), _digest(path.parent / DECOY)
    for sql in WRITES:
        status, _, body = _get(f"{base}/twisted.json?{urllib.parse.urlencode({'sql': sql})}")
        assert status == 400 and b"readonly" in body, (sql, status, body[:300])
    assert (_digest(path), _digest(path.parent / DECOY)) == digests
    runs = json.loads(_page(f"{base}/twisted/runs.json?_shape=array"))
    assert runs and not any(run["message"] == "decoy" for run in runs)  # the store, not the decoy


def test_a_planted_rope_is_not_drawn(hostile) -> None:
    base, _, _ = hostile
    status, _, html = _get(f"{base}/twisted/search_nodes?_size=5&_sort=id")
    assert status == 200 and len(html) < 500_000  # was 66 MB for 1,000 links
    status, _, body = _get(f"{base}/-/twisted/state.svg?key=[]")
    assert status == 404 and b"not a rope of this store" in body and b"(1001, 3)" in body
    plan_runs = json.loads(_page(f"{base}/twisted/search_runs.json?_shape=array&outcome=solved"))
    status, _, body = _get(f"{base}/-/twisted/runs/{plan_runs[0]['run_id']}/plan.png")
    assert status == 404 and b"not a rope of this store" in body


def test_parameters_nested_deep_are_shown_as_text(hostile, store) -> None:
    base, _, _ = hostile
    collect_id = store[2]
    for page in ("/twisted/runs", f"/twisted/runs/{collect_id}", "/twisted/runs.json"):
        status, _, body = _get(f"{base}{page}")
        assert status == 200, (page, body[:300])
    status, _, body = _get(f"{base}/twisted/runs.json?_json=parameters")  # Datasette parses the JSON
    assert status == 400 and b"nested too deep" in body


def test_only_get_on_localhost_and_known_pages_is_answered(hostile) -> None:
    base, _, _ = hostile
    port = base.rsplit(":", 1)[1]
    for host in (f"127.0.0.1:{port}", f"localhost:{port}", "localhost"):
        assert _get(f"{base}/twisted/runs", headers={"Host": host})[0] == 200, host
    for host in ("evil.example", f"evil.example:{port}", "127.0.0.1:1", f"127.0.0.1.evil.example:{port}"):
        status, _, body = _get(f"{base}/twisted/runs", headers={"Host": host})
        assert status == 421 and b"is not served" in body, host
    assert _get(f"{base}/twisted/runs", data=b"a=1")[0] == 405
    assert _get(f"{base}/twisted/runs_tree?run_id=1", data=b"")[0] == 405
    for page in ("/-/nope", "/-/twisted/nope", "/-/auth-token", "/_memory", "/_memory.json?sql=select+1"):
        assert _get(f"{base}{page}")[0] == 404, page


def test_the_server_prints_no_traceback(hostile) -> None:
    _, proc, _ = hostile
    _stop(proc)
    out = proc.communicate()[0]
    assert proc.returncode == 143 and "Traceback" not in out and "locals" not in out, out[-3000:]
    assert len(out.splitlines()) <= 2 + len(WRITES), out  # the banner, one line per refused write, "stopped"


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_stops_the_server_while_a_picture_is_drawn(hostile, signum: int) -> None:
    """The planted rope's picture held the server for minutes (and SIGTERM / SIGINT with it)."""
    _, _, path = hostile
    base, proc = _start(f"sqlite:///{urllib.parse.quote(str(path))}")
    try:
        pending = threading.Thread(target=_get, args=(f"{base}/-/twisted/state.svg?key=[]",), daemon=True)
        pending.start()
        time.sleep(1.0)
        proc.send_signal(signum)
        out, _ = proc.communicate(timeout=30)
    finally:
        _stop(proc)
    assert proc.returncode == 128 + signum and f"stopped ({signal.Signals(signum).name})" in out, out


def test_a_picture_past_its_time_limit_is_refused(store) -> None:
    pytest.importorskip("datasette")
    import asyncio

    from twisted.browse.plugin import draw_picture

    path, plan_id, _ = store
    url = f"sqlite:///{path}"
    status, body, _ = asyncio.run(draw_picture(url, "plan", str(plan_id), "gif", 0.05))
    assert status == 503 and b"time limit" in body
    status, body, content_type = asyncio.run(draw_picture(url, "plan", str(plan_id), "png", 120))
    assert status == 200 and content_type == "image/png" and body[:4] == b"\x89PNG"


# ------------------------------------------------------------------ a run's story (issue 63 item 6)


def _run_ids(base: str) -> dict[str, int]:
    runs = json.loads(_page(f"{base}/twisted/runs.json?_shape=array&_sort=id"))
    untie = [r["id"] for r in runs if '"from_run"' in (r["parameters"] or "")]
    return {"untie": untie[0]}


def test_the_front_page_lists_the_runs_first(server, store) -> None:
    base, _, _ = server
    _, plan_id, collect_id = store
    html = _page(f"{base}/")
    runs = html.index("Runs, newest first")
    assert runs < html.index("Questions") < html.index("Tables")
    untie_id = _run_ids(base)["untie"]
    for run_id in (plan_id, collect_id, untie_id):
        assert f'href="/-/twisted/runs/{run_id}"' in html
    assert f"from run <a href=\"/-/twisted/runs/{plan_id}\">{plan_id}</a>" in html  # the untie run
    assert "_memory" not in html and _get(f"{base}/_memory")[0] == 404
    assert f"/twisted/run_tree?run_id={plan_id}" in html  # an example of the query that takes a run


def test_a_run_page_tells_the_story_plan_first(server, store) -> None:
    base, _, _ = server
    path, plan_id, _ = store
    html = _page(f"{base}/-/twisted/runs/{plan_id}")
    for fact in ("<dt>goal</dt>", "<dt>outcome</dt><dd>solved</dd>", "simulator calls", "<dt>pull test</dt>"):
        assert fact in html, fact
    assert f'<img src="/-/twisted/runs/{plan_id}/plan.png"' in html
    with open_store(f"sqlite:///{path}", readonly=True) as opened:
        from twisted.store.search_tree import solution_path

        plan = solution_path(opened, plan_id)
    marks = re.findall(r"<tr><td>(plan)?</td><td>(\d+)</td>", html)
    assert [seq for mark, seq in marks[: len(plan)] if mark] == [str(n.seq) for n in plan]  # the plan first
    assert not any(mark for mark, _ in marks[len(plan) :])
    assert "next 50 nodes" not in html and "previous" in _page(f"{base}/-/twisted/runs/{plan_id}?page=2")
    untie = _page(f"{base}/-/twisted/runs/{_run_ids(base)['untie']}")
    assert f'the end of run <a href="/-/twisted/runs/{plan_id}">{plan_id}</a>' in untie
    assert "<dt>knots tied</dt><dd>none</dd>" in untie  # the trefoil it started from is not tied
    assert _get(f"{base}/-/twisted/runs/999999")[0] == 404


def test_knots_tied_counts_what_a_run_tied_not_its_start(server, store) -> None:
    base, _, _ = server
    _, _, collect_id = store
    untie_id = _run_ids(base)["untie"]
    sql = urllib.parse.urlencode({"sql": "select distinct run_id from knots_tied order by run_id"})
    view = json.loads(_page(f"{base}/twisted.json?{sql}&_shape=array"))  # the store's view credits the start
    assert [r["run_id"] for r in view] == [collect_id, untie_id]
    query = json.loads(_page(f"{base}/twisted/knots_tied.json?_shape=array"))
    assert [r["run_id"] for r in query] == [collect_id]


def test_every_canned_query_with_parameters_has_a_working_example(server) -> None:
    from twisted.browse.queries import EXAMPLE_ROWS

    base, _, _ = server
    for name in EXAMPLE_ROWS:
        html = _page(f"{base}/twisted/{name}")
        found = re.search(r"Example: <a href='([^']+)'>", html)
        if name == "eval_goals":  # this store has no eval results
            assert found is None and "nothing to show here yet" in html
            continue
        assert found, name
        address = found.group(1).replace(f"/twisted/{name}?", f"/twisted/{name}.json?")
        assert json.loads(_page(base + address))["rows"], name


def test_the_plan_picture_is_plan_pictures_and_the_gif_keeps_its_axes(store, monkeypatch, tmp_path) -> None:
    from twisted.browse.draw import draw
    from twisted.render import stored

    path, plan_id, _ = store
    limits: list[tuple[tuple[float, float], tuple[float, float]]] = []
    to_array = stored.figure_to_array

    def keep_limits(fig, dpi=80):  # the real drawing; its axes' limits noted
        limits.append((fig.axes[-1].get_xlim(), fig.axes[-1].get_ylim()))
        return to_array(fig, dpi=dpi)

    monkeypatch.setattr(stored, "figure_to_array", keep_limits)
    with open_store(f"sqlite:///{path}", readonly=True) as opened:
        draw(opened, tmp_path / "plan.gif", "plan", str(plan_id))
        assert len(limits) >= 3 and len(set(limits)) == 1  # the rope does not jump between frames
        draw(opened, tmp_path / "browser.png", "plan", str(plan_id))
        stored.render_tightened(opened, plan_id, tmp_path / "plan-picture.png")  # what plan --picture draws
    assert (tmp_path / "browser.png").read_bytes() == (tmp_path / "plan-picture.png").read_bytes()


def test_no_link_of_the_story_pages_is_broken(server, store) -> None:
    """Every link and picture of the front page and the run pages answers (bench/browse_page.py --crawl
    opens the same pages, and the canned queries, in headless Chromium)."""
    base, _, _ = server
    runs = json.loads(_page(f"{base}/twisted/runs.json?_shape=array"))
    pages = [f"{base}/", *(f"{base}/-/twisted/runs/{run['id']}" for run in runs)]
    checked: dict[str, int] = {}
    for page in pages:
        for raw in re.findall(r'(?:href|src)="([^"#]+)"', _page(page)):
            url = urllib.parse.urljoin(page, raw.replace("&amp;", "&"))
            if url.startswith(base + "/") and url not in checked:
                checked[url] = _get(url)[0]
    assert len(checked) > 15 and {url: s for url, s in checked.items() if s != 200} == {}


# the last test of the story server: it stops it
def test_the_server_listens_on_localhost_only_reads_and_stops(server, store) -> None:
    base, proc, digest = server
    port = int(base.rsplit(":", 1)[1])
    tcp = Path("/proc/net/tcp")
    if tcp.exists():  # Linux: the listening socket's local address is 127.0.0.1 (0100007F)
        listening = [line.split()[1] for line in tcp.read_text().splitlines()[1:] if line.split()[3] == "0A"]
        assert f"0100007F:{port:04X}" in listening
        assert not any(a.endswith(f":{port:04X}") and a != f"0100007F:{port:04X}" for a in listening)
    _page(f"{base}/twisted/search_nodes")
    proc.terminate()
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 143 and "stopped (SIGTERM)" in out, out
    assert hashlib.sha256(store[0].read_bytes()).hexdigest() == digest  # served read-only
