"""Alembic environment of the store's migrations.

The store runs them itself on open (``vda_master.store.migrate``), handing over its connection in
``config.attributes["connection"]``; no alembic.ini is needed. On PostgreSQL an advisory lock
serialises two masters starting on the same database at once.
"""

from __future__ import annotations

from alembic import context
from sqlalchemy import text
from sqlalchemy.engine import Connection

#: Any constant; the same for every master of this project.
_MIGRATION_LOCK = 5_050_010


def _run(connection: Connection) -> None:
    context.configure(connection=connection, render_as_batch=True, compare_type=True)
    with context.begin_transaction():
        if connection.dialect.name == "postgresql":
            connection.execute(text(f"SELECT pg_advisory_xact_lock({_MIGRATION_LOCK})"))
        context.run_migrations()


_connection = context.config.attributes.get("connection")
if not isinstance(_connection, Connection):
    msg = "the store's migrations run through vda_master.store.migrate, with a connection"
    raise TypeError(msg)
_run(_connection)
