"""Write batches and how pending batches merge (pure; the writer's core).

A :class:`WriteBatch` is applied by the store in one transaction. While batches wait to be
written, :class:`PendingWrites` merges them: a later upsert of the same order, vehicle or header
counter replaces the earlier one (only the newest content matters, and upserts are idempotent);
events accumulate in submission order (the history is append-only).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from vda_master.store.records import HeaderCounter, OrderEvent, OrderRecord, VehicleRecord

#: What a record is about: ("order", order_id), ("event", event_id), ("vehicle", m, s),
#: ("counter", m, s, topic). Used to tell a write-ahead caller whether its records were stored.
RecordKey = tuple[str, ...]


@dataclass(frozen=True, slots=True)
class WriteBatch:
    """Records to write together, atomically."""

    orders: tuple[OrderRecord, ...] = ()
    events: tuple[OrderEvent, ...] = ()
    vehicles: tuple[VehicleRecord, ...] = ()
    counters: tuple[HeaderCounter, ...] = ()

    @property
    def size(self) -> int:
        """Number of records."""
        return len(self.orders) + len(self.events) + len(self.vehicles) + len(self.counters)

    @property
    def empty(self) -> bool:
        return self.size == 0

    def keys(self) -> frozenset[RecordKey]:
        """The key of every record in the batch."""
        return frozenset(key(r) for _, records, key in _by_kind(self) for r in records)


def order_key(record: OrderRecord) -> RecordKey:
    return ("order", record.order_id)


def event_key(event: OrderEvent) -> RecordKey:
    return ("event", event.event_id)


def vehicle_key(record: VehicleRecord) -> RecordKey:
    return ("vehicle", record.manufacturer, record.serial_number)


def counter_key(counter: HeaderCounter) -> RecordKey:
    return ("counter", *counter.key)


def split_batch(batch: WriteBatch) -> list[tuple[RecordKey, WriteBatch]]:
    """One single-record batch per record, each with its key (to isolate a record the database
    refuses from the others)."""
    return [
        (key(r), WriteBatch(**{field: (r,)}))
        for field, records, key in _by_kind(batch)
        for r in records
    ]


def _by_kind(
    batch: WriteBatch,
) -> tuple[tuple[str, tuple[Any, ...], Callable[[Any], RecordKey]], ...]:
    """Each kind of record in ``batch``: its field name, its records and its key function."""
    return (
        ("orders", batch.orders, order_key),
        ("events", batch.events, event_key),
        ("vehicles", batch.vehicles, vehicle_key),
        ("counters", batch.counters, counter_key),
    )


def merge_batches(*batches: WriteBatch) -> WriteBatch:
    """One batch equivalent to writing ``batches`` in turn."""
    pending = PendingWrites()
    for batch in batches:
        pending.add(batch)
    return pending.peek()


class PendingWrites:
    """Batches submitted but not yet written, merged (see the module docstring).

    Mutable on purpose: it lives in the writer and takes many small batches per second, so a merge
    is O(records added), not O(records pending).
    """

    __slots__ = ("_counters", "_events", "_orders", "_vehicles")

    def __init__(self) -> None:
        self._orders: dict[str, OrderRecord] = {}
        self._events: OrderedDict[str, OrderEvent] = OrderedDict()
        self._vehicles: dict[tuple[str, str], VehicleRecord] = {}
        self._counters: dict[tuple[str, str, str], HeaderCounter] = {}

    def __len__(self) -> int:
        return len(self._orders) + len(self._events) + len(self._vehicles) + len(self._counters)

    @property
    def event_count(self) -> int:
        return len(self._events)

    def add(self, batch: WriteBatch) -> None:
        """Merge ``batch`` in as the newest submission."""
        for order in batch.orders:
            self._orders.pop(order.order_id, None)  # keep dict order = order of last change
            self._orders[order.order_id] = order
        for event in batch.events:
            self._events.setdefault(event.event_id, event)
        for vehicle in batch.vehicles:
            self._vehicles[(vehicle.manufacturer, vehicle.serial_number)] = vehicle
        for counter in batch.counters:
            self._counters[counter.key] = counter

    def discard_superseded(self, newer: WriteBatch) -> None:
        """Forget the pending orders, vehicles and counters that ``newer``'s records replace
        (events are never superseded: each has an id of its own)."""
        for order in newer.orders:
            self._orders.pop(order.order_id, None)
        for vehicle in newer.vehicles:
            self._vehicles.pop((vehicle.manufacturer, vehicle.serial_number), None)
        for counter in newer.counters:
            self._counters.pop(counter.key, None)

    def add_older(self, batch: WriteBatch) -> None:
        """Merge ``batch`` in as older than everything pending (a failed write put back)."""
        newer = self.take()
        self.add(batch)
        self.add(newer)

    def peek(self) -> WriteBatch:
        """Everything pending, as one batch; nothing is removed."""
        return WriteBatch(
            orders=tuple(self._orders.values()),
            events=tuple(self._events.values()),
            vehicles=tuple(self._vehicles.values()),
            counters=tuple(self._counters.values()),
        )

    def take(self) -> WriteBatch:
        """Everything pending, as one batch; the pending set is left empty."""
        batch = self.peek()
        self._orders.clear()
        self._events.clear()
        self._vehicles.clear()
        self._counters.clear()
        return batch

    def drop_oldest_events(self, keep: int) -> list[OrderEvent]:
        """Drop the oldest events so that at most ``keep`` stay; return the dropped ones."""
        dropped: list[OrderEvent] = []
        while len(self._events) > keep:
            dropped.append(self._events.popitem(last=False)[1])
        return dropped
