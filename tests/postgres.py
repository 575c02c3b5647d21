"""A private PostgreSQL server for the store's tests, or the one ``VDA_TEST_DATABASE_URL`` names.

The private server lives in a temporary folder on a free loopback port (``initdb`` + ``pg_ctl``),
never on the machine's own PostgreSQL. As root, initdb refuses to run, so the server runs as the
``postgres`` user (``runuser``) in a folder that user owns.

Tests that need PostgreSQL skip when its binaries are missing and no URL is given, unless
``VDA_REQUIRE_POSTGRES`` is set (CI sets it), in which case they fail instead.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import pwd
import re
import shutil
import subprocess
import tempfile
import uuid
from collections.abc import Callable, Coroutine, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest
from sqlalchemy import text
from sqlalchemy.engine import URL, make_url
from sqlalchemy.ext.asyncio import create_async_engine

from tests.mosquitto import free_port

_BINARIES = ("initdb", "pg_ctl", "postgres")
_SERVER_USER = "postgres"


def postgres_bin_dir() -> Path | None:
    """The folder holding initdb, pg_ctl and postgres: on PATH, else the newest
    ``/usr/lib/postgresql/<version>/bin`` (Debian keeps them there)."""
    found = [shutil.which(name) for name in _BINARIES]
    if all(found):
        return Path(str(found[0])).resolve().parent
    candidates = sorted(
        Path("/usr/lib/postgresql").glob("*/bin"),
        key=lambda p: int(p.parent.name) if p.parent.name.isdigit() else 0,
    )
    for candidate in reversed(candidates):
        if all((candidate / name).is_file() for name in _BINARIES):
            return candidate
    return None


def require_postgres_bin_dir() -> Path:
    """The binaries' folder, or skip (fail when VDA_REQUIRE_POSTGRES is set) when missing."""
    found = postgres_bin_dir()
    if found is None:
        if os.environ.get("VDA_REQUIRE_POSTGRES"):
            pytest.fail("PostgreSQL is required (VDA_REQUIRE_POSTGRES is set) but not installed")
        pytest.skip("PostgreSQL binaries (initdb, pg_ctl) are not installed")
    return found


@dataclass(frozen=True)
class PostgresServer:
    """A server to create test databases on: ``admin_url`` names its maintenance database."""

    admin_url: URL

    def database_url(self, name: str) -> str:
        """A ``postgresql://`` URL of database ``name`` on this server (as a user writes it)."""
        return self.admin_url.set(database=name).render_as_string(hide_password=False)


@dataclass(frozen=True)
class PrivatePostgres(PostgresServer):
    """A server of our own, which tests may stop and start again (same port, same data)."""

    bin_dir: Path
    folder: Path
    #: False: fsync off (durable unless the machine itself crashes), for fast tests.
    durable: bool = False

    def start(self) -> None:
        options = f"-p {self.admin_url.port} -k {self.folder} -c listen_addresses=127.0.0.1"
        if not self.durable:
            options += " -c fsync=off -c full_page_writes=off"
        log = str(self.folder / "server.log")
        self._pg_ctl("-o", options, "-l", log, "-w", "-t", "30", "start")

    def stop(self) -> None:
        """Stop at once, as a crash would (open connections are cut)."""
        self._pg_ctl("-m", "immediate", "-w", "stop")

    def _pg_ctl(self, *args: str) -> None:
        _run(_as_server_user(self.bin_dir, "pg_ctl", "-D", str(self.folder / "data"), *args))


def _as_server_user(bin_dir: Path, *args: str) -> list[str]:
    command = [str(bin_dir / args[0]), *args[1:]]
    if os.geteuid() != 0:
        return command
    return ["runuser", "-u", _SERVER_USER, "--", *command]


@contextlib.contextmanager
def run_postgres(*, durable: bool = False) -> Iterator[PrivatePostgres]:
    """Start a throw-away server (initdb, pg_ctl start) and remove it afterwards."""
    bin_dir = require_postgres_bin_dir()
    folder = Path(tempfile.mkdtemp(prefix="vda-pg-"))
    if os.geteuid() == 0:
        user = pwd.getpwnam(_SERVER_USER)
        os.chown(folder, user.pw_uid, user.pw_gid)
    url = URL.create(
        "postgresql", "postgres", host="127.0.0.1", port=free_port(), database="postgres"
    )
    server = PrivatePostgres(url, bin_dir, folder, durable)
    try:
        _run(_as_server_user(bin_dir, "initdb", "-D", str(folder / "data"), "-U", "postgres",
                             "--auth=trust", "-E", "UTF8", "--no-sync", "--locale=C"))  # fmt: skip
        server.start()
        try:
            yield server
        finally:
            with contextlib.suppress(RuntimeError):  # already stopped
                server.stop()
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _run(command: list[str]) -> None:
    done = subprocess.run(command, capture_output=True, text=True, check=False)  # noqa: S603
    if done.returncode != 0:
        msg = f"{' '.join(command)} failed ({done.returncode}): {done.stderr[-2000:]}"
        raise RuntimeError(msg)


@contextlib.contextmanager
def postgres_server() -> Iterator[PostgresServer]:
    """The server named by VDA_TEST_DATABASE_URL, else a private one."""
    url = os.environ.get("VDA_TEST_DATABASE_URL")
    if url:
        yield PostgresServer(make_url(url))
        return
    with run_postgres() as server:
        yield server


def _in_a_thread(work: Callable[[], Coroutine[object, object, None]]) -> None:
    """Run async admin work on its own event loop in a helper thread, so that it works from
    sync fixtures whether or not a test's event loop is running."""
    with ThreadPoolExecutor(1) as pool:
        pool.submit(asyncio.run, work()).result()


async def _admin(server: PostgresServer, statement: str) -> None:
    engine = create_async_engine(
        server.admin_url.set(drivername="postgresql+asyncpg"), isolation_level="AUTOCOMMIT"
    )
    try:
        async with engine.connect() as connection:
            await connection.execute(text(statement))
    finally:
        await engine.dispose()


@contextlib.contextmanager
def session_database(server: PostgresServer) -> Iterator[str]:
    """A database of its own on ``server`` (its URL), dropped afterwards."""
    name = f"vda_test_{uuid.uuid4().hex[:16]}"
    assert re.fullmatch(r"[a-z0-9_]+", name)  # safe to put into DDL
    _in_a_thread(lambda: _admin(server, f"CREATE DATABASE {name}"))
    try:
        yield server.database_url(name)
    finally:
        _in_a_thread(lambda: _admin(server, f"DROP DATABASE IF EXISTS {name} WITH (FORCE)"))


async def empty_database(url: str) -> None:
    """Remove every table of the database at ``url`` (its ``public`` schema starts anew); much
    cheaper than a new database per test."""
    engine = create_async_engine(make_url(url).set(drivername="postgresql+asyncpg"))
    try:
        async with engine.begin() as connection:
            await connection.execute(text("DROP SCHEMA public CASCADE"))
            await connection.execute(text("CREATE SCHEMA public"))
    finally:
        await engine.dispose()
