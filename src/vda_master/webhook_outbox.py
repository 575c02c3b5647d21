"""Keeping webhook events in the store until they are delivered (docs/master.md, *Webhooks*),
so that a restart of master control, or a crash, loses none that a receiver had not taken.

Events are delivered from memory as before; this keeper writes them to the store behind the
delivery, in one transaction every :data:`FLUSH_INTERVAL_S` at most: the events emitted since
the last write, the (url, eventId) pairs delivered or dropped since (an event done before it
was written is never written), and the last eventId given out. A crash loses at most the events
of that last interval; an event delivered whose deletion was not yet written is sent again after
a restart (a receiver can tell by its eventId). A store that fails keeps everything pending in
memory and is tried again at the next interval, logged once per outage; a write the store
refuses for its data is logged and not tried again (those events still go out from memory).
"""

from __future__ import annotations

import asyncio
from typing import Final

import structlog

from vda5050.clock import Clock
from vda_master.store.errors import StoreError, StoreWriteRejectedError
from vda_master.store.interface import Store
from vda_master.store.records import WebhookRecord

log = structlog.get_logger()

#: Seconds between two writes at most while events come and go.
FLUSH_INTERVAL_S: Final = 0.2

EventKey = tuple[str, int]


class OutboxKeeper:
    """What the store should hold of the webhook events, and the loop that writes it."""

    def __init__(self, store: Store, clock: Clock, last_event_id: int) -> None:
        self._store = store
        self._clock = clock
        self._unsaved: dict[EventKey, WebhookRecord] = {}
        self._done: list[EventKey] = []
        #: The events of the write under way: one done meanwhile must still be forgotten.
        self._in_flight: set[EventKey] = set()
        self._last_event_id = last_event_id
        self._dirty = asyncio.Event()
        self._failing = False

    @property
    def pending(self) -> int:
        """Events and completions not yet written."""
        return len(self._unsaved) + len(self._done)

    def added(self, url: str, event_id: int, body: bytes) -> None:
        """An event for ``url`` was emitted."""
        record = WebhookRecord(url, event_id, body.decode(), self._clock.now())
        self._unsaved[record.key] = record
        self._last_event_id = max(self._last_event_id, event_id)
        self._dirty.set()

    def done(self, url: str, event_id: int) -> None:
        """The event was delivered to ``url``, or dropped: the store may forget it."""
        key = (url, event_id)
        if key not in self._in_flight and self._unsaved.pop(key, None) is not None:
            return  # never written: nothing to forget
        self._done.append(key)
        self._dirty.set()

    async def run(self) -> None:
        """Write what is pending, every :data:`FLUSH_INTERVAL_S` at most, until cancelled."""
        while True:
            await self._dirty.wait()
            await asyncio.sleep(FLUSH_INTERVAL_S)
            await self.flush()

    async def flush(self) -> None:
        """Write what is pending now; on a store error keep it for the next time. What is
        pending is taken off only once written, so a cancelled write loses nothing."""
        self._dirty.clear()
        if not self.pending:
            return
        added = list(self._unsaved.values())
        done = list(self._done)
        self._in_flight = {r.key for r in added}
        try:
            await self._store.save_webhook_events(added, done, self._last_event_id)
        except StoreWriteRejectedError as exc:
            # The data itself was refused: trying again cannot help. The events still go out
            # from memory; they are only not kept across a restart.
            log.warning("webhook.not_kept", error=str(exc), events=len(added), done=len(done))
        except StoreError as exc:
            self._dirty.set()
            if not self._failing:
                self._failing = True
                log.warning("webhook.store_failed", error=str(exc), pending=self.pending)
            return
        finally:
            self._in_flight = set()
        for record in added:
            if self._unsaved.get(record.key) is record:
                del self._unsaved[record.key]
        del self._done[: len(done)]
        if self._failing:
            self._failing = False
            log.info("webhook.store_recovered")
