"""What master control writes to its store, and when (issue 10): the shell's side of
persistence. Decisions about what a change means are pure (:mod:`vda_master.order_records`);
this module turns them into store records and hands them to the
:class:`~vda_master.store.StoreWriter`, which batches them off the hot path.

=====================================  ==========================================================
when                                   what is written
=====================================  ==========================================================
an order is created or gets a new      its record and history entries, **written ahead**: the
plan (re-plan, back-off)               service holds its messages until the commit
                                       (:meth:`Journal.write_ahead`)
any other change of an order's track   its record (release counters, sent/confirmed
(status, release, confirmation, ...)   orderUpdateIds, status, reason) and history entries;
                                       queued, merged per order, committed within 50 ms
a message is published                 the vehicle's headerId counter for that topic; for an
                                       order message a ``published`` event (headerId,
                                       orderUpdateId)
the vehicle passes a node, waits in    ``node_passed``, ``waiting``, ``wait_ended`` events
traffic or stops waiting
a vehicle is first seen, changes its   its fleet registry record (version, connection state,
connection state, version or           factsheet)
factsheet
=====================================  ==========================================================

Nothing here runs per state unless the state changed something of the above.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from vda5050.clock import Clock
from vda5050.codec import SharedBodyDumps
from vda5050.models import Order
from vda5050.topics import AgvId, Topic
from vda_master.dispatcher import OrderTrack
from vda_master.fleet import VehicleView
from vda_master.order_builder import OrderPlan
from vda_master.order_records import plan_document, to_record, track_events
from vda_master.store import (
    HeaderCounter,
    JsonObject,
    OrderEvent,
    OrderEventKind,
    Store,
    StoreWriter,
    VehicleRecord,
    WriteBatch,
)

#: How long a new order's messages wait for its record to be committed. Past it they go out
#: anyway (the record stays queued and is written once the database answers), and the delay
#: is logged: a slow database must not stop the fleet.
WRITE_AHEAD_TIMEOUT_S = 2.0


@dataclass(frozen=True, slots=True)
class _PlanCache:
    """An order's plan as JSON, computed once per plan (plans are immutable)."""

    plan: OrderPlan
    document: JsonObject
    created: datetime


class Journal:
    """Store records for what happens to orders and vehicles (see the module docstring)."""

    def __init__(self, store: Store, writer: StoreWriter, clock: Clock) -> None:
        self.store = store
        self.writer = writer
        self._clock = clock
        self._plans: dict[str, _PlanCache] = {}
        self._factsheets = SharedBodyDumps()

    # -- orders --------------------------------------------------------------------------------

    def order_batch(self, old: OrderTrack | None, new: OrderTrack) -> WriteBatch:
        """The record of ``new`` and the history entries of the change from ``old``."""
        now = self._clock.now()
        cached = self._plan(new, now)
        record = to_record(new, cached.document, created=cached.created, updated=now)
        return WriteBatch(orders=(record,), events=tuple(track_events(old, new, now)))

    def track(self, old: OrderTrack | None, new: OrderTrack) -> None:
        """Queue ``new``'s record and history entries (never blocks)."""
        self.writer.submit(self.order_batch(old, new))
        if new.terminal:
            self._plans.pop(new.order_id, None)

    async def write_ahead(self, old: OrderTrack | None, new: OrderTrack) -> None:
        """Write ``new``'s record and history entries; return once committed.

        Raises:
            StoreError: not committed within :data:`WRITE_AHEAD_TIMEOUT_S`, or refused.
        """
        batch = self.order_batch(old, new)
        await self.writer.write_ahead(batch, timeout_s=WRITE_AHEAD_TIMEOUT_S)

    def event(self, order_id: str, kind: OrderEventKind, details: JsonObject) -> None:
        """Append one entry to the order's history."""
        self.writer.submit(
            WriteBatch(events=(OrderEvent(order_id, self._clock.now(), kind, details),))
        )

    def nodes_passed(self, track: OrderTrack, after: int, upto: int) -> None:
        """``node_passed`` for the plan's nodes ``after + 1`` … ``upto``."""
        now = self._clock.now()
        events = tuple(
            OrderEvent(
                track.order_id,
                now,
                OrderEventKind.NODE_PASSED,
                {"nodeId": node.node_id, "sequenceId": node.sequence_id},
            )
            for node in track.plan.nodes[after + 1 : upto + 1]
        )
        self.writer.submit(WriteBatch(events=events))

    def published(self, agv: AgvId, kind: Topic, header_id: int, order: Order | None) -> None:
        """The headerId counter of ``agv``'s ``kind`` topic; for an order, its history entry."""
        counter = HeaderCounter(agv.manufacturer, agv.serial_number, kind.value, header_id)
        events: tuple[OrderEvent, ...] = ()
        if order is not None:
            details: JsonObject = {
                "headerId": header_id,
                "orderUpdateId": order.order_update_id,
                "baseEnd": _base_end(order),
            }
            events = (
                OrderEvent(order.order_id, self._clock.now(), OrderEventKind.PUBLISHED, details),
            )
        self.writer.submit(WriteBatch(events=events, counters=(counter,)))

    def forget(self, order_id: str) -> None:
        """The order left memory: drop its cached plan."""
        self._plans.pop(order_id, None)

    def _plan(self, track: OrderTrack, now: datetime) -> _PlanCache:
        cached = self._plans.get(track.order_id)
        if cached is None or cached.plan is not track.plan:
            created = created_time(track.created_utc, now)
            cached = _PlanCache(track.plan, plan_document(track.plan), created)
            self._plans[track.order_id] = cached
        return cached

    # -- fleet registry ------------------------------------------------------------------------

    def vehicle(self, vehicle: VehicleView) -> None:
        """Queue ``vehicle``'s registry record (the store keeps its first ``first_seen``)."""
        now = self._clock.now()
        factsheet = vehicle.factsheet
        record = VehicleRecord(
            manufacturer=vehicle.agv.manufacturer,
            serial_number=vehicle.agv.serial_number,
            first_seen=now,
            last_seen=now,
            version=vehicle.version,
            connection_state=vehicle.connection.value if vehicle.connection else None,
            factsheet=self._factsheets.dump(factsheet) if factsheet is not None else None,
        )
        self.writer.submit(WriteBatch(vehicles=(record,)))


def registry_changed(before: VehicleView | None, after: VehicleView) -> bool:
    """Whether ``after`` differs from ``before`` in what the fleet registry keeps."""
    return (
        before is None
        or before.connection != after.connection
        or before.version != after.version
        or before.factsheet is not after.factsheet
    )


def _base_end(order: Order) -> str | None:
    """The last released node of an order message (its base end)."""
    released = [n.node_id for n in order.nodes if n.released]
    return released[-1] if released else None


def created_time(created_utc: str, fallback: datetime) -> datetime:
    """An order's creation time from its header-format text (``fallback`` if unreadable)."""
    try:
        return datetime.fromisoformat(created_utc)
    except ValueError:
        return fallback
