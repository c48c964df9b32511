"""The example SQL of docs/database.md runs against a database twisted made.

Every fenced ```sql block of the page is cut into statements and each is executed on a small store
built here through the CLI: planner run 1 (solved, to one crossing, with random curves), a short
collection and a pull test of the plan's final rope. A query that names a column or a view the schema
no longer has fails here instead of on a reader's machine.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.main import app

DOCS = Path(__file__).resolve().parents[1] / "docs" / "database.md"
ONE_CROSSING = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
runner = CliRunner()


def sql_blocks(text: str) -> list[str]:
    """The bodies of the fenced ```sql blocks of a markdown text, in order."""
    return re.findall(r"^```sql\n(.*?)^```", text, flags=re.S | re.M)


def statements(block: str) -> list[str]:
    """The statements of one block (they end with ';' at the end of a line)."""
    parts = re.split(r";[ \t]*$", block, flags=re.M)
    return [p.strip() for p in parts if p.strip()]


def test_sql_blocks_are_found_and_split() -> None:
    text = (
        "x\n```sql\nSELECT 1;\nSELECT 2 FROM t\n  WHERE a = ';';\n```\n"
        "```bash\nls\n```\n```sql\nSELECT 3;\n```\n"
    )
    blocks = sql_blocks(text)
    assert blocks == ["SELECT 1;\nSELECT 2 FROM t\n  WHERE a = ';';\n", "SELECT 3;\n"]
    assert [statements(b) for b in blocks] == [["SELECT 1", "SELECT 2 FROM t\n  WHERE a = ';'"], ["SELECT 3"]]


def _cli(db: str, *args: str) -> int:
    result = runner.invoke(app, ["--db", db, *args])
    return result.exit_code


@pytest.fixture(scope="module")
def small_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("docs_sql") / "twisted.db"
    db = f"sqlite:///{path}"
    plan = ["--goal", ONE_CROSSING, "--planner", "random-low", "--workers", "1", "--seed", "0"]
    assert _cli(db, "plan", *plan, "--max-iterations", "400", "--timeout", "3600") == 0  # run 1, solved
    assert _cli(db, "replay", "1", "--tighten") in (0, 3)  # stores a pull test either way
    collect = ["--hours", "0.5", "--max-kept", "15", "--workers", "1", "--seed", "0"]  # ends at 15 kept
    assert _cli(db, "collect", *collect) == 0
    return path


# Runs the queries given as JSON on stdin on the database named by argv[1]; prints the row counts.
_RUN_QUERIES = """
import json, sqlite3, sys
connection = sqlite3.connect(sys.argv[1], timeout=30)
counts = []
for query in json.load(sys.stdin):
    try:
        counts.append(len(connection.execute(query).fetchall()))
    except sqlite3.Error as exc:
        sys.exit(f"{exc} in\\n{query}")
print(json.dumps(counts))
"""


def test_every_sql_example_of_the_database_page_runs(small_store: Path) -> None:
    blocks = sql_blocks(DOCS.read_text())
    queries = [q for block in blocks for q in statements(block)]
    assert len(blocks) >= 8 and len(queries) >= 10, "docs/database.md lost its example SQL"
    # in a process of their own, as a reader of the database would run them: connections in the process
    # that wrote the file met "disk I/O error" now and then, a plain sqlite3 one and the store's engine too
    done = subprocess.run(
        [sys.executable, "-c", _RUN_QUERIES, str(small_store)],
        input=json.dumps(queries),
        capture_output=True,
        text=True,
        timeout=300,
    )
    if done.returncode != 0:  # pragma: no cover - the failure message is the point
        pytest.fail(f"docs/database.md: {done.stderr.strip()}")
    results = dict(zip(queries, json.loads(done.stdout), strict=True))  # rows per query
    # the store has what the examples look at: the plan's path, its pull test, the collection
    path_query = next(q for q in queries if q.startswith("WITH RECURSIVE path"))
    assert results[path_query] >= 1
    assert any(q.startswith("SELECT run_id, node_seq") and results[q] for q in queries)
    assert any("states_by_cross" in q and results[q] for q in queries)
