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
import tempfile
import threading
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

from datasette import hookimpl
from datasette.utils.asgi import Response
from markupsafe import Markup, escape

from twisted.browse.queries import PLUGIN
from twisted.browse.svg import gauss_svg, knot_words, p_data_of_cell, rope_svg

_KNOT_COLUMNS = {"knot_type", "closure_under", "closure_over", "goal_knot", "knot_before", "knot_after"}
_KEY_COLUMNS = {"key", "state", "goal_key", "start_key", "recorded_key", "result_key"}
_PICTURES_KEPT = 256

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
    try:
        parameters = json.loads(value)
    except ValueError:
        return None
    if not isinstance(parameters, dict) or not parameters:
        return None
    shown = [f"{name}: {parameters[name]}" for name in ("planner", "goal_spec") if name in parameters]
    summary = "; ".join(shown) or f"{len(parameters)} parameters"
    summary = summary if len(summary) <= 100 else summary[:99] + "…"
    return Markup(
        f"<details><summary>{escape(summary)}</summary>"
        f"<pre style='white-space:pre-wrap;font-size:0.8em'>{escape(json.dumps(parameters, indent=1))}</pre>"
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
        return Markup(f"{escape(value)}<br><small>{links}</small>") if links else None
    if table == "search_runs" and column == "outcome" and isinstance(value, str):
        links = _run_links(datasette, database, row["run_id"], "plan", value == "solved")
        return Markup(f"{escape(value)}<br><small>{links}</small>")
    if table is None and column in ("run_id", "plan_run_id") and isinstance(value, int):
        run = _link(f"{datasette.urls.table(database, 'runs')}/{value}", str(value))
        kind = "plan" if column == "plan_run_id" else _column(row, "run_kind")
        links = _run_links(datasette, database, value, kind or "", solved=_column(row, "solved") == 1)
        return Markup(f"{run}<br><small>{links}</small>" if links else run)
    if table is None and column == "label" and isinstance(value, str) and _column(row, "set_name"):
        query = datasette.urls.query(database, "eval_goals")
        return Markup(_link(f"{query}?{urlencode({'set_name': row['set_name'], 'label': value})}", value))
    return None


# ------------------------------------------------------------------ pictures drawn on demand


_Make = Callable[[Path], tuple[Path, str]]  # draws into a folder: the file and its content type


class _Pictures:
    """The matplotlib pictures of one store: drawn in a worker thread, one at a time (pyplot keeps
    global state), the last few kept."""

    def __init__(self, db_url: str) -> None:
        self.db_url = db_url
        self._store: Any = None
        self._lock = threading.Lock()
        self._kept: OrderedDict[tuple[str, str], tuple[bytes, str]] = OrderedDict()

    def store(self) -> Any:
        if self._store is None:
            from twisted.store import open_store

            self._store = open_store(self.db_url, create=False, readonly=True)
        return self._store

    def draw(self, what: tuple[str, str], make: _Make) -> tuple[bytes, str]:
        """``make(folder)`` draws into a fresh folder and names the file and its content type."""
        with self._lock:
            if what not in self._kept:
                with tempfile.TemporaryDirectory(prefix="twisted-browse-") as folder:
                    path, content_type = make(Path(folder))
                    self._kept[what] = (path.read_bytes(), content_type)
                while len(self._kept) > _PICTURES_KEPT:
                    self._kept.popitem(last=False)
            self._kept.move_to_end(what)
            return self._kept[what]


_pictures: dict[str, _Pictures] = {}


def _pictures_of(datasette: Any) -> _Pictures:
    db_url = (datasette.plugin_config(PLUGIN) or {})["db_url"]
    if db_url not in _pictures:
        _pictures[db_url] = _Pictures(db_url)
    return _pictures[db_url]


async def _picture(datasette: Any, what: tuple[str, str], make: _Make) -> Response:
    from twisted.render import RenderError

    pictures = _pictures_of(datasette)
    try:
        body, content_type = await asyncio.get_running_loop().run_in_executor(None, pictures.draw, what, make)
    except RenderError as exc:
        return Response.text(str(exc), status=404)
    return Response(body, content_type=content_type, headers={"Cache-Control": "max-age=600"})


async def _state_picture(datasette: Any, request: Any) -> Response:
    from twisted.render import render_goal

    p_data = p_data_of_cell(request.args.get("key", ""))
    if p_data is None:
        return Response.text('give ?key=P-DATA, a state\'s key, e.g. [[1,"O",2,"+"],[2,"U",1,"+"]]', 400)
    pictures = _pictures_of(datasette)

    def make(folder: Path) -> tuple[Path, str]:
        return render_goal(pictures.store(), p_data, folder / "state.svg").files[0], "image/svg+xml"

    return await _picture(datasette, ("state", p_data.key), make)


async def _plan_picture(datasette: Any, request: Any) -> Response:
    from twisted.render import render_run

    run_id, kind = int(request.url_vars["run_id"]), request.url_vars["kind"]
    pictures = _pictures_of(datasette)

    def make(folder: Path) -> tuple[Path, str]:
        gif = folder / "plan.gif" if kind == "gif" else None
        files = render_run(pictures.store(), run_id, folder / "plan.png", gif, gl=False).files
        return files[-1], f"image/{kind}"

    return await _picture(datasette, (f"run {run_id}", kind), make)


@hookimpl
def register_routes(datasette: Any) -> list[tuple[str, Any]]:
    return [
        (r"^/-/twisted/state\.svg$", _state_picture),
        (r"^/-/twisted/runs/(?P<run_id>\d{1,18})/plan\.(?P<kind>png|gif)$", _plan_picture),
    ]
