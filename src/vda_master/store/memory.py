"""A store in memory with the same contract as the SQL store (the contract tests run on it too):
for tests of master control that need no database. Nothing survives the process."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from datetime import datetime
from types import TracebackType
from typing import Self

import orjson

from vda_master.store.batch import WriteBatch
from vda_master.store.errors import StoreWriteRejectedError
from vda_master.store.interface import DEFAULT_LIST_LIMIT, check_limit
from vda_master.store.records import (
    HeaderCounter,
    JsonObject,
    OrderEvent,
    OrderRecord,
    OutOfServiceRecord,
    VehicleRecord,
    WebhookOutbox,
    WebhookRecord,
    ZoneRecord,
)


class MemoryStore:
    """Everything in dicts; payloads are copied in and out, as a database would."""

    def __init__(self) -> None:
        self._orders: dict[str, tuple[int, OrderRecord]] = {}
        self._events: dict[str, tuple[int, OrderEvent]] = {}
        self._vehicles: dict[tuple[str, str], VehicleRecord] = {}
        self._counters: dict[tuple[str, str, str], HeaderCounter] = {}
        self._zones: dict[str, tuple[int, ZoneRecord]] = {}
        self._out_of_service: dict[tuple[str, str], OutOfServiceRecord] = {}
        self._webhooks: dict[tuple[str, int], WebhookRecord] = {}  # in the order written
        self._last_event_id = 0
        self._seq = 0
        self.writes = 0  # committed write() calls, for tests of batching

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        return None

    async def write(self, batch: WriteBatch) -> None:
        if batch.empty:
            return
        copied = _copied(batch)  # validates everything before changing anything: atomic
        for order in copied.orders:
            seq = (
                self._orders[order.order_id][0] if order.order_id in self._orders else self._next()
            )
            self._orders[order.order_id] = (seq, order)
        for event in copied.events:
            if event.event_id not in self._events:
                self._events[event.event_id] = (self._next(), event)
        for vehicle in copied.vehicles:
            key = (vehicle.manufacturer, vehicle.serial_number)
            stored = self._vehicles.get(key)
            first_seen = vehicle.first_seen if stored is None else stored.first_seen
            self._vehicles[key] = replace(vehicle, first_seen=first_seen)
        for counter in copied.counters:
            self._counters[counter.key] = counter
        self.writes += 1

    async def load_open_orders(self) -> tuple[OrderRecord, ...]:
        rows = sorted((o.created_at, seq, o) for seq, o in self._orders.values() if not o.terminal)
        return tuple(_copy_order(o) for _, _, o in rows)

    async def get_order(self, order_id: str) -> OrderRecord | None:
        found = self._orders.get(order_id)
        return _copy_order(found[1]) if found else None

    async def list_orders(
        self,
        *,
        status: str | None = None,
        manufacturer: str | None = None,
        serial_number: str | None = None,
        limit: int = DEFAULT_LIST_LIMIT,
    ) -> tuple[OrderRecord, ...]:
        check_limit(limit)
        rows = sorted(
            (
                (o.created_at, seq, o)
                for seq, o in self._orders.values()
                if status in (None, o.status)
                and manufacturer in (None, o.manufacturer)
                and serial_number in (None, o.serial_number)
            ),
            reverse=True,
        )
        return tuple(_copy_order(o) for _, _, o in rows[:limit])

    async def order_events(self, order_id: str) -> tuple[OrderEvent, ...]:
        rows = sorted(
            (e.time, seq, e) for seq, e in self._events.values() if e.order_id == order_id
        )
        return tuple(replace(e, details=_json(e.details)) for _, _, e in rows)

    async def load_vehicles(self) -> tuple[VehicleRecord, ...]:
        return tuple(
            replace(v, factsheet=None if v.factsheet is None else _json(v.factsheet))
            for _, v in sorted(self._vehicles.items())
        )

    async def load_header_counters(self) -> tuple[HeaderCounter, ...]:
        return tuple(c for _, c in sorted(self._counters.items()))

    async def prune(self, before: datetime) -> int:
        doomed = {i for i, (_, o) in self._orders.items() if o.terminal and o.updated_at < before}
        for order_id in doomed:
            del self._orders[order_id]
        self._events = {k: v for k, v in self._events.items() if v[1].order_id not in doomed}
        return len(doomed)

    async def put_zone(self, record: ZoneRecord) -> None:
        copied = replace(record, document=_json(record.document))
        stored = self._zones.get(record.zone_id)
        self._zones[record.zone_id] = (self._next() if stored is None else stored[0], copied)

    async def delete_zone(self, zone_id: str) -> bool:
        return self._zones.pop(zone_id, None) is not None

    async def load_zones(self) -> tuple[ZoneRecord, ...]:
        rows = sorted((z.created_at, seq, z) for seq, z in self._zones.values())
        return tuple(replace(z, document=_json(z.document)) for _, _, z in rows)

    async def put_out_of_service(self, record: OutOfServiceRecord) -> None:
        self._out_of_service[record.key] = record

    async def delete_out_of_service(self, manufacturer: str, serial_number: str) -> bool:
        return self._out_of_service.pop((manufacturer, serial_number), None) is not None

    async def load_out_of_service(self) -> tuple[OutOfServiceRecord, ...]:
        return tuple(record for _, record in sorted(self._out_of_service.items()))

    async def save_webhook_events(
        self,
        added: Sequence[WebhookRecord],
        done: Sequence[tuple[str, int]],
        last_event_id: int,
    ) -> None:
        if not added and not done:
            return
        for record in added:
            self._webhooks.setdefault(record.key, record)
        for key in done:
            self._webhooks.pop(key, None)
        self._last_event_id = max(self._last_event_id, last_event_id)

    async def load_webhook_outbox(self) -> WebhookOutbox:
        return WebhookOutbox(tuple(self._webhooks.values()), self._last_event_id)

    def _next(self) -> int:
        self._seq += 1
        return self._seq


def _json(value: JsonObject) -> JsonObject:
    """A deep copy through JSON, which also proves the value can be stored."""
    try:
        copied: JsonObject = orjson.loads(orjson.dumps(value))
    except TypeError as exc:  # orjson.JSONEncodeError is a TypeError
        msg = f"a value cannot be stored: {exc}"
        raise StoreWriteRejectedError(msg) from exc
    return copied


def _copy_order(order: OrderRecord) -> OrderRecord:
    return replace(order, request=_json(order.request), plan=_json(order.plan))


def _copied(batch: WriteBatch) -> WriteBatch:
    return WriteBatch(
        orders=tuple(_copy_order(o) for o in batch.orders),
        events=tuple(replace(e, details=_json(e.details)) for e in batch.events),
        vehicles=tuple(
            replace(v, factsheet=None if v.factsheet is None else _json(v.factsheet))
            for v in batch.vehicles
        ),
        counters=batch.counters,
    )
