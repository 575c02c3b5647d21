"""Store backends for the contract tests: in memory, SQLite in a temporary folder, PostgreSQL
(one database for the whole session, on a private server or VDA_TEST_DATABASE_URL's, emptied
before each test)."""

from __future__ import annotations

from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.postgres import empty_database, postgres_server, session_database
from vda_master.store import MemoryStore, Store, open_store

SQL_BACKENDS = ["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)]
ALL_BACKENDS = ["memory", *SQL_BACKENDS]


@dataclass
class Database:
    """One empty database of one backend; ``open()`` gives a new (unopened) store on it."""

    backend: str
    url: str | None
    data_dir: Path
    memory: MemoryStore | None = None

    def open(self) -> Store:
        if self.memory is not None:
            return self.memory  # the same "database" every time
        return open_store(self.url, self.data_dir)


@pytest.fixture(scope="session")
def postgres_url() -> Iterator[str]:
    """A PostgreSQL database for the session (on VDA_TEST_DATABASE_URL's server, else on a
    private one), dropped at the end."""
    with postgres_server() as server, session_database(server) as url:
        yield url


async def _database(request: pytest.FixtureRequest, tmp_path: Path) -> AsyncIterator[Database]:
    backend: str = request.param
    if backend == "memory":
        yield Database(backend, None, tmp_path, MemoryStore())
    elif backend == "sqlite":
        yield Database(backend, None, tmp_path / "data")
    else:
        url: str = request.getfixturevalue("postgres_url")
        await empty_database(url)
        yield Database(backend, url, tmp_path)


@pytest.fixture(params=ALL_BACKENDS)
async def database(request: pytest.FixtureRequest, tmp_path: Path) -> AsyncIterator[Database]:
    """An empty database on every backend, the memory store included."""
    async for database in _database(request, tmp_path):
        yield database


@pytest.fixture(params=SQL_BACKENDS)
async def sql_database(request: pytest.FixtureRequest, tmp_path: Path) -> AsyncIterator[Database]:
    """An empty database on each SQL backend."""
    async for database in _database(request, tmp_path):
        yield database


@pytest.fixture
async def store(database: Database) -> AsyncIterator[Store]:
    """An open store on an empty database of every backend."""
    async with database.open() as opened:
        yield opened
