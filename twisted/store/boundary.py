"""Values read back from the store, checked where they come in (docs/security.md, DESIGN 13.4).

A store is input like any file: whoever can write it (a shared PostgreSQL database, a ``.db`` file
handed over, ``sqlite3`` on a copy) chooses every cell. What the commands read back from their own
tables therefore passes the checks a value typed on the command line passes, before anything is
written: a run's parameters the planner options' own declarations (:func:`check_declared`, given
``twisted.planner.options.specs()``), a checkpoint its generator state and counters
(:func:`check_checkpoint`), a stored rope configuration its sizes and finiteness
(:func:`check_configuration`; the planner adds the simulator's verdict). Every refusal is a
:class:`StoredValueError` naming the table, the row and the field; the CLI exits 2 with it, and no
run changes state.

JSON text is parsed by :func:`parse_json` only (it is also the engine's ``json_deserializer``, so an
ORM read of any JSON column goes through it): the text is bounded in size and in nesting before the
parser sees it, so a row nested 200,000 levels deep is refused in linear time instead of ending in a
RecursionError. :func:`get_row` reads a row and names the JSON column that failed.
"""

from __future__ import annotations

import json
import math
import numbers
import re
from collections.abc import Iterable, Mapping
from itertools import islice
from typing import Any, Protocol, cast

import numpy as np
from sqlalchemy import JSON, Text, select
from sqlalchemy import cast as sql_cast
from sqlalchemy.orm import Session

from twisted.store.cells import StoredValueError
from twisted.store.models import blob_to_array

__all__ = [
    "MAX_JSON_BYTES",
    "MAX_JSON_DEPTH",
    "Declared",
    "StoredJSONError",
    "StoredValueError",
    "check_checkpoint",
    "check_configuration",
    "check_declared",
    "get_row",
    "parse_json",
    "shown",
    "stored_count",
    "stored_curve",
    "stored_floats",
    "stored_object",
    "stored_seconds",
]

# the largest JSON cell read back: the planner's own cells reach 100 kB in short searches (a checkpoint's
# statistics, a knot goal's states) and grow with a long search; 64 MiB leaves room for hours of search
# and bounds what the parser can allocate (a few hundred MB of Python objects)
MAX_JSON_BYTES = 64 * 2**20
# the deepest nesting read back: the code writes at most 4 levels (a list of P-data, each a list of
# crossings, each a list); Python's parser recurses once per level
MAX_JSON_DEPTH = 32
MAX_COUNT = 2**31 - 1  # iterations, simulator calls, nodes: what an INTEGER column of PostgreSQL holds


class StoredJSONError(ValueError):
    """JSON text that is not read: too large, nested too deep, or not JSON (the reason in words)."""


def shown(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to about ``limit`` characters, for quoting a stored value in a message."""
    if isinstance(value, str | bytes | list | dict) and len(value) > 10 * limit:
        # repr of a huge value is never built whole (a dict is cut by its first items: it has no slices)
        value = dict(islice(value.items(), 10 * limit)) if isinstance(value, dict) else value[: 10 * limit]
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 5]}...{text[-2:]}"


_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"', re.DOTALL)


def _depth(raw: bytes) -> int:
    """How deep ``[``/``{`` nest in JSON text ``raw`` outside its strings (linear time, no recursion)."""
    if raw.count(b"[") + raw.count(b"{") <= MAX_JSON_DEPTH:
        return 0  # too few to nest deeper than the limit (most cells: a microsecond, not a scan)
    structure = np.frombuffer(_STRING.sub(b'""', raw), dtype=np.uint8)
    step = ((structure == ord("[")) | (structure == ord("{"))).astype(np.int64)
    step -= (structure == ord("]")) | (structure == ord("}"))
    return int(np.cumsum(step).max(initial=0))


def parse_json(text: str | bytes | bytearray) -> Any:
    """JSON text read back from the store, parsed within :data:`MAX_JSON_BYTES` and :data:`MAX_JSON_DEPTH`.

    Raises :class:`StoredJSONError` (a ValueError) saying why it was not read."""
    raw = text.encode("utf-8", "surrogatepass") if isinstance(text, str) else bytes(text)
    if len(raw) > MAX_JSON_BYTES:
        raise StoredJSONError(f"{len(raw):,} bytes of JSON, more than the {MAX_JSON_BYTES:,} read back")
    depth = _depth(raw)
    if depth > MAX_JSON_DEPTH:
        limit = MAX_JSON_DEPTH
        raise StoredJSONError(f"JSON nested {depth:,} levels deep, more than the {limit} read back")
    try:
        return json.loads(raw)
    except (ValueError, RecursionError) as exc:  # RecursionError: never, with the depth bounded
        raise StoredJSONError(f"not JSON ({type(exc).__name__}: {str(exc)[:120]})") from None


def get_row(session: Session, model: Any, key: Any) -> Any:
    """``session.get(model, key)``; a JSON column that does not read (:func:`parse_json`) is a
    :class:`StoredValueError` naming it."""
    try:
        return session.get(model, key)
    except StoredValueError as exc:  # a cell refused as the row loaded (twisted.store.cells): its row is key
        if exc.row is None and exc.table == model.__table__.name:
            raise StoredValueError(exc.table, key, exc.field, exc.problem) from None
        raise
    except StoredJSONError as exc:
        table = model.__table__
        failed = "a JSON column"
        for column in table.columns:
            if isinstance(column.type, JSON):
                key_column = next(iter(table.primary_key.columns))
                text = session.scalar(select(sql_cast(column, Text)).where(key_column == key))
                try:
                    parse_json(text or "null")
                except StoredJSONError:
                    failed = column.name
                    break
        raise StoredValueError(table.name, key, failed, str(exc)) from None


def stored_object(value: Any, table: str, row: Any, field: str) -> dict[str, Any]:
    """A JSON object read back (a dict with string keys); None counts as empty."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        got = f"{type(value).__name__} {shown(value)}"
        raise StoredValueError(table, row, field, f"must be a JSON object, got {got}")
    return value


class Declared(Protocol):
    """A declared value (``twisted.planner.options.OptionSpec``): its name, and why a value is refused."""

    @property
    def name(self) -> str: ...

    def check(self, value: Any) -> str | None: ...


def check_declared(
    values: Mapping[str, Any], declared: Iterable[Declared], table: str, row: Any, field: str
) -> None:
    """Each declared name present in ``values`` passes its declaration's own check (the one the
    command line's value passes); a name that is absent is left to the caller (a default)."""
    for spec in declared:
        if spec.name in values:
            problem = spec.check(values[spec.name])
            if problem is not None:
                raise StoredValueError(table, row, f"{field}.{spec.name}", problem)


def stored_count(value: Any, table: str, row: Any, field: str) -> int:
    """A stored count (iterations, steps, a node's sequence number): an integer in [0, 2**31)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not 0 <= int(value) <= MAX_COUNT:
        raise StoredValueError(table, row, field, f"must be a count in [0, {MAX_COUNT}], got {shown(value)}")
    return int(value)


def stored_seconds(value: Any, table: str, row: Any, field: str) -> float:
    """A stored duration: a finite number of seconds, not negative."""
    if not _finite(value) or value < 0:
        problem = f"must be a finite number of seconds >= 0, got {shown(value)}"
        raise StoredValueError(table, row, field, problem)
    return float(value)


def check_checkpoint(
    row: Any, iteration: Any, elapsed_s: Any, sim_calls: Any, nodes: Any, rng_state: Any, stats: Any
) -> tuple[int, float, int, int, dict[str, Any], dict[str, Any]]:
    """A planner checkpoint (``search_checkpoints`` row ``row``) checked: counts in [0, 2**31), the search
    time finite, the generator state one that numpy's PCG64 takes (the planner's), the selection
    statistics objects of ``[count, reward]`` pairs. Returns the values, the generator state parsed."""
    table = "search_checkpoints"
    named = ((iteration, "iteration"), (sim_calls, "sim_calls"), (nodes, "nodes"))
    counts = [stored_count(value, table, row, name) for value, name in named]
    seconds = stored_seconds(elapsed_s, table, row, "elapsed_s")
    try:
        state = parse_json(rng_state) if isinstance(rng_state, str | bytes) else rng_state
    except StoredJSONError as exc:
        raise StoredValueError(table, row, "rng_state", str(exc)) from None
    generator_state = stored_object(state, table, row, "rng_state")
    try:
        np.random.PCG64().state = cast(Any, generator_state)  # what Search restores: numpy checks it
    except (ValueError, TypeError, KeyError, OverflowError) as exc:
        problem = f"not a PCG64 generator state ({shown(str(exc), 120)})"
        raise StoredValueError(table, row, "rng_state", problem) from None
    tables = stored_object(stats, table, row, "stats")
    for name, entries in tables.items():
        for key, entry in stored_object(entries, table, row, f"stats.{name}").items():
            if not (isinstance(entry, list) and len(entry) == 2 and all(_finite(x) for x in entry)):
                where = f"stats.{name}[{shown(key, 40)}]"
                problem = f"must be [count, reward], two finite numbers, got {shown(entry)}"
                raise StoredValueError(table, row, where, problem)
    return counts[0], seconds, counts[1], counts[2], generator_state, tables


def _finite(x: Any) -> bool:
    return not isinstance(x, bool) and isinstance(x, numbers.Real) and math.isfinite(x)


def stored_floats(blob: Any, table: str, row: Any, field: str, width: int = 1) -> np.ndarray:
    """A BLOB of little-endian float64 values (:func:`twisted.store.models.array_to_blob`) read back, in
    rows of ``width`` when it is above 1: whole values, at least one."""
    if not isinstance(blob, bytes) or not blob or len(blob) % (8 * width):
        size = f"{len(blob):,} bytes" if isinstance(blob, bytes) else type(blob).__name__
        rows = f" in rows of {width}" if width > 1 else ""
        raise StoredValueError(table, row, field, f"must be float64 values{rows}, got {size}")
    return blob_to_array(blob, (-1, width) if width > 1 else None)


def stored_curve(
    link: Any, z_max_m: Any, x_m: Any, y_m: Any, n_links: int, table: str, row: Any
) -> tuple[int, float, float, float]:
    """A stored curve's columns (``link``, ``z_max_m``, ``x_m``, ``y_m``): a link of the rope, finite
    numbers."""
    if isinstance(link, bool) or not isinstance(link, numbers.Integral) or not 0 <= int(link) < n_links:
        raise StoredValueError(table, row, "link", f"must be a link 0..{n_links - 1}, got {shown(link)}")
    for name, value in (("z_max_m", z_max_m), ("x_m", x_m), ("y_m", y_m)):
        if not _finite(value):
            raise StoredValueError(table, row, name, f"must be a finite number, got {shown(value)}")
    return int(link), float(z_max_m), float(x_m), float(y_m)


def check_configuration(q: np.ndarray, points: np.ndarray, n_points: int, table: str, row: Any) -> None:
    """A stored rope configuration: ``q`` a flat vector of finite floats, ``points`` ``n_points`` finite
    3-D points (the rope profile's). Whether the simulator takes ``q`` is the planner's check
    (:func:`twisted.planner.both_ways.accepted_configuration`): the store knows no simulator."""
    if q.ndim != 1 or q.size == 0 or not np.all(np.isfinite(q)):
        raise StoredValueError(table, row, "q", f"must be finite floats, got {_describe(q)}")
    if points.shape != (n_points, 3) or not np.all(np.isfinite(points)):
        problem = f"must be {n_points} finite 3-D points (the rope's), got {_describe(points)}"
        raise StoredValueError(table, row, "points", problem)


def _describe(a: np.ndarray) -> str:
    bad = int(np.size(a) - np.count_nonzero(np.isfinite(a)))
    return f"{a.size} floats" + (f", {bad} of them NaN or infinite" if bad else "")
