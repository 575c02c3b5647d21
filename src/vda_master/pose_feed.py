"""Visualization only while someone looks: the master's ``visualization`` subscription follows
the live map's open streams.

The master reads ``visualization`` (§6.13, display only, typically 1 Hz per vehicle) for one
consumer: the poses of the live map's stream (:mod:`vda_master.web.stream`, through
:class:`vda_master.live.LiveView`). No rule, no GET endpoint and no stored record uses them; the
map's snapshot takes the newer of the last pose and the last state's ``agvPosition``
(:func:`vda_master.web.payloads.current_pose`). With a thousand vehicles that is a thousand
messages a second decoded for nobody while no map is open (~7 % of an idle master's CPU, see
docs/performance.md), so :class:`PoseFeed` subscribes to the visualization filters (``v2`` and
``v3``) when the first stream opens, and unsubscribes ``GRACE_S`` after the last one closed, so
reloading the page does not unsubscribe and subscribe again. A stream that opens meanwhile shows
state positions until the vehicles' next visualization arrives (within their visualization
interval).

The rule is small (subscribed while a stream is open or the last one closed less than
``GRACE_S`` ago); :class:`PoseFeed` holds the grace timer and tells the MQTT session.
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from typing import Final, Protocol

import structlog

log = structlog.get_logger()

#: Seconds the subscription outlives the last open stream (a reload reopens within this).
GRACE_S: Final = 10.0


class Subscriber(Protocol):
    """What the feed needs of the MQTT session (:class:`vda5050.mqtt.MqttSession`)."""

    def set_subscribed(self, topic_filter: str, *, subscribed: bool) -> None: ...


class PoseFeed:
    """Keeps ``filters`` subscribed while a stream is open and ``grace_s`` after the last one.

    Args:
        session: Subscribes and unsubscribes; the filters are registered there inactive.
        filters: The visualization filters (one per major version).
        grace_s: How long the subscription outlives the last stream.
    """

    def __init__(
        self, session: Subscriber, filters: Sequence[str], *, grace_s: float = GRACE_S
    ) -> None:
        self._session = session
        self._filters = tuple(filters)
        self.grace_s = grace_s
        self.subscribed = False
        self._timer: asyncio.TimerHandle | None = None
        self._closed = False

    def readers_changed(self, readers: int) -> None:
        """The number of open streams changed (called by the live view)."""
        if self._closed:
            return
        if readers > 0:
            self._cancel_timer()
            self._switch(on=True, readers=readers)
        elif self.subscribed and self._timer is None:
            self._timer = asyncio.get_running_loop().call_later(self.grace_s, self._expired)

    def close(self) -> None:
        """The master stops: no timer outlives it (streams that end later change nothing)."""
        self._closed = True
        self._cancel_timer()

    def _expired(self) -> None:
        self._timer = None
        self._switch(on=False, readers=0)

    def _switch(self, *, on: bool, readers: int) -> None:
        if self.subscribed == on:
            return
        self.subscribed = on
        for topic_filter in self._filters:
            self._session.set_subscribed(topic_filter, subscribed=on)
        event = "visualization.subscribed" if on else "visualization.unsubscribed"
        log.info(event, readers=readers, filters=len(self._filters))

    def _cancel_timer(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
