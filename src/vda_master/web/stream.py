"""The map's live stream: Server-Sent Events on ``GET /events`` (architecture §3.5).

A client first gets one ``snapshot`` event (graph, every vehicle, recent orders, traffic), then
``changes`` events holding only what changed: whole vehicles (a state, connection or factsheet
arrived), poses (a visualization arrived), vehicles the master forgot (``removed``), orders,
and the traffic snapshot when it changed.

Cost model. Nothing runs per message except :class:`vda_master.live.LiveView` adding a key to
each open stream's dirty set. A stream wakes on the first change, waits until ``flush_s`` has
passed since its previous event and sends everything pending as one event, so a client gets at
most ``1 / flush_s`` events per second whatever the message rate, and a vehicle that changed
five times in between is serialised once. Sending awaits the client's socket: while a slow
client drains, its dirty set coalesces further, and past ``vda_master.live.MAX_PENDING`` keys it
is dropped for a fresh snapshot, so memory stays bounded and the event loop never waits for it.

Traffic control has no change notifications yet: the snapshot is also re-read every
``TRAFFIC_POLL_S`` while a stream is open, and sent only when it differs from the last one sent.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncGenerator
from typing import Final

import orjson

from vda5050.topics import AgvId
from vda_master.live import Changes, Subscription
from vda_master.service import MasterService
from vda_master.web import payloads

#: Least time between two events of one stream (batching window), seconds.
FLUSH_S: Final = 0.05
#: How often the traffic snapshot is re-read while nothing notifies its changes, seconds.
TRAFFIC_POLL_S: Final = 1.0
#: A comment line after this much silence keeps proxies and the client's watchdog content.
KEEPALIVE_S: Final = 15.0
#: Orders in a snapshot (newest first).
RECENT_ORDERS: Final = 50


def sse(event: str, data: object) -> bytes:
    """One Server-Sent Event (the data is one line of JSON)."""
    return b"event: " + event.encode() + b"\ndata: " + orjson.dumps(data) + b"\n\n"


class MapStream:
    """One client's stream over ``service``; iterate :meth:`events` once."""

    def __init__(self, service: MasterService, *, flush_s: float = FLUSH_S) -> None:
        self.service = service
        self.flush_s = flush_s
        self._traffic_sent = b"null"
        self._traffic_read_at = 0.0

    async def events(self) -> AsyncGenerator[bytes, None]:
        """Snapshot, then batched changes until the client leaves or the master stops."""
        live = self.service.live
        reader = live.subscribe()
        try:
            yield self.snapshot()
            loop = asyncio.get_running_loop()
            last_event = loop.time()
            while not reader.closed:
                await _wait_ready(reader, TRAFFIC_POLL_S)
                delay = last_event + self.flush_s - loop.time()
                if delay > 0:
                    await asyncio.sleep(delay)
                if reader.closed:
                    break
                changes = live.drain(reader)
                event = self.snapshot() if changes.resync else self.changes(changes)
                if event is None and loop.time() - last_event >= KEEPALIVE_S:
                    event = b": keep-alive\n\n"
                if event is not None:
                    yield event
                    last_event = loop.time()
        finally:
            live.unsubscribe(reader)

    def snapshot(self) -> bytes:
        """Everything the page draws, from scratch."""
        service = self.service
        now, wall = service.clock.monotonic(), time.time()
        vehicles = [self._vehicle(v.agv, now, wall) for v in service.fleet]
        traffic = self._read_traffic()
        self._traffic_sent = traffic
        return sse(
            "snapshot",
            {
                "serverTime": round(wall * 1000.0, 1),
                "graph": payloads.graph_payload(service.graph),
                "vehicles": [v for v in vehicles if v is not None],
                "orders": self._recent_orders(),
                "traffic": orjson.Fragment(traffic),
            },
        )

    def _recent_orders(self) -> list[payloads.Json]:
        """The recent orders and every order waiting for a vehicle, newest first."""
        service = self.service
        orders = [
            *payloads.orders_payload(
                service.recent_orders(RECENT_ORDERS), service.active, service.expected_finish_utc
            ),
            *(payloads.queued_order_payload(q) for q in service.queue.values()),
        ]
        return sorted(orders, key=lambda o: str(o["createdAt"]), reverse=True)

    def changes(self, changes: Changes) -> bytes | None:
        """A ``changes`` event with what ``changes`` names, or None when nothing is to send."""
        service = self.service
        now, wall = service.clock.monotonic(), time.time()
        body: dict[str, object] = {}
        vehicles: list[payloads.Json] = []
        removed: list[str] = []  # forgotten by the master (forget_after_s)
        for agv in changes.vehicles:
            vehicle = self._vehicle(agv, now, wall)
            if vehicle is None:
                removed.append(payloads.vehicle_key(agv))
            else:
                vehicles.append(vehicle)
        if vehicles:
            body["vehicles"] = vehicles
        if removed:
            body["removed"] = removed
        poses = [
            payloads.pose_payload(agv, pose, service.live.received.get(agv))
            for agv in changes.poses
            if (pose := service.live.poses.get(agv)) is not None
        ]
        if poses:
            body["poses"] = poses
        orders = [track for o in changes.orders if (track := service.tracks.get(o)) is not None]
        queued = [
            payloads.queued_order_payload(entry)
            for o in changes.orders
            if o not in service.tracks and (entry := service.queued(o)) is not None
        ]
        if orders or queued:
            listed = payloads.orders_payload(orders, service.active, service.expected_finish_utc)
            body["orders"] = [*listed, *queued]
        traffic = self._traffic_if_changed(force=changes.traffic)
        if traffic is not None:
            body["traffic"] = orjson.Fragment(traffic)
        if not body:
            return None
        body["sent"] = round(time.time() * 1000.0, 1)  # lets the page split its latency
        return sse("changes", body)

    def _vehicle(self, agv: AgvId, now: float, wall: float) -> payloads.Json | None:
        service = self.service
        view = service.fleet.get(agv)
        if view is None:
            return None
        active = service.tracks.get(service.active.get(view.agv, ""))
        return payloads.vehicle_payload(
            view,
            pose=service.live.poses.get(view.agv),
            received=service.live.received.get(view.agv),
            active_order=active,
            settings=service.fleet_settings,
            now=now,
            wall_now=wall,
            out_of_service=service.out_of_service.get(agv),
            expected_finish=service.expected_finish_utc(active) if active else None,
            alarms=service.alarms.board.alarms_of(agv),
        )

    def _read_traffic(self) -> bytes:
        self._traffic_read_at = time.monotonic()
        return orjson.dumps(payloads.traffic_payload(self.service.traffic_snapshot()))

    def _traffic_if_changed(self, *, force: bool) -> bytes | None:
        if not force and time.monotonic() - self._traffic_read_at < TRAFFIC_POLL_S:
            return None
        traffic = self._read_traffic()
        if traffic == self._traffic_sent:
            return None
        self._traffic_sent = traffic
        return traffic


async def _wait_ready(reader: Subscription, timeout_s: float) -> None:
    """Until the reader has changes, or ``timeout_s`` passed (to re-read traffic)."""
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(timeout_s):
            await reader.ready.wait()
