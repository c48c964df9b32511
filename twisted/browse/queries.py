"""The canned queries of ``twisted browse`` and the Datasette metadata that carries them.

Each query is one of the README's example questions, written against the schema of docs/DESIGN.md
section 11 (SQLite: Datasette reads SQLite files only). Columns are named so that the plugin
(:mod:`twisted.browse.plugin`) knows what to draw: ``points`` / ``*_points`` (a rope's link points),
``p_data``, ``state`` / ``key`` (a P-data key), ``knot_type``, ``run_id``, ``plan_run_id``. Queries that
can return thousands of rows (a run's tree, the ropes of one state) show 100 a page: ``&page=2``.
"""

from __future__ import annotations

from html import escape
from typing import Any
from urllib.parse import urlencode

__all__ = ["EXAMPLE_ROWS", "PAGE_ROWS", "PLUGIN", "QUERIES", "TIED", "examples", "metadata"]

PLUGIN = "twisted-browse"
PAGE_ROWS = 100

# LIMIT / OFFSET of a paged query: :page is 1, 2, ... (empty: 1).
_PAGE = (
    f"LIMIT {PAGE_ROWS} OFFSET {PAGE_ROWS} * "
    "(MAX(CAST(COALESCE(NULLIF(:page, ''), '1') AS INTEGER), 1) - 1)"
)

RUN_TREE = f"""
WITH RECURSIVE tree(node_id, depth) AS (
    SELECT n.id, 0 FROM search_nodes n WHERE n.run_id = :run_id AND n.parent_id IS NULL
  UNION ALL
    SELECT n.id, t.depth + 1 FROM search_nodes n JOIN tree t ON n.parent_id = t.node_id
), page AS (  -- the page's nodes first (a node's id grows with its seq), then their columns
    SELECT node_id, depth FROM tree ORDER BY depth, node_id
    {_PAGE}
), plan(node_id) AS (
    SELECT r.goal_node_id FROM search_runs r WHERE r.run_id = :run_id AND r.goal_node_id IS NOT NULL
  UNION ALL
    SELECT n.parent_id FROM search_nodes n JOIN plan p ON n.id = p.node_id WHERE n.parent_id IS NOT NULL
)
SELECT t.depth, n.seq, parent.seq AS parent_seq,
       CASE WHEN n.id IN (SELECT node_id FROM plan) THEN 'plan' ELSE '' END AS on_plan,
       n.points, n.cross AS crossings, s.knot_type,
       n.action, n.link, ROUND(n.z_max_m, 3) AS z_max_m, ROUND(n.x_m, 3) AS x_m, ROUND(n.y_m, 3) AS y_m,
       n.iteration, n.sim_call, ROUND(n.created_s, 2) AS created_s, n.id AS node_id, s.key AS state
FROM page t
JOIN search_nodes n ON n.id = t.node_id
JOIN topological_states s ON s.id = n.state_id
LEFT JOIN search_nodes parent ON parent.id = n.parent_id
ORDER BY t.depth, n.seq
"""

# What each run tied: the knots_tied view without the knot a run started from (an untie run's tree holds
# the trefoil it was given from its root on; that is not a knot it tied). A run's start is its first root.
TIED = """
SELECT k.* FROM knots_tied k
WHERE NOT EXISTS (
    SELECT 1 FROM search_nodes n JOIN topological_states s ON s.id = n.state_id
    WHERE n.run_id = k.run_id AND n.parent_id IS NULL AND s.knot_type = k.knot_type
      AND n.seq = (SELECT MIN(m.seq) FROM search_nodes m WHERE m.run_id = k.run_id AND m.parent_id IS NULL)
)
"""

KNOTS_TIED = f"""
WITH k AS ({TIED})
SELECT k.knot_type, k.run_id, k.run_kind, k.configurations, k.states,
       COALESCE(
         (SELECT c.points FROM topological_states s JOIN configurations c ON c.state_id = s.id
          WHERE s.knot_type = k.knot_type AND c.run_id = k.run_id ORDER BY c.id LIMIT 1),
         (SELECT n.points FROM topological_states s JOIN search_nodes n ON n.state_id = s.id
          WHERE s.knot_type = k.knot_type AND n.run_id = k.run_id ORDER BY n.id LIMIT 1)
       ) AS example_points, k.first_seen
FROM k
ORDER BY k.knot_type, k.run_id
"""

EVAL_GOALS = """
SELECT p.idx AS goal, p.cross AS crossings, p.tag, p.frequency, r.seed, r.timeout_s, r.friction_scale,
       r.status, r.solved, ROUND(r.time_to_solve_s, 2) AS time_to_solve_s, r.sim_calls, r.plan_run_id,
       p.p_data
FROM problems p
JOIN problem_sets ps ON ps.id = p.set_id
LEFT JOIN eval_results r ON r.problem_id = p.id AND r.planner = :label
WHERE ps.name = :set_name
ORDER BY p.idx, r.seed, r.timeout_s, r.friction_scale
"""

EVAL_LABELS = """
SELECT ps.name AS set_name, r.planner AS label, COUNT(DISTINCT r.problem_id) AS goals, COUNT(*) AS attempts,
       SUM(CASE WHEN r.solved THEN 1 ELSE 0 END) AS solved,
       ROUND(AVG(CASE WHEN r.solved THEN r.time_to_solve_s END), 2) AS mean_time_to_solve_s,
       ROUND(AVG(r.sim_calls)) AS mean_sim_calls
FROM eval_results r JOIN problem_sets ps ON ps.id = r.set_id
GROUP BY ps.name, r.planner
ORDER BY ps.name, r.planner
"""

STATES_MOST_REACHED = """
WITH reached AS (
    SELECT state_id, COUNT(*) AS configurations, 0 AS search_nodes FROM configurations GROUP BY state_id
  UNION ALL
    SELECT state_id, 0, COUNT(*) FROM search_nodes GROUP BY state_id
), per_state AS (
    SELECT s.cross AS crossings, s.key, s.knot_type, s.p_data,
           SUM(r.configurations) AS configurations, SUM(r.search_nodes) AS search_nodes,
           SUM(r.configurations + r.search_nodes) AS reached
    FROM reached r JOIN topological_states s ON s.id = r.state_id
    GROUP BY s.id
), ranked AS (
    SELECT *, ROW_NUMBER() OVER (PARTITION BY crossings ORDER BY reached DESC, key) AS rank
    FROM per_state
)
SELECT crossings, rank, knot_type, configurations, search_nodes, reached, key, p_data
FROM ranked WHERE rank <= 5
ORDER BY crossings, rank
"""

PULL_TESTS = """
SELECT t.id AS pull_test, t.run_id, r.kind AS run_kind, t.node_seq, t.configuration_id, s.key AS state,
       t.knot_before, t.knot_after, t.goal_knot, t.ties_goal, t.ok, t.reason,
       ROUND(t.end_distance_m, 3) AS end_distance_m, ROUND(t.sim_seconds, 2) AS sim_seconds,
       COALESCE(
         (SELECT n.points FROM search_nodes n WHERE n.run_id = t.run_id AND n.seq = t.node_seq),
         (SELECT c.points FROM configurations c WHERE c.id = t.configuration_id)
       ) AS before_points,
       t.points AS pulled_points
FROM tightenings t
JOIN topological_states s ON s.id = t.state_id
LEFT JOIN runs r ON r.id = t.run_id
ORDER BY t.id DESC
"""

STATE_REACHED_BY = f"""
SELECT 'configuration' AS reached_in, c.id AS configuration_id, NULL AS node_id, c.run_id, r.kind AS run_kind,
       NULL AS seq, c.created_at, NULL AS created_s, c.points
FROM topological_states s
JOIN configurations c ON c.state_id = s.id
LEFT JOIN runs r ON r.id = c.run_id
WHERE s.key = :key
UNION ALL
SELECT 'search node', NULL, n.id, n.run_id, 'plan', n.seq, NULL, ROUND(n.created_s, 2), n.points
FROM topological_states s
JOIN search_nodes n ON n.state_id = s.id
WHERE s.key = :key
ORDER BY reached_in, configuration_id, node_id
{_PAGE}
"""

EPISODE = f"""
SELECT s.seq, s.kind, s.link, s.z_max_m, s.x_m, s.y_m, s.observed_key AS state, s.expected_key,
       ROUND(s.drift_m, 3) AS drift_m, s.fault, s.knot, s.replan_run_id, ROUND(s.planning_s, 1) AS planning_s,
       ROUND(s.elapsed_s, 1) AS elapsed_s, s.points
FROM episode_steps s
WHERE s.episode_id = :episode
ORDER BY s.seq
{_PAGE}
"""

_PAGED = f"{PAGE_ROWS} rows a page: give <code>page</code> 2, 3, ... for the next ones."

QUERIES: dict[str, dict[str, Any]] = {
    "knots_tied": {
        "title": "Knots tied, per run",
        "description_html": (
            "Which knots the collected data (<code>collect</code> runs) and the planner trees "
            "(<code>plan</code>, <code>untie</code> runs) have really tied: both closures agree, the unknot "
            "and knotoids left out (the <code>knots_tied</code> view), and the knot a run started from "
            "(an untie run's) not counted as tied; with the first rope of each."
        ),
        "sql": KNOTS_TIED,
    },
    "run_tree": {
        "title": "A planner run's tree, by depth",
        "description_html": (
            "The search tree of run <code>run_id</code>, breadth first: each node's state, what "
            "reached it from its parent (a curve: link, z_max_m, x_m, y_m; or a cinch, the rope pulled "
            "tight and let go) and its rope from above; "
            "<code>plan</code> marks the found plan. " + _PAGED
        ),
        "sql": RUN_TREE,
    },
    "eval_labels": {
        "title": "Eval results per problem set and label",
        "description_html": "Follow a label to its goals.",
        "sql": EVAL_LABELS,
    },
    "eval_goals": {
        "title": "The goals of an eval set under one label",
        "description_html": (
            "Every goal of problem set <code>set_name</code> with what the planner stored under "
            "<code>label</code> found for it: solved, time to solve, simulator calls, its plan run."
        ),
        "sql": EVAL_GOALS,
    },
    "states_most_reached": {
        "title": "The states reached most often, per crossing count",
        "description_html": (
            "The five states with the most collected configurations plus planner nodes, for each "
            "crossing count."
        ),
        "sql": STATES_MOST_REACHED,
    },
    "pull_tests": {
        "title": "Pull tests and their outcomes",
        "description_html": (
            "Every pull test (<code>replay --tighten</code>, <code>plan --tighten</code>): the knot "
            "before and after both ends were pulled apart, the rope before and after, newest first."
        ),
        "sql": PULL_TESTS,
    },
    "state_reached_by": {
        "title": "Every rope that reached a state",
        "description_html": (
            "The collected configurations and planner nodes in state <code>key</code> (P-data, as in "
            "<code>topological_states.key</code>). " + _PAGED
        ),
        "sql": STATE_REACHED_BY,
    },
    "episode": {
        "title": "An episode in a world apart from the model, as its observed ropes",
        "description_html": (
            "The steps of episode <code>episode</code> (<code>twisted execute</code>, <code>tie</code>): "
            "each action sent, the rope as the world showed it afterwards, the plan's expected state, "
            "each replan and pull test. " + _PAGED
        ),
        "sql": EPISODE,
    },
}

_TABLES: dict[str, dict[str, Any]] = {
    # label_column: a foreign key to the table shows this column beside the id (state 41 3_1-, run 2 plan)
    "runs": {
        "description": "Long jobs. A plan run links to its tree and its plan pictures (kind column).",
        "label_column": "kind",
    },
    "topological_states": {
        "description": "Distinct P-data states: the Gauss diagram, a stored rope in that state, its knot.",
        "label_column": "knot_type",
    },
    "configurations": {"description": "Collected ropes (D_Q); points drawn from above."},
    "search_nodes": {"description": "Planner tree nodes; points drawn from above.", "sort_desc": "id"},
    "tightenings": {"description": "Pull tests: the rope pulled tight (points)."},
}


# An example for each canned query that takes parameters, from the store itself (a row of each SELECT)
EXAMPLE_ROWS = {
    "run_tree": (
        "SELECT run_id FROM search_runs ORDER BY outcome = 'solved' DESC, run_id DESC LIMIT 1",
        ("run_id",),
    ),
    "eval_goals": (
        "SELECT ps.name, r.planner FROM eval_results r JOIN problem_sets ps ON ps.id = r.set_id "
        "ORDER BY r.id DESC LIMIT 1",
        ("set_name", "label"),
    ),
    "state_reached_by": (
        "SELECT key FROM topological_states WHERE length(key) < 1000 ORDER BY cross DESC, id LIMIT 1",
        ("key",),
    ),
}


def examples(database: str, rows: dict[str, tuple[Any, ...] | None]) -> dict[str, str]:
    """The example address of every canned query: the plain page, or with the parameters of the
    example row found in the store (``rows``: the first row of each :data:`EXAMPLE_ROWS` query)."""
    found = {}
    for name in QUERIES:
        address = f"/{database}/{name}"
        if name in EXAMPLE_ROWS:
            row = rows.get(name)
            if row is None:
                continue
            address += "?" + urlencode(dict(zip(EXAMPLE_ROWS[name][1], row, strict=True)))
        found[name] = address
    return found


def metadata(database: str, db_url: str, example_rows: dict[str, tuple[Any, ...] | None]) -> dict[str, Any]:
    """Datasette metadata for the store file served as ``database``: the canned queries (each with an
    example from the store, or a note that it has none), the table notes and the plugin's own settings
    (``db_url``: where it reads what it renders beyond one cell; ``examples``)."""
    shown = examples(database, example_rows)
    queries = {}
    for name, query in QUERIES.items():
        example = shown.get(name)
        note = (
            f" Example: <a href='{escape(example)}'>{escape(example.rsplit('/', 1)[-1])}</a>."
            if example and "?" in example
            else " This store has nothing to show here yet." if name in EXAMPLE_ROWS else ""
        )
        queries[name] = {**query, "description_html": query["description_html"] + note, "hide_sql": True}
    return {
        "title": "twisted store",
        "description_html": (
            "Runs, states, ropes and knots of one twisted database, read-only. Canned queries: "
            + ", ".join(f"<a href='/{database}/{name}'>{q['title']}</a>" for name, q in QUERIES.items())
            + "."
        ),
        "plugins": {PLUGIN: {"db_url": db_url, "examples": shown}},
        "databases": {
            database: {
                "queries": queries,
                "tables": _TABLES,
            }
        },
    }
