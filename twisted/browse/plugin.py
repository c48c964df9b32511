"""The Datasette plugin of ``twisted browse``: pictures in table cells, links, and two picture routes.

``render_cell`` (every table and canned query page):

- a ``points`` / ``*_points`` BLOB (link points of a rope): the rope from above as a knot diagram;
- a ``p_data`` cell: a stored rope in that state (the first collected configuration, else the first
  planner node) as a knot diagram beside the state's Gauss diagram, as ``render --goal`` draws it,
  with links to that full drawing and to every rope that reached the state;
- a ``key`` / ``state`` / ``*_key`` cell holding a P-data key: a link to every rope that reached it;
- a knot type (``knot_type``, the two closures, ``goal_knot``): the type with its name in words;
- ``runs.kind`` of a plan run, ``search_runs.outcome``: links to the run's tree, nodes and plan
  pictures; a collect run: its configurations; ``run_id`` / ``plan_run_id`` in a query: the run.

Routes (drawn on demand with matplotlib, cached, one at a time): ``/-/twisted/state.svg?key=KEY`` is
``render --goal`` as SVG; ``/-/twisted/runs/ID/plan.png`` and ``plan.gif`` are ``render --run ID``
(the rope drawn from its link points, no OpenGL).
"""

from __future__ import annotations

import asyncio
import json
import os
import sys
import tempfile
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

from datasette import hookimpl
from datasette.utils.asgi import Response
from markupsafe import Markup, escape

from twisted.browse import pages
from twisted.browse.pages import stored_parameters
from twisted.browse.queries import PLUGIN
from twisted.browse.svg import gauss_svg, knot_words, p_data_of_cell, rope_svg

_KNOT_COLUMNS = {"knot_type", "closure_under", "closure_over", "goal_knot", "knot_before", "knot_after"}
_KEY_COLUMNS = {"key", "state", "goal_key", "start_key", "recorded_key", "result_key"}

# A rope in each state, looked up once per key (the first stored one never changes).
_ROPE_OF_STATE = """
SELECT COALESCE(
  (SELECT c.points FROM topological_states s JOIN configurations c ON c.state_id = s.id
   WHERE s.key = :key ORDER BY c.id LIMIT 1),
  (SELECT n.points FROM topological_states s JOIN search_nodes n ON n.state_id = s.id
   WHERE s.key = :key ORDER BY n.id LIMIT 1)) AS points
"""
_rope_of_state: OrderedDict[tuple[str, str], bytes] = OrderedDict()


def _column(row: Any, name: str) -> Any:
    try:
        return row[name]
    except (IndexError, KeyError):
        return None


def _link(href: str, text: str) -> str:
    return f'<a href="{escape(href)}">{escape(text)}</a>'


def _run_page(datasette: Any, run_id: int) -> str:
    return str(datasette.urls.path(f"/-/twisted/runs/{run_id}"))


def _run_links(datasette: Any, database: str, run_id: int, kind: str, solved: bool) -> str:
    """Links from a run to what it made: a plan run's tree, nodes and plan pictures; a collect run's
    configurations."""
    table = datasette.urls.table
    if kind == "plan":
        links = [
            _link(f"{datasette.urls.query(database, 'run_tree')}?run_id={run_id}", "tree"),
            _link(f"{table(database, 'search_nodes')}?run_id={run_id}", "nodes"),
        ]
        if solved:
            base = datasette.urls.path(f"/-/twisted/runs/{run_id}/plan")
            links += [_link(f"{base}.png", "plan picture"), _link(f"{base}.gif", "plan GIF")]
        return " · ".join(links)
    if kind == "collect":
        return _link(f"{table(database, 'configurations')}?run_id={run_id}", "configurations")
    return ""


def _reached_link(datasette: Any, database: str, key: str, text: str) -> str:
    query = datasette.urls.query(database, "state_reached_by")
    return _link(f"{query}?{urlencode({'key': key})}", text)


async def _state_rope(datasette: Any, database: str, key: str) -> bytes | None:
    cached = _rope_of_state.get((database, key))
    if cached is not None:
        return cached
    result = await datasette.get_database(database).execute(_ROPE_OF_STATE, {"key": key})
    points = result.first()["points"] if result.rows else None
    if points is not None:
        _rope_of_state[(database, key)] = points
        while len(_rope_of_state) > 4096:
            _rope_of_state.popitem(last=False)
    return points


def _p_data_cell(datasette: Any, database: str, value: str) -> Callable[[], Any] | None:
    p_data = p_data_of_cell(value)
    if p_data is None:
        return None
    key = p_data.key

    async def cell() -> Markup:
        points = await _state_rope(datasette, database, key)
        rope = rope_svg(points) if points is not None else None
        full = datasette.urls.path("/-/twisted/state.svg") + "?" + urlencode({"key": key})
        pictures = (rope or "") + gauss_svg(key)
        reached = _reached_link(datasette, database, key, "ropes in this state")
        links = f"{_link(full, 'full drawing')} · {reached}"
        return Markup(
            f'<div style="display:flex;gap:6px;align-items:flex-end;flex-wrap:wrap">{pictures}</div>'
            f'<div style="font-size:0.8em">{links}</div>'
        )

    return cell


def _parameters_cell(value: str) -> Markup | None:
    """A run's parameters folded: the planner and goal (if any) in the summary, all of them inside."""
    parameters = stored_parameters(value)
    if not parameters:
        return None  # not JSON, too long or too deep: Datasette shows the start of the text
    try:
        folded = json.dumps(parameters, indent=1)
    except (ValueError, RecursionError):
        return None
    shown = [f"{name}: {parameters[name]}" for name in ("planner", "goal_spec") if name in parameters]
    summary = "; ".join(shown) or f"{len(parameters)} parameters"
    summary = summary if len(summary) <= 100 else summary[:99] + "…"
    return Markup(
        f"<details><summary>{escape(summary)}</summary>"
        f"<pre style='white-space:pre-wrap;font-size:0.8em'>{escape(folded)}</pre>"
        "</details>"
    )


@hookimpl
def render_cell(row: Any, value: Any, column: str, table: str | None, database: str, datasette: Any) -> Any:
    if isinstance(value, bytes) and (column == "points" or column.endswith("_points")):
        svg = rope_svg(value)
        return Markup(svg) if svg is not None else None
    if column == "p_data" and isinstance(value, str):
        return _p_data_cell(datasette, database, value)
    if column in _KEY_COLUMNS and isinstance(value, str) and value.startswith("["):
        return Markup(_reached_link(datasette, database, value, value))
    if column in _KNOT_COLUMNS:
        words = knot_words(value)
        if words is not None:
            return Markup(f"<strong>{escape(value)}</strong> <small>{escape(words)}</small>")
        return None
    if isinstance(value, float) and column.endswith(("_seconds", "_s")):
        return f"{value:,.2f}"
    if table == "runs" and column == "parameters" and isinstance(value, str):
        return _parameters_cell(value)
    if table == "runs" and column == "kind" and isinstance(value, str):
        links = _run_links(datasette, database, row["id"], value, _column(row, "message") == "solved")
        links = " · ".join(filter(None, [_link(_run_page(datasette, row["id"]), "story"), links]))
        return Markup(f"{escape(value)}<br><small>{links}</small>") if links else None
    if table == "search_runs" and column == "outcome" and isinstance(value, str):
        links = _run_links(datasette, database, row["run_id"], "plan", value == "solved")
        return Markup(f"{escape(value)}<br><small>{links}</small>")
    if table is None and column in ("run_id", "plan_run_id") and isinstance(value, int):
        run = _link(_run_page(datasette, value), str(value))  # the run's story
        kind = "plan" if column == "plan_run_id" else _column(row, "run_kind")
        links = _run_links(datasette, database, value, kind or "", solved=_column(row, "solved") == 1)
        return Markup(f"{run}<br><small>{links}</small>" if links else run)
    if table is None and column == "label" and isinstance(value, str) and _column(row, "set_name"):
        query = datasette.urls.query(database, "eval_goals")
        return Markup(_link(f"{query}?{urlencode({'set_name': row['set_name'], 'label': value})}", value))
    return None


# ------------------------------------------------------------------ pictures drawn on demand

PICTURE_TIME_LIMIT_S = 60.0  # a picture not drawn by then is refused (503) and its drawing killed
_PICTURES_KEPT = 256
_Answer = tuple[int, bytes, str]  # status, body, content type
_kept: OrderedDict[tuple[str, ...], _Answer] = OrderedDict()
_one_at_a_time = asyncio.Semaphore(1)  # matplotlib is CPU-bound: one drawing at a time


def _child_env() -> dict[str, str]:
    """The environment of a drawing child: this process's, with the folder this twisted is imported from
    first on the path (the child must draw with the same code)."""
    root = str(Path(__file__).resolve().parents[2])  # twisted/browse/plugin.py -> the folder above twisted/
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([root, *filter(None, [env.get("PYTHONPATH")])])
    env.setdefault("MPLBACKEND", "Agg")
    return env


async def draw_picture(db_url: str, kind: str, arg: str, suffix: str, limit_s: float) -> _Answer:
    """One picture drawn by a child process (:mod:`twisted.browse.draw`), killed after ``limit_s``:
    (200, the file, its type), (404, why it cannot be drawn), or (503, over the time limit). When the
    request is cancelled (the server stops), the child is killed with it."""
    content_type = {"svg": "image/svg+xml", "png": "image/png", "gif": "image/gif"}[suffix]
    async with _one_at_a_time:
        with tempfile.TemporaryDirectory(prefix="twisted-browse-") as folder:
            out = Path(folder) / f"picture.{suffix}"
            child = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "twisted.browse.draw", db_url, str(out), kind, arg,
                stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.DEVNULL,
                stderr=asyncio.subprocess.PIPE, env=_child_env(),
            )  # fmt: skip
            try:
                _, error = await asyncio.wait_for(child.communicate(), limit_s)
            except TimeoutError:
                late = f"not drawn: the drawing took over {limit_s:g} s, the time limit"
                return 503, late.encode(), "text/plain"
            finally:
                if child.returncode is None:
                    child.kill()
                    await child.wait()
            if child.returncode == 0 and out.is_file():
                return 200, out.read_bytes(), content_type
            reason = error.decode("utf-8", "replace").strip()[-500:] or f"exit {child.returncode}"
            return (404 if child.returncode == 2 else 500), reason.encode(), "text/plain"


async def _picture(datasette: Any, kind: str, arg: str, suffix: str) -> Response:
    db_url = (datasette.plugin_config(PLUGIN) or {})["db_url"]
    what = (db_url, kind, arg, suffix)
    answer = _kept.get(what)
    if answer is None:
        answer = await draw_picture(db_url, kind, arg, suffix, PICTURE_TIME_LIMIT_S)
        if answer[0] < 500:  # a picture, or why it cannot be drawn; a drawing cut short is tried again
            _kept[what] = answer
            while len(_kept) > _PICTURES_KEPT:
                _kept.popitem(last=False)
    else:
        _kept.move_to_end(what)
    status, body, content_type = answer
    headers = {"Cache-Control": "max-age=600"} if status == 200 else {}
    if content_type == "text/plain":
        content_type = "text/plain; charset=utf-8"
    return Response(body, status=status, content_type=content_type, headers=headers)


async def _state_picture(datasette: Any, request: Any) -> Response:
    p_data = p_data_of_cell(request.args.get("key", ""))
    if p_data is None:
        return Response.text('give ?key=P-DATA, a state\'s key, e.g. [[1,"O",2,"+"],[2,"U",1,"+"]]', 400)
    return await _picture(datasette, "state", p_data.key, "svg")


async def _plan_picture(datasette: Any, request: Any) -> Response:
    run_id, kind = int(request.url_vars["run_id"]), request.url_vars["kind"]
    return await _picture(datasette, "plan", str(run_id), kind)


# ------------------------------------------------------------------ the front page and run pages


def _page_number(request: Any) -> int:
    text = request.args.get("page", "1")
    return int(text) if text.isdigit() and 0 < len(text) < 7 and int(text) > 0 else 1


async def _html(datasette: Any, request: Any, title: str, body: Markup, status: int = 200) -> Response:
    template = datasette.jinja_env.from_string(
        '{% extends "base.html" %}{% block title %}{{ title }}{% endblock %}'
        '{% block content %}{{ body }}{% endblock %}'
    )
    html = await datasette.render_template(template, {"title": title, "body": body}, request=request)
    return Response.html(html, status=status)


async def _front_page(datasette: Any, request: Any) -> Response:
    from twisted.browse.server import DATABASE

    page = _page_number(request)
    database = datasette.get_database(DATABASE)
    runs = (await database.execute(pages.RUNS, {"offset": (page - 1) * pages.RUNS_A_PAGE})).rows
    examples = (datasette.plugin_config(PLUGIN) or {}).get("examples", {})
    body = pages.front_page(runs, page, lambda run_id: _run_page(datasette, run_id), examples)
    return await _html(datasette, request, "twisted store", body)


async def _run_story(datasette: Any, request: Any) -> Response:
    from twisted.browse.server import DATABASE

    run_id, page = int(request.url_vars["run_id"]), _page_number(request)
    database = datasette.get_database(DATABASE)
    ids = {"run_id": run_id}
    run = (await database.execute(pages.RUN, ids)).first()
    if run is None:
        missing = Markup(f"<p>No run {run_id} in this store.</p>")
        return await _html(datasette, request, "no such run", missing, 404)
    search = (await database.execute(pages.SEARCH, ids)).first()
    calls = (await database.execute(pages.RUN_CALLS, ids)).first()
    pull_test = (await database.execute(pages.PULL_TEST, ids)).first()
    nodes = []
    if calls["nodes"]:
        offset = (page - 1) * pages.NODES_A_PAGE
        nodes = (await database.execute(pages.RUN_NODES, {**ids, "offset": offset})).rows
    urls = {
        "self": _run_page(datasette, run_id),
        "plan": datasette.urls.path(f"/-/twisted/runs/{run_id}/plan"),
        "tree": f"{datasette.urls.query(DATABASE, 'run_tree')}?run_id={run_id}",
        "nodes": f"{datasette.urls.table(DATABASE, 'search_nodes')}?run_id={run_id}",
    }
    body = pages.run_page(
        run, search, calls, pull_test, nodes, page, urls, lambda other: _run_page(datasette, other)
    )
    return await _html(datasette, request, f"run {run_id}", body)


# ------------------------------------------------------------------ routes


@hookimpl
def register_routes(datasette: Any) -> list[tuple[str, Any]]:
    return [
        (r"^/$", _front_page),
        (r"^/-/twisted/runs/(?P<run_id>\d{1,18})$", _run_story),
        (r"^/-/twisted/state\.svg$", _state_picture),
        (r"^/-/twisted/runs/(?P<run_id>\d{1,18})/plan\.(?P<kind>png|gif)$", _plan_picture),
    ]


# ------------------------------------------------------------------ errors


@hookimpl(tryfirst=True)
def handle_exception(datasette: Any, request: Any, exception: Exception) -> Any:
    """An error page without Datasette's console traceback: a refused query (a 4xx: bad SQL, a write
    SQLite refused) prints nothing on the server's terminal, anything else one line."""
    from datasette.utils.asgi import Base400
    from datasette.views.base import DatasetteError

    title = None
    if isinstance(exception, Base400):
        status, message = exception.status, str(exception.args[0] if exception.args else exception)
    elif isinstance(exception, DatasetteError):
        status, message, title = exception.status, str(exception.message), exception.title
    elif isinstance(exception, RecursionError):  # e.g. ?_json=COLUMN on a stored value nested 200,000 deep
        status, message = 400, "a stored value is nested too deep to be read as JSON: not shown"
    else:
        status, message = 500, f"{type(exception).__name__}: {exception}"
    if status >= 500:
        shown = " ".join(message.split())[:300]
        print(f"twisted browse: {status} on {request.path[:200]}: {shown}", file=sys.stderr)

    async def page() -> Response:
        info = {"ok": False, "error": message, "status": status, "title": title}
        if request.path.endswith(".json"):
            return Response.json(info, status=status)
        html = await datasette.render_template(["error.html"], info, request=request)
        return Response.html(html, status=status)

    return page
