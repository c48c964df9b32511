"""The rope as a per-process profile (``TWISTED_ROPE``), stored per database and carried by models.

The rope's constants bind when :mod:`twisted.rope` is imported, so every test of another rope than the
default runs a subprocess with ``TWISTED_ROPE`` set.
"""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from alembic import command
from sqlalchemy import create_engine, text

from twisted.model.config import ModelRopeError, NetConfig
from twisted.rope import DEFAULT_ROPE, MAX_ROPE_LENGTH_M, ROPE, RopeProfile, parse_rope
from twisted.store import RopeMismatchError, alembic_config, head_revisions, open_store
from twisted.store.db import make_engine, parse_url

REPO = Path(__file__).resolve().parents[1]
ONE_CROSSING = '[[1,"O",2,"+"],[2,"U",1,"+"]]'
TINY = "NetConfig(hidden=16, layers=1, head_hidden=16, components=2)"


def _env(rope: str | None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("TWISTED_ROPE", "TWISTED_DB")}
    if rope is not None:
        env["TWISTED_ROPE"] = rope
    return env


def _python(code: str, rope: str | None, timeout_s: float = 120) -> subprocess.CompletedProcess[str]:
    """Run ``code`` in a fresh interpreter (the repository's twisted) with ``TWISTED_ROPE=rope``."""
    return subprocess.run(
        [sys.executable, "-c", code],
        cwd=REPO,
        env=_env(rope),
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def _twisted(rope: str | None, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "cli.main", *args],
        cwd=REPO,
        env=_env(rope),
        capture_output=True,
        text=True,
        timeout=120,
    )


def _err(result: subprocess.CompletedProcess[str]) -> str:
    """stderr with rich's line wrapping undone."""
    return " ".join(result.stderr.split())


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _make_store(path: Path, rope: str | None) -> None:
    result = _python(f"from twisted.store import open_store\nopen_store('sqlite:///{path}').close()", rope)
    assert result.returncode == 0, result.stderr


def _select(path: Path, sql: str) -> list[Any]:
    conn = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)
    try:
        return conn.execute(sql).fetchall()
    finally:
        conn.close()


def _stored_rope(path: Path) -> list[tuple[int, float]]:
    return _select(path, "SELECT n_links, link_spacing_m FROM rope_profile")


def _stored_limit(path: Path) -> int:
    return int(_select(path, "SELECT max_crossings FROM rope_profile")[0][0])


# --- the profile ------------------------------------------------------------------------------------------


def test_parse_rope_reads_links_and_an_optional_spacing() -> None:
    assert parse_rope("31") == RopeProfile(31, 0.04)
    assert parse_rope("31x0.03") == RopeProfile(31, 0.03)
    assert parse_rope(" 25X0.045 ") == RopeProfile(25, 0.045)
    assert parse_rope("") == DEFAULT_ROPE == RopeProfile(21, 0.04)
    assert DEFAULT_ROPE.name == "21 links x 0.04 m (0.84 m)"
    assert parse_rope("31").env_value == "31" and parse_rope("31x0.03").env_value == "31x0.03"
    assert ROPE == DEFAULT_ROPE  # the tests run without TWISTED_ROPE


def test_parse_rope_reads_an_optional_crossing_limit() -> None:
    assert parse_rope("31c7") == RopeProfile(31, 0.04, 7) != RopeProfile(31, 0.04)
    assert parse_rope("31x0.03C8") == RopeProfile(31, 0.03, 8)
    assert parse_rope("21c6") == DEFAULT_ROPE and DEFAULT_ROPE.max_crossings == 6
    assert parse_rope("31c7").env_value == "31c7" and parse_rope("31x0.03c7").env_value == "31x0.03c7"
    assert parse_rope("31c7").name == "31 links x 0.04 m (1.24 m), states of up to 7 crossings"


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("abc", "TWISTED_ROPE='abc': the link count 'abc' is not an integer"),
        ("21.5", "the link count '21.5' is not an integer"),
        ("5", "5 links is out of range (give 11 to 56 links)"),
        ("31x", "the spacing '' is not a number of metres"),
        ("31xfoo", "the spacing 'foo' is not a number of metres"),
        ("31x-0.04", "the spacing must be a positive length"),
        ("31xnan", "the spacing must be a positive length"),
        ("31x0.1", "links 0.1 m apart is out of range"),
        ("40", "a rope of 40 links x 0.04 m (1.60 m) is longer than 1.4 m"),
        ("31c", "the crossing limit '' is not an integer"),
        ("31c7.5", "the crossing limit '7.5' is not an integer"),
        ("31c2", "a crossing limit of 2 is out of range (give 3 to 8)"),
        ("31c9", "a crossing limit of 9 is out of range (give 3 to 8)"),
        ("11c7", "11 links cannot lay out 7 crossings (14 visits along the rope): give at least 13 links"),
    ],
)
def test_parse_rope_says_which_value_is_wrong_and_why(value: str, message: str) -> None:
    with pytest.raises(ValueError) as info:
        parse_rope(value)
    assert message in str(info.value) and f"TWISTED_ROPE={value!r}" in str(info.value)


def test_the_longest_rope_allowed_fits_the_workspace() -> None:
    from twisted.sim.simulator import CURVE_HIGH, WORKSPACE_RADIUS_M

    # half the straight rope plus the longest curve displacement stays inside the workspace
    assert MAX_ROPE_LENGTH_M / 2 + float(CURVE_HIGH[2]) <= WORKSPACE_RADIUS_M + 1e-9


def test_an_invalid_rope_in_the_environment_exits_2_before_anything_is_made(tmp_path: Path) -> None:
    path = tmp_path / "new.db"
    for args in (["db"], ["collect", "--hours", "0.01", "--workers", "1"]):
        result = _twisted("31xabc", "--db", f"sqlite:///{path}", *args)
        assert result.returncode == 2, result.stderr
        assert "TWISTED_ROPE='31xabc': the spacing 'abc' is not a number of metres" in _err(result)
        assert "unset TWISTED_ROPE to run the default rope (21 links x 0.04 m" in _err(result)
        assert "Traceback" not in result.stderr
    assert list(tmp_path.iterdir()) == []


def test_an_invalid_rope_keeps_the_default_and_check_rope_env_raises() -> None:
    code = (
        "from twisted.rope import ROPE, ROPE_ENV_ERROR, check_rope_env\n"
        "print(ROPE.n_links, ROPE_ENV_ERROR)\n"
        "try:\n    check_rope_env()\nexcept ValueError as exc:\n    print('raised', exc)\n"
    )
    result = _python(code, "7")
    assert result.returncode == 0, result.stderr
    first, second = result.stdout.splitlines()
    assert first.startswith("21 TWISTED_ROPE='7': 7 links is out of range")
    assert second.startswith("raised TWISTED_ROPE='7'")


# --- the database ------------------------------------------------------------------------------------------


def test_a_new_store_records_the_process_rope(sqlite_url: str, tmp_path: Path) -> None:
    open_store(sqlite_url).close()
    assert _stored_rope(tmp_path / "twisted.db") == [(21, 0.04)]
    open_store(sqlite_url).close()  # the same rope again: accepted, still one row
    assert _stored_rope(tmp_path / "twisted.db") == [(21, 0.04)]
    _make_store(tmp_path / "long.db", "31x0.03")
    assert _stored_rope(tmp_path / "long.db") == [(31, 0.03)]


def test_a_read_only_open_records_nothing(sqlite_url: str, tmp_path: Path) -> None:
    path = tmp_path / "twisted.db"
    open_store(sqlite_url).close()
    conn = sqlite3.connect(path)
    conn.execute("DELETE FROM rope_profile")
    conn.commit()
    conn.close()
    before = _digest(path)
    open_store(sqlite_url, readonly=True).close()
    assert _stored_rope(path) == [] and _digest(path) == before


@pytest.mark.parametrize(
    ("made_by", "opened_by"), [(None, "31"), ("31", None), ("31", "31x0.03"), ("31c7", "31"), (None, "21c7")]
)
def test_a_store_of_one_rope_refuses_a_process_of_another(
    tmp_path: Path, made_by: str | None, opened_by: str | None
) -> None:
    path = tmp_path / "twisted.db"
    _make_store(path, made_by)
    made, opened = parse_rope(made_by or ""), parse_rope(opened_by or "")
    before, files = _digest(path), sorted(tmp_path.iterdir())
    for args in (["db"], ["collect", "--hours", "0.01", "--workers", "1"]):
        result = _twisted(opened_by, "--db", f"sqlite:///{path}", *args)
        assert result.returncode == 2, result.stderr
        message = _err(result)
        assert (
            f"holds data of a rope of {made.name}, but this process runs a rope of {opened.name}" in message
        )
        assert "nothing was written" in message and "Traceback" not in result.stderr
        if made_by is None:
            assert "run without TWISTED_ROPE" in message
        else:
            assert f"`TWISTED_ROPE={made_by} twisted ...`" in message
    assert _digest(path) == before and sorted(tmp_path.iterdir()) == files
    assert _stored_rope(path) == [(made.n_links, made.link_spacing_m)]
    assert _stored_limit(path) == made.max_crossings


def test_open_store_raises_rope_mismatch_naming_both(tmp_path: Path) -> None:
    path = tmp_path / "long.db"
    _make_store(path, "31")
    with pytest.raises(
        RopeMismatchError, match=r"31 links x 0.04 m \(1.24 m\).*21 links x 0.04 m \(0.84 m\)"
    ):
        open_store(f"sqlite:///{path}")
    with pytest.raises(RopeMismatchError):
        open_store(f"sqlite:///{path}", readonly=True)


# rows as revision 0001 wrote them ("cross" is a keyword on PostgreSQL, quoted everywhere)
_OLD_STATE = "INSERT INTO topological_states (id, key, p_data, \"cross\") VALUES (1, '[]', '[]', 0)"
_OLD_CONFIGURATION = (
    'INSERT INTO configurations (id, run_id, state_id, "cross", q, points, created_at) '
    "VALUES (1, NULL, 1, 0, x'', x'', '2026-01-01 00:00:00.000000')"
)


def test_a_store_made_before_the_rope_profile_is_tagged_21_links(tmp_path: Path) -> None:
    """A database with configurations written before revision 0013 was made on the paper's rope; one with
    none is tagged by the first process that writes to it."""
    old, empty = tmp_path / "old.db", tmp_path / "empty.db"
    for path in (old, empty):
        engine = create_engine(f"sqlite:///{path}")
        with engine.begin() as conn:
            command.upgrade(alembic_config(conn), "0001")
            if path == old:
                conn.execute(text(_OLD_STATE))
                conn.execute(text(_OLD_CONFIGURATION))
        engine.dispose()
    # the migration alone (no process rope recorded yet): only the store with data is tagged
    for path in (old, empty):
        engine = create_engine(f"sqlite:///{path}")
        with engine.begin() as conn:
            command.upgrade(alembic_config(conn), "heads")
        engine.dispose()
    assert _stored_rope(old) == [(21, 0.04)] and _stored_rope(empty) == []
    result = _twisted("31", "--db", f"sqlite:///{old}", "db")
    assert result.returncode == 2 and "holds data of a rope of 21 links x 0.04 m" in _err(result)
    _make_store(empty, "31")
    assert _stored_rope(empty) == [(31, 0.04)]
    with open_store(f"sqlite:///{old}") as store, store.engine.connect() as conn:
        revisions = {r[0] for r in conn.execute(text("SELECT version_num FROM alembic_version"))}
    assert revisions == head_revisions() and "0017" in revisions


def test_a_store_from_before_the_rope_profile_refuses_another_rope_before_upgrading(tmp_path: Path) -> None:
    path = tmp_path / "old.db"
    engine = make_engine(parse_url(f"sqlite:///{path}"))  # as twisted made it (WAL mode)
    with engine.begin() as conn:
        command.upgrade(alembic_config(conn), "0001")
        conn.execute(text(_OLD_STATE))
        conn.execute(text(_OLD_CONFIGURATION))
    engine.dispose()
    before = _digest(path)
    for args in (["db"], ["collect", "--hours", "0.01", "--workers", "1"]):
        result = _twisted("31", "--db", f"sqlite:///{path}", *args)
        assert result.returncode == 2, result.stderr
        assert "holds data of a rope of 21 links x 0.04 m (0.84 m)" in _err(result)
    assert _digest(path) == before  # not even upgraded
    conn = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)
    assert conn.execute("SELECT version_num FROM alembic_version").fetchall() == [("0001",)]
    conn.close()


def test_twisted_db_shows_the_rope(tmp_path: Path) -> None:
    path = tmp_path / "long.db"
    _make_store(path, "31")
    result = _twisted("31", "--db", f"sqlite:///{path}", "db", "--json")
    assert result.returncode == 0, result.stderr
    shown = json.loads(result.stdout)
    assert (
        shown["rope"] == {"n_links": 31, "link_spacing_m": 0.04, "max_crossings": 6}
        and shown["rows"]["rope_profile"] == 1
    )
    result = _twisted("31", "--db", f"sqlite:///{path}", "db")
    assert "rope: 31 links x 0.04 m (1.24 m)" in result.stdout


# --- the simulator and the model on a longer rope ----------------------------------------------------------


def test_a_31_link_process_simulates_and_runs_an_inverse_net(tmp_path: Path) -> None:
    model_file = tmp_path / "tiny31.pt"
    code = f"""
import json
import numpy as np
from twisted.model.config import NetConfig
from twisted.model.network import InverseModel, InverseNet
from twisted.rope import N_LINKS, N_POINTS
from twisted.sim import RopeSim, sample_curve

sim = RopeSim()
sim.reset()
straight = sim.link_points()
rng = np.random.default_rng(3)
outcomes = []
for _ in range(3):
    sim.reset()
    curve = sample_curve(rng)
    outcomes.append((curve.link, sim.apply(curve).ok))
model = InverseModel(InverseNet({TINY}))
probs = model.link_probabilities(straight, {ONE_CROSSING!r})
curves = model.sample(straight, None, {ONE_CROSSING!r}, 3, rng)
open({str(model_file)!r}, "wb").write(model.to_bytes())
print(json.dumps({{
    "n_links": N_LINKS, "points": list(straight.shape), "length": float(np.ptp(straight[:, 0])),
    "outcomes": outcomes, "probs": len(probs), "links": [c.link for c in curves],
    "unusable": model.unusable(), "config": model.net.config.to_dict(),
}}))
"""
    result = _python(code, "31")
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["n_links"] == 31 and out["points"] == [32, 3]
    assert out["length"] == pytest.approx(1.24, abs=0.01)
    assert any(ok for _, ok in out["outcomes"]) and all(0 <= link <= 30 for link, _ in out["outcomes"])
    assert out["probs"] == 31 and all(0 <= link <= 30 for link in out["links"])
    assert out["unusable"] is None
    assert (out["config"]["n_links"], out["config"]["link_spacing_m"]) == (31, 0.04)

    # this (21-link) process refuses the 31-link model, naming both ropes
    from twisted.model.registry import ModelError, load_model_file

    with pytest.raises(ModelError, match=r"for a rope of 31 links x 0.04 m \(1.24 m\).*21 links x 0.04 m"):
        load_model_file(model_file)


def test_a_21_link_model_refuses_to_load_in_a_31_link_process(tmp_path: Path) -> None:
    from twisted.model.network import InverseModel, InverseNet

    model_file = tmp_path / "tiny21.pt"
    model_file.write_bytes(InverseModel(InverseNet(eval(TINY))).to_bytes())
    db = tmp_path / "long.db"
    code = f"""
from twisted.model.network import InverseModel
from twisted.model.config import ModelRopeError
from twisted.model.registry import ModelError, load_model, load_model_file
from twisted.store import open_store
from pathlib import Path

path = Path({str(model_file)!r})
try:
    InverseModel.from_bytes(path.read_bytes())
except ModelRopeError as exc:
    print("from_bytes:", exc)
try:
    load_model_file(path)
except ModelError as exc:
    print("file:", exc)
with open_store("sqlite:///{db}") as store:
    try:
        load_model(store)
    except ModelError as exc:
        print("store:", exc)
"""
    result = _python(code, "31")
    assert result.returncode == 0, result.stderr
    lines = dict(line.split(": ", 1) for line in result.stdout.splitlines())
    assert set(lines) == {"from_bytes", "file", "store"}
    for which in ("from_bytes", "file"):
        assert "the model is for a rope of 21 links x 0.04 m (0.84 m)" in lines[which]
        assert "this process runs a rope of 31 links x 0.04 m (1.24 m)" in lines[which]
    assert lines["store"].startswith("the database holds no model, and no model is shipped for this")
    assert "process's rope of 31 links x 0.04 m (1.24 m) (models are shipped for: 21 links" in lines["store"]
    assert "`twisted train`" in lines["store"]


def test_a_31_link_plan_without_a_model_exits_2(tmp_path: Path) -> None:
    result = _twisted("31", "--db", f"sqlite:///{tmp_path / 'long.db'}", "plan", "--goal", ONE_CROSSING)
    assert result.returncode == 2, result.stderr
    assert "the database holds no model, and no model is shipped for this process's rope of 31 links" in _err(
        result
    )
    assert "Traceback" not in result.stderr


def test_every_shipped_model_is_for_the_rope_its_file_names() -> None:
    """Each ``twisted/data`` model loads in a process of the rope its file name gives (and only there),
    with that rope's shapes; a misnamed file would make ``shipped_ropes`` lie."""
    from twisted.model.registry import shipped_model_path, shipped_ropes

    ropes = shipped_ropes()
    assert ropes[0] == DEFAULT_ROPE and parse_rope("31c7") in ropes
    code = (
        "from twisted.model.registry import load_model\n"
        "from twisted.rope import ROPE\n"
        "model = load_model()\n"
        "print(model.model_id, model.net.config.rope == ROPE, ROPE.env_value)\n"
    )
    for rope in ropes:
        assert shipped_model_path(rope).is_file()
        result = _python(code, None if rope == DEFAULT_ROPE else rope.env_value)
        assert result.returncode == 0, result.stderr
        assert result.stdout.split() == ["None", "True", rope.env_value]


def test_a_31c7_process_with_an_empty_database_plans_with_its_shipped_model(tmp_path: Path) -> None:
    """``TWISTED_ROPE=31c7`` works right after installation, as the default rope does: the database holds
    no model, the shipped ``model_31c7.pt`` plans (a one-crossing goal on the 31-link rope)."""
    db = tmp_path / "r31c7.db"
    result = _twisted("31c7", "--db", f"sqlite:///{db}", "plan", "--goal", ONE_CROSSING, "--timeout", "60")
    assert result.returncode == 0, result.stderr  # exit 0: solved (3 would be out of time)
    assert "inverse model (shipped, model_31c7.pt): trained on" in result.stderr  # this rope's file named
    assert _select(db, "SELECT status FROM runs WHERE kind = 'plan'") == [("finished",)]
    assert _select(db, "SELECT COUNT(*) FROM models") == [(0,)]
    assert _select(db, "SELECT n_links, max_crossings FROM rope_profile") == [(31, 7)]


def test_models_stored_before_the_rope_field_are_21_links() -> None:
    legacy = {k: v for k, v in NetConfig().to_dict().items() if k not in ("n_links", "link_spacing_m")}
    assert NetConfig.from_dict(legacy).rope == DEFAULT_ROPE
    with pytest.raises(ModelRopeError, match="run with TWISTED_ROPE=31 to use it"):
        NetConfig.from_dict({**legacy, "n_links": 31}).check_rope()
    assert np.isclose(NetConfig().link_spacing_m, 0.04)


def test_a_rope_with_a_crossing_limit_of_7_encodes_and_accepts_a_7_crossing_knot() -> None:
    """The crossing limit is the rope's: a process running ``31c7`` encodes a state of 7_1 and takes it as a
    goal (the model's input widened by two visits and one count); the default rope refuses it."""
    code = (
        "from twisted.goals import make_goal\n"
        "from twisted.model.encoding import P_DATA_DIM, encode_p_data\n"
        "from twisted.rope import MAX_CROSSINGS\n"
        "goal = make_goal(knot='7_1+')\n"
        "print(MAX_CROSSINGS, P_DATA_DIM, encode_p_data(goal.states[0]).shape[0], goal.states[0].cross)\n"
    )
    seven = _python(code, "31c7")
    assert seven.returncode == 0, seven.stderr
    limit, dim, encoded, cross = map(int, seven.stdout.split())
    assert (limit, cross) == (7, 7) and encoded == dim
    six = _python(code, None)
    assert (
        six.returncode != 0
        and "the model encodes at most 6" in six.stderr
        and "TWISTED_ROPE=21c7" in six.stderr
    )
    default_dim = _python("from twisted.model.encoding import P_DATA_DIM\nprint(P_DATA_DIM)", None)
    assert int(default_dim.stdout) < dim


def test_a_model_of_another_crossing_limit_is_refused() -> None:
    with pytest.raises(ModelRopeError, match="states of up to 7 crossings.*TWISTED_ROPE=21c7"):
        NetConfig(max_crossings=7).check_rope()
    assert NetConfig.from_dict({"n_links": 21, "link_spacing_m": 0.04}).max_crossings == 6  # stored before
