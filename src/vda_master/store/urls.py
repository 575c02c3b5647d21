"""Which database a ``database_url`` names, and the SQLAlchemy URL that reaches it (pure).

Accepted forms (``database_url`` unset means the SQLite file ``<data_dir>/master.sqlite3``)::

    sqlite:///relative/path.sqlite3      sqlite:////absolute/path.sqlite3
    postgresql://user:password@host:port/database   (also postgres://, postgresql+asyncpg://)

The async drivers (aiosqlite, asyncpg) are chosen here; users never name them.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

from sqlalchemy.engine import URL, make_url
from sqlalchemy.exc import ArgumentError

from vda5050.errors import ConfigError

SQLITE_FILE_NAME = "master.sqlite3"
_POSTGRES_PORT = 5432
_FORMS = "sqlite:///path/to/file.sqlite3 or postgresql://user:password@host:port/database"
_DRIVERS = {
    "sqlite": ("sqlite", "sqlite+aiosqlite"),
    "sqlite+aiosqlite": ("sqlite", "sqlite+aiosqlite"),
    "postgresql": ("postgresql", "postgresql+asyncpg"),
    "postgres": ("postgresql", "postgresql+asyncpg"),
    "postgresql+asyncpg": ("postgresql", "postgresql+asyncpg"),
}


class Backend(StrEnum):
    SQLITE = "sqlite"
    POSTGRESQL = "postgresql"


@dataclass(frozen=True, slots=True)
class DatabaseTarget:
    """A resolved database: the backend, the async SQLAlchemy URL, and a description for logs
    and errors that never shows a password (``/var/master.sqlite3``, ``db.local:5432/vda``)."""

    backend: Backend
    url: URL
    where: str
    sqlite_path: Path | None = None


def resolve_database_url(database_url: str | None, data_dir: Path) -> DatabaseTarget:
    """The database ``database_url`` names, or the SQLite file in ``data_dir`` when it is None.

    Raises:
        ConfigError: the URL is malformed or names a database this store does not support.
    """
    if database_url is None or not database_url.strip():
        return _sqlite(data_dir / SQLITE_FILE_NAME)
    try:
        url = make_url(database_url.strip())
    except (ArgumentError, ValueError):  # ValueError: a port that is not a number
        msg = f"database_url {_masked(database_url)!r} is not a database URL; use {_FORMS}"
        raise ConfigError(msg) from None
    backend, driver = _DRIVERS.get(url.drivername, (None, None))
    if backend is None or driver is None:
        msg = f"database_url scheme {url.drivername!r} is not supported; use {_FORMS}"
        raise ConfigError(msg)
    if backend == Backend.SQLITE:
        return _sqlite_from_url(url)
    return _postgresql(url.set(drivername=driver))


def _sqlite_from_url(url: URL) -> DatabaseTarget:
    if url.host or url.username or url.port:
        msg = f"a sqlite database_url names a file, not a host: use {_FORMS}"
        raise ConfigError(msg)
    if not url.database or url.database == ":memory:":
        msg = f"a sqlite database_url needs a file path (an in-memory database is lost): {_FORMS}"
        raise ConfigError(msg)
    return _sqlite(Path(url.database))


def _sqlite(path: Path) -> DatabaseTarget:
    url = URL.create("sqlite+aiosqlite", database=str(path))
    return DatabaseTarget(Backend.SQLITE, url, str(path), sqlite_path=path)


def _postgresql(url: URL) -> DatabaseTarget:
    if not url.database:
        msg = f"a postgresql database_url needs a database name: {_FORMS}"
        raise ConfigError(msg)
    if url.port is not None and not 0 < url.port < 2**16:
        msg = f"database_url port {url.port} is out of range"
        raise ConfigError(msg)
    host = url.host or "localhost"
    where = f"{host}:{url.port or _POSTGRES_PORT}/{url.database}"
    return DatabaseTarget(Backend.POSTGRESQL, url, where)


def _masked(text: str) -> str:
    """``text`` with anything between ``://user:`` and ``@`` hidden."""
    scheme, sep, rest = text.partition("://")
    credentials, at, host = rest.rpartition("@")
    if not sep or not at or ":" not in credentials:
        return text
    return f"{scheme}://{credentials.split(':', 1)[0]}:***@{host}"
