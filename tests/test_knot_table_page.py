"""scripts/knot_table_page.py: the knot table's measured columns read from stores (docs/knots.md)."""

from __future__ import annotations

import importlib.util
import sqlite3
import sys
from pathlib import Path
from types import ModuleType

from twisted.rope import RopeProfile

REPO = Path(__file__).resolve().parents[1]


def _page() -> ModuleType:
    spec = importlib.util.spec_from_file_location("knot_table_page", REPO / "scripts" / "knot_table_page.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclass looks its module up
    spec.loader.exec_module(module)
    return module


def _store(path: Path, rope: tuple[int, float, int] | None, rows: list[tuple[object, ...]]) -> None:
    """A file with the two tables the script reads, as twisted writes them (``max_crossings`` only from
    revision 0017 on: ``rope[2]`` None leaves the column out)."""
    conn = sqlite3.connect(path)
    limit = "" if rope is None else ", max_crossings INTEGER"
    conn.execute(f"CREATE TABLE rope_profile (id INTEGER, n_links INTEGER, link_spacing_m FLOAT{limit})")
    values = (1, 21, 0.04) if rope is None else (1, *rope)
    conn.execute(f"INSERT INTO rope_profile VALUES ({', '.join('?' for _ in values)})", values)
    conn.execute(
        "CREATE TABLE eval_results (planner TEXT, goal_key TEXT, seed INTEGER, status TEXT, solved BOOLEAN, "
        "wall_s FLOAT, sim_calls INTEGER, plan_run_id INTEGER)"
    )
    conn.executemany("INSERT INTO eval_results VALUES (?, ?, ?, ?, ?, ?, ?, ?)", rows)
    conn.commit()
    conn.close()


def test_measured_columns_come_from_every_label_and_name_each_rope(tmp_path: Path) -> None:
    page = _page()
    old, long = tmp_path / "old.db", tmp_path / "long.db"
    _store(
        old,
        None,  # a store from before revision 0017: the default limit
        [
            ("a", "knot:granny+@6", 0, "solved", 1, 50.0, 1000, 3),
            ("a", "knot:granny+@6", 1, "timeout", 0, 600.0, 9000, None),
            ("a", "knot:granny+@6", 2, "running", 0, None, None, None),  # not finished: left out
            ("other", "knot:3_1+@3", 0, "solved", 1, 5.0, 10, 1),  # another label: left out
        ],
    )
    _store(
        long,
        (31, 0.04, 7),
        [
            ("b", "knot:3_1+#3_1+@6", 0, "solved", 1, 20.0, 300, 5),
            ("c", "knot:3_1+#3_1+@6", 1, "solved", 1, 40.0, 500, 8),
            ("c", "knot:7_2+@7", 1, "timeout", 0, 300.0, 4000, None),
        ],
    )
    first = page._read_measurement(old, "a")
    second = page._read_measurement(long, "b,c")
    assert set(first) == {"3_1+#3_1+"} and set(second) == {"3_1+#3_1+", "7_2+"}  # granny+ is its type
    assert first["3_1+#3_1+"].rope == RopeProfile(21, 0.04, 6)
    assert second["7_2+"].rope == RopeProfile(31, 0.04, 7)
    both = page._measured_columns("3_1+#3_1+", [first["3_1+#3_1+"], second["3_1+#3_1+"]], "img/x.png")
    assert both == [
        "1 / 2 (21 links)<br>2 / 2 (31 links)",
        "50.0 s<br>30.0 s",
        "1,000<br>400",
        "![3_1+#3_1+ pulled tight](img/x.png)",
    ]
    assert page._measured_columns("7_2+", [second["7_2+"]], None) == ["0 / 1 (31 links)", "-", "-", "-"]
    assert page._measured_columns("4_1", [], None) == ["not yet measured"] * 4
