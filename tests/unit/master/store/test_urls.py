"""Which database a database_url names (issue 10: SQLite by default, PostgreSQL by URL)."""

from __future__ import annotations

from pathlib import Path

import pytest

from vda5050.errors import ConfigError
from vda_master.store import resolve_database_url
from vda_master.store.urls import Backend


def test_no_url_means_the_sqlite_file_in_the_data_dir() -> None:
    """Without database_url the store is <data_dir>/master.sqlite3 on aiosqlite."""
    for unset in (None, "", "  "):
        target = resolve_database_url(unset, Path("var"))
        assert target.backend == Backend.SQLITE
        assert target.sqlite_path == Path("var/master.sqlite3")
        assert target.url.drivername == "sqlite+aiosqlite"
        assert target.url.database == "var/master.sqlite3"


@pytest.mark.parametrize(
    ("url", "path"),
    [("sqlite:///rel/m.db", "rel/m.db"), ("sqlite:////abs/m.db", "/abs/m.db")],
)
def test_sqlite_urls_name_a_file(url: str, path: str) -> None:
    """sqlite:/// URLs follow SQLAlchemy: three slashes relative, four absolute."""
    target = resolve_database_url(url, Path("ignored"))
    assert target.sqlite_path == Path(path)
    assert target.where == path


@pytest.mark.parametrize("scheme", ["postgresql", "postgres", "postgresql+asyncpg"])
def test_postgresql_urls_use_the_async_driver(scheme: str) -> None:
    """Every PostgreSQL spelling maps to asyncpg; the description never shows the password."""
    target = resolve_database_url(f"{scheme}://vda:s3cret@db.local:6543/fleet", Path("var"))
    assert target.backend == Backend.POSTGRESQL
    assert target.url.drivername == "postgresql+asyncpg"
    assert (target.url.username, target.url.password) == ("vda", "s3cret")
    assert target.where == "db.local:6543/fleet"


def test_postgresql_without_host_or_port_names_the_defaults() -> None:
    """A URL without host and port describes itself as localhost:5432."""
    assert resolve_database_url("postgresql:///fleet", Path()).where == "localhost:5432/fleet"


@pytest.mark.parametrize(
    ("url", "complaint"),
    [
        ("mysql://u:p@h/db", "scheme 'mysql' is not supported"),
        ("not a url", "is not a database URL"),
        ("postgresql://u:topsecret@h:port/db", "is not a database URL"),
        ("postgresql://u:p@h:5432", "needs a database name"),
        ("postgresql://u:p@h:70000/db", "port 70000 is out of range"),
        ("sqlite://", "needs a file path"),
        ("sqlite:///:memory:", "needs a file path"),
        ("sqlite://host/file.db", "names a file, not a host"),
    ],
)
def test_bad_urls_are_config_errors(url: str, complaint: str) -> None:
    """A URL the store cannot use fails at start-up with a message saying why and what works,
    without echoing a password."""
    with pytest.raises(ConfigError, match=complaint) as caught:
        resolve_database_url(url, Path("var"))
    assert "postgresql://user:password@host:port/database" in str(caught.value) or (
        "out of range" in complaint
    )
    assert "topsecret" not in str(caught.value)
