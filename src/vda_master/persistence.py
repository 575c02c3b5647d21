"""Persistence in the master service (issue 10): write-ahead, the journal hooks, recovery after a
restart and reads of orders that left memory.

:class:`Persistence` is mixed into :class:`vda_master.service.MasterService`; without a journal
(unit tests of the service) every hook does nothing and orders live in memory only.

- A new order, or a new plan of one, is written ahead: its messages are held until the store has
  committed it (at most :data:`~vda_master.journal.WRITE_AHEAD_TIMEOUT_S`), so a crash between
  the two loses nothing. Every other track change is queued for the writer.
- :meth:`Persistence.recover` takes what the store gave back on start: vehicles (factsheets,
  versions), headerId counters, and the open orders, each marked as recovering. Traffic control
  holds each recovered vehicle's whole released base until its first state shows where it is.
- That first state settles the order (:func:`vda_master.recovery.reconcile`); a vehicle silent for
  ``recovery_timeout_s`` makes its order UNKNOWN (:func:`vda_master.recovery.overdue`).
- Ended orders beyond the newest :data:`KEPT_ENDED` leave memory; the API reads them from the
  store (:meth:`Persistence.find_order`, :meth:`Persistence.find_orders`).
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Final

import orjson
import structlog
from pydantic import ValidationError

from vda5050.clock import Clock, format_timestamp
from vda5050.codec import DecodeFailure, HeaderStamper, decode_as
from vda5050.models import (
    UINT32_MAX,
    Factsheet,
    InstantActions,
    Order,
    State,
)
from vda5050.topics import AgvId, Topic
from vda_master.config import MasterConfig
from vda_master.coordination import Coordinator, WaitChange
from vda_master.dispatcher import OrderStatus, OrderTrack, observe_track
from vda_master.faults import crash_point
from vda_master.fleet import FleetView, Observation, VehicleView, reduce_fleet
from vda_master.graph import Graph
from vda_master.graph_change import Rerouted, around_closed_way, holdable
from vda_master.journal import Journal
from vda_master.order_records import from_record, last_passed
from vda_master.queue_rules import QueuedOrder
from vda_master.recovery import overdue, reconcile
from vda_master.release import progress_index
from vda_master.routing import Route, RouteProblem, shortest_route
from vda_master.stops import stop_number
from vda_master.store import (
    HeaderCounter,
    JsonObject,
    OrderEvent,
    OrderEventKind,
    OrderRecord,
    OutOfServiceRecord,
    Store,
    StoreError,
    VehicleRecord,
    WriteBatch,
    ZoneRecord,
)

log = structlog.get_logger()

#: Ended orders kept in memory (newest); older ones are read from the store.
KEPT_ENDED: Final = 1000
#: After a restart headerIds go on this far beyond the stored counter: the counters are written
#: in batches, so a crash can lose the last flush interval's messages (several order updates to
#: one vehicle); a gap keeps headerIds increasing per topic (R15), a repeat would not.
RESTART_HEADER_GAP: Final = 100
#: Seconds between two checks for recovered orders whose vehicle stays silent.
RECOVERY_CHECK_EVERY_S: Final = 1.0
#: How long a history read waits for queued writes (a StoreUnavailableError after that).
HISTORY_FLUSH_TIMEOUT_S: Final = 2.0

#: A recovered order that could not be read back: why, for the log and the stored record.
_UNREADABLE = (ValidationError, KeyError, ValueError, TypeError, IndexError)


class Persistence:
    """The store side of the master service (see the module docstring)."""

    config: MasterConfig
    clock: Clock
    fleet: FleetView
    tracks: dict[str, OrderTrack]
    active: dict[AgvId, str]
    _unsettled: set[AgvId]
    sent: dict[str, Order]
    coordinator: Coordinator
    graph: Graph

    if TYPE_CHECKING:

        def _pump(self, agv: AgvId, now: float) -> None: ...
        def _store(self, agv: AgvId, track: OrderTrack) -> None: ...
        def restore_zones(self, records: tuple[ZoneRecord, ...]) -> None: ...
        def restore_out_of_service(self, records: tuple[OutOfServiceRecord, ...]) -> None: ...
        def _stamper(self, agv: AgvId) -> HeaderStamper: ...
        def _publish(self, agv: AgvId, message: Order | InstantActions, now: float) -> None: ...
        def _with_cancel(self, track: OrderTrack) -> OrderTrack | str: ...
        def restore_queue(self, records: Sequence[OrderRecord]) -> None: ...
        def queued(self, order_id: str) -> QueuedOrder | None: ...
        @property
        def queued_orders(self) -> Iterable[QueuedOrder]: ...

    def _init_persistence(self) -> None:
        #: A wait that began as a new order was released, before it was active (by vehicle).
        self._early_waits: dict[AgvId, WaitChange] = {}
        self.journal: Journal | None = None
        self._unwritten: dict[str, asyncio.Task[None]] = {}
        self._recovering: set[str] = set()
        self._passed: dict[str, int] = {}
        self._ended: deque[str] = deque()
        self._next_recovery_check = 0.0
        #: Creation time (UTC text) of the newest order that may be in the store only: earlier
        #: runs' orders and ended orders that left memory. Newer orders are all in memory; ""
        #: while the store holds no order that memory lacks (a listing reads memory alone).
        self._newest_only_stored = ""

    def attach_journal(self, journal: Journal) -> None:
        """Write orders, their history and the fleet registry through ``journal`` from now on."""
        self.journal = journal
        self.coordinator.on_wait = self._wait_changed

    # -- writing -------------------------------------------------------------------------------

    def _record(self, agv: AgvId, old: OrderTrack | None, new: OrderTrack) -> None:
        """Write a track change: a new order or plan ahead of its messages, the rest queued."""
        if self.journal is None or old is new:
            return
        if old is None or old.plan is not new.plan:
            task = asyncio.get_running_loop().create_task(
                self._write_ahead(agv, old, new), name=f"master.write_ahead.{new.order_id}"
            )
            self._unwritten[new.order_id] = task
        else:
            self.journal.track(old, new)
        if new.terminal and (old is None or not old.terminal):
            self._order_ended(new.order_id)

    async def _write_ahead(self, agv: AgvId, old: OrderTrack | None, new: OrderTrack) -> None:
        """Commit ``new`` (:data:`~vda_master.journal.WRITE_AHEAD_TIMEOUT_S` at most), then let
        its messages go."""
        assert self.journal is not None  # noqa: S101 - only scheduled with a journal
        try:
            await self.journal.write_ahead(old, new)
        except StoreError as exc:
            log.warning(
                "order.write_ahead_failed",
                order_id=new.order_id,
                reason=str(exc),
                consequence="its messages go out anyway; the record is written once the store "
                "answers",
            )
        finally:
            if self._unwritten.get(new.order_id) is asyncio.current_task():
                del self._unwritten[new.order_id]
        crash_point("after_write_ahead")
        self._pump(agv, self.clock.monotonic())

    def _held(self, order_id: str) -> bool:
        """Whether the order's messages wait for its write-ahead."""
        return order_id in self._unwritten

    async def committed(self, order_id: str) -> None:
        """Return once the order's write-ahead is done (at once if none is under way)."""
        task = self._unwritten.get(order_id)
        if task is not None:
            await asyncio.shield(task)

    def _order_ended(self, order_id: str) -> None:
        """Keep the newest :data:`KEPT_ENDED` ended orders in memory; the store has the rest."""
        self._passed.pop(order_id, None)
        self._recovering.discard(order_id)
        self._ended.append(order_id)
        while len(self._ended) > KEPT_ENDED:
            old = self._ended.popleft()
            track = self.tracks.get(old)
            if track is not None and track.terminal:
                self._newest_only_stored = max(self._newest_only_stored, track.created_utc)
                del self.tracks[old]
                self.sent.pop(old, None)
                if self.journal is not None:
                    self.journal.forget(old)

    def _note_progress(self, track: OrderTrack, progress: int | None) -> None:
        """``node_passed`` history entries for the nodes passed since the last state."""
        if self.journal is None or progress is None:
            return
        before = self._passed.get(track.order_id, -1)
        if progress > before:
            self._passed[track.order_id] = progress
            self.journal.nodes_passed(track, before, progress)

    def _wait_changed(self, change: WaitChange) -> None:
        order_id = self.active.get(change.agv)
        if self.journal is None:
            return
        if order_id is None:  # a new order that waits from the start: filed once it is active
            if change.waited_s is None:
                self._early_waits[change.agv] = change
            return
        if change.waited_s is None:
            started: JsonObject = {
                "nodeId": change.node_id,
                "waitingFor": list(change.waiting_for),
                "resource": change.resource,
            }
            self.journal.event(order_id, OrderEventKind.WAITING, started)
        else:
            ended: JsonObject = {"nodeId": change.node_id, "waitedS": change.waited_s}
            self.journal.event(order_id, OrderEventKind.WAIT_ENDED, ended)

    def _file_early_wait(self, agv: AgvId) -> None:
        """The wait a new order of ``agv`` began with, filed now that the order is active."""
        change = self._early_waits.pop(agv, None)
        if change is not None:
            self._wait_changed(change)

    # -- recovery ------------------------------------------------------------------------------

    async def resume_from(self, store: Store) -> list[OrderTrack]:
        """Load what an earlier run left in ``store`` and :meth:`recover` it."""
        newest = await store.list_orders(limit=1)
        if newest:  # an earlier run's orders: listings beyond memory read the store
            self._newest_only_stored = format_timestamp(newest[0].created_at)
        self.restore_zones(await store.load_zones())  # before the orders that drive round them
        self.restore_out_of_service(await store.load_out_of_service())  # before the queue
        orders = await store.load_open_orders()
        self.restore_queue([r for r in orders if r.status == OrderStatus.QUEUED])
        orders = tuple(r for r in orders if r.status != OrderStatus.QUEUED)
        passed = {r.order_id: last_passed(await store.order_events(r.order_id)) for r in orders}
        return self.recover(
            orders,
            vehicles=await store.load_vehicles(),
            counters=await store.load_header_counters(),
            passed=passed,
        )

    def recover(
        self,
        orders: Sequence[OrderRecord],
        *,
        vehicles: Sequence[VehicleRecord] = (),
        counters: Sequence[HeaderCounter] = (),
        passed: Mapping[str, int] | None = None,
    ) -> list[OrderTrack]:
        """Resume from the store: known vehicles, headerId counters and the open ``orders``
        (oldest first); ``passed`` is the last node index each order's history shows passed.
        Returns the orders resumed; each waits for its vehicle's first state."""
        now = self.clock.monotonic()
        for vehicle in vehicles:
            self._recover_vehicle(vehicle, now)
        for counter in counters:
            self._recover_counter(counter)
        resumed = []
        for record in orders:
            track = self._recover_order(record, now, (passed or {}).get(record.order_id, -1))
            if track is not None:
                resumed.append(track)
        return resumed

    def _recover_vehicle(self, record: VehicleRecord, now: float) -> None:
        """A vehicle of an earlier run: known with its version and factsheet until it reports
        (its connection state is unknown until it publishes one)."""
        agv = AgvId(record.manufacturer, record.serial_number)
        if self.fleet.get(agv) is None:
            self.fleet = self.fleet.with_vehicle(VehicleView(agv, first_seen=now, last_seen=now))
        if record.factsheet is None:
            return
        decoded = decode_as(Factsheet, Topic.FACTSHEET, orjson.dumps(record.factsheet))
        if isinstance(decoded, DecodeFailure):
            log.warning("vehicle.stored_factsheet_unusable", agv=str(agv), reason=decoded.summary())
            return
        self.fleet = reduce_fleet(self.fleet, Observation(agv, decoded), now)
        self.coordinator.note_factsheet(agv, decoded)

    def _recover_counter(self, counter: HeaderCounter) -> None:
        try:
            topic = Topic(counter.topic)
        except ValueError:
            return
        agv = AgvId(counter.manufacturer, counter.serial_number)
        resume_after = (counter.header_id + RESTART_HEADER_GAP) % (UINT32_MAX + 1)
        self._stamper(agv).continue_from(topic, resume_after)

    def _recover_order(self, record: OrderRecord, now: float, passed: int) -> OrderTrack | None:
        try:
            track = from_record(record, now=now)
        except _UNREADABLE as exc:
            self._unrecoverable(record, f"its stored plan cannot be read back: {exc}")
            return None
        agv = track.plan.agv
        previous = self.active.get(agv)
        if previous is not None:  # records come oldest first: the newer order wins
            superseded = replace(
                self.tracks[previous],
                status=OrderStatus.FAILED,
                reason=f"order {track.order_id!r} of the same vehicle is newer (found when "
                "master control restarted)",
                pending=None,
            )
            self._store(agv, superseded)
        self.tracks[track.order_id] = track
        self.active[agv] = track.order_id
        self._unsettled.add(agv)  # the tick resends what the vehicle may not have
        self._recovering.add(track.order_id)
        self._passed[track.order_id] = passed
        if track.plan.route is not None:  # hold its whole released base until a state shows more
            route, released_end, way = holdable(self.graph, track.plan.route, track.released_end)
            if way is not None:  # the graph changed since: settled by the first state
                log.warning(
                    "order.way_closed", order_id=track.order_id, agv=str(agv), reason=way.why
                )
            self.coordinator.assign(agv, route, now, released_end=released_end)
        log.info(
            "order.recovered",
            order_id=track.order_id,
            agv=str(agv),
            status=track.status.value,
            order_update_id=track.update_id,
            sent_order_update_id=track.sent_update_id,
            confirmed_order_update_id=track.confirmed_update_id,
            released_nodes=track.released_end + 1,
            nodes=len(track.plan.nodes),
        )
        if self.journal is not None:
            details: JsonObject = {"status": track.status.value, "orderUpdateId": track.update_id}
            self.journal.event(track.order_id, OrderEventKind.RECOVERED, details)
        return track

    def _unrecoverable(self, record: OrderRecord, reason: str) -> None:
        log.error("order.not_recoverable", order_id=record.order_id, reason=reason)
        if self.journal is None:
            return
        failed = replace(
            record,
            status=OrderStatus.FAILED.value,
            reason=f"not resumed after a master restart: {reason}",
            updated_at=self.clock.now(),
        )
        changed: JsonObject = {
            "status": failed.status,
            "previous": record.status,
            "reason": failed.reason,
        }
        event = OrderEvent(
            record.order_id, failed.updated_at, OrderEventKind.STATUS_CHANGED, changed
        )
        self.journal.writer.submit(WriteBatch(orders=(failed,), events=(event,)))

    def _fold_state(self, agv: AgvId, order_id: str | None, state: State) -> OrderTrack | None:
        """The vehicle's order with ``state`` folded in; a recovered one is settled first."""
        if order_id is None:
            return None
        track = self.tracks[order_id]
        if track.recovering_since is None:
            return observe_track(track, state)
        return self._settle(agv, track, state)

    def _settle(self, agv: AgvId, track: OrderTrack, state: State) -> OrderTrack:
        now = self.clock.monotonic()
        since = track.recovering_since or now
        reconciled = reconcile(track, state)
        settled = reconciled.track
        self._recovering.discard(track.order_id)
        progress = progress_index(settled.plan, state)
        if not settled.terminal:
            settled = self._around_closed_way(settled, progress or 0, now)
        if settled.plan.route is not None and not settled.terminal:
            # being cancelled on a closed way: it holds what it may still drive
            route, released_end, _ = holdable(
                self.graph, settled.plan.route, settled.released_end, progress or 0
            )
            self.coordinator.assign(
                agv, route, now, progress=progress or 0, released_end=released_end
            )
        log.info(
            "order.reconciled",
            order_id=track.order_id,
            agv=str(agv),
            outcome=reconciled.outcome.value,
            status=settled.status.value,
            vehicle_order_id=state.order_id,
            vehicle_order_update_id=state.order_update_id,
            after_s=round(now - since, 3),
        )
        if self.journal is not None:
            details: JsonObject = {
                "outcome": reconciled.outcome.value,
                "vehicleOrderId": state.order_id,
                "vehicleOrderUpdateId": state.order_update_id,
                "lastNodeId": state.last_node_id,
            }
            self.journal.event(track.order_id, OrderEventKind.RECONCILED, details)
        return settled

    def _around_closed_way(self, track: OrderTrack, progress: int, now: float) -> OrderTrack:
        """An order whose way the graph no longer has (:mod:`vda_master.graph_change`; after a
        restart, or a change of zones: :mod:`vda_master.zone_changes`): re-routed from its
        released end when the closed part is not released yet, else (or with no other way)
        cancelled on the vehicle, to end FAILED with the reason."""
        agv = track.plan.agv
        vehicle = self.fleet.get(agv)

        def tail_for(start: str, destination: str) -> Route | RouteProblem:
            planned = self.coordinator.plan(agv, start, destination, now)
            return planned.route if planned else shortest_route(self.graph, start, destination)

        outcome = around_closed_way(
            self.graph,
            track.plan,
            released_end=track.released_end,
            progress=progress,
            cancelling=track.cancel_action_id is not None,
            tail_for=tail_for,
            factsheet=None if vehicle is None else vehicle.factsheet,
            resume_to=None if track.resume is None else track.resume.node_id,
            onward=track.onward,
            first_onward=stop_number(track.request_json, len(track.onward)),
        )
        if outcome is None:
            return track
        if isinstance(outcome, Rerouted):
            log.warning("order.rerouted", order_id=track.order_id, agv=str(agv), reason=outcome.why)
            return replace(track, plan=outcome.plan)
        cancelled = self._with_cancel(track)
        if isinstance(cancelled, str):
            return track  # already being cancelled
        log.warning("order.stopped", order_id=track.order_id, agv=str(agv), reason=outcome.reason)
        return replace(cancelled, cancel_reason=outcome.reason)

    def _check_recovering(self, now: float) -> None:
        """Recovered orders whose vehicle stayed silent too long become UNKNOWN."""
        if not self._recovering or now < self._next_recovery_check:
            return
        self._next_recovery_check = now + RECOVERY_CHECK_EVERY_S
        for order_id in list(self._recovering):
            track = self.tracks.get(order_id)
            if track is None or track.recovering_since is None:
                self._recovering.discard(order_id)
                continue
            unknown = overdue(track, now, self.config.recovery_timeout_s)
            if unknown is not None:
                log.warning("order.progress_unknown", order_id=order_id, reason=unknown.reason)
                self._store(track.plan.agv, unknown)

    # -- reads ---------------------------------------------------------------------------------

    async def find_order(self, order_id: str) -> OrderTrack | QueuedOrder | OrderRecord | None:
        """The order from memory (sent, or waiting for a vehicle), else from the store (orders
        of earlier runs)."""
        track = self.tracks.get(order_id) or self.queued(order_id)
        if track is not None or self.journal is None:
            return track
        return await self.journal.store.get_order(order_id)

    async def find_orders(
        self,
        *,
        status: OrderStatus | None,
        manufacturer: str | None,
        serial_number: str | None,
        limit: int,
    ) -> list[OrderTrack | QueuedOrder | OrderRecord]:
        """Orders newest first from memory and the store; memory wins for an order in both."""
        memory: list[OrderTrack | QueuedOrder | OrderRecord] = [
            t
            for t in reversed(self.tracks.values())
            if (status is None or t.status == status)
            and _vehicle_matches(t.plan.agv, manufacturer, serial_number)
        ]
        memory += [
            q
            for q in self.queued_orders
            if (status is None or q.status == status)
            and _vehicle_matches(q.request.agv, manufacturer, serial_number)
        ]
        # newest first: an order served from the queue keeps its older creation time
        memory.sort(key=_created_text, reverse=True)
        if (
            self.journal is None
            or not self._newest_only_stored
            or (
                len(memory) >= limit and _created_text(memory[limit - 1]) > self._newest_only_stored
            )
        ):
            return memory[:limit]  # the store holds nothing memory lacks, or nothing newer
        stored = await self.journal.store.list_orders(
            status=status.value if status is not None else None,
            manufacturer=manufacturer,
            serial_number=serial_number,
            limit=limit,
        )
        merged = memory + [
            r for r in stored if r.order_id not in self.tracks and self.queued(r.order_id) is None
        ]
        merged.sort(key=_created_text, reverse=True)
        return merged[:limit]

    async def order_history(self, order_id: str) -> tuple[OrderEvent, ...] | None:
        """The order's history (everything queued is written first); None without a store."""
        if self.journal is None:
            return None
        await self.journal.writer.flush(timeout_s=HISTORY_FLUSH_TIMEOUT_S)
        return await self.journal.store.order_events(order_id)


def _vehicle_matches(agv: AgvId | None, manufacturer: str | None, serial: str | None) -> bool:
    """Whether an order of ``agv`` (None: a queued order for any vehicle) passes the listing's
    vehicle filters."""
    if manufacturer is None and serial is None:
        return True
    if agv is None:
        return False
    return (manufacturer is None or agv.manufacturer == manufacturer) and (
        serial is None or agv.serial_number == serial
    )


def _created_text(order: OrderTrack | QueuedOrder | OrderRecord) -> str:
    """Creation time as sortable UTC text (both forms use the header timestamp format)."""
    if isinstance(order, OrderRecord):
        return format_timestamp(order.created_at)
    return order.created_utc
