"""Delivering webhook events (:mod:`vda_master.webhook_events`) to each ``webhook_urls`` entry.

The service calls :meth:`Webhooks.emit` wherever an order's status, a vehicle's connection, its
errors or its safety chain change; it only stamps the event and appends it to each receiver's
queue, so a slow or dead receiver never holds up the fleet. One task per receiver
(:meth:`Webhooks.run`) POSTs its queue in order, one request at a time: a receiver sees the
events in the order they happened. A failed attempt (no answer within ``_TIMEOUT_S``, 5xx, 408,
425, 429) is tried again after 0.5 s, 1 s, 2 s, … up to 30 s, ``webhook_max_attempts`` times in
all; an answer that refuses the event (another 4xx) drops it at once. Either is logged
(``webhook.dropped``). A queue holds at most ``_QUEUE_LIMIT`` events; beyond that the oldest go,
logged (``webhook.overflow``). Events are kept in memory only: what is queued when master
control stops is lost, and a receiver that must not miss an order's end reads ``GET /orders``
after it was unreachable (every event's ``eventId`` shows a gap).
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

    def emit(self, event: Event) -> None:
        """Stamp ``event`` and queue it for every receiver (never blocks, never raises)."""
        if not self._receivers:
            return
        full = stamped(event, next(self._ids), format_timestamp(self._clock.now()))
        body = orjson.dumps(full)
        for receiver in self._receivers:
            if len(receiver.queue) >= _QUEUE_LIMIT:
                receiver.queue.popleft()
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
        """Deliver until cancelled: one sender per receiver."""
        if not self._receivers:
            return
        timeout = httpx.Timeout(_TIMEOUT_S)
        async with httpx.AsyncClient(timeout=timeout) as client, asyncio.TaskGroup() as group:
            for receiver in self._receivers:
                group.create_task(self._send_loop(client, receiver), name="master.webhooks")

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
            if not receiver.queue:
                self._idle.set()

    async def _deliver(
        self, client: httpx.AsyncClient, url: str, event: Event, body: bytes
    ) -> None:
        headers = {"content-type": "application/json", EVENT_HEADER: str(event["type"])}
        if self._secret:
            headers[SIGNATURE_HEADER] = signature(self._secret, body)
        why = ""
        for attempt in range(1, self._attempts + 1):
            status, why = await _post(client, url, body, headers)
            outcome = verdict(status)
            if outcome is Verdict.DELIVERED:
                self.delivered += 1
                return
            if outcome is Verdict.REFUSED:
                break
            if attempt < self._attempts:
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
