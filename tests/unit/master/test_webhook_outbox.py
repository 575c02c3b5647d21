"""Webhook events kept in the store until delivered (docs/master.md, *Webhooks*): what the
keeper writes, when, and what it does when the store fails."""

from __future__ import annotations

import asyncio
from collections.abc import Sequence

from structlog.testing import capture_logs

from vda5050.clock import FakeClock
from vda_master.config import MasterConfig
from vda_master.store import MemoryStore, WebhookOutbox, WebhookRecord
from vda_master.store.errors import StoreUnavailableError, StoreWriteRejectedError
from vda_master.webhook_events import order_event
from vda_master.webhook_outbox import OutboxKeeper
from vda_master.webhooks import Webhooks

URL = "http://wms.example/events"


class FlakyStore(MemoryStore):
    """A memory store whose webhook writes fail while ``failure`` is set, and that can hold a
    write open until ``release`` is set."""

    def __init__(self) -> None:
        super().__init__()
        self.failure: Exception | None = None
        self.release: asyncio.Event | None = None
        self.saves = 0

    async def save_webhook_events(
        self,
        added: Sequence[WebhookRecord],
        done: Sequence[tuple[str, int]],
        last_event_id: int,
    ) -> None:
        self.saves += 1
        if self.release is not None:
            await self.release.wait()
        if self.failure is not None:
            raise self.failure
        await super().save_webhook_events(added, done, last_event_id)


def _ids(outbox: WebhookOutbox) -> list[int]:
    return [r.event_id for r in outbox.events]


async def test_an_event_done_before_it_was_written_is_never_written() -> None:
    store = FlakyStore()
    keeper = OutboxKeeper(store, FakeClock(), 0)
    keeper.added(URL, 1, b'{"eventId": 1}')
    keeper.added(URL, 2, b'{"eventId": 2}')
    keeper.done(URL, 1)
    await keeper.flush()
    outbox = await store.load_webhook_outbox()
    assert (_ids(outbox), outbox.last_event_id) == ([2], 2)
    assert outbox.events[0].body == '{"eventId": 2}'
    keeper.done(URL, 2)
    await keeper.flush()
    assert await store.load_webhook_outbox() == WebhookOutbox((), 2)
    await keeper.flush()  # nothing pending: no write
    assert store.saves == 2


async def test_an_event_done_while_its_write_is_under_way_is_forgotten_next() -> None:
    store = FlakyStore()
    store.release = asyncio.Event()
    keeper = OutboxKeeper(store, FakeClock(), 0)
    keeper.added(URL, 1, b"{}")
    writing = asyncio.create_task(keeper.flush())
    await asyncio.sleep(0)
    keeper.done(URL, 1)  # delivered while the write is under way
    store.release.set()
    await writing
    assert _ids(await store.load_webhook_outbox()) == [1]
    await keeper.flush()
    assert _ids(await store.load_webhook_outbox()) == []
    assert keeper.pending == 0


async def test_a_failing_store_keeps_everything_for_the_next_write_logged_once() -> None:
    store = FlakyStore()
    store.failure = StoreUnavailableError("cannot keep webhook events: database is locked")
    keeper = OutboxKeeper(store, FakeClock(), 0)
    with capture_logs() as logs:
        keeper.added(URL, 1, b"{}")
        await keeper.flush()
        keeper.added(URL, 2, b"{}")
        keeper.done(URL, 1)  # never written: forgotten without a write
        await keeper.flush()
        store.failure = None
        await keeper.flush()
    assert _ids(await store.load_webhook_outbox()) == [2]
    assert keeper.pending == 0
    events = [e["event"] for e in logs]
    assert events == ["webhook.store_failed", "webhook.store_recovered"]


async def test_a_write_the_store_refuses_is_not_tried_again() -> None:
    store = FlakyStore()
    store.failure = StoreWriteRejectedError("the database refused to keep webhook events")
    keeper = OutboxKeeper(store, FakeClock(), 0)
    keeper.added(URL, 1, b"{}")
    with capture_logs() as logs:
        await keeper.flush()
    assert [e["event"] for e in logs] == ["webhook.not_kept"]
    assert keeper.pending == 0


async def test_webhooks_take_up_what_an_earlier_run_kept_and_go_on_counting() -> None:
    """The events an earlier run kept are queued first with their ids and bodies; those for a
    receiver no longer configured are forgotten; new events go on after the last eventId."""
    store = MemoryStore()
    old_url = "http://gone.example/events"
    earlier = Webhooks(MasterConfig.model_validate({"webhook_urls": [URL, old_url]}), FakeClock())
    await earlier.attach(store)
    for n in range(3):
        earlier.emit(order_event(f"o{n}", "SENT", None, None, None))
    await earlier.close()
    assert len((await store.load_webhook_outbox()).events) == 6

    later = Webhooks(MasterConfig.model_validate({"webhook_urls": [URL]}), FakeClock())
    with capture_logs() as logs:
        await later.attach(store)
    later.emit(order_event("o3", "SENT", None, None, None))
    assert later.queued() == 4
    await later.close()
    outbox = await store.load_webhook_outbox()
    assert [(r.url, r.event_id) for r in outbox.events] == [(URL, n) for n in (1, 2, 3, 4)]
    assert outbox.last_event_id == 4
    forgotten = next(e for e in logs if e["event"] == "webhook.forgotten")
    assert (forgotten["events"], forgotten["urls"]) == (3, [old_url])
