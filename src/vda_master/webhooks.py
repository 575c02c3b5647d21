"""Delivering webhook events (:mod:`vda_master.webhook_events`) to each ``webhook_urls`` entry.

The service calls :meth:`Webhooks.emit` wherever an order's status, a vehicle's connection, its
errors or its safety chain change; it only stamps the event and appends it to each receiver's
queue, so a slow or dead receiver never holds up the fleet. One task per receiver
(:meth:`Webhooks.run`) POSTs its queue in order, one request at a time: a receiver sees the
events in the order they happened. A failed attempt (no answer within ``_TIMEOUT_S``, 5xx, 408,
425, 429) is tried again after 0.5 s, 1 s, 2 s, … up to 30 s, ``webhook_max_attempts`` times (0:
until delivered) in all; an answer that refuses the event (another 4xx) drops it at once. Either
is logged (``webhook.dropped``). A queue holds at most ``_QUEUE_LIMIT`` events; beyond that the
oldest go, logged (``webhook.overflow``). With a store attached (:meth:`Webhooks.attach`) every
event is also kept there until it is done (:mod:`vda_master.webhook_outbox`): what is queued
when master control stops goes out after the next start, with its eventId.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from collections import deque
from collections.abc import Awaitable, Callable

import httpx
import orjson
import structlog

from vda5050.clock import Clock, format_timestamp
from vda_master.config import MasterConfig
from vda_master.store.interface import Store
from vda_master.webhook_events import (
    EVENT_HEADER,
    SIGNATURE_HEADER,
    Event,
    Verdict,
    retry_delay,
    signature,
    stamped,
    verdict,
)
from vda_master.webhook_outbox import OutboxKeeper

log = structlog.get_logger()

#: Seconds a receiver has to answer one request.
_TIMEOUT_S = 5.0
#: Events one receiver's queue holds at most.
_QUEUE_LIMIT = 10_000


class _Receiver:
    """One URL: its queue and the event that wakes its sender."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.queue: deque[tuple[Event, bytes]] = deque()
        self.ready = asyncio.Event()
        self.dropped_for_overflow = 0


class Webhooks:
    """The receivers of ``config.webhook_urls``; without any, :meth:`emit` does nothing."""

    def __init__(
        self,
        config: MasterConfig,
        clock: Clock,
        *,
        sleep: Callable[[float], Awaitable[object]] | None = None,
    ) -> None:
        self._receivers = [_Receiver(url) for url in config.webhook_urls]
        self._secret = config.webhook_secret
        self._attempts = config.webhook_max_attempts
        self._clock = clock
        self._ids = itertools.count(1)
        #: Keeps the events in the store until they are done (:meth:`attach`); None: memory only.
        self._keeper: OutboxKeeper | None = None
        #: Waits between attempts (tests pass a faster one).
        self._sleep = sleep or asyncio.sleep
        #: Set whenever a sender empties its queue (:meth:`drain` checks them all then).
        self._idle = asyncio.Event()
        #: Events delivered and dropped (refused, out of attempts, overflow), over all
        #: receivers, since the start (``GET /metrics``).
        self.delivered = 0
        self.dropped = 0

    @property
    def enabled(self) -> bool:
        return bool(self._receivers)

    async def attach(self, store: Store) -> None:
        """Keep every event in ``store`` until it is delivered or dropped, and take up what an
        earlier run left there: its events for the receivers still configured are queued first
        (in their order, with their eventIds and bodies), those for receivers no longer
        configured are forgotten (logged), and eventIds go on after the last one given out.
        Call it before the first :meth:`emit`."""
        outbox = await store.load_webhook_outbox()
        self._ids = itertools.count(outbox.last_event_id + 1)
        receivers = {r.url: r for r in self._receivers}
        forgotten: list[tuple[str, int]] = []
        for record in outbox.events:
            receiver = receivers.get(record.url)
            if receiver is None:
                forgotten.append(record.key)
                continue
            body = record.body.encode()
            receiver.queue.append((orjson.loads(body), body))
            receiver.ready.set()
        if forgotten:
            log.warning(
                "webhook.forgotten",
                events=len(forgotten),
                urls=sorted({url for url, _ in forgotten}),
                why="no longer in webhook_urls",
            )
            await store.save_webhook_events((), forgotten, outbox.last_event_id)
        if outbox.events:
            log.info("webhook.resumed", events=len(outbox.events) - len(forgotten))
        if self._receivers:
            self._keeper = OutboxKeeper(store, self._clock, outbox.last_event_id)

    async def close(self) -> None:
        """Write what the store does not hold yet (at shutdown, after :meth:`drain`): the
        events still queued go out after the next start."""
        if self._keeper is not None:
            await self._keeper.flush()
            if self._keeper.pending:
                log.warning(
                    "webhook.not_kept", pending=self._keeper.pending, why="the store failed"
                )

    def emit(self, event: Event) -> None:
        """Stamp ``event`` and queue it for every receiver (never blocks, never raises)."""
        if not self._receivers:
            return
        event_id = next(self._ids)
        full = stamped(event, event_id, format_timestamp(self._clock.now()))
        body = orjson.dumps(full)
        keeper = self._keeper
        for receiver in self._receivers:
            if keeper is not None:
                keeper.added(receiver.url, event_id, body)
            if len(receiver.queue) >= _QUEUE_LIMIT:
                oldest, _ = receiver.queue.popleft()
                self._done(receiver, oldest)
                receiver.dropped_for_overflow += 1
                self.dropped += 1
                if receiver.dropped_for_overflow in {1, 100, 10_000}:  # not once per event
                    log.warning(
                        "webhook.overflow",
                        url=receiver.url,
                        dropped=receiver.dropped_for_overflow,
                        limit=_QUEUE_LIMIT,
                    )
            receiver.queue.append((full, body))
            receiver.ready.set()

    def queued(self) -> int:
        """Events waiting for delivery, over all receivers."""
        return sum(len(r.queue) for r in self._receivers)

    async def drain(self, timeout_s: float) -> None:
        """Wait until every queued event is delivered or dropped, ``timeout_s`` at most (at
        shutdown: the orders' last events still go out)."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                while self.queued():
                    self._idle.clear()
                    await self._idle.wait()

    async def run(self) -> None:
        """Deliver until cancelled: one sender per receiver (and the keeper's writes)."""
        if not self._receivers:
            return
        timeout = httpx.Timeout(_TIMEOUT_S)
        async with httpx.AsyncClient(timeout=timeout) as client, asyncio.TaskGroup() as group:
            for receiver in self._receivers:
                group.create_task(self._send_loop(client, receiver), name="master.webhooks")
            if self._keeper is not None:
                group.create_task(self._keeper.run(), name="master.webhook_outbox")

    def _done(self, receiver: _Receiver, event: Event) -> None:
        """``event`` was delivered to ``receiver`` or dropped: the store may forget it."""
        if self._keeper is not None:
            event_id = event["eventId"]
            assert isinstance(event_id, int)  # noqa: S101 - stamped() sets it
            self._keeper.done(receiver.url, event_id)

    async def _send_loop(self, client: httpx.AsyncClient, receiver: _Receiver) -> None:
        while True:
            if not receiver.queue:
                receiver.ready.clear()
                await receiver.ready.wait()
                continue
            event, body = receiver.queue[0]
            await self._deliver(client, receiver.url, event, body)
            if receiver.queue and receiver.queue[0][1] is body:  # unless overflow took it
                receiver.queue.popleft()
                self._done(receiver, event)
            if not receiver.queue:
                self._idle.set()

    async def _deliver(
        self, client: httpx.AsyncClient, url: str, event: Event, body: bytes
    ) -> None:
        headers = {"content-type": "application/json", EVENT_HEADER: str(event["type"])}
        if self._secret:
            headers[SIGNATURE_HEADER] = signature(self._secret, body)
        why = ""
        limit = self._attempts or None  # 0: until delivered
        for attempt in itertools.count(1):
            status, why = await _post(client, url, body, headers)
            outcome = verdict(status)
            if outcome is Verdict.DELIVERED:
                self.delivered += 1
                return
            if outcome is Verdict.REFUSED or attempt == limit:
                break
            await self._sleep(retry_delay(attempt))
        self.dropped += 1
        log.warning(
            "webhook.dropped",
            url=url,
            event_id=event["eventId"],
            type=event["type"],
            attempts=attempt,
            why=why,
        )


async def _post(
    client: httpx.AsyncClient, url: str, body: bytes, headers: dict[str, str]
) -> tuple[int | None, str]:
    """The answer's status (None: none came) and, when it is no 2xx, why in words."""
    try:
        response = await client.post(url, content=body, headers=headers)
    except httpx.HTTPError as exc:
        return None, f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    if 200 <= response.status_code < 300:  # noqa: PLR2004 - HTTP 2xx
        return response.status_code, ""
    return response.status_code, f"HTTP {response.status_code}: {response.text[:200]}"
