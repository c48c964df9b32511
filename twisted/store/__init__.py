"""The twisted database: one SQL store (SQLite by default, PostgreSQL optional) for every area.

``open_store(url)`` is the one way to open it; models live in :mod:`twisted.store.models` (other areas
add theirs in ``twisted/store/<area>.py``), query helpers in :mod:`twisted.store.queries`.
"""

from twisted.store.db import (
    RopeMismatchError,
    Store,
    StoreError,
    alembic_config,
    head_revisions,
    open_store,
    parse_url,
    stored_rope,
)
from twisted.store.models import (
    VIEW_NAMES,
    Base,
    CollectBatch,
    CollectTry,
    Configuration,
    Run,
    TopologicalState,
    Transition,
    array_to_blob,
    blob_to_array,
)

__all__ = [
    "VIEW_NAMES",
    "Base",
    "CollectBatch",
    "CollectTry",
    "Configuration",
    "RopeMismatchError",
    "Run",
    "Store",
    "StoreError",
    "TopologicalState",
    "Transition",
    "alembic_config",
    "array_to_blob",
    "blob_to_array",
    "head_revisions",
    "open_store",
    "parse_url",
    "stored_rope",
]
