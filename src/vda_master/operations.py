"""What the HTTP API asks of master control: new orders, cancels, instant actions, lookups.

:class:`Operations` is the request side of :class:`vda_master.service.MasterService`, kept in its
own module; it works on the service's fleet view and order tracks through the attributes
declared below. Refusals are :class:`vda_master.requests.RequestError` with the HTTP status to
answer (404 unknown, 409 not now, 422 wrong request or never possible).
"""

from __future__ import annotations

import itertools
from collections.abc import Collection
from http import HTTPStatus
from typing import TYPE_CHECKING

import structlog

from vda5050.clock import Clock, format_timestamp
from vda5050.codec import encode
from vda5050.evolve import evolve
from vda5050.models import Action, ActionParameter, ActionScope, BlockingType, InstantActions, Order
from vda5050.topics import AgvId
from vda_master import capabilities as caps
from vda_master.capabilities import ActionSpec
from vda_master.charge_rules import CHARGING_NOTE, ChargeSettings, reach_problem, wants_charge
from vda_master.config import MasterConfig
from vda_master.coordination import Coordinator
from vda_master.dispatcher import (
    TRAFFIC_NOTE,
    DispatchSettings,
    OrderTrack,
    request_cancel,
    start_track,
)
from vda_master.fleet import (
    FleetSettings,
    FleetView,
    VehicleView,
    not_ready_reason,
    unavailable_reason,
)
from vda_master.graph import Graph
from vda_master.load_rules import (
    Fit,
    LoadFit,
    LoadNeed,
    load_fit,
    load_need,
    load_set_problem,
)
from vda_master.map_rules import map_problem
from vda_master.order_builder import (
    BuildProblem,
    PlanRequest,
    build_message,
    plan_order,
    stop_actions,
)
from vda_master.planner import Chooser, Router, Target, choose_vehicle, route_for
from vda_master.queue_rules import QueuedOrder
from vda_master.release import release_end
from vda_master.requests import (
    PROBLEM_STATUS,
    OrderRequest,
    RequestError,
    instant_actions_message,
    speaking_version,
)
from vda_master.routing import ProblemKind, Route, RouteProblem, nearest_route, shortest_route
from vda_master.start import find_start
from vda_master.stops import Stop

log = structlog.get_logger()
#: 3.0: wakes a HIBERNATING vehicle (T06).
STOP_HIBERNATION = "stopHibernation"
#: An operator's charge (an instant action or in an order asked for) runs until ended by hand.
START_CHARGING = "startCharging"


class Operations:
    """The operations behind the HTTP API; mixed into the service that owns the state."""

    config: MasterConfig
    graph: Graph
    clock: Clock
    fleet: FleetView
    tracks: dict[str, OrderTrack]
    active: dict[AgvId, str]
    fleet_settings: FleetSettings
    dispatch_settings: DispatchSettings
    coordinator: Coordinator
    charge_settings: ChargeSettings

    if TYPE_CHECKING:

        def reruns_stop_actions(self, agv: AgvId) -> str | None: ...

        def _new_id(self) -> str: ...
        def _pump(self, agv: AgvId, now: float) -> None: ...
        def zone_set_lag(self, agv: AgvId) -> str | None: ...
        def service_hold(self, agv: AgvId) -> str | None: ...
        def taken_for_good(self, node_id: str, *, but: AgvId | None = None) -> str | None: ...
        def _store(self, agv: AgvId, track: OrderTrack) -> None: ...
        def _publish(self, agv: AgvId, message: Order | InstantActions, now: float) -> None: ...
        def clear_the_way(self, agv: AgvId, now: float) -> None: ...
        def _file_early_wait(self, agv: AgvId) -> None: ...
        def note_operator_charge(self, agv: AgvId) -> None: ...
        def serve_before_new(self, now: float) -> None: ...
        def enqueue(self, request: OrderRequest, reason: str) -> QueuedOrder: ...
        def queued(self, order_id: str) -> QueuedOrder | None: ...
        def cancel_queued(self, order_id: str) -> QueuedOrder: ...
        def reprioritize(self, order_id: str, priority: int) -> QueuedOrder: ...

    def place_order(self, request: OrderRequest) -> OrderTrack | QueuedOrder:
        """:meth:`create_order`; with ``request.queue``, what would be a 409 keeps the order
        waiting for a vehicle instead (:mod:`vda_master.order_queue`), after those already
        waiting had their turn."""
        if not request.queue:
            return self.create_order(request)
        now = self.clock.monotonic()
        self.serve_before_new(now)
        try:
            return self.create_order(request)
        except RequestError as exc:
            if exc.status != HTTPStatus.CONFLICT:
                raise
            self._check_never(request)
            return self.enqueue(request, exc.message)

    def create_order(
        self,
        request: OrderRequest,
        *,
        now: float | None = None,
        order_id: str | None = None,
        created_utc: str | None = None,
    ) -> OrderTrack:
        """Plan, track and send a new order; raises :class:`RequestError` (404/409/422).
        ``order_id`` and ``created_utc``: a queued order's own (a new id and now otherwise)."""
        now = self.clock.monotonic() if now is None else now
        vehicle, route = self._select(request, now)
        if request.onward:
            self._check_onward(vehicle, route, request.onward)
        track = self.start_order(
            vehicle,
            route,
            request.destination_actions,
            now,
            request_json=request.as_json(),
            order_id=order_id,
            created_utc=created_utc,
            onward=request.onward,
        )
        if any(a.action_type == START_CHARGING for a in request.destination_actions):
            self.note_operator_charge(vehicle.agv)
        return track

    def _check_never(self, request: OrderRequest) -> None:
        """422 for an order that would wait for a named vehicle that can never take it: an
        action at the destination its factsheet does not offer there (R112)."""
        if request.agv is None:
            return
        factsheet = self.known_vehicle(request.agv).factsheet
        if factsheet is None:
            return
        for spec in request.destination_actions:
            declared = caps.declared_action(factsheet, spec.action_type, ActionScope.NODE)
            if isinstance(declared, str):
                msg = f"vehicle {request.agv} cannot take this order: {declared}"
                raise RequestError(422, msg)

    def start_order(
        self,
        vehicle: VehicleView,
        route: Route,
        destination_actions: tuple[ActionSpec, ...],
        now: float,
        *,
        note: str = "",
        request_json: str = "{}",
        order_id: str | None = None,
        created_utc: str | None = None,
        onward: tuple[Stop, ...] = (),
    ) -> OrderTrack:
        """Build, track and send the order that drives ``route``; the first base is what the
        release window wants and traffic control allows. ``note`` says why the master itself
        created it (traffic), empty for orders that were asked for; ``request_json`` is what
        the API was asked (kept in the store); ``order_id`` and ``created_utc`` are a queued
        order's own (a new id and now otherwise); ``onward``: the stops after ``route``'s
        end, each appended once the vehicle stands at the one before (:mod:`stops`)."""
        order_id = order_id or self._new_id()
        plan = plan_order(
            self.graph,
            PlanRequest(route, order_id, {len(route.edge_ids): destination_actions}, {}),
            agv=vehicle.agv,
            version=speaking_version(vehicle.version),
            factsheet=vehicle.factsheet,
            action_ids=(self._new_id() for _ in itertools.count()),
        )
        if isinstance(plan, BuildProblem):
            raise RequestError(422, f"vehicle {vehicle.agv} cannot take this order: {plan.reason}")
        max_nodes = caps.max_order_nodes(vehicle.factsheet)
        whole = build_message(
            plan, first=0, release_end=plan.last_index, update_id=0, max_nodes=max_nodes
        )
        size = caps.message_size_problem(vehicle.factsheet, len(encode(whole)))
        if size is not None:
            raise RequestError(422, f"vehicle {vehicle.agv} cannot take this order: {size}")
        self.coordinator.assign(vehicle.agv, route, now)
        desired = release_end(self.dispatch_settings.release, plan.last_index, 0)
        granted = self.coordinator.grant(
            vehicle.agv, route, progress=0, released_end=0, desired_end=desired, now=now
        )
        track = start_track(
            plan,
            self.dispatch_settings,
            max_nodes=max_nodes,
            now=now,
            created_utc=created_utc or format_timestamp(self.clock.now()),
            granted_end=granted,
            note=note,
            whole=whole,
        )
        self._store(vehicle.agv, evolve(track, request_json=request_json, onward=onward))
        self.active[vehicle.agv] = order_id
        self._file_early_wait(vehicle.agv)
        self.clear_the_way(vehicle.agv, now)
        log.info(
            "order.created",
            order_id=order_id,
            agv=str(vehicle.agv),
            edges=list(route.edge_ids),
            length_m=round(route.length_m, 3),
            released_nodes=granted + 1,
            note=note or None,
        )
        self._pump(vehicle.agv, now)
        return self.tracks[order_id]

    def _router(self, now: float) -> Router | None:
        """Time-aware routes from traffic control, or None (shortest routes) when it is off."""
        if not self.coordinator.enabled:
            return None

        def route(agv: AgvId, start: str, destination: str) -> Route | None:
            planned = self.coordinator.plan(agv, start, destination, now)
            return None if planned is None else planned.route

        return route

    def _chooser(self, now: float) -> Chooser | None:
        """The vehicle and destination expected to meet first, counting traffic (None when
        off)."""
        if not self.coordinator.enabled:
            return None

        def choose(
            options: list[tuple[AgvId, str]], destinations: tuple[str, ...]
        ) -> tuple[AgvId, Route] | None:
            chosen = self.coordinator.choose(options, destinations, now)
            return None if chosen is None else (chosen[0], chosen[1].route)

        return choose

    def _select(self, request: OrderRequest, now: float) -> tuple[VehicleView, Route]:
        target = request.target
        self._check_target(target, request.agv)
        need = load_need(request.destination_actions)
        later = tuple(load_need(stop.actions) for stop in request.onward)
        if request.agv is None:
            return self._choose(target, need, now, stops=bool(request.onward), later=later)
        vehicle = self.known_vehicle(request.agv)
        rerun = self.reruns_stop_actions(vehicle.agv) if request.onward else None
        if rerun is not None:
            raise RequestError(422, f"vehicle {vehicle.agv} takes no order with stops: {rerun}")
        unsuited = _unsuited(vehicle, need, later)
        if unsuited is not None:
            raise RequestError(422, f"vehicle {vehicle.agv} cannot take this order: {unsuited}")
        reason = self.availability(vehicle, now, automatic_only=False)
        if reason is not None:
            raise RequestError(409, f"vehicle {vehicle.agv} is not available: {reason}")
        fit = _load_fit(vehicle, need)
        if fit.fit is Fit.REFUSED:
            raise RequestError(409, f"vehicle {vehicle.agv} cannot {need.action} now: {fit.reason}")
        if target.station_type is not None:
            chosen = choose_vehicle(
                self.graph, [vehicle], target, self._chooser(now), busy=self._busy_nodes([vehicle])
            )
            if chosen is None:
                raise RequestError(409, f"vehicle {vehicle.agv} cannot reach {target.describe()}")
            _check_reach(vehicle, chosen[1])
            return chosen
        route = route_for(self.graph, vehicle, target, self._router(now))
        if isinstance(route, RouteProblem):
            raise RequestError(PROBLEM_STATUS[route.kind], route.reason)
        _check_reach(vehicle, route)
        return vehicle, route

    def _check_onward(self, vehicle: VehicleView, route: Route, onward: tuple[Stop, ...]) -> None:
        """The stops after the first, checked before anything is sent: 404 for a node or
        station type the graph lacks, 409 for one a BLOCKED zone closes or that no route
        reaches from the stop before it, or when the battery does not reach the last; 422 for an
        action the vehicle's factsheet does not offer there (R112)."""
        at, length = route.destination, route.length_m
        for number, stop in enumerate(onward, start=2):
            target = Target(destination=stop.destination, station_type=stop.station_type)
            self._check_target(target, vehicle.agv)
            leg = self._leg(at, stop)
            if isinstance(leg, RouteProblem):
                raise RequestError(409, f"stop {number}: {leg.reason}")
            built = stop_actions(
                self.graph,
                leg.destination,
                stop.actions,
                factsheet=vehicle.factsheet,
                action_ids=(str(i) for i in itertools.count()),
            )
            if isinstance(built, BuildProblem):
                msg = f"vehicle {vehicle.agv} cannot take this order: stop {number}: {built.reason}"
                raise RequestError(422, msg)
            at, length = leg.destination, length + leg.length_m
        short = reach_problem(vehicle.state, length)
        if short is not None:
            raise RequestError(409, f"vehicle {vehicle.agv} cannot drive this order: {short}")

    def _leg(self, start: str, stop: Stop) -> Route | RouteProblem:
        """The shortest route from ``start`` to ``stop`` (the nearest node of its station type
        other than ``start``)."""
        if stop.destination is not None:
            return shortest_route(self.graph, start, stop.destination)
        candidates = [n for n in self.graph.station_nodes(stop.station_type or "") if n != start]
        if not candidates:
            return RouteProblem(
                ProblemKind.NO_ROUTE,
                f"no other node of stationType {stop.station_type!r} than {start!r}",
            )
        return nearest_route(self.graph, start, candidates)

    def _check_target(self, target: Target, agv: AgvId | None = None) -> None:
        """404 for a destination, edge or station type the graph does not have; 409 for one a
        BLOCKED zone closes (docs/master.md, Zones) or a vehicle out of service stands on
        (other than ``agv``, the one the order is for)."""
        graph = self.graph
        if target.destination is not None and target.destination not in graph.nodes:
            raise RequestError(404, f"node {target.destination!r} is not in the graph")
        closed_node = (
            None
            if target.destination is None
            else graph.node_closed(target.destination)
            or self.taken_for_good(target.destination, but=agv)
        )
        if closed_node is not None:
            raise RequestError(409, closed_node)
        closed = [e for e in target.route or () if e in graph.blocked_edges]
        if closed:
            zone = graph.blocked_edges[closed[0]].zone_id
            raise RequestError(409, f"edge {closed[0]!r} enters BLOCKED zone {zone!r}")
        unknown = [e for e in target.route or () if e not in graph.edges]
        if unknown:
            raise RequestError(404, f"edge {unknown[0]!r} is not in the graph")
        closed_type = (
            None if target.station_type is None else graph.station_type_closed(target.station_type)
        )
        if closed_type is not None:
            why, known = closed_type
            raise RequestError(409 if known else 404, why)

    def _choose(
        self,
        target: Target,
        need: LoadNeed,
        now: float,
        *,
        stops: bool = False,
        later: tuple[LoadNeed, ...] = (),
    ) -> tuple[VehicleView, Route]:
        candidates, reasons = [], []
        for vehicle in self.fleet:
            reason = self.availability(vehicle, now)
            if reason is None and stops:
                reason = self.reruns_stop_actions(vehicle.agv)
            if reason is None:
                unsuited = _unsuited(vehicle, need, later)
                reason = None if unsuited is None else f"cannot take this order: {unsuited}"
            if reason is None:
                candidates.append(vehicle)
            else:
                reasons.append(f"{vehicle.agv}: {reason}")
        busy = self._busy_nodes(candidates) if target.station_type is not None else ()
        # vehicles that want a charge (and wait for a charger) only when no other can go; among
        # each, those whose loads are known to suit a pick or drop before those that may
        groups: dict[tuple[bool, Fit], list[VehicleView]] = {
            (low, fit): [] for low in (False, True) for fit in (Fit.FITS, Fit.UNKNOWN)
        }
        for vehicle in candidates:
            fit = _load_fit(vehicle, need)
            if fit.fit in (Fit.REFUSED, Fit.UNSUITED):
                reasons.append(f"{vehicle.agv}: cannot {need.action} now: {fit.reason}")
                continue
            wants = bool(vehicle.state and wants_charge(vehicle.state, self.charge_settings))
            groups[wants, fit.fit].append(vehicle)
        for group in groups.values():
            chosen = self._first_within_reach(group, target, busy, reasons, now)
            if chosen is not None:
                return chosen
        detail = "; ".join(reasons[:5]) or "no vehicle has reported"
        raise RequestError(409, f"no available vehicle can reach {target.describe()} ({detail})")

    def _first_within_reach(
        self,
        candidates: list[VehicleView],
        target: Target,
        busy: Collection[str],
        reasons: list[str],
        now: float,
    ) -> tuple[VehicleView, Route] | None:
        """The candidate expected at ``target`` first whose battery reaches it; each one passed
        over for its reach is added to ``reasons``."""
        while candidates:
            chosen = choose_vehicle(self.graph, candidates, target, self._chooser(now), busy=busy)
            if chosen is None:
                return None
            short = reach_problem(chosen[0].state, chosen[1].length_m)
            if short is None:
                return chosen
            reasons.append(f"{chosen[0].agv}: {short}")
            candidates = [v for v in candidates if v.agv != chosen[0].agv]
        return None

    def _busy_nodes(self, candidates: Collection[VehicleView]) -> set[str]:
        """Nodes an active order is bound for, and nodes idle vehicles other than ``candidates``
        stand on: a station of a type there is taken (traffic control off; with it on, the
        planner counts the others' routes and stays instead)."""
        busy = {
            track.plan.destination
            for order_id in self.active.values()
            if (track := self.tracks.get(order_id)) is not None
        }
        ours = {v.agv for v in candidates}
        for vehicle in self.fleet:
            state = vehicle.state
            idle = vehicle.agv not in self.active and vehicle.agv not in ours
            if idle and state is not None and state.last_node_id:
                busy.add(state.last_node_id)
        return busy

    def availability(
        self, vehicle: VehicleView, now: float, *, automatic_only: bool = True
    ) -> str | None:
        """Why ``vehicle`` cannot take a new order now, or None when it can.

        Never None while its next order would be rejected (issue 8): besides the fleet view's
        conditions, the next order must be plannable from where the vehicle stands, on a map
        the vehicle has ENABLED when it lists its maps (:func:`map_rules.map_problem`). Never None
        for a vehicle an operator took out of service (:mod:`vda_master.out_of_service`).
        """
        running = self.active.get(vehicle.agv)
        # the operator's word (out of service) first, then the order it runs
        busy = self.service_hold(vehicle.agv) or (
            None if running is None else _running(running, self.tracks.get(running))
        )
        if busy is not None:
            return busy
        reason = unavailable_reason(
            vehicle, now, self.fleet_settings, automatic_only=automatic_only
        )
        if reason is not None:
            return reason
        lag = self.zone_set_lag(vehicle.agv)
        if lag is not None:
            return lag
        return self._start_problem(vehicle)

    def _start_problem(self, vehicle: VehicleView) -> str | None:
        """Why the vehicle's next order cannot start where it stands: no plannable start, a
        temporary start node its factsheet does not allow, or (when it lists its maps) a map
        there it has not ENABLED (§6.7.1)."""
        start = find_start(self.graph, vehicle.state)
        if isinstance(start, str):
            return f"its next order cannot be planned: {start}"
        if start.position is not None and not caps.supports_field(
            vehicle.factsheet, caps.NODE_POSITION
        ):
            return (
                f"it stands {start.offset_m:.2f} m off node {start.node_id!r} and its factsheet "
                "does not allow the nodePosition a temporary start node needs (§6.6.3.1)"
            )
        if vehicle.state is not None and vehicle.state.maps:  # 2.1 and 3.0
            return map_problem(
                vehicle.state, self.graph.node_map_id(self.graph.nodes[start.node_id])
            )
        return None

    def availability_of(self, agv: AgvId) -> str | None:
        """:meth:`availability` of a known vehicle now ("it is unknown" otherwise)."""
        vehicle = self.fleet.get(agv)
        if vehicle is None:
            return "it is unknown"
        return self.availability(vehicle, self.clock.monotonic())

    def recent_orders(self, limit: int) -> list[OrderTrack]:
        """The newest ``limit`` orders in memory (every active one and the latest ended ones),
        newest first; ``find_orders`` also reads the store."""
        return list(itertools.islice(reversed(self.tracks.values()), limit))

    def known_vehicle(self, agv: AgvId) -> VehicleView:
        """The vehicle's view; 404 if it never published anything valid."""
        vehicle = self.fleet.get(agv)
        if vehicle is None:
            raise RequestError(404, f"vehicle {agv} is unknown: it never published a valid message")
        return vehicle

    def known_order(self, order_id: str) -> OrderTrack:
        """The order's track; 404 if this master never created it."""
        track = self.tracks.get(order_id)
        if track is None:
            raise RequestError(404, f"order {order_id!r} is unknown")
        return track

    def cancel_order(self, order_id: str) -> OrderTrack | QueuedOrder:
        """Send ``cancelOrder`` for an active order (§6.6.3), or end a queued one at once; 404
        unknown, 409 already ended."""
        if self.queued(order_id) is not None:
            return self.cancel_queued(order_id)
        track = self.known_order(order_id)
        cancelled = self._with_cancel(track)
        if isinstance(cancelled, str):
            raise RequestError(409, cancelled)
        self._store(track.plan.agv, cancelled)
        log.info("order.cancel_requested", order_id=order_id, action_id=cancelled.cancel_action_id)
        self._pump(track.plan.agv, self.clock.monotonic())
        return self.tracks[order_id]

    def reprioritize_order(self, order_id: str, priority: int) -> QueuedOrder:
        """A queued order's new priority; 409 once a vehicle took it or it ended (404 is the
        caller's: an order this master has in its store only has ended)."""
        if self.queued(order_id) is not None:
            return self.reprioritize(order_id, priority)
        track = self.tracks.get(order_id)
        sent = f"was sent to {track.plan.agv} ({track.status.value})" if track else "has ended"
        raise RequestError(
            409, f"order {order_id!r} {sent}: only a queued order's priority changes"
        )

    def _with_cancel(self, track: OrderTrack) -> OrderTrack | str:
        """``track`` with a ``cancelOrder`` to send (§6.6.3), or why not (it ended, or is
        being cancelled already)."""
        action = Action(
            action_type="cancelOrder", action_id=self._new_id(), blocking_type=BlockingType.HARD
        )
        return request_cancel(track, instant_actions_message(track.plan.agv, [action]))

    def send_instant_actions(self, agv: AgvId, specs: list[ActionSpec]) -> list[str]:
        """Check and publish instant actions (§6.9, R84, R112); returns their actionIds."""
        vehicle = self.known_vehicle(agv)
        reason = not_ready_reason(vehicle, self.clock.monotonic(), self.fleet_settings)
        if vehicle.hibernating and all(s.action_type == STOP_HIBERNATION for s in specs):
            reason = None  # 3.0 T06: the one action a hibernating vehicle answers
        if reason is not None:
            raise RequestError(409, f"vehicle {agv} cannot take instant actions: {reason}")
        if agv in self.active and any(s.action_type == "cancelOrder" for s in specs):
            order_id = self.active[agv]
            raise RequestError(409, f"cancel the active order with DELETE /orders/{order_id}")
        actions = [self._instant_action(vehicle, spec) for spec in specs]
        message = instant_actions_message(agv, actions)
        problems = [
            *caps.array_problems(vehicle.factsheet, {"instantActions": len(actions)}),
            *caps.action_limit_problems(vehicle.factsheet, actions),
        ]
        size = caps.message_size_problem(vehicle.factsheet, len(encode(message)))
        if size is not None:
            problems.append(size)
        if problems:
            raise RequestError(422, f"vehicle {agv} cannot take these actions: {problems[0]}")
        self._publish(agv, message, self.clock.monotonic())
        if any(a.action_type == START_CHARGING for a in actions):
            self.note_operator_charge(agv)
        return [a.action_id for a in actions]

    def send_fleet_instant_actions(
        self, specs: list[ActionSpec], manufacturer: str | None = None
    ) -> list[tuple[AgvId, list[str] | RequestError]]:
        """The same instant actions to every vehicle (of ``manufacturer``), each checked and
        sent as :meth:`send_instant_actions` does: per vehicle its actionIds, or why it was
        not sent them. 404 when no vehicle of ``manufacturer`` is known."""
        outcomes: list[tuple[AgvId, list[str] | RequestError]] = []
        for vehicle in self.fleet:
            if manufacturer is not None and vehicle.agv.manufacturer != manufacturer:
                continue
            try:
                outcomes.append((vehicle.agv, self.send_instant_actions(vehicle.agv, specs)))
            except RequestError as exc:
                outcomes.append((vehicle.agv, exc))
        if manufacturer is not None and not outcomes:
            raise RequestError(404, f"no vehicle of manufacturer {manufacturer!r} is known")
        refused = [o.message for _, o in outcomes if isinstance(o, RequestError)]
        log.info(
            "vehicles.instant_actions",
            actions=[s.action_type for s in specs],
            sent=len(outcomes) - len(refused),
            refused=refused,
        )
        return outcomes

    def _instant_action(self, vehicle: VehicleView, spec: ActionSpec) -> Action:
        resolved = caps.resolve_action(vehicle.factsheet, spec, ActionScope.INSTANT)
        if isinstance(resolved, str):
            raise RequestError(422, f"vehicle {vehicle.agv} cannot take this action: {resolved}")
        blocking, parameters = resolved
        return Action(
            action_type=spec.action_type,
            action_id=self._new_id(),
            blocking_type=blocking,
            action_parameters=[ActionParameter(key=k, value=v) for k, v in parameters.items()]
            or None,
        )


def _unsuited(vehicle: VehicleView, first: LoadNeed, later: tuple[LoadNeed, ...]) -> str | None:
    """Why no load set of ``vehicle``'s factsheet takes a load type the order's stops name
    (:func:`load_rules.load_set_problem`), or None."""
    for number, need in enumerate((first, *later), start=1):
        problem = load_set_problem(vehicle.factsheet, need)
        if problem is not None:
            where = f" at stop {number}" if later else ""
            return f"{need.action}{where}: {problem}"
    return None


def _load_fit(vehicle: VehicleView, need: LoadNeed) -> LoadFit:
    """How ``vehicle``'s reported loads suit the order's pick or drop (:mod:`load_rules`)."""
    loads = vehicle.state.loads if vehicle.state is not None else None
    return load_fit(loads, vehicle.factsheet, need)


def _check_reach(vehicle: VehicleView, route: Route) -> None:
    """409 for a route longer than the battery's reach (docs/master.md, *Charging*)."""
    short = reach_problem(vehicle.state, route.length_m)
    if short is not None:
        raise RequestError(409, f"vehicle {vehicle.agv} cannot drive this order: {short}")


def _running(order_id: str, track: OrderTrack | None) -> str:
    """Why a vehicle running ``order_id`` takes no order now; for a move of master control's
    own (traffic control sends an idle vehicle out of another's way, energy management sends a
    low one to charge), where to and why."""
    if track is not None and track.note.startswith(CHARGING_NOTE):
        return (
            f"master control is sending it to node {track.plan.destination!r} "
            f"({track.note}, order {order_id!r})"
        )
    if track is None or not track.note.startswith(TRAFFIC_NOTE):
        return f"it runs order {order_id!r}"
    return (
        f"master control is moving it to node {track.plan.destination!r} "
        f"({track.note.removeprefix(TRAFFIC_NOTE)}, order {order_id!r}); it takes orders again "
        "once it is there"
    )
