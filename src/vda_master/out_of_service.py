"""Vehicles an operator takes out of service (``PATCH /vehicles/{manufacturer}/{serialNumber}``
with ``inService: false``; docs/master.md, *Out of service*): a robot due for maintenance, one
whose scanner needs cleaning, one kept free for a test.

Mixed into :class:`vda_master.service.MasterService`. While a vehicle is out of service,
:meth:`vda_master.operations.Operations.availability` names it as the reason, so master control
sends it nothing of its own accord and nothing a client asks for: ``POST /orders`` naming it
answers 409 (with ``queue: true`` the order waits until it is back), no order without a vehicle
goes to it, the queue passes it over, energy management does not send it to charge and traffic
control does not move it out of the way (it plans around it as around any idle vehicle). Instant
actions still go to it: an operator may need them. An order it runs when taken out of service
runs to its end (``DELETE /orders/{id}`` stops it).

The mark is written to the store before it acts, and restored at start before any order is
recovered, so it outlives a restart of master control. A vehicle out of service stays in the
fleet view (``GET /vehicles``, the map) while it is silent, and after a restart before it is
heard from again, so that it can always be seen and put back.
"""

from __future__ import annotations

import asyncio
from dataclasses import replace
from typing import TYPE_CHECKING

import structlog

from vda5050.clock import Clock, format_timestamp
from vda5050.topics import AgvId
from vda_master.fleet import FleetView, VehicleView
from vda_master.journal import Journal
from vda_master.live import LiveView
from vda_master.store import OutOfServiceRecord

log = structlog.get_logger()


def out_of_service_reason(record: OutOfServiceRecord) -> str:
    """Why the vehicle takes no order, as ``unavailableReason`` and a 409 say it."""
    note = f": {record.note}" if record.note else ""
    return f"it is out of service since {format_timestamp(record.since)}{note}"


class OutOfService:
    """The vehicles taken out of service, and putting them back."""

    clock: Clock
    journal: Journal | None
    live: LiveView
    fleet: FleetView
    active: dict[AgvId, str]

    if TYPE_CHECKING:

        def known_vehicle(self, agv: AgvId) -> VehicleView: ...
        def serve_queue_afresh(self, now: float) -> None: ...

    def _init_out_of_service(self) -> None:
        #: The vehicles out of service now, with the operator's note and since when.
        self.out_of_service: dict[AgvId, OutOfServiceRecord] = {}
        #: One change at a time: a change is stored before it acts.
        self._service_lock = asyncio.Lock()

    def service_hold(self, agv: AgvId) -> str | None:
        """Why ``agv`` is out of service, or None when it is in service."""
        record = self.out_of_service.get(agv)
        return None if record is None else out_of_service_reason(record)

    def taken_for_good(self, node_id: str, *, but: AgvId | None = None) -> str | None:
        """Why an order cannot end at ``node_id``: a vehicle out of service (other than
        ``but``) stands there idle, and master control does not move it out of the way; None
        when none does."""
        for agv, record in self.out_of_service.items():
            vehicle = self.fleet.get(agv)
            state = None if vehicle is None else vehicle.state
            if agv != but and agv not in self.active and state and state.last_node_id == node_id:
                return (
                    f"node {node_id!r} is taken by {agv}, which stands there out of service "
                    f"({out_of_service_reason(record).removeprefix('it is ')}); put it back in "
                    "service or choose another node"
                )
        return None

    async def set_in_service(self, agv: AgvId, *, in_service: bool, note: str = "") -> VehicleView:
        """Take a known vehicle out of service (a vehicle already out keeps its ``since`` and
        gets the new note) or put it back; 404 for a vehicle never heard from. Stored first."""
        self.known_vehicle(agv)
        async with self._service_lock:
            if in_service:
                await self._put_back(agv)
            else:
                await self._take_out(agv, note)
        self.live.vehicle_changed(agv)
        return self.known_vehicle(agv)  # as it is now: states came in while the store wrote

    async def _take_out(self, agv: AgvId, note: str) -> None:
        known = self.out_of_service.get(agv)
        if known is not None and known.note == note:
            return
        record = (
            OutOfServiceRecord(agv.manufacturer, agv.serial_number, note, self.clock.now())
            if known is None
            else replace(known, note=note)
        )
        if self.journal is not None:
            await self.journal.store.put_out_of_service(record)
        self.out_of_service[agv] = record
        log.info("vehicle.out_of_service", agv=str(agv), note=note, changed=known is not None)

    async def _put_back(self, agv: AgvId) -> None:
        if agv not in self.out_of_service:
            return
        if self.journal is not None:
            await self.journal.store.delete_out_of_service(agv.manufacturer, agv.serial_number)
        del self.out_of_service[agv]
        log.info("vehicle.in_service", agv=str(agv))
        # orders waiting for it, or for the node it stands on, go now
        self.serve_queue_afresh(self.clock.monotonic())

    def restore_out_of_service(self, records: tuple[OutOfServiceRecord, ...]) -> None:
        """At start, before orders are recovered: the vehicles an earlier run had out of
        service. Each is listed from the start, as a vehicle of ``robots`` is, heard from or
        not, so that it can be seen and put back."""
        now = self.clock.monotonic()
        for record in records:
            agv = AgvId(record.manufacturer, record.serial_number)
            self.out_of_service[agv] = record
            if self.fleet.get(agv) is None:
                self.fleet = self.fleet.with_vehicle(VehicleView(agv, now, now))
        if records:
            log.info("vehicles.out_of_service_restored", vehicles=len(records))
