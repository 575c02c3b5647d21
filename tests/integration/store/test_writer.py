"""The store writer's batching, write-ahead and failure behaviour, on a store that can be made
unavailable, slow or refusing (issue 10: never block, never crash, never lose data silently)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable, MutableMapping
from contextlib import asynccontextmanager
from dataclasses import replace
from typing import Any

import pytest
from structlog.testing import capture_logs

from vda_master.store import (
    MemoryStore,
    StoreUnavailableError,
    StoreWriter,
    StoreWriteRejectedError,
    WriteBatch,
    WriterSettings,
)
from vda_master.store.testing import at, make_event, make_order_record


def fast_retry(flush_interval_s: float = 0.05, max_pending_events: int = 100_000) -> WriterSettings:
    """Settings that retry every 10-20 ms."""
    return WriterSettings(
        flush_interval_s=flush_interval_s,
        max_pending_events=max_pending_events,
        retry_initial_s=0.01,
        retry_max_s=0.02,
    )


class FlakyStore(MemoryStore):
    """A memory store that can be down (every write fails) or held (writes wait)."""

    def __init__(self) -> None:
        super().__init__()
        self.down: str | None = None
        self.held = asyncio.Event()
        self.held.set()
        self.attempts = 0
        self.write_started = asyncio.Event()

    async def write(self, batch: WriteBatch) -> None:
        self.attempts += 1
        self.write_started.set()
        await self.held.wait()
        if self.down is not None:
            raise StoreUnavailableError(self.down)
        await super().write(batch)


async def eventually(condition: Callable[[], bool], timeout_s: float = 5.0) -> None:
    async with asyncio.timeout(timeout_s):
        while not condition():
            await asyncio.sleep(0.005)


@asynccontextmanager
async def running(writer: StoreWriter) -> AsyncIterator[asyncio.Task[None]]:
    """The writer's flush loop running as a task; closed (and the loop ended) afterwards."""
    async with asyncio.TaskGroup() as tg:
        loop = tg.create_task(writer.flush_loop(), name="test.store_flush_loop")
        try:
            yield loop
        finally:
            await writer.close(timeout_s=1)


def _events(logs: list[MutableMapping[str, Any]], name: str) -> list[MutableMapping[str, Any]]:
    return [entry for entry in logs if entry["event"] == name]


async def test_submitted_batches_share_one_transaction_within_the_interval() -> None:
    """Batches submitted together are merged, the later order version winning, and written
    within the flush interval."""
    store = FlakyStore()
    writer = StoreWriter(store, WriterSettings(flush_interval_s=0.05))
    async with running(writer):
        loop_time = asyncio.get_running_loop().time
        start = loop_time()
        writer.submit(WriteBatch(orders=(make_order_record(status="SENT"),)))
        writer.submit(WriteBatch(events=(make_event(),)))
        writer.submit(WriteBatch(orders=(make_order_record(status="ACCEPTED", updated_at=at(1)),)))
        await eventually(lambda: store.writes > 0)
        elapsed = loop_time() - start
        assert elapsed < 0.5
        assert store.writes == 1
    stored = await store.get_order("order-1")
    assert stored is not None
    assert stored.status == "ACCEPTED"
    assert len(await store.order_events("order-1")) == 1


async def test_many_queued_records_are_written_without_waiting_for_the_interval() -> None:
    """Reaching flush_at_records writes at once, even with a long flush interval."""
    store = FlakyStore()
    writer = StoreWriter(store, WriterSettings(flush_interval_s=60, flush_at_records=10))
    async with running(writer):
        for i in range(10):
            writer.submit(WriteBatch(events=(make_event(event=f"e{i}"),)))
        await eventually(lambda: store.writes > 0, timeout_s=2)
    assert len(await store.order_events("order-1")) == 10


async def test_write_ahead_returns_once_its_batch_and_earlier_ones_are_committed() -> None:
    """write_ahead commits what was queued before it and its own batch, in one transaction."""
    store = FlakyStore()
    writer = StoreWriter(store, WriterSettings(flush_interval_s=60))
    async with running(writer):
        writer.submit(WriteBatch(events=(make_event(event="queued"),)))
        await writer.write_ahead(WriteBatch(orders=(make_order_record(),)), timeout_s=5)
        assert await store.get_order("order-1") is not None
        assert [e.event for e in await store.order_events("order-1")] == ["queued"]
        assert store.writes == 1
        assert writer.pending_records == 0


async def _burst(
    store: FlakyStore, writer: StoreWriter, queued: WriteBatch, ahead: WriteBatch
) -> None:
    """A write-ahead of ``ahead`` that comes while another write is in progress (a burst of
    orders), with ``queued`` submitted meanwhile; returns once the write-ahead is committed."""
    store.held.clear()
    writer.submit(WriteBatch(events=(make_event("other", event="earlier"),)))
    first = asyncio.create_task(writer.flush())
    await store.write_started.wait()
    writer.submit(queued)
    write_ahead = asyncio.create_task(writer.write_ahead(ahead, timeout_s=5))
    await asyncio.sleep(0.01)
    store.held.set()
    await first
    await write_ahead


async def test_write_aheads_queued_behind_a_write_go_first_and_the_rest_follows() -> None:
    """In a burst the write-ahead is committed in a transaction of its own, so the order goes
    out before the records queued with it are written (lever 50); those follow once no
    write-ahead waits, and nothing is lost."""
    store = FlakyStore()
    writer = StoreWriter(store, WriterSettings(flush_interval_s=60))
    async with running(writer):
        queued = WriteBatch(events=(make_event("order-0", event="queued"),))
        await _burst(store, writer, queued, WriteBatch(orders=(make_order_record(),)))
        assert await store.get_order("order-1") is not None
        assert await store.order_events("order-0") == ()
        assert store.writes == 2
        await writer.flush()
        assert [e.event for e in await store.order_events("order-0")] == ["queued"]
        assert store.writes == 3


async def test_queued_records_wait_behind_write_aheads_at_most_queued_wait_max_s() -> None:
    """Records that have waited queued_wait_max_s go with the next write-ahead even in a
    burst (here at once: 0 s)."""
    store = FlakyStore()
    writer = StoreWriter(store, WriterSettings(flush_interval_s=60, queued_wait_max_s=0.0))
    async with running(writer):
        queued = WriteBatch(events=(make_event("order-0", event="queued"),))
        await _burst(store, writer, queued, WriteBatch(orders=(make_order_record(),)))
        assert [e.event for e in await store.order_events("order-0")] == ["queued"]
        assert store.writes == 2


async def test_an_older_queued_version_never_overwrites_a_write_ahead() -> None:
    """An order's record queued before its write-ahead (e.g. a status change before a re-plan)
    and left behind by the burst is not written after the write-ahead's newer record."""
    store = FlakyStore()
    writer = StoreWriter(store, WriterSettings(flush_interval_s=60))
    async with running(writer):
        older = WriteBatch(orders=(make_order_record(status="RUNNING"),))
        newer = WriteBatch(orders=(make_order_record(status="SENT", update_id=1),))
        await _burst(store, writer, older, newer)
        await writer.flush()
    stored = await store.get_order("order-1")
    assert stored is not None
    assert (stored.status, stored.update_id) == ("SENT", 1)


async def test_write_ahead_and_flush_work_without_the_loop() -> None:
    """Without a running flush loop, write_ahead and flush write by themselves."""
    store = FlakyStore()
    writer = StoreWriter(store)
    await writer.write_ahead(WriteBatch(orders=(make_order_record(),)))
    writer.submit(WriteBatch(events=(make_event(),)))
    await writer.flush()
    assert await store.get_order("order-1") is not None
    assert len(await store.order_events("order-1")) == 1


async def test_an_outage_keeps_the_records_logs_once_and_recovers() -> None:
    """While the database is down records stay queued, one ERROR names the reason, and after
    recovery everything is written and the recovery is logged."""
    store = FlakyStore()
    store.down = "connection refused by db:5432"
    writer = StoreWriter(store, fast_retry(flush_interval_s=0.01))
    with capture_logs() as logs:
        async with running(writer):
            for i in range(5):
                writer.submit(WriteBatch(events=(make_event(event=f"e{i}", time=at(i)),)))
                await asyncio.sleep(0.01)
            await eventually(lambda: store.attempts >= 5)
            assert writer.unavailable_reason == "connection refused by db:5432"
            assert writer.pending_records == 5
            store.down = None
            await writer.flush(timeout_s=2)
    assert [e.event for e in await store.order_events("order-1")] == [f"e{i}" for i in range(5)]
    failed = _events(logs, "store.write_failed")
    assert len(failed) == 1
    assert failed[0]["log_level"] == "error"
    assert failed[0]["reason"] == "connection refused by db:5432"
    recovered = _events(logs, "store.recovered")
    assert len(recovered) == 1
    failed_attempts = recovered[0]["failed_attempts"]
    assert isinstance(failed_attempts, int)
    assert failed_attempts >= 5
    assert recovered[0]["dropped_events"] == 0


async def test_write_ahead_times_out_in_an_outage_and_its_batch_is_written_later() -> None:
    """A write-ahead that cannot commit in time raises StoreUnavailableError naming the reason;
    its batch stays queued and is written once the database is back."""
    store = FlakyStore()
    store.down = "server closed the connection"
    writer = StoreWriter(store, fast_retry())
    async with running(writer):
        with pytest.raises(StoreUnavailableError, match="server closed the connection"):
            await writer.write_ahead(WriteBatch(orders=(make_order_record(),)), timeout_s=0.1)
        store.down = None
        await writer.flush(timeout_s=2)
    assert await store.get_order("order-1") is not None


async def test_beyond_the_bound_the_oldest_queued_events_are_dropped_and_said_so() -> None:
    """Past max_pending_events the oldest queued events go, with an ERROR naming their orders;
    orders are kept, and the recovery line counts what was dropped."""
    store = FlakyStore()
    store.down = "disk full"
    settings = fast_retry(flush_interval_s=0.01, max_pending_events=5)
    writer = StoreWriter(store, settings)
    with capture_logs() as logs:
        async with running(writer):
            writer.submit(WriteBatch(orders=(make_order_record("kept"),)))
            for i in range(8):
                writer.submit(WriteBatch(events=(make_event(f"o{i}", time=at(i)),)))
            store.down = None
            await writer.flush(timeout_s=2)
    assert await store.get_order("kept") is not None
    assert [len(await store.order_events(f"o{i}")) for i in range(8)] == [0, 0, 0, 1, 1, 1, 1, 1]
    dropped = _events(logs, "store.events_dropped")
    assert len(dropped) == 1
    assert dropped[0]["log_level"] == "error"
    assert dropped[0]["order_ids"] == ["o0"]
    recovered = _events(logs, "store.recovered")
    assert recovered[0]["dropped_events"] == 3
    assert recovered[0]["dropped_event_orders"] == ["o0", "o1", "o2"]


async def test_a_refused_record_is_dropped_and_the_others_are_written() -> None:
    """When the database refuses one record, the others of the merged batch are still written
    and the refused one is named in an ERROR."""
    store = FlakyStore()
    writer = StoreWriter(store, WriterSettings(flush_interval_s=0.01))
    poison = make_event("bad", event="poison", value=2**70)
    with capture_logs() as logs:
        async with running(writer):
            writer.submit(WriteBatch(orders=(make_order_record(),), events=(make_event(),)))
            writer.submit(WriteBatch(events=(poison,)))
            await writer.flush(timeout_s=2)
    assert await store.get_order("order-1") is not None
    assert len(await store.order_events("order-1")) == 1
    assert await store.order_events("bad") == ()
    dropped = _events(logs, "store.record_dropped")
    assert [d["record"] for d in dropped] == [["event", poison.event_id]]


async def test_write_ahead_of_a_refused_record_raises() -> None:
    """A caller of write_ahead learns that its own record was refused, not just logged."""
    store = FlakyStore()
    writer = StoreWriter(store)
    order = make_order_record(request={"huge": 2**70})
    with pytest.raises(StoreWriteRejectedError, match="order-1"):
        await writer.write_ahead(WriteBatch(orders=(order,), events=(make_event(),)))
    assert await store.get_order("order-1") is None
    assert len(await store.order_events("order-1")) == 1


async def test_close_writes_what_is_queued() -> None:
    """Closing the writer writes everything still queued, then ends the flush loop."""
    store = FlakyStore()
    writer = StoreWriter(store, WriterSettings(flush_interval_s=60))
    async with running(writer) as loop:
        writer.submit(WriteBatch(orders=(make_order_record(),)))
        await writer.close()
        await asyncio.wait_for(loop, 1)
    assert await store.get_order("order-1") is not None
    with pytest.raises(RuntimeError, match="closed"):
        writer.submit(WriteBatch(events=(make_event(),)))


async def test_close_in_an_outage_says_what_is_lost() -> None:
    """When the database stays down past close's timeout, an ERROR lists what was not written."""
    store = FlakyStore()
    store.down = "no route to host"
    writer = StoreWriter(store, fast_retry())
    writer.submit(WriteBatch(orders=(make_order_record(),), events=(make_event(),)))
    with capture_logs() as logs:
        await writer.close(timeout_s=0.1)
    lost = _events(logs, "store.writes_lost")
    assert len(lost) == 1
    assert lost[0]["orders"] == ["order-1"]
    assert lost[0]["events"] == 1
    assert lost[0]["reason"] == "no route to host"


async def test_a_write_cancelled_midway_is_queued_again() -> None:
    """Cancelling the flush loop in the middle of a write (shutdown) puts the batch back, and
    close then writes it."""
    store = FlakyStore()
    store.held.clear()
    writer = StoreWriter(store, WriterSettings(flush_interval_s=0.01))
    loop = asyncio.create_task(writer.flush_loop(), name="test.store_flush_loop")
    writer.submit(WriteBatch(orders=(make_order_record(),)))
    await asyncio.wait_for(store.write_started.wait(), 1)
    loop.cancel()
    with pytest.raises(asyncio.CancelledError):
        await loop
    assert writer.pending_records == 1
    store.held.set()
    await writer.close(timeout_s=1)
    assert await store.get_order("order-1") == replace(make_order_record())


def test_submit_needs_no_running_event_loop() -> None:
    """Synchronous code (the master's handlers, its sync unit tests) can submit, even past the
    event bound."""
    writer = StoreWriter(MemoryStore(), WriterSettings(max_pending_events=2))
    with capture_logs() as logs:
        for i in range(3):
            writer.submit(WriteBatch(events=(make_event(event=f"e{i}"),)))
    assert writer.pending_records == 2
    assert len(_events(logs, "store.events_dropped")) == 1
