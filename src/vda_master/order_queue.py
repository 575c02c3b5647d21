"""Queued transport orders in the master service (the rules: :mod:`vda_master.queue_rules`;
docs/master.md, *Queued orders*).

Mixed into :class:`vda_master.service.MasterService`. An order asked for with ``queue: true``
that no vehicle can take now waits here (status QUEUED) instead of being refused. The queue is
served once a (simulated) second from the tick, at once when an order ends (after energy
management has had its look), and before a new queued request is considered, so those waiting
go first. A served order keeps its orderId and creation time and goes on as any other order.

A queued order is written ahead like a new order (the 202 comes once it is committed) and
comes back after a restart; cancelled while waiting, it ends CANCELLED without any vehicle
having been sent anything; if it can never be carried out (the graph no longer has its
destination, the vehicle it names can never take it), FAILED with the reason.
"""

from __future__ import annotations

import asyncio
import itertools
import math
from collections import OrderedDict
from collections.abc import Iterable, Sequence
from dataclasses import replace
from http import HTTPStatus
from typing import TYPE_CHECKING, Final

import structlog
from pydantic import ValidationError

from vda5050.clock import Clock, format_timestamp
from vda5050.topics import AgvId
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderStatus, OrderTrack
from vda_master.fleet import FleetView, VehicleView
from vda_master.journal import WRITE_AHEAD_TIMEOUT_S, Journal, created_time
from vda_master.live import LiveView
from vda_master.metrics import Counters
from vda_master.order_records import queued_from_record, queued_record
from vda_master.queue_rules import (
    NEVER_SENT,
    RETRY_EVERY_S,
    QueuedOrder,
    deadline_of,
    overdue,
    queue_position,
    relevant,
    serving_order,
    worth_trying,
)
from vda_master.requests import OrderRequest, RequestError
from vda_master.store import (
    JsonObject,
    OrderEvent,
    OrderEventKind,
    OrderRecord,
    StoreError,
    WriteBatch,
)
from vda_master.webhook_events import order_event
from vda_master.webhooks import Webhooks

log = structlog.get_logger()
#: Ended queued orders (cancelled or failed while waiting) kept in memory, newest.
KEPT_ENDED_QUEUED: Final = 1000
#: Seconds between two passes over the queue made for new queued requests.
PASS_BEFORE_NEW_EVERY_S: Final = 0.05


class OrderQueue:
    """Orders that wait for a vehicle (see the module docstring)."""

    config: MasterConfig
    clock: Clock
    fleet: FleetView
    journal: Journal | None
    live: LiveView
    counters: Counters
    webhooks: Webhooks
    _unwritten: dict[str, asyncio.Task[None]]

    if TYPE_CHECKING:

        def _new_id(self) -> str: ...
        def availability(
            self, vehicle: VehicleView, now: float, *, automatic_only: bool = True
        ) -> str | None: ...
        def create_order(
            self,
            request: OrderRequest,
            *,
            now: float | None = None,
            order_id: str | None = None,
            created_utc: str | None = None,
        ) -> OrderTrack: ...
        def _unrecoverable(self, record: OrderRecord, reason: str) -> None: ...

    def _init_queue(self) -> None:
        #: Orders waiting for a vehicle, by orderId.
        self.queue: dict[str, QueuedOrder] = {}
        #: Orders that ended while waiting (newest :data:`KEPT_ENDED_QUEUED`; the store keeps all).
        self.queue_ended: OrderedDict[str, QueuedOrder] = OrderedDict()
        self._queue_seq = itertools.count()
        self._last_pass_before_new = -math.inf

    # -- asked for -----------------------------------------------------------------------------

    def enqueue(self, request: OrderRequest, reason: str) -> QueuedOrder:
        """Keep ``request``, which no vehicle can take now for ``reason``, until one can."""
        created = self.clock.now()
        entry = QueuedOrder(
            order_id=self._new_id(),
            request=request,
            priority=request.priority,
            seq=next(self._queue_seq),
            created_utc=format_timestamp(created),
            reason=reason,
            deadline=deadline_of(created, request.queue_timeout_s, self.config.time_lapse),
        )
        self.queue[entry.order_id] = entry
        self.counters.orders_queued += 1
        self.live.order_changed(entry.order_id)
        log.info(
            "order.queued",
            order_id=entry.order_id,
            agv=str(request.agv) if request.agv else None,
            target=request.target.describe(),
            priority=entry.priority,
            position=self.position(entry.order_id),
            reason=reason,
        )
        details: JsonObject = {"priority": entry.priority, "reason": reason}
        self._write_queued(entry, OrderEventKind.QUEUED, details, ahead=True)
        self.webhooks.emit(order_event(entry.order_id, "QUEUED", None, request.agv, reason))
        return entry

    def position(self, order_id: str) -> int | None:
        """Where a waiting order stands in the queue (1 goes next)."""
        return queue_position(self.queue.values(), order_id)

    @property
    def queued_orders(self) -> Iterable[QueuedOrder]:
        """Every order waiting, and those that ended while waiting still in memory."""
        return itertools.chain(self.queue.values(), self.queue_ended.values())

    def queued(self, order_id: str) -> QueuedOrder | None:
        """The order if it waits, or ended while waiting (and is still in memory)."""
        return self.queue.get(order_id) or self.queue_ended.get(order_id)

    def cancel_queued(self, order_id: str) -> QueuedOrder:
        """End a waiting order CANCELLED (no vehicle was sent anything); 409 if it ended."""
        entry = self.queue.get(order_id)
        if entry is None:
            ended = self.queue_ended[order_id]
            raise RequestError(409, f"order {order_id!r} has ended ({ended.status.value})")
        return self._end_queued(entry, OrderStatus.CANCELLED, "cancelled while queued")

    def reprioritize(self, order_id: str, priority: int) -> QueuedOrder:
        """Give a waiting order another priority: it moves in the queue; 409 if it ended."""
        entry = self.queue.get(order_id)
        if entry is None:
            ended = self.queue_ended[order_id]
            raise RequestError(
                409, f"order {order_id!r} has ended ({ended.status.value}): its priority is final"
            )
        request = replace(entry.request, priority=priority)
        changed = replace(entry, priority=priority, request=request)
        self.queue[order_id] = changed
        self.live.order_changed(order_id)
        log.info(
            "order.reprioritized",
            order_id=order_id,
            priority=priority,
            previous=entry.priority,
            position=self.position(order_id),
        )
        details: JsonObject = {"priority": priority, "previous": entry.priority}
        self._write_queued(changed, OrderEventKind.REPRIORITIZED, details, ahead=False)
        return changed

    # -- serving -------------------------------------------------------------------------------

    def serve_before_new(self, now: float) -> None:
        """Before a new order that may wait is considered: those waiting go first (a pass at
        most every :data:`PASS_BEFORE_NEW_EVERY_S`: a pass looks at every vehicle, and a
        wave of queued requests would otherwise cost O(fleet) each)."""
        if now - self._last_pass_before_new >= PASS_BEFORE_NEW_EVERY_S:
            self._last_pass_before_new = now
            self.serve_queue(now)

    def serve_queue(self, now: float, *, freed: AgvId | None = None) -> None:
        """Send the waiting orders that a vehicle can take now, in their serving order;
        ``freed``: only that vehicle came free (its order ended), the others are as the last
        pass found them."""
        if not self.queue:
            return
        if freed is None:
            self._fail_overdue()
        vehicles = self.fleet if freed is None else [self.fleet.get(freed)]
        available = frozenset(
            v.agv for v in vehicles if v is not None and self.availability(v, now) is None
        )
        retry_s = RETRY_EVERY_S / self.config.time_lapse
        for entry in serving_order(self.queue.values()):
            if not available:
                return
            if not worth_trying(entry, available, now, retry_s):
                continue
            try:
                track = self._start_queued(entry, now)
            except RequestError as exc:
                if exc.status != HTTPStatus.CONFLICT:
                    self._end_queued(entry, OrderStatus.FAILED, exc.message)
                    continue
                tried = relevant(entry, available)
                self.queue[entry.order_id] = replace(
                    entry, reason=exc.message, tried_with=tried, tried_at=now
                )
                if exc.message != entry.reason:
                    self.live.order_changed(entry.order_id)  # the map shows why it waits
                continue
            available -= {track.plan.agv}

    def serve_queue_afresh(self, now: float) -> None:
        """Something changed that may let waiting orders go with any vehicle (one came back
        into service, and with it the node it stands on): each is tried again at once, not
        only those whose candidate vehicles changed."""
        for order_id, entry in self.queue.items():
            self.queue[order_id] = replace(entry, tried_with=frozenset())
        self.serve_queue(now)

    def _fail_overdue(self) -> None:
        """Orders that waited their ``queueTimeoutS`` without a vehicle end FAILED."""
        for entry in overdue(self.queue.values(), self.clock.now()):
            timeout = entry.request.queue_timeout_s
            why = f"no vehicle could take it within queueTimeoutS {timeout:g} s ({entry.reason})"
            self._end_queued(entry, OrderStatus.FAILED, why)

    def _start_queued(self, entry: QueuedOrder, now: float) -> OrderTrack:
        track = self.create_order(
            entry.request, now=now, order_id=entry.order_id, created_utc=entry.created_utc
        )
        del self.queue[entry.order_id]
        log.info(
            "order.dequeued",
            order_id=entry.order_id,
            agv=str(track.plan.agv),
            priority=entry.priority,
            waiting=len(self.queue),
        )
        return track

    def _end_queued(self, entry: QueuedOrder, status: OrderStatus, why: str) -> QueuedOrder:
        ended = replace(entry, status=status, reason=NEVER_SENT + why)
        del self.queue[entry.order_id]
        self.queue_ended[entry.order_id] = ended
        self.counters.orders_ended[status.value] += 1
        self.live.order_changed(entry.order_id)
        while len(self.queue_ended) > KEPT_ENDED_QUEUED:
            self.queue_ended.popitem(last=False)
        log.info("order.status_changed", order_id=entry.order_id, status=status.value, reason=why)
        agv = entry.request.agv
        self.webhooks.emit(order_event(entry.order_id, status.value, "QUEUED", agv, ended.reason))
        details: JsonObject = {"status": status.value, "previous": "QUEUED", "reason": ended.reason}
        self._write_queued(ended, OrderEventKind.STATUS_CHANGED, details, ahead=False)
        return ended

    # -- the store -----------------------------------------------------------------------------

    def _write_queued(
        self, entry: QueuedOrder, event: OrderEventKind, details: JsonObject, *, ahead: bool
    ) -> None:
        """The entry's record and a history entry: written ahead for a new one (the API
        answers once it is committed), queued for the writer otherwise."""
        if self.journal is None:
            return
        now = self.clock.now()
        created = created_time(entry.created_utc, now)
        batch = WriteBatch(
            orders=(queued_record(entry, created=created, updated=now),),
            events=(OrderEvent(entry.order_id, now, event, details),),
        )
        if not ahead:
            self.journal.writer.submit(batch)
            return
        task = asyncio.get_running_loop().create_task(
            self._queued_ahead(entry.order_id, batch), name=f"master.queued.{entry.order_id}"
        )
        self._unwritten[entry.order_id] = task

    async def _queued_ahead(self, order_id: str, batch: WriteBatch) -> None:
        assert self.journal is not None  # noqa: S101 - only scheduled with a journal
        try:
            await self.journal.writer.write_ahead(batch, timeout_s=WRITE_AHEAD_TIMEOUT_S)
        except StoreError as exc:
            log.warning(
                "order.queue_write_failed",
                order_id=order_id,
                reason=str(exc),
                consequence="it waits in memory; the record is written once the store answers",
            )
        finally:
            if self._unwritten.get(order_id) is asyncio.current_task():
                del self._unwritten[order_id]

    def restore_queue(self, records: Sequence[OrderRecord]) -> None:
        """Orders that waited when master control stopped (oldest first) wait again."""
        for record in records:
            try:
                entry = queued_from_record(record, next(self._queue_seq), self.config.time_lapse)
            except ValidationError as exc:
                problem = exc.errors()[0]
                where = ".".join(str(p) for p in problem["loc"]) or "request"
                self._unrecoverable(
                    record, f"its stored request cannot be read back: {where}: {problem['msg']}"
                )
                continue
            self.queue[entry.order_id] = entry
            log.info("order.recovered", order_id=entry.order_id, status="QUEUED")
