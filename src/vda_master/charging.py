"""Energy management in the master service: vehicles sent to charge and their charges ended
(the rules: :mod:`vda_master.charge_rules`; docs/master.md, *Charging*).

Mixed into :class:`vda_master.service.MasterService`; :meth:`Charging.manage_charging` runs once
a (simulated) second from the tick, :meth:`Charging.charge_if_low` when a vehicle's order ends.
A charging order is an order of master control's own (``note`` "charging: ..."), planned and
released like any other, traffic control included; until it has ended, ``POST /orders`` for
the vehicle answers 409 saying so.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Collection, Sequence
from typing import TYPE_CHECKING, Final

import structlog

from vda5050.clock import Clock
from vda5050.models import Action, InstantActions, Order, State
from vda5050.topics import AgvId
from vda_master.capabilities import ActionSpec
from vda_master.charge_rules import (
    CHARGING_NOTE,
    RETRY_AFTER_S,
    ChargeAttempt,
    ChargeSettings,
    charge_done,
    charging_queue,
    charging_reason,
    free_chargers,
    retry_blocked,
    spots_for,
    vacating,
    wants_charge,
)
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderTrack
from vda_master.fleet import FleetSettings, FleetView, VehicleView, is_idle, not_ready_reason
from vda_master.graph import Graph
from vda_master.planner import Router, Target, departure_node, route_for
from vda_master.requests import RequestError, instant_actions_message
from vda_master.routing import Route, nearest_route
from vda_master.start import find_start

log = structlog.get_logger()
#: Wall seconds before a stopCharging the vehicle's state does not answer yet is sent again.
STOP_REPEAT_S: Final = 5.0
START_CHARGING: Final = ActionSpec("startCharging")
STOP_CHARGING: Final = ActionSpec("stopCharging")


class Charging:
    """Who charges where, and when a charge ends."""

    config: MasterConfig
    clock: Clock
    graph: Graph
    fleet: FleetView
    tracks: dict[str, OrderTrack]
    active: dict[AgvId, str]
    fleet_settings: FleetSettings

    if TYPE_CHECKING:

        def availability(
            self, vehicle: VehicleView, now: float, *, automatic_only: bool = True
        ) -> str | None: ...
        def start_order(
            self,
            vehicle: VehicleView,
            route: Route,
            destination_actions: tuple[ActionSpec, ...],
            now: float,
            *,
            note: str = "",
        ) -> OrderTrack: ...
        def _router(self, now: float) -> Router | None: ...
        def _instant_action(self, vehicle: VehicleView, spec: ActionSpec) -> Action: ...
        def _publish(self, agv: AgvId, message: Order | InstantActions, now: float) -> None: ...

    def _init_charging(self) -> None:
        self.charge_settings = ChargeSettings(self.config.charge_below_pct, self.config.charged_pct)
        self._charge_attempts: dict[AgvId, ChargeAttempt] = {}
        self._stops_sent: dict[AgvId, float] = {}
        #: (vehicle, event) logged already: one line per vehicle and situation, not per second.
        self._charge_said: set[tuple[AgvId, str]] = set()
        #: Charges an operator started through the API (startCharging as an instant action or
        #: in an order asked for): they run until the operator or the vehicle ends them. The
        #: value: when it was asked for, None once the vehicle has been seen charging (the mark
        #: goes when it stops, or when it has not started within RETRY_AFTER_S).
        self._operator_charges: dict[AgvId, float | None] = {}

    def note_operator_charge(self, agv: AgvId) -> None:
        """An operator asked for ``agv`` to charge: master control does not end that charge."""
        self._operator_charges[agv] = self.clock.monotonic()

    def manage_charging(self, now: float) -> None:
        """End the charges that are done, send the vehicles that want one to a free charger."""
        settings = self.charge_settings
        if not settings.enabled:
            return
        chargers = self.graph.station_nodes("charging")
        wanting: list[VehicleView] = []
        for vehicle in self.fleet:
            state = vehicle.state
            if state is None:
                continue
            operators = self._operator_charges
            if (
                operators
                and vehicle.agv in operators
                and not self._operator_charge_over(vehicle.agv, state, now)
            ):
                continue
            if charge_done(state, settings):
                self._end_charge(vehicle, now)
            elif wants_charge(state, settings):
                if chargers:
                    wanting.append(vehicle)
            elif self._charge_said:
                self._charge_said.discard((vehicle.agv, "charging.waiting"))
        if wanting:
            self._send_to_chargers(wanting, chargers, now)

    def _operator_charge_over(self, agv: AgvId, state: State, now: float) -> bool:
        """Whether the operator's charge is over (the vehicle charged and stopped, or never
        started within RETRY_AFTER_S): the mark goes and the vehicle is managed again."""
        asked_at = self._operator_charges[agv]
        if state.battery_state.charging:
            self._operator_charges[agv] = None
            return False
        if asked_at is None or now - asked_at >= RETRY_AFTER_S / self.config.time_lapse:
            del self._operator_charges[agv]
            return True
        return False

    def charge_if_low(self, agv: AgvId, state: State, now: float) -> None:
        """An order of the vehicle just ended: if it wants a charge, it goes now, before a
        client's next order (which would otherwise race the once-a-second look) takes it."""
        if not wants_charge(state, self.charge_settings) or agv in self.active:
            return
        chargers = self.graph.station_nodes("charging")
        vehicle = self.fleet.get(agv)
        if chargers and vehicle is not None:
            self._send_to_chargers([vehicle], chargers, now)

    def _end_charge(self, vehicle: VehicleView, now: float) -> None:
        """§6.8.2 stopCharging to a vehicle charged enough that runs no order."""
        agv, state = vehicle.agv, vehicle.state
        if state is None or agv in self.active or not is_idle(state):
            return
        if now - self._stops_sent.get(agv, -math.inf) < STOP_REPEAT_S:
            return
        if not_ready_reason(vehicle, now, self.fleet_settings) is not None:
            return
        try:
            action = self._instant_action(vehicle, STOP_CHARGING)
        except RequestError as refused:
            self._say_once(agv, "charging.cannot_stop", reason=refused.message)
            return
        self._stops_sent[agv] = now
        self._publish(agv, instant_actions_message(agv, [action]), now)
        log.info(
            "charging.ended",
            agv=str(agv),
            battery=state.battery_state.battery_charge,
            charged_pct=self.charge_settings.until_pct,
        )

    def _send_to_chargers(
        self, wanting: Sequence[VehicleView], chargers: tuple[str, ...], now: float
    ) -> None:
        standing: dict[str, set[AgvId]] = defaultdict(set)
        for vehicle in self.fleet:
            if vehicle.state is not None and vehicle.state.last_node_id:
                standing[vehicle.state.last_node_id].add(vehicle.agv)
        bound = {
            track.plan.destination
            for order_id in self.active.values()
            if (track := self.tracks.get(order_id)) is not None
        }
        free = free_chargers(chargers, standing, bound)
        retry_s = RETRY_AFTER_S / self.config.time_lapse
        ready: dict[AgvId, VehicleView] = {}
        for vehicle in wanting:
            assert vehicle.state is not None  # noqa: S101 - only vehicles with a state want one
            battery = vehicle.state.battery_state.battery_charge
            if self.availability(vehicle, now) is not None:
                continue
            if retry_blocked(self._charge_attempts.get(vehicle.agv), battery, now, retry_s):
                self._say_once(
                    vehicle.agv,
                    "charging.not_charging",
                    battery=battery,
                    reason="its battery has not risen since master control last sent it to "
                    f"charge; it is not sent again for {RETRY_AFTER_S:g} s",
                )
                continue
            ready[vehicle.agv] = vehicle
        queue = charging_queue(
            (agv, v.state.battery_state.battery_charge) for agv, v in ready.items() if v.state
        )
        unplaced: list[AgvId] = []
        for agv in queue:
            vehicle = ready[agv]
            own = vehicle.state.last_node_id if vehicle.state else ""
            spots = spots_for(
                agv, own, chargers=chargers, standing=standing, bound_for=bound, free=free
            )
            if not spots:
                self._say_once(agv, "charging.waiting", reason="every charger is taken")
                unplaced.append(agv)
                continue
            sent = self._send_to_charge(vehicle, spots, now)
            if sent is not None:
                bound.add(sent)
                free = [c for c in free if c != sent]
        soon_free = vacating(chargers, standing, bound, self.active.keys())
        for agv in unplaced[len(soon_free) :]:
            self._make_room(agv, chargers, standing, bound, now)

    def _send_to_charge(
        self, vehicle: VehicleView, spots: Collection[str], now: float
    ) -> str | None:
        """An order to the nearest of ``spots`` with startCharging there; the node, or None."""
        route = self._route_to_nearest(vehicle, spots, now)
        if route is None:
            self._say_once(vehicle.agv, "charging.no_route", chargers=sorted(spots))
            return None
        assert vehicle.state is not None  # noqa: S101 - checked by the caller
        battery = vehicle.state.battery_state.battery_charge
        reason = charging_reason(battery, self.charge_settings)
        try:
            self.start_order(vehicle, route, (START_CHARGING,), now, note=CHARGING_NOTE + reason)
        except RequestError as refused:
            self._say_once(vehicle.agv, "charging.cannot_send", reason=refused.message)
            return None
        self._charge_attempts[vehicle.agv] = ChargeAttempt(now, battery)
        self._charge_said.discard((vehicle.agv, "charging.waiting"))
        log.info(
            "charging.sent",
            agv=str(vehicle.agv),
            node_id=route.destination,
            battery=battery,
            charge_below_pct=self.charge_settings.below_pct,
        )
        return route.destination

    def _make_room(
        self,
        waiting: AgvId,
        chargers: tuple[str, ...],
        standing: dict[str, set[AgvId]],
        bound: set[str],
        now: float,
    ) -> None:
        """Move one vehicle that stands idle on a charger without charging to free parking."""
        parking = [p for p in self.graph.station_nodes("parking") if p not in standing]
        parking = [p for p in parking if p not in bound]
        if not parking:
            return
        for charger in chargers:
            for agv in sorted(standing.get(charger, ()), key=str):
                vehicle = self.fleet.get(agv)
                state = None if vehicle is None else vehicle.state
                if vehicle is None or state is None or state.battery_state.charging:
                    continue
                if wants_charge(state, self.charge_settings) or agv in self.active:
                    continue
                if self.availability(vehicle, now) is not None:
                    continue
                route = self._route_to_nearest(vehicle, parking, now)
                if route is None:
                    continue
                note = f"{CHARGING_NOTE}making room at charger {charger!r} for {waiting}"
                try:
                    self.start_order(vehicle, route, (), now, note=note)
                except RequestError:
                    continue
                bound.add(route.destination)
                log.info(
                    "charging.room_made",
                    agv=str(agv),
                    charger=charger,
                    node_id=route.destination,
                    waiting=str(waiting),
                )
                return

    def _route_to_nearest(
        self, vehicle: VehicleView, nodes: Collection[str], now: float
    ) -> Route | None:
        """The route to the nearest of ``nodes`` by length; with traffic control, planned
        round the others' expected passages to that node."""
        start = find_start(self.graph, vehicle.state)
        if isinstance(start, str):
            return None
        nearest = nearest_route(self.graph, departure_node(self.graph, start), nodes)
        if not isinstance(nearest, Route):
            return None
        target = Target(destination=nearest.destination)
        route = route_for(self.graph, vehicle, target, self._router(now))
        return route if isinstance(route, Route) else None

    def _say_once(self, agv: AgvId, event: str, **fields: object) -> None:
        if (agv, event) not in self._charge_said:
            self._charge_said.add((agv, event))
            log.info(event, agv=str(agv), **fields)
