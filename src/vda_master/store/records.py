"""What the store keeps: plain records with JSON payloads (issue 10 "What is stored").

The store never sees pydantic wire models: master control converts its orders, plans,
factsheets and zones to JSON objects (``model_dump(mode="json", by_alias=True)``) before it
builds a record, and back after loading one. Every time is a timezone-aware datetime, kept in UTC.

Records are frozen; their JSON payloads are plain dicts that callers treat as read-only.
"""

from __future__ import annotations

import itertools
import os
import secrets
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from enum import StrEnum
from typing import TypeAlias

from vda_master.dispatcher import TERMINAL

JsonValue: TypeAlias = bool | int | float | str | list["JsonValue"] | dict[str, "JsonValue"] | None
JsonObject: TypeAlias = dict[str, JsonValue]

#: headerId is a uint32 (§6.4, R15).
_UINT32_MAX = 2**32 - 1


def utc(value: datetime, name: str) -> datetime:
    """``value`` in UTC; a naive datetime is a programming error."""
    if value.tzinfo is None or value.utcoffset() is None:
        msg = f"{name} must be timezone-aware, got naive {value.isoformat()}"
        raise ValueError(msg)
    return value.astimezone(UTC)


class OrderEventKind(StrEnum):
    """Events master control records in an order's history (``OrderEvent.event``).

    The store accepts any string; these are the names the master uses.
    """

    #: Asked for with ``queue: true`` while no vehicle could take it (docs/master.md, *Queued
    #: orders*); ``created`` follows once a vehicle takes it.
    QUEUED = "queued"
    #: A queued order's priority changed (``PATCH /orders/{orderId}``).
    REPRIORITIZED = "reprioritized"
    CREATED = "created"
    PUBLISHED = "published"
    ACCEPTED = "accepted"
    NODE_PASSED = "node_passed"
    WAITING = "waiting"
    WAIT_ENDED = "wait_ended"
    REPLANNED = "replanned"
    #: The next stop of an order with several was appended (docs/master.md, *Orders with
    #: several stops*).
    STOP_APPENDED = "stop_appended"
    STATUS_CHANGED = "status_changed"
    CANCEL_REQUESTED = "cancel_requested"
    #: Loaded from the store after a master restart.
    RECOVERED = "recovered"
    #: Settled by the vehicle's first state after the restart (:mod:`vda_master.recovery`).
    RECONCILED = "reconciled"


@dataclass(frozen=True, slots=True)
class OrderRecord:
    """One order as master control tracks it, enough to resume it after a restart.

    ``request`` is what the API was asked; ``plan`` the whole order plan (version, nodes and edges
    with their actions), from which every message is cut again (see ``order_builder``).
    ``update_id`` is the latest orderUpdateId built, ``sent_update_id`` the latest published and
    ``confirmed_update_id`` the latest a state confirmed. ``terminal`` follows from ``status``.
    """

    order_id: str
    manufacturer: str
    serial_number: str
    status: str
    created_at: datetime
    updated_at: datetime
    request: JsonObject
    plan: JsonObject
    released_end: int
    update_id: int
    sent_update_id: int | None = None
    confirmed_update_id: int | None = None
    cancel_action_id: str | None = None
    reason: str = ""
    terminal: bool = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "created_at", utc(self.created_at, "created_at"))
        object.__setattr__(self, "updated_at", utc(self.updated_at, "updated_at"))
        object.__setattr__(self, "terminal", self.status in TERMINAL)


class _EventIds:
    """Order event ids: 64 random bits drawn once per process (again in a forked child), then a
    counter. No system call per event (an order's history gets one per node passed); two
    processes share a prefix with a chance of 2^-64."""

    def __init__(self) -> None:
        self._numbers = itertools.count()
        self._prefix = ""
        self.draw()
        os.register_at_fork(after_in_child=self.draw)

    def draw(self) -> None:
        self._prefix = secrets.token_hex(8)

    def next(self) -> str:
        """The next id: 32 hex digits, as ``uuid4().hex`` gave them (count's next is atomic)."""
        return f"{self._prefix}{next(self._numbers):016x}"


#: The next id of an order event.
next_event_id: Callable[[], str] = _EventIds().next


@dataclass(frozen=True, slots=True)
class OrderEvent:
    """One entry of an order's append-only history.

    ``details`` carries what the event is about (headerId, orderUpdateId, nodeId, status,
    reason, ...). ``event_id`` makes appending idempotent: a batch written twice (a retry after
    a commit whose answer was lost) adds each event once.
    """

    order_id: str
    time: datetime
    event: str
    details: JsonObject = field(default_factory=dict)
    #: 32 hex digits, unique across processes and restarts (see :func:`next_event_id`).
    event_id: str = field(default_factory=next_event_id)

    def __post_init__(self) -> None:
        object.__setattr__(self, "time", utc(self.time, "time"))


@dataclass(frozen=True, slots=True)
class VehicleRecord:
    """One vehicle of the fleet registry: identity, protocol version, last connection state and
    factsheet. An upsert replaces everything but ``first_seen``, which keeps the stored value."""

    manufacturer: str
    serial_number: str
    first_seen: datetime
    last_seen: datetime
    version: str | None = None
    connection_state: str | None = None
    factsheet: JsonObject | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "first_seen", utc(self.first_seen, "first_seen"))
        object.__setattr__(self, "last_seen", utc(self.last_seen, "last_seen"))


@dataclass(frozen=True, slots=True)
class OutOfServiceRecord:
    """A vehicle an operator took out of service (``PATCH /vehicles/...``, docs/master.md,
    *Out of service*): master control sends it no order of its own choosing until it is put back.
    A put for a stored vehicle replaces the record."""

    manufacturer: str
    serial_number: str
    note: str
    since: datetime

    def __post_init__(self) -> None:
        object.__setattr__(self, "since", utc(self.since, "since"))

    @property
    def key(self) -> tuple[str, str]:
        return (self.manufacturer, self.serial_number)


@dataclass(frozen=True, slots=True)
class HeaderCounter:
    """The last headerId master control sent on one topic of one vehicle (§6.4, R15), so that
    headerIds continue after a restart instead of starting again at 0."""

    manufacturer: str
    serial_number: str
    topic: str
    header_id: int

    def __post_init__(self) -> None:
        if not 0 <= self.header_id <= _UINT32_MAX:
            msg = f"header_id must be a uint32, got {self.header_id}"
            raise ValueError(msg)

    @property
    def key(self) -> tuple[str, str, str]:
        return (self.manufacturer, self.serial_number, self.topic)


@dataclass(frozen=True, slots=True)
class ZoneRecord:
    """A zone added at run time through the HTTP API, kept so that it outlives a restart.

    ``document`` is the zone as the API took it (zoneId, zoneType, vertices, ...); the store does
    not look inside it. A put with a stored ``zone_id`` replaces the record.
    """

    zone_id: str
    document: JsonObject
    created_at: datetime

    def __post_init__(self) -> None:
        object.__setattr__(self, "created_at", utc(self.created_at, "created_at"))


@dataclass(frozen=True, slots=True)
class WebhookRecord:
    """A webhook event not yet delivered to one receiver (docs/master.md, *Webhooks*): the
    receiver's ``url``, the event's ``event_id`` and its ``body`` exactly as it is POSTed
    (JSON text), so that a restarted master control sends the same bytes again."""

    url: str
    event_id: int
    body: str
    created_at: datetime

    def __post_init__(self) -> None:
        object.__setattr__(self, "created_at", utc(self.created_at, "created_at"))

    @property
    def key(self) -> tuple[str, int]:
        return (self.url, self.event_id)


@dataclass(frozen=True, slots=True)
class WebhookOutbox:
    """What a store holds of the webhook events: those not yet delivered, oldest first, and
    the last eventId given out (0: none yet), so that eventIds go on after a restart."""

    events: tuple[WebhookRecord, ...] = ()
    last_event_id: int = 0
