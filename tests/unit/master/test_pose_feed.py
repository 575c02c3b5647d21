"""The master's visualization subscription follows the live map's open streams, with a grace
period after the last one closes so that a reload does not flap."""

from __future__ import annotations

import asyncio

from structlog.testing import capture_logs

from vda_master.live import LiveView
from vda_master.pose_feed import PoseFeed

FILTERS = ("uagv/v2/+/+/visualization", "vda5050/v3/+/+/visualization")


class FakeSession:
    """Records set_subscribed calls."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, bool]] = []

    def set_subscribed(self, topic_filter: str, *, subscribed: bool) -> None:
        self.calls.append((topic_filter, subscribed))


def wired(grace_s: float) -> tuple[LiveView, PoseFeed, FakeSession]:
    session = FakeSession()
    feed = PoseFeed(session, FILTERS, grace_s=grace_s)
    live = LiveView()
    live.on_readers_changed = feed.readers_changed
    return live, feed, session


async def test_the_first_stream_subscribes_both_filters_at_once() -> None:
    """Opening the first stream subscribes the v2 and v3 filters; a second stream changes
    nothing."""
    live, feed, session = wired(grace_s=0.05)
    assert not feed.subscribed
    with capture_logs() as logs:
        live.subscribe()
        live.subscribe()
    assert feed.subscribed
    assert session.calls == [(FILTERS[0], True), (FILTERS[1], True)]
    assert [entry["event"] for entry in logs] == ["visualization.subscribed"]


async def test_the_subscription_ends_a_grace_period_after_the_last_stream() -> None:
    """Closing one of two streams keeps the subscription; closing the last ends it only after
    the grace period."""
    live, feed, session = wired(grace_s=0.05)
    first, second = live.subscribe(), live.subscribe()
    live.unsubscribe(first)
    live.unsubscribe(second)
    assert feed.subscribed
    await asyncio.sleep(0.02)
    assert feed.subscribed
    await asyncio.sleep(0.06)
    assert not feed.subscribed
    assert session.calls[2:] == [(FILTERS[0], False), (FILTERS[1], False)]


async def test_a_reload_within_the_grace_period_does_not_flap() -> None:
    """A stream that closes and reopens within the grace period (a page reload) keeps the
    subscription without unsubscribing and subscribing again."""
    live, feed, session = wired(grace_s=0.05)
    live.unsubscribe(live.subscribe())
    await asyncio.sleep(0.02)
    reader = live.subscribe()
    await asyncio.sleep(0.06)
    assert feed.subscribed
    assert len(session.calls) == len(FILTERS)
    live.unsubscribe(reader)
    await asyncio.sleep(0.08)
    assert not feed.subscribed


async def test_closing_the_feed_stops_it_from_changing_anything() -> None:
    """When the master stops, streams that end afterwards leave the session alone."""
    live, feed, session = wired(grace_s=0.01)
    reader = live.subscribe()
    feed.close()
    live.unsubscribe(reader)
    await asyncio.sleep(0.03)
    assert session.calls == [(FILTERS[0], True), (FILTERS[1], True)]


def test_the_live_view_tells_the_number_of_readers() -> None:
    """on_readers_changed hears every change of the number of open streams, and only those."""
    live = LiveView()
    counts: list[int] = []
    live.on_readers_changed = counts.append
    first = live.subscribe()
    second = live.subscribe()
    live.unsubscribe(first)
    live.unsubscribe(first)  # already gone: no change
    live.unsubscribe(second)
    assert counts == [1, 2, 1, 0]
