"""What only the SQL store does: create the SQLite file, set its pragmas, name an unreachable
database clearly, and come back after a PostgreSQL restart (issue 10)."""

from __future__ import annotations

import asyncio
import sqlite3
import threading
from pathlib import Path

import pytest
from sqlalchemy import text

from tests.mosquitto import free_port
from tests.postgres import run_postgres, session_database
from vda_master.store import (
    HeaderCounter,
    SqlStore,
    StoreUnavailableError,
    StoreWriter,
    WriteBatch,
    WriterSettings,
    open_store,
    sql,
)
from vda_master.store.testing import make_event, make_order_record, make_vehicle_record

pytestmark = pytest.mark.integration


async def test_the_default_store_is_a_new_sqlite_file_in_a_new_data_dir(tmp_path: Path) -> None:
    """Without database_url the data_dir and master.sqlite3 are created, in WAL mode with full
    synchronous commits."""
    data_dir = tmp_path / "var" / "deeper"
    async with open_store(None, data_dir) as store:
        assert isinstance(store, SqlStore)
        async with store.engine.connect() as connection:
            journal = (await connection.execute(text("PRAGMA journal_mode"))).scalar()
            synchronous = (await connection.execute(text("PRAGMA synchronous"))).scalar()
    assert (data_dir / "master.sqlite3").is_file()
    assert journal == "wal"
    assert synchronous == 2  # FULL


async def test_sqlite_writes_store_every_field_of_every_record(tmp_path: Path) -> None:
    """The SQLite writer thread sends rows to the driver itself: every key of every row is a
    parameter of its statement (none dropped), and the rows read back as the records written,
    the same as through SQLAlchemy's own execute."""
    order = make_order_record(status="RUNNING", sent_update_id=3, cancel_action_id="c-1")
    event = make_event()
    vehicle = make_vehicle_record(connection_state="ONLINE", factsheet={"typeSpecification": {}})
    counter = HeaderCounter("acme", "robot_0", "state", 41)
    async with open_store(None, tmp_path) as store:
        driver = store._driver_writes
        assert driver is not None
        for statement, row in (
            (driver.orders, sql._order_row(order)),
            (driver.events, sql._event_row(event)),
            (driver.vehicles, sql._vehicle_row(vehicle)),
            (driver.counters, sql._counter_row(counter)),
        ):
            assert sorted(name for name, _ in statement.params) == sorted(row), statement.sql
        await store.write(
            WriteBatch(orders=(order,), events=(event,), vehicles=(vehicle,), counters=(counter,))
        )
        assert await store.get_order(order.order_id) == order
        assert await store.order_events(order.order_id) == (event,)
        assert await store.load_vehicles() == (vehicle,)
        assert await store.load_header_counters() == (counter,)


async def test_small_sqlite_writes_commit_on_the_loop_until_a_commit_is_slow(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Write-aheads in a burst are small: they commit on the event loop's own thread, big writes
    in the writer thread; once a commit takes longer than _INLINE_MAX_S (a slow disk), small
    writes go to the writer thread too, so the loop is not held up by the disk again (lever 50).
    Every record is stored whichever way it went."""
    threads: list[str] = []
    async with open_store(None, tmp_path) as store:
        write = store._write_sqlite

        def noting_thread(batch: WriteBatch, *, wait_for_locks: bool = True) -> None:
            threads.append(threading.current_thread().name)
            write(batch, wait_for_locks=wait_for_locks)

        monkeypatch.setattr(store, "_write_sqlite", noting_thread)
        small = WriteBatch(orders=(make_order_record("small-1"),), events=(make_event("small-1"),))
        big = WriteBatch(
            orders=tuple(make_order_record(f"big-{i}") for i in range(sql._INLINE_MAX_RECORDS + 1))
        )
        await store.write(small)
        await store.write(big)
        monkeypatch.setattr(sql, "_INLINE_MAX_S", 0.0)  # every commit is slow from here on
        await store.write(WriteBatch(orders=(make_order_record("small-2"),)))
        await store.write(WriteBatch(orders=(make_order_record("small-3"),)))
        stored = [await store.get_order(o) for o in ("small-1", "big-200", "small-2", "small-3")]
    loop_thread = threading.current_thread().name
    assert threads[0] == loop_thread
    assert threads[1].startswith("store-writer")
    assert threads[2] == loop_thread  # the slow one: measured inline
    assert threads[3].startswith("store-writer")
    assert all(record is not None for record in stored)


async def test_a_database_locked_by_another_connection_never_stalls_the_loop(
    tmp_path: Path,
) -> None:
    """Another connection holds SQLite's write lock for 0.5 s: the small write does not wait for
    it on the event loop (which keeps running: no gap over 0.2 s) but in the writer thread,
    and is stored once the lock is gone; small writes then go through the thread for a
    while (lever 50)."""
    async with open_store(None, tmp_path) as store:
        await store.write(WriteBatch(orders=(make_order_record("before"),)))  # tables in place
        other = sqlite3.connect(
            tmp_path / "master.sqlite3", isolation_level=None, check_same_thread=False
        )
        other.execute("BEGIN IMMEDIATE")
        threading.Timer(0.5, other.rollback).start()
        gaps: list[float] = []

        async def ticking() -> None:
            loop = asyncio.get_running_loop()
            last = loop.time()
            while True:
                await asyncio.sleep(0.01)
                now = loop.time()
                gaps.append(now - last)
                last = now

        ticker = asyncio.create_task(ticking())
        started = asyncio.get_running_loop().time()
        await store.write(WriteBatch(orders=(make_order_record("locked-out"),)))
        waited = asyncio.get_running_loop().time() - started
        ticker.cancel()
        other.close()
        assert await store.get_order("locked-out") is not None
        assert store._inline_after > 0  # paused: the next small writes use the thread
    assert waited >= 0.4  # it did wait for the lock ...
    assert max(gaps) < 0.2  # ... but not on the loop


async def test_a_data_dir_that_cannot_be_created_is_a_clear_error(tmp_path: Path) -> None:
    """A data_dir below a plain file fails to open, naming the path."""
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    with pytest.raises(StoreUnavailableError, match=str(blocker / "sub")):
        async with open_store(None, blocker / "sub"):
            pass


async def test_an_unreachable_postgresql_names_host_and_port(tmp_path: Path) -> None:
    """Opening a PostgreSQL store where nothing listens fails fast, saying where it looked."""
    port = free_port()
    url = f"postgresql://vda:secret@127.0.0.1:{port}/fleet"
    with pytest.raises(StoreUnavailableError, match=f"127.0.0.1:{port}/fleet") as caught:
        async with asyncio.timeout(10), open_store(url, tmp_path, connect_timeout_s=2):
            pass
    assert "secret" not in str(caught.value)


@pytest.mark.postgres
async def test_the_writer_rides_out_a_postgresql_restart(tmp_path: Path) -> None:
    """Records submitted while PostgreSQL is down are written once it is back, through the same
    store (its connection pool recovers)."""
    settings = WriterSettings(flush_interval_s=0.01, retry_initial_s=0.05, retry_max_s=0.2)
    with run_postgres() as server, session_database(server) as url:
        async with open_store(url, tmp_path, connect_timeout_s=2) as store:
            writer = StoreWriter(store, settings)
            await writer.write_ahead(WriteBatch(orders=(make_order_record(),)), timeout_s=5)
            await asyncio.to_thread(server.stop)
            with pytest.raises(StoreUnavailableError, match=f"127.0.0.1:{server.admin_url.port}"):
                await store.get_order("order-1")
            writer.submit(WriteBatch(events=(make_event(event="during-outage"),)))
            with pytest.raises(StoreUnavailableError):
                await writer.flush(timeout_s=0.3)
            await asyncio.to_thread(server.start)
            await writer.flush(timeout_s=10)
            await writer.close()
            assert [e.event for e in await store.order_events("order-1")] == ["during-outage"]
