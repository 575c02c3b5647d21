"""The store seam: what master control asks of persistence, and nothing more.

Two implementations keep the same contract (``tests/integration/store/test_contract.py``):
:class:`vda_master.store.sql.SqlStore` on SQLite (embedded, the default) or PostgreSQL, and
:class:`vda_master.store.memory.MemoryStore` for tests of the master that need no database.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from types import TracebackType
from typing import Protocol, Self

from vda_master.store.batch import WriteBatch
from vda_master.store.records import (
    HeaderCounter,
    OrderEvent,
    OrderRecord,
    OutOfServiceRecord,
    VehicleRecord,
    WebhookOutbox,
    WebhookRecord,
    ZoneRecord,
)

#: Default and largest page of ``list_orders``.
DEFAULT_LIST_LIMIT = 100
MAX_LIST_LIMIT = 10_000


class Store(Protocol):
    """Persistent orders, order history, fleet registry, headerId counters, the zones added
    through the API, the vehicles taken out of service through it and the webhook events not
    yet delivered.

    Open it with ``async with``: opening creates the database if needed and migrates it to the
    newest schema. Every method may raise :class:`~vda_master.store.errors.StoreError`;
    :class:`~vda_master.store.errors.StoreUnavailableError` means "try again later".
    """

    async def __aenter__(self) -> Self: ...

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None: ...

    async def write(self, batch: WriteBatch) -> None:
        """Apply ``batch`` in one transaction: all of it or nothing.

        Orders, vehicles and counters are upserts by key (a vehicle keeps its stored
        ``first_seen``); events are appended once per ``event_id``.
        """
        ...

    async def load_open_orders(self) -> tuple[OrderRecord, ...]:
        """Every order that is not terminal, oldest first (what recovery resumes)."""
        ...

    async def get_order(self, order_id: str) -> OrderRecord | None:
        """The order, or None if it was never stored or has been pruned."""
        ...

    async def list_orders(
        self,
        *,
        status: str | None = None,
        manufacturer: str | None = None,
        serial_number: str | None = None,
        limit: int = DEFAULT_LIST_LIMIT,
    ) -> tuple[OrderRecord, ...]:
        """Orders matching every given filter, newest first, at most ``limit`` (1 to 10,000)."""
        ...

    async def order_events(self, order_id: str) -> tuple[OrderEvent, ...]:
        """The order's history in time order (ties in the order they were written)."""
        ...

    async def load_vehicles(self) -> tuple[VehicleRecord, ...]:
        """Every known vehicle, by manufacturer and serial number."""
        ...

    async def load_header_counters(self) -> tuple[HeaderCounter, ...]:
        """The last headerId sent on every (vehicle, topic)."""
        ...

    async def prune(self, before: datetime) -> int:
        """Delete terminal orders last updated before ``before``, with their events; how many
        orders were deleted."""
        ...

    async def put_zone(self, record: ZoneRecord) -> None:
        """Insert the zone, or replace the stored one with the same ``zone_id``, in one
        transaction; it is durable when this returns. A replaced zone keeps its place among
        zones created at the same time."""
        ...

    async def delete_zone(self, zone_id: str) -> bool:
        """Delete the zone; True if it was stored."""
        ...

    async def load_zones(self) -> tuple[ZoneRecord, ...]:
        """Every stored zone, oldest ``created_at`` first (ties in the order they were first
        put)."""
        ...

    async def put_out_of_service(self, record: OutOfServiceRecord) -> None:
        """Mark the vehicle out of service (replacing a stored mark) in one transaction; it is
        durable when this returns."""
        ...

    async def delete_out_of_service(self, manufacturer: str, serial_number: str) -> bool:
        """Put the vehicle back in service; True if it was marked out of service."""
        ...

    async def load_out_of_service(self) -> tuple[OutOfServiceRecord, ...]:
        """Every vehicle marked out of service, by manufacturer and serial number."""
        ...

    async def save_webhook_events(
        self,
        added: Sequence[WebhookRecord],
        done: Sequence[tuple[str, int]],
        last_event_id: int,
    ) -> None:
        """In one transaction: keep the events ``added`` (each (url, event_id) once), forget
        those ``done`` (delivered or dropped; (url, event_id) pairs), and raise the last eventId
        given out to ``last_event_id`` (never lower it). Nothing to add or forget: a no-op."""
        ...

    async def load_webhook_outbox(self) -> WebhookOutbox:
        """The events kept and not yet done, in the order they were added, and the last
        eventId given out."""
        ...


def check_limit(limit: int) -> None:
    """A ``list_orders`` limit out of range is a programming error (the API validates input)."""
    if not 1 <= limit <= MAX_LIST_LIMIT:
        msg = f"limit must be between 1 and {MAX_LIST_LIMIT}, got {limit}"
        raise ValueError(msg)
