"""Alembic revisions (Alembic ignores this file; it makes the folder part of the installed package)."""
