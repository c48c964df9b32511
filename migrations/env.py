"""Alembic environment of the twisted database.

Normally run through ``twisted.store.open_store`` which passes an open connection (already inside a
transaction holding the write lock) in ``config.attributes["connection"]``. From a shell,
``alembic -c alembic.ini upgrade heads`` (or ``-x db=URL``) also works, as does autogenerate
(``alembic -c alembic.ini revision --autogenerate -m ...``) for drafting a new area's revision.
Batch mode is on so that SQLite can ALTER tables.
"""

from __future__ import annotations

import importlib
import pkgutil

from alembic import context

import twisted.store
from twisted.store.models import Base

# Every area's tables live in twisted/store/<area>.py on the same Base: import them all so that
# autogenerate sees the whole schema.
for _module in pkgutil.iter_modules(twisted.store.__path__):
    importlib.import_module(f"twisted.store.{_module.name}")

config = context.config
target_metadata = Base.metadata


def _configure(**kwargs: object) -> None:
    context.configure(target_metadata=target_metadata, render_as_batch=True, compare_type=True, **kwargs)


def run_migrations_offline() -> None:
    _configure(url=config.get_main_option("sqlalchemy.url"), literal_binds=True)
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        _configure(connection=connection)
        with context.begin_transaction():
            context.run_migrations()
        return
    from twisted.store.db import StoreError, open_store

    url = context.get_x_argument(as_dictionary=True).get("db") or config.get_main_option("sqlalchemy.url")
    try:
        store = open_store(url, upgrade=False)  # refuses foreign / newer databases before any write
    except StoreError as exc:
        raise SystemExit(f"error: {exc}") from exc
    try:
        with store.engine.connect() as conn:
            conn.execution_options(twisted_begin_immediate=True)
            with conn.begin():
                _configure(connection=conn)
                context.run_migrations()
    finally:
        store.close()


if context.is_offline_mode():
    run_migrations_offline()
else:
    run_migrations_online()
