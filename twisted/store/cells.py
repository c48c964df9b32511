"""Stored times and JSON cells checked as each row loads: a cell that does not read names its column.

SQLAlchemy parses a ``DateTime`` cell (SQLite keeps text) and a ``JSON`` cell (through the engine's
``json_deserializer``, :func:`twisted.store.boundary.parse_json`) while it builds the row, before any code
of ours sees the value, so a cell that is not a time or not readable JSON used to end in a ValueError
traceback (exit 1) from deep inside the ORM. :func:`check_cells_of` wraps the type of every such column of
a metadata in :class:`CheckedCell` as the column joins its table: the wrapped parser's failure becomes a
:class:`StoredValueError` naming the table and the column (the row is not known there), which the CLI
turns into exit 2 before anything is written.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import JSON, Column, DateTime, MetaData, Table, event
from sqlalchemy.types import TypeDecorator, TypeEngine

__all__ = ["CheckedCell", "StoredValueError", "check_cells_of"]


class StoredValueError(ValueError):
    """A value read back from the store that the code refuses: "table, row N, field: what is wrong".

    The CLI exits 2 with the message (cli/app.py); it is raised before anything is written. ``row`` is
    None where the row is not known (a cell refused while SQLAlchemy loads it)."""

    def __init__(self, table: str, row: Any, field: str, problem: str) -> None:
        self.table, self.row, self.field, self.problem = table, row, field, problem
        refused = "damaged in the store: refused, nothing changed"
        where = f"row {row}" if row is not None else "a row"
        super().__init__(f"{table}, {where}, {field}: {problem} ({refused})")


class CheckedCell(TypeDecorator[Any]):
    """``inner`` (a DateTime or JSON type) whose result parser's refusal names ``table``.``field``."""

    impl = DateTime  # replaced by ``inner`` in each instance
    cache_ok = True

    def __init__(self, inner: TypeEngine[Any], table: str, field: str) -> None:
        super().__init__()
        self.inner, self.table, self.field = inner, table, field
        self.impl = inner  # type: ignore[assignment]  # any DateTime or JSON type, per column

    def result_processor(self, dialect: Any, coltype: Any) -> Any:
        process = super().result_processor(dialect, coltype)
        if process is None:
            return None
        table, field = self.table, self.field
        time = isinstance(self.inner, DateTime)

        def checked(value: Any) -> Any:
            try:
                return process(value)
            except (ValueError, TypeError, OverflowError) as exc:
                # parse_json's refusal says why in words; SQLAlchemy's time parser names its exception
                said = f"{type(exc).__name__}: {str(exc)[:120]}" if time else str(exc)[:200]
                problem = f"not a time ({said})" if time else said
                raise StoredValueError(table, None, field, problem) from None

        return checked


_CHECKED: list[MetaData] = []


def check_cells_of(metadata: MetaData) -> None:
    """Every DateTime and JSON column of a table of ``metadata`` defined from now on is read through
    :class:`CheckedCell`."""
    _CHECKED.append(metadata)


@event.listens_for(Column, "after_parent_attach")
def _wrap(column: Column[Any], table: Any) -> None:
    if not isinstance(table, Table) or not any(table.metadata is m for m in _CHECKED):
        return
    if isinstance(column.type, DateTime | JSON) and not isinstance(column.type, CheckedCell):
        column.type = CheckedCell(column.type, table.name, column.name)
