"""The rope a database holds data of (Alembic revision 0013): one row, ``rope_profile``.

Every configuration, transition, plan and model in a database was made on one rope
(:data:`twisted.rope.ROPE`, chosen per process by ``TWISTED_ROPE``). The first process that opens
the database for writing records its rope here; every later open compares (``twisted.store.db``)
and refuses a process running another rope (:class:`twisted.store.db.RopeMismatchError`). Databases
made before this table existed hold 21-link data: the migration records 21 x 0.04 m when they hold
configurations. Revision 0017 adds the rope's crossing limit (``max_crossings``, 6 in every store made
before it).
"""

from __future__ import annotations

import datetime as dt

from sqlalchemy import DateTime, Float, Integer
from sqlalchemy.orm import Mapped, mapped_column

from twisted.rope import DEFAULT_MAX_CROSSINGS, RopeProfile
from twisted.store.models import Base, utcnow

__all__ = ["ROPE_ROW_ID", "StoredRope"]

ROPE_ROW_ID = 1  # the one row: a second insert (two first writers at once) fails on the primary key


class StoredRope(Base):
    """The rope of this database's data: ``n_links`` links ``link_spacing_m`` apart, states of up to
    ``max_crossings`` crossings."""

    __tablename__ = "rope_profile"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    n_links: Mapped[int] = mapped_column(Integer)
    link_spacing_m: Mapped[float] = mapped_column(Float)
    max_crossings: Mapped[int] = mapped_column(Integer, default=DEFAULT_MAX_CROSSINGS)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    def profile(self) -> RopeProfile:
        return RopeProfile(self.n_links, self.link_spacing_m, self.max_crossings)
