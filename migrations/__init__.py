"""Alembic environment and revisions of the twisted database (an installed package, so that a
non-editable install finds them: ``twisted.store.db.alembic_config`` points Alembic here)."""
