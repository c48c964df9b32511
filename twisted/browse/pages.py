"""The two pages of ``twisted browse`` that tell a run's story (HTML bodies; the plugin serves them).

- the front page (``/``): the runs, newest first, each with its goal, outcome, the knots it tied and
  its pull test, then the canned questions with an example each and the tables;
- a run page (``/-/twisted/runs/ID``): what the run was asked (goal, planner), what came of it
  (outcome, knots tied, pull test, simulator calls, pictures), the run it started from (an untie run),
  and its tree with the plan's nodes first, 50 nodes a page.

Everything here is SQL and HTML text from rows; every stored value is escaped, and a cell picture is
drawn only for a rope of the store's profile (:func:`twisted.browse.svg.rope_svg`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any
from urllib.parse import unquote_plus, urlencode

from markupsafe import Markup, escape

from twisted.browse.queries import QUERIES, TIED
from twisted.browse.svg import knot_words, rope_svg

__all__ = ["NODES_A_PAGE", "RUNS_A_PAGE", "front_page", "run_page", "stored_parameters"]

RUNS_A_PAGE = 50
NODES_A_PAGE = 50
_MAX_PARAMETERS_CHARS = 64_000  # a run's parameters are a few hundred characters

_RUNS = f"""
WITH tied AS ({TIED})
SELECT r.id, r.kind, r.status, r.message, r.started_at, ROUND(r.wall_seconds, 1) AS wall_seconds,
       r.parameters, sr.outcome, sr.goal_knot,
       (SELECT GROUP_CONCAT(knot_type, ' ') FROM (
          SELECT DISTINCT t.knot_type FROM tied t WHERE t.run_id = r.id ORDER BY t.knot_type)) AS knots_tied,
       (SELECT t.knot_after || CASE WHEN t.ties_goal THEN ' (ties the goal)' ELSE '' END
        FROM tightenings t WHERE t.run_id = r.id AND t.ok ORDER BY t.id DESC LIMIT 1) AS pull_test
FROM runs r LEFT JOIN search_runs sr ON sr.run_id = r.id
"""
RUNS = f"{_RUNS} ORDER BY r.id DESC LIMIT {RUNS_A_PAGE + 1} OFFSET :offset"
RUN = f"{_RUNS} WHERE r.id = :run_id"
SEARCH = "SELECT * FROM search_runs WHERE run_id = :run_id"

RUN_CALLS = """
SELECT COUNT(*) AS nodes, MAX(sim_call) AS sim_calls, MAX(iteration) AS iterations
FROM search_nodes WHERE run_id = :run_id
"""

PULL_TEST = """
SELECT t.knot_before, t.knot_after, t.goal_knot, t.ties_goal, t.ok, t.reason, ROUND(t.end_distance_m, 3)
       AS end_distance_m, t.node_seq
FROM tightenings t WHERE t.run_id = :run_id ORDER BY t.id DESC LIMIT 1
"""

# The run's nodes, the plan's first (root to goal: a node's seq grows along the path), then the rest by seq.
RUN_NODES = f"""
WITH RECURSIVE plan(node_id) AS (
    SELECT goal_node_id FROM search_runs WHERE run_id = :run_id AND goal_node_id IS NOT NULL
  UNION ALL
    SELECT n.parent_id FROM search_nodes n JOIN plan p ON n.id = p.node_id WHERE n.parent_id IS NOT NULL
)
SELECT n.seq, parent.seq AS parent_seq, n.id IN (SELECT node_id FROM plan) AS on_plan, n.points, n.cross,
       s.knot_type, s.key, n.action, n.link, ROUND(n.z_max_m, 3) AS z_max_m, ROUND(n.x_m, 3) AS x_m,
       ROUND(n.y_m, 3) AS y_m, n.iteration, n.sim_call
FROM search_nodes n
JOIN topological_states s ON s.id = n.state_id
LEFT JOIN search_nodes parent ON parent.id = n.parent_id
WHERE n.run_id = :run_id
ORDER BY on_plan DESC, n.seq
LIMIT {NODES_A_PAGE + 1} OFFSET :offset
"""


_NODE_COLUMNS = ["", "seq", "parent", "rope", "crossings", "knot", "reached by", "iteration", "sim call"]


def stored_parameters(value: object) -> dict[str, Any]:
    """A run's parameters as a dict; {} for anything else (not JSON, too long, nested too deep)."""
    if not isinstance(value, str) or len(value) > _MAX_PARAMETERS_CHARS:
        return {}
    try:
        parameters = json.loads(value)
    except (ValueError, RecursionError):
        return {}
    return parameters if isinstance(parameters, dict) else {}


def _a(href: str, text: object) -> str:
    return f'<a href="{escape(href)}">{escape(str(text))}</a>'


def _knot(knot_type: object) -> str:
    if knot_type is None:
        return ""
    words = knot_words(knot_type)
    shown = f"<strong>{escape(str(knot_type))}</strong>"
    return shown + (f" <small>{escape(words)}</small>" if words else "")


def _table(columns: Sequence[str], rows: Sequence[Sequence[str]], css: str = "rows-and-columns") -> str:
    head = "".join(f"<th>{escape(c)}</th>" for c in columns)
    body = "".join("<tr>" + "".join(f"<td>{cell}</td>" for cell in row) + "</tr>" for row in rows)
    table = f'<table class="{css}"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'
    return f'<div class="table-wrapper">{table}</div>'


def _pager(base: str, page: int, more: bool, what: str) -> str:
    links = []
    if page > 1:
        links.append(_a(f"{base}?{urlencode({'page': page - 1})}", f"← previous {what}"))
    links.append(f"page {page}")
    if more:
        links.append(_a(f"{base}?{urlencode({'page': page + 1})}", f"next {what} →"))
    return f'<p class="twisted-pager">{" · ".join(links)}</p>'


def goal_text(parameters: dict[str, Any], goal_knot: object) -> str:
    """What a run was asked for, in a few words: its goal knot, else its goal (P-data), else its planner."""
    if goal_knot:
        return str(goal_knot)
    goal = parameters.get("goal_spec") or parameters.get("goal")
    text = goal if isinstance(goal, str) else json.dumps(goal) if goal is not None else ""
    return text if len(text) <= 80 else text[:79] + "…"


def front_page(runs: Sequence[Any], page: int, run_url: Any, examples: dict[str, str]) -> Markup:
    """The runs (newest first, a page of them), the canned questions with their examples, the tables."""
    rows = []
    for run in runs[:RUNS_A_PAGE]:
        parameters = stored_parameters(run["parameters"])
        outcome = run["outcome"] or run["message"] or ""
        tied = " ".join(_knot(k) for k in (run["knots_tied"] or "").split())
        started = f" from run {_a(run_url(parameters['from_run']), parameters['from_run'])}" if isinstance(
            parameters.get("from_run"), int) else ""
        rows.append([
            _a(run_url(run["id"]), run["id"]),
            f"{escape(run['kind'])}{' (untie)' if started else ''}{started}",
            escape(goal_text(parameters, run["goal_knot"])),
            escape(f"{run['status']}: {outcome}" if outcome else run["status"]),
            tied,
            escape(run["pull_test"] or ""),
            escape(run["started_at"] or ""),
            escape("" if run["wall_seconds"] is None else f"{run['wall_seconds']:,}"),
        ])  # fmt: skip
    runs_html = (
        _table(["run", "kind", "goal", "outcome", "knots tied", "pull test", "started", "wall s"], rows)
        if rows else "<p>No runs stored yet.</p>"
    )  # fmt: skip
    questions = []
    for name, query in QUERIES.items():
        example = examples.get(name)
        text = unquote_plus(example.rsplit("/", 1)[-1]) if example else ""
        text = text if len(text) <= 60 else text[:59] + "…"
        shown = (
            f" (for example {_a(example, text)})" if example and "?" in example
            else "" if example else " (nothing in this store to show yet)"
        )  # fmt: skip
        questions.append(f"<li>{_a('/twisted/' + name, query['title'])}{shown}</li>")
    return Markup(
        "<h1>twisted store</h1>"
        "<p>Runs, states, ropes and knots of one twisted database, read-only. A run's number opens its "
        "story: goal, outcome, knots tied, pull test, pictures, its tree with the plan first.</p>"
        f"<h2>Runs, newest first</h2>{runs_html}{_pager('/', page, len(runs) > RUNS_A_PAGE, 'runs')}"
        f"<h2>Questions</h2><ul>{''.join(questions)}</ul>"
        f"<h2>Tables</h2><p>{_a('/twisted', 'every table and view')} (filters, facets, JSON, CSV)</p>"
    )


def run_page(
    run: Any,
    search: Any | None,
    calls: Any,
    pull_test: Any | None,
    nodes: Sequence[Any],
    page: int,
    urls: dict[str, str],
    run_url: Any,
) -> Markup:
    """One run's story; ``urls``: ``plan`` (the picture's address without suffix), ``tree``, ``nodes``."""
    parameters = stored_parameters(run["parameters"])
    facts: list[tuple[str, str]] = [("kind", escape(run["kind"])), ("status", escape(run["status"]))]
    if search is not None:
        facts += [
            ("goal", escape(goal_text(parameters, search["goal_knot"]))),
            ("planner", escape(f"{search['planner']} (heuristic {search['heuristic']})")),
            ("outcome", escape(search["outcome"] or "")),
        ]
    elif run["message"]:
        facts.append(("message", escape(run["message"])))
    from_run = parameters.get("from_run")
    if isinstance(from_run, int):
        facts.append(("started from", f"the end of run {_a(run_url(from_run), from_run)} (untie)"))
    tied = " ".join(_knot(k) for k in (run["knots_tied"] or "").split())
    facts.append(("knots tied", tied or "none"))
    if pull_test is not None:
        verdict = "ties the goal" if pull_test["ties_goal"] else "does not tie the goal"
        done = (f"{escape(pull_test['knot_before'])} → {_knot(pull_test['knot_after'])}, {verdict} "
                f"({escape(pull_test['goal_knot'] or 'no knot')}), ends {pull_test['end_distance_m']} m apart"
                if pull_test["ok"] else f"failed: {escape(pull_test['reason'] or '')}")  # fmt: skip
        facts.append(("pull test", done))
    else:
        facts.append(("pull test", "none stored"))
    if calls["nodes"]:
        facts.append(("calls", escape(
            f"{calls['sim_calls'] or 0:,} simulator calls, {calls['nodes']:,} nodes, "
            f"{(calls['iterations'] or 0) + 1:,} iterations")))  # fmt: skip
    if run["wall_seconds"] is not None:
        facts.append(("time", escape(f"{run['wall_seconds']:,.1f} s from {run['started_at']}")))
    facts_html = "".join(f"<dt>{escape(k)}</dt><dd>{v}</dd>" for k, v in facts)
    pictures = ""
    if search is not None and search["outcome"] == "solved":
        plan = urls["plan"]
        pictures = (
            f'<h2>The plan</h2><p><img src="{escape(plan)}.png" alt="the plan\'s final rope" '
            'style="max-width:100%"></p>'
            f"<p>{_a(plan + '.gif', 'the plan as a GIF, one frame a step')} · "
            f"{_a(plan + '.png', 'the picture alone')}</p>"
        )
    rows = []
    for node in nodes[:NODES_A_PAGE]:
        curve = ("cinch" if node["action"] == "cinch" else
                 f"link {node['link']}, z {node['z_max_m']}, x {node['x_m']}, y {node['y_m']}"
                 if node["link"] is not None else "")  # fmt: skip
        rows.append([
            "plan" if node["on_plan"] else "", escape(node["seq"]), escape("" if node["parent_seq"] is None
            else node["parent_seq"]), rope_svg(node["points"]) or "(not a rope of this store)",
            escape(node["cross"]), _knot(node["knot_type"]), escape(curve), escape(node["iteration"]),
            escape(node["sim_call"]),
        ])  # fmt: skip
    tree = ""
    if calls["nodes"]:
        tree = (
            "<h2>The tree, the plan's nodes first</h2>"
            f"<p>{_a(urls['tree'], 'the tree by depth')} · {_a(urls['nodes'], 'the nodes as a table')}</p>"
            + _table(_NODE_COLUMNS, rows)
            + _pager(urls["self"], page, len(nodes) > NODES_A_PAGE, f"{NODES_A_PAGE} nodes")
        )
    return Markup(
        f"<h1>Run {escape(run['id'])}</h1><dl class='twisted-facts'>{facts_html}</dl>{pictures}{tree}"
        "<style>.twisted-facts dt{font-weight:bold;float:left;clear:left;width:8em}"
        ".twisted-facts dd{margin-left:9em}</style>"
    )
