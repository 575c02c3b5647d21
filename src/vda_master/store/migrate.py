"""Versioned schema migrations (Alembic), run by the store on open, shipped in the package.

Run on an open connection: :func:`upgrade_to_head` brings any database, empty or older, to the
newest revision in one transaction per revision (PostgreSQL's DDL is transactional; SQLite's is
too, for what these migrations do).

Writing a new revision: ``python -m vda_master.store revision "add something"`` renders
an empty one in ``migrations/versions/``; fill in ``upgrade()`` and ``downgrade()``, add the same
change to ``schema.py``, and the contract test that compares the migrated database with
``schema.metadata`` tells whether they agree.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy.engine import Connection

from vda_master.store.errors import StoreError

SCRIPT_LOCATION = "vda_master.store:migrations"


@dataclass(frozen=True, slots=True)
class Migration:
    """The revision a database had before opening (None: empty) and the one it has now."""

    before: str | None
    after: str | None


def alembic_config(connection: Connection | None = None) -> Config:
    """An in-memory Alembic config for the shipped migrations (no alembic.ini)."""
    config = Config()
    config.set_main_option("script_location", SCRIPT_LOCATION)
    config.set_main_option("path_separator", "os")
    config.set_main_option("file_template", "v%%(rev)s_%%(slug)s")
    if connection is not None:
        config.attributes["connection"] = connection
    return config


def head_revision() -> str | None:
    """The newest revision the package ships."""
    return ScriptDirectory.from_config(alembic_config()).get_current_head()


def current_revision(connection: Connection) -> str | None:
    """The revision the database is at (None: not migrated at all)."""
    return MigrationContext.configure(connection).get_current_revision()


def upgrade_to_head(connection: Connection) -> Migration:
    """Apply every migration the database lacks; a sync function, run through ``run_sync``.

    Raises:
        StoreError: the database has a revision this code does not know (a newer master wrote
            it): opening it would risk its data.
    """
    before = current_revision(connection)
    script = ScriptDirectory.from_config(alembic_config())
    known = {revision.revision for revision in script.walk_revisions()}
    if before is not None and before not in known:
        msg = (
            f"the database has schema revision {before!r}, which this master does not know"
            f" (its newest is {script.get_current_head()!r}): run the master that wrote it"
        )
        raise StoreError(msg)
    command.upgrade(alembic_config(connection), "head")
    return Migration(before, current_revision(connection))


def main(argv: list[str]) -> int:
    """``revision MESSAGE``: render a new empty revision (for developers)."""
    if len(argv) != 2 or argv[0] != "revision":  # noqa: PLR2004
        sys.stderr.write('usage: python -m vda_master.store revision "message"\n')
        return 2
    head = head_revision()
    command.revision(alembic_config(), message=argv[1], rev_id=f"{int(head or '0') + 1:04d}")
    return 0
