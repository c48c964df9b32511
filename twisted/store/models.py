"""SQLAlchemy declarative models of the foundation tables (Alembic revision 0001).

Other areas add their own tables on the same :class:`Base` in ``twisted/store/<area>.py`` with their own
migration (``down_revision = "0001"``). The schema here must match ``migrations/versions/0001_foundation.py``
exactly (``tests/test_store.py`` compares them).

Arrays are stored as little-endian float64 BLOBs so a configuration restores bit for bit:
``configurations.q`` is the simulator's opaque state vector, ``configurations.points`` the N_POINTS
link points (N_POINTS x 3, head to tail; 22 on the default rope). Use :meth:`Configuration.q_array` /
:meth:`Configuration.points_array` to read them.
"""

from __future__ import annotations

import datetime as dt
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt
from sqlalchemy import (
    JSON,
    BigInteger,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Text,
    inspect,
    select,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, Session, declared_attr, mapped_column

from twisted.store.cells import check_cells_of

# Deterministic constraint names: Alembic batch mode (SQLite) and PostgreSQL both need named constraints
# to alter or drop them later.
NAMING_CONVENTION = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}

# The status of every run table (runs, training_runs, rl_runs, eval_runs): see RunLifecycle.
RUN_STATUSES = ("running", "finished", "interrupted", "failed")


def utcnow() -> dt.datetime:
    """Timezone-aware current time in UTC (what every timestamp column stores)."""
    return dt.datetime.now(dt.UTC)


def array_to_blob(values: npt.ArrayLike) -> bytes:
    """Pack an array as little-endian float64 bytes (exact round trip)."""
    return np.ascontiguousarray(values, dtype="<f8").tobytes()


def blob_to_array(blob: bytes, shape: tuple[int, ...] | None = None) -> npt.NDArray[np.float64]:
    """Unpack :func:`array_to_blob` bytes into a writable float64 array, optionally reshaped."""
    out = np.frombuffer(blob, dtype="<f8").astype(np.float64)
    return out.reshape(shape) if shape is not None else out


class Base(DeclarativeBase):
    """Declarative base shared by every area's tables."""

    metadata = MetaData(naming_convention=NAMING_CONVENTION)
    type_annotation_map = {dict[str, Any]: JSON, list[Any]: JSON}


check_cells_of(Base.metadata)  # a stored time or JSON cell that does not read names its column


RowT = TypeVar("RowT", bound=Base)


def by_id_or_newest(
    session: Session,
    table: type[RowT],
    row_id: int | None,
    *,
    what: str,
    see: str,
    error: type[Exception] = LookupError,
) -> RowT | None:
    """Row ``row_id`` of ``table`` or, when it is None, the newest row (highest id; None if there is none).

    An id that is not there raises ``error``, naming ``what`` was asked for, the ids there are, and the
    command ``see`` that lists them (how a stored model or SAC policy is chosen by id).
    """
    (key,) = inspect(table).primary_key
    if row_id is None:
        return session.scalars(select(table).order_by(key.desc()).limit(1)).first()
    row = session.get(table, row_id)
    if row is None:
        known = session.scalars(select(key).order_by(key)).all()
        raise error(
            f"there is no {what} {row_id} in the database (ids: {list(known) or 'none'}); see `{see}`"
        )
    return row


class RunLifecycle:
    """The columns every run table shares: ``status`` (in :data:`RUN_STATUSES`), start, end, message.

    Mixed into ``runs``, ``training_runs``, ``rl_runs`` and ``eval_runs``. A table whose status is
    indexed (its migration made one) sets ``status_indexed = True``. :meth:`end_values` are what
    closing a run writes.
    """

    status_indexed = False

    @declared_attr
    def status(cls) -> Mapped[str]:
        return mapped_column(String(16), default="running", index=cls.status_indexed)

    started_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    ended_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True))
    message: Mapped[str | None] = mapped_column(Text)

    @staticmethod
    def end_values(status: str, message: str | None = None) -> dict[str, Any]:
        """The column values of a run that ends now with ``status`` and ``message``."""
        return {"status": status, "ended_at": utcnow(), "message": message}


class Run(RunLifecycle, Base):
    """One invocation of a long job (``kind`` = "collect", "train", "plan", ...), with its counters."""

    __tablename__ = "runs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    kind: Mapped[str] = mapped_column(String(32), index=True)
    parameters: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    seed: Mapped[int | None] = mapped_column(BigInteger)
    # Counters, updated in the same transaction as the rows they count (so they survive a SIGKILL).
    tried: Mapped[int] = mapped_column(Integer, default=0)
    kept: Mapped[int] = mapped_column(Integer, default=0)
    rejected: Mapped[int] = mapped_column(Integer, default=0)
    wall_seconds: Mapped[float] = mapped_column(Float, default=0.0)
    sim_seconds: Mapped[float] = mapped_column(Float, default=0.0)
    host: Mapped[str | None] = mapped_column(String(255))
    pid: Mapped[int | None] = mapped_column(Integer)


class TopologicalState(Base):
    """A distinct P-data state; ``key`` is ``PData.key`` (compact JSON), ``cross`` its crossing count.

    ``knot_type`` (revision 0006, meaning fixed by 0010) names the knot the state really ties: both
    closures (``closure_under``, ``closure_over``: the ends joined under / over the table) are that knot;
    ``"knotoid"`` when they differ (:class:`twisted.knots.RopeKnot`).
    """

    __tablename__ = "topological_states"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    key: Mapped[str] = mapped_column(Text, unique=True)
    p_data: Mapped[list[Any]] = mapped_column(JSON)
    cross: Mapped[int] = mapped_column(Integer, index=True)
    # twisted.knots.identify(p_data).name: the knot both closures agree on, or "knotoid" (0006, 0010)
    knot_type: Mapped[str | None] = mapped_column(String(16), index=True)
    closure_under: Mapped[str | None] = mapped_column(String(16))  # 0010
    closure_over: Mapped[str | None] = mapped_column(String(16))  # 0010


class Configuration(Base):
    """A rope configuration q that was reached, with its link points and topological state.

    The transition that produced it (if any) is the ``transitions`` row whose ``to_configuration_id`` is
    this id; a root configuration (the straight rope) has none.
    """

    __tablename__ = "configurations"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id"), index=True)
    state_id: Mapped[int] = mapped_column(ForeignKey("topological_states.id"), index=True)
    cross: Mapped[int] = mapped_column(Integer, index=True)
    q: Mapped[bytes] = mapped_column(LargeBinary)
    points: Mapped[bytes] = mapped_column(LargeBinary)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    def q_array(self) -> npt.NDArray[np.float64]:
        """The exact simulator state, for ``RopeSim.set_state``."""
        return blob_to_array(self.q)

    def points_array(self) -> npt.NDArray[np.float64]:
        """The N_POINTS link points (N_POINTS, 3), head to tail."""
        return blob_to_array(self.points, (-1, 3))


class CollectBatch(Base):
    """One batch committed by a collector, keyed by an idempotency id ``"<run>-<worker>-<seq>"``."""

    __tablename__ = "collect_batches"

    batch_id: Mapped[str] = mapped_column(String(64), primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), index=True)
    worker: Mapped[int] = mapped_column(Integer)
    seq: Mapped[int] = mapped_column(Integer)
    tried: Mapped[int] = mapped_column(Integer)
    kept: Mapped[int] = mapped_column(Integer)
    rejected: Mapped[int] = mapped_column(Integer)
    sim_seconds: Mapped[float] = mapped_column(Float)
    committed_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class CollectTry(Base):
    """Curves tried / kept / rejected in one batch, per crossing count of the start configuration."""

    __tablename__ = "collect_tries"

    batch_id: Mapped[str] = mapped_column(ForeignKey("collect_batches.batch_id"), primary_key=True)
    from_cross: Mapped[int] = mapped_column(Integer, primary_key=True)
    tried: Mapped[int] = mapped_column(Integer)
    kept: Mapped[int] = mapped_column(Integer)
    rejected: Mapped[int] = mapped_column(Integer)


class Transition(Base):
    """A kept transition (q, s, c, q', s'): configuration ``from`` + curve ``c`` -> configuration ``to``."""

    __tablename__ = "transitions"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), index=True)
    batch_id: Mapped[str | None] = mapped_column(ForeignKey("collect_batches.batch_id"), index=True)
    from_configuration_id: Mapped[int] = mapped_column(ForeignKey("configurations.id"), index=True)
    to_configuration_id: Mapped[int] = mapped_column(ForeignKey("configurations.id"), index=True)
    link: Mapped[int] = mapped_column(Integer)
    z_max_m: Mapped[float] = mapped_column(Float)
    x_m: Mapped[float] = mapped_column(Float)
    y_m: Mapped[float] = mapped_column(Float)
    from_state_id: Mapped[int] = mapped_column(ForeignKey("topological_states.id"))
    to_state_id: Mapped[int] = mapped_column(ForeignKey("topological_states.id"))
    # Crossing counts copied from the states so the common per-count questions need no join.
    from_cross: Mapped[int] = mapped_column(Integer)
    to_cross: Mapped[int] = mapped_column(Integer)
    steps: Mapped[int | None] = mapped_column(Integer)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    __table_args__ = (
        Index("ix_transitions_from_state_id_to_state_id", "from_state_id", "to_state_id"),
        Index("ix_transitions_from_cross_to_cross", "from_cross", "to_cross"),
    )


# SQL views created by the migrations (texts in migrations/versions/0001_foundation.py), queryable from a
# sqlite3/psql shell: SELECT * FROM states_by_cross;
VIEW_NAMES = (
    "states_by_cross",
    "state_visits",
    "transitions_per_run",
    "collect_throughput",
    "acceptance_by_cross",
)
