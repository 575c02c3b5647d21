"""The live side of the fleet view: latest poses from ``visualization`` and a change feed.

The master folds ``state``, ``connection`` and ``factsheet`` into its fleet view; for a live map it
also needs where each vehicle is between two states. :meth:`LiveView.observe_visualization` keeps
the latest pose per vehicle from the ``visualization`` topic (§6.13, display only, typically 1 Hz
per vehicle). It is on the master's hottest path, so it parses only ``agvPosition`` with orjson,
checks the four fields the map uses and stores one small tuple: no pydantic model, no copy of the
fleet view, no work that grows with the fleet.

The change feed tells readers (the map's live stream, :mod:`vda_master.web.stream`) *which*
vehicles and orders changed, not what changed: each reader holds a :class:`Subscription`, a set
of dirty keys it drains when it is ready to send. Notifying is O(readers) and coalesces repeats,
so a vehicle that publishes ten times between two flushes costs one entry. A reader that falls
behind cannot grow memory without bound: past ``max_pending`` keys its sets are dropped and it
is told to start over from a fresh snapshot (``resync``).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final

import orjson
import structlog

from vda5050.topics import AgvId

log = structlog.get_logger()

#: Dirty keys a reader may hold before it is told to resync from a snapshot.
MAX_PENDING: Final = 5_000


@dataclass(frozen=True, slots=True)
class Pose:
    """Where a vehicle was at monotonic time ``at``: metres and radians on ``map_id``."""

    x: float
    y: float
    theta: float
    map_id: str
    at: float


def parse_pose(payload: bytes, now: float) -> Pose | str:
    """The ``agvPosition`` (3.0: ``mobileRobotPosition``) of a visualization message, or why
    there is none to show."""
    try:
        message = orjson.loads(payload)
    except orjson.JSONDecodeError:
        return "not JSON"
    position = None
    if isinstance(message, dict):
        position = message.get("agvPosition") or message.get("mobileRobotPosition")
    if not isinstance(position, dict):
        return "no agvPosition"
    x, y, theta, map_id = (position.get(k) for k in ("x", "y", "theta", "mapId"))
    if not all(_is_number(v) for v in (x, y, theta)) or not isinstance(map_id, str):
        return "agvPosition lacks a numeric x, y, theta or a mapId"
    return Pose(float(x), float(y), float(theta), map_id, now)  # type: ignore[arg-type]


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


@dataclass(eq=False, slots=True)
class Subscription:
    """One reader's pending changes; drained by :meth:`LiveView.drain`."""

    vehicles: set[AgvId] = field(default_factory=set)
    #: Vehicles whose pose alone changed (a visualization message).
    poses: set[AgvId] = field(default_factory=set)
    orders: set[str] = field(default_factory=set)
    traffic: bool = False
    #: The reader fell behind: drop what it knows and send a snapshot.
    resync: bool = False
    closed: bool = False
    ready: asyncio.Event = field(default_factory=asyncio.Event)

    @property
    def pending(self) -> int:
        return len(self.vehicles) + len(self.poses) + len(self.orders)


@dataclass(frozen=True, slots=True)
class Changes:
    """What changed since a reader's last drain."""

    vehicles: frozenset[AgvId] = frozenset()
    poses: frozenset[AgvId] = frozenset()
    orders: frozenset[str] = frozenset()
    traffic: bool = False
    resync: bool = False


class LiveView:
    """Latest poses, receive stamps and the change feed of one master."""

    def __init__(
        self, *, wall: Callable[[], float] = time.time, max_pending: int = MAX_PENDING
    ) -> None:
        self.poses: dict[AgvId, Pose] = {}
        #: Wall time (epoch seconds) of the latest message folded in, per vehicle: the map
        #: measures from it how long a change takes to reach the screen.
        self.received: dict[AgvId, float] = {}
        self._wall = wall
        self._max_pending = max_pending
        self._readers: list[Subscription] = []
        self._warned: set[AgvId] = set()
        #: Told the number of readers whenever it changes (the master's visualization
        #: subscription follows it, vda_master.pose_feed).
        self.on_readers_changed: Callable[[int], None] | None = None

    # -- producers (the service) --------------------------------------------------------------

    def observe_visualization(self, agv: AgvId, payload: bytes, now: float) -> None:
        """Keep the pose of one visualization message; an unusable one is dropped (one warning
        per vehicle: at 1 Hz a line per message would flood the log)."""
        pose = parse_pose(payload, now)
        if isinstance(pose, str):
            if agv not in self._warned:
                self._warned.add(agv)
                log.warning("message.dropped", agv=str(agv), topic="visualization", reason=pose)
            return
        self.poses[agv] = pose
        self.received[agv] = self._wall()
        for reader in self._readers:
            reader.poses.add(agv)
            self._wake(reader)

    def vehicle_changed(self, agv: AgvId) -> None:
        """The vehicle's view changed (a state, connection or factsheet was folded in)."""
        self.received[agv] = self._wall()
        for reader in self._readers:
            reader.vehicles.add(agv)
            self._wake(reader)

    def forget(self, agv: AgvId) -> None:
        """The master forgot the vehicle: its pose goes, and readers are told (the stream
        lists it as removed, as it is in no fleet view any more)."""
        self.poses.pop(agv, None)
        self.received.pop(agv, None)
        self._warned.discard(agv)
        for reader in self._readers:
            reader.poses.discard(agv)
            reader.vehicles.add(agv)
            self._wake(reader)

    def order_changed(self, order_id: str) -> None:
        """An order track was created or changed."""
        for reader in self._readers:
            reader.orders.add(order_id)
            self._wake(reader)

    def traffic_changed(self) -> None:
        """Reservations or waits changed (traffic control calls this)."""
        for reader in self._readers:
            reader.traffic = True
            self._wake(reader)

    def graph_changed(self) -> None:
        """The graph's zones changed: every reader starts over from a snapshot (it holds the
        graph)."""
        for reader in self._readers:
            reader.vehicles.clear()
            reader.poses.clear()
            reader.orders.clear()
            reader.resync = True
            reader.ready.set()

    def _wake(self, reader: Subscription) -> None:
        if reader.pending > self._max_pending:
            reader.vehicles.clear()
            reader.poses.clear()
            reader.orders.clear()
            reader.resync = True
        reader.ready.set()

    # -- readers (the map stream) -------------------------------------------------------------

    def subscribe(self) -> Subscription:
        """A new reader; it starts from a snapshot, so nothing is pending yet."""
        reader = Subscription()
        self._readers.append(reader)
        self._readers_changed()
        return reader

    def unsubscribe(self, reader: Subscription) -> None:
        """Forget a reader (its stream ended)."""
        if reader in self._readers:
            self._readers.remove(reader)
            self._readers_changed()

    def _readers_changed(self) -> None:
        if self.on_readers_changed is not None:
            self.on_readers_changed(len(self._readers))

    @property
    def readers(self) -> int:
        return len(self._readers)

    def drain(self, reader: Subscription) -> Changes:
        """Take the reader's pending changes; pose-only entries of vehicles that also changed
        as a whole are folded into the latter."""
        changes = Changes(
            vehicles=frozenset(reader.vehicles),
            poses=frozenset(reader.poses - reader.vehicles),
            orders=frozenset(reader.orders),
            traffic=reader.traffic,
            resync=reader.resync,
        )
        reader.vehicles.clear()
        reader.poses.clear()
        reader.orders.clear()
        reader.traffic = reader.resync = False
        reader.ready.clear()
        return changes

    def close(self) -> None:
        """End every reader's stream (the master is stopping)."""
        for reader in self._readers:
            reader.closed = True
            reader.ready.set()
