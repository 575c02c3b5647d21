"""The master-control service: the thin shell around the pure core.

Inbound: every ``state``, ``connection`` and ``factsheet`` message is decoded at the edge; an
invalid one is dropped with one log line naming vehicle, topic and reason, and never reaches the
fleet view (house style §3.1.4). A valid one is folded into the fleet view and, for a state, into
the vehicle's active order track. Outbound: whatever the dispatcher says is due is stamped with
the vehicle's own header counters in the version it speaks (§6.4) and handed to the publisher.
``visualization`` only updates the live map's poses, and every change is told to the live map's
change feed (:mod:`vda_master.live`).

The hot path per state is: a cached topic lookup, one pydantic decode, one O(1) fleet update and
one track update. Nothing here awaits except :meth:`on_message` and :meth:`tick_loop`.
"""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import Callable, Iterator, Mapping
from typing import Final, Protocol

import structlog

from vda5050.clock import Clock, format_timestamp
from vda5050.codec import DecodeFailure, HeaderStamper, decode_as, encode
from vda5050.errors import TopicError
from vda5050.models import (
    Action,
    ActionParameter,
    ActionScope,
    BlockingType,
    Connection,
    Factsheet,
    InstantActions,
    Order,
    State,
)
from vda5050.mqtt import InboundMessage
from vda5050.topics import AgvId, Topic, TopicAddress, build_topic, parse_topic, subscription_filter
from vda_master import capabilities as caps
from vda_master.capabilities import ActionSpec
from vda_master.config import MasterConfig
from vda_master.dispatcher import (
    DispatchSettings,
    OrderStatus,
    OrderTrack,
    SendGate,
    due_messages,
    reduce_track,
    request_cancel,
    start_track,
)
from vda_master.fleet import (
    FactsheetProblem,
    FleetSettings,
    FleetView,
    Observation,
    VehicleView,
    not_ready_reason,
    reduce_fleet,
    unavailable_reason,
)
from vda_master.graph import Graph
from vda_master.inquirer import Inquirer
from vda_master.live import LiveView
from vda_master.order_builder import BuildProblem, PlanRequest, plan_order
from vda_master.planner import Target, choose_vehicle, route_for
from vda_master.release import ReleasePolicy
from vda_master.requests import (
    PROBLEM_STATUS,
    OrderRequest,
    RequestError,
    instant_actions_message,
    speaking_version,
    with_legacy_key,
)
from vda_master.routing import Route, RouteProblem
from vda_master.start import find_start

log = structlog.get_logger()

MAJOR_VERSION: Final = 2
_INBOUND: Final[dict[Topic, type[State | Connection | Factsheet]]] = {
    Topic.STATE: State,
    Topic.CONNECTION: Connection,
    Topic.FACTSHEET: Factsheet,
}


class Publisher(Protocol):
    """Where outbound messages go (:class:`vda5050.mqtt.MqttSession` in production)."""

    def publish(self, topic: str, kind: Topic, payload: bytes | Callable[[], bytes]) -> None: ...


class MasterService:
    """Fleet view, order tracks and the operations behind the HTTP API."""

    def __init__(
        self, config: MasterConfig, graph: Graph, publisher: Publisher, clock: Clock
    ) -> None:
        self.config = config
        self.graph = graph
        self.clock = clock
        self.publisher = publisher
        self.fleet = FleetView()
        self.tracks: dict[str, OrderTrack] = {}
        self.active: dict[AgvId, str] = {}
        #: The latest order message sent per orderId, with its real header.
        self.sent: dict[str, Order] = {}
        self.fleet_settings = FleetSettings(config.unreachable_after_intervals)
        self.dispatch_settings = DispatchSettings(
            config.confirm_timeout_s, config.max_sends, ReleasePolicy(config.release_window_nodes)
        )
        self._stampers: dict[AgvId, HeaderStamper] = {}
        self._last_order_at: dict[AgvId, float] = {}
        self._addresses: dict[str, TopicAddress] = {}
        self.inquirer = Inquirer(self._send_instant_action, self._new_id)
        #: Latest poses (visualization) and the change feed of the live map (vda_master.web).
        self.live = LiveView()
        # Numeric ids unique across restarts (idNumericalOnly vehicles take them too, R114).
        self._ids: Iterator[int] = itertools.count(int(clock.now().timestamp() * 1000) * 1000)
        now = clock.monotonic()
        for robot in config.robots:
            agv = AgvId(robot.manufacturer, robot.serial_number)
            self.fleet = self.fleet.with_vehicle(VehicleView(agv, first_seen=now, last_seen=now))

    # -- inbound ------------------------------------------------------------------------------

    def subscriptions(self) -> list[tuple[str, Topic]]:
        """Filters for every vehicle's state, connection, factsheet and visualization topics
        (§6.5); visualization only feeds the live map's poses."""
        return [
            (subscription_filter(self.config.interface_name, MAJOR_VERSION, topic), topic)
            for topic in (*_INBOUND, Topic.VISUALIZATION)
        ]

    async def on_message(self, message: InboundMessage) -> None:
        """MqttSession handler: the per-message boundary that never lets an error escape."""
        try:
            self.ingest(message.topic, message.payload)
        except Exception:
            log.exception("message.handling_failed", topic=message.topic)

    def ingest(self, topic: str, payload: bytes) -> None:
        """Decode one vehicle message, drop it if invalid, fold it in otherwise."""
        address = self._address(topic)
        if address is None:
            return
        if address.topic is Topic.VISUALIZATION:
            if self.fleet.get(address.agv) is not None:
                self.live.observe_visualization(address.agv, payload, self.clock.monotonic())
            return
        model = _INBOUND.get(address.topic)
        if model is None:
            return
        decoded = decode_as(model, address.topic, payload, address=address)
        if isinstance(decoded, DecodeFailure):
            log.warning(
                "message.dropped",
                agv=str(address.agv),
                topic=topic,
                reason=decoded.summary(),
                header_id=decoded.header_id,
            )
            if address.topic is Topic.FACTSHEET:
                self._factsheet_unusable(address.agv, decoded.summary(limit=3))
            return
        self._observe(address.agv, decoded)

    def _factsheet_unusable(self, agv: AgvId, reason: str) -> None:
        """Remember why a known vehicle's factsheet was not used; the vehicle stays usable and
        gets full orders (the factsheet only narrows, capabilities module docstring)."""
        if self.fleet.get(agv) is None:
            return
        now = self.clock.monotonic()
        self.fleet = reduce_fleet(self.fleet, Observation(agv, FactsheetProblem(reason)), now)
        vehicle = self.fleet.get(agv)
        if vehicle is not None:
            self.inquirer.observe_factsheet(vehicle, None)

    def _address(self, topic: str) -> TopicAddress | None:
        address = self._addresses.get(topic)
        if address is None:
            try:
                address = parse_topic(topic)
            except TopicError as exc:
                log.warning("message.dropped", topic=topic, reason=str(exc))
                return None
            self._addresses[topic] = address
        return address

    def _observe(self, agv: AgvId, message: State | Connection | Factsheet) -> None:
        now = self.clock.monotonic()
        before = self.fleet.get(agv)
        self.fleet = reduce_fleet(self.fleet, Observation(agv, message), now)
        vehicle = self.fleet.get(agv)
        assert vehicle is not None  # noqa: S101 - reduce_fleet just added it
        self.live.vehicle_changed(agv)
        if isinstance(message, State):
            self.inquirer.observe_state(vehicle, message, now)
        elif isinstance(message, Connection):
            if before is None or before.connection != message.connection_state:
                log.info("vehicle.connection_changed", agv=str(agv), state=message.connection_state)
                self.inquirer.vehicle_reconnected(vehicle, now)
        else:
            log.info("vehicle.factsheet_received", agv=str(agv), version=message.version)
            self.inquirer.observe_factsheet(vehicle, message)
            self.inquirer.consider(vehicle, now)
        order_id = self.active.get(agv)
        if order_id is None:
            return
        if isinstance(message, State):
            track = reduce_track(self.tracks[order_id], message, self.dispatch_settings)
            self._store(agv, track)
        self._pump(agv, now)

    # -- outbound -----------------------------------------------------------------------------

    def tick(self) -> None:
        """Resends and delayed sends of every active order (O(active orders)), and the state
        and factsheet requests still open (O(vehicles asked))."""
        now = self.clock.monotonic()
        for agv in list(self.active):
            self._pump(agv, now)
        self.inquirer.tick(self.fleet, now)

    async def on_broker_connected(self) -> None:
        """MqttSession hook, after every (re)connect: states seen before may be stale (what
        happened while the master was away was not seen), so every ONLINE vehicle is asked for a
        state at once instead of waiting for its heartbeat (§6.8.1 stateRequest)."""
        self.inquirer.broker_connected(self.fleet, self.clock.monotonic())

    def _send_instant_action(self, agv: AgvId, action: Action) -> None:
        self._publish(agv, instant_actions_message(agv, [action]), self.clock.monotonic())

    async def tick_loop(self) -> None:
        """Forever: :meth:`tick` every ``tick_s``."""
        while True:
            await asyncio.sleep(self.config.tick_s)
            self.tick()

    def _gate(self, agv: AgvId, now: float) -> SendGate:
        vehicle = self.fleet.get(agv)
        if vehicle is None:
            return SendGate(vehicle_ready=False, order_allowed=False)
        ready = not_ready_reason(vehicle, now, self.fleet_settings) is None
        last = self._last_order_at.get(agv)
        interval = caps.min_order_interval_s(vehicle.factsheet)
        return SendGate(ready, last is None or now - last >= interval)

    def _pump(self, agv: AgvId, now: float) -> None:
        order_id = self.active.get(agv)
        if order_id is None:
            return
        gate = self._gate(agv, now)
        track, messages = due_messages(self.tracks[order_id], now, self.dispatch_settings, gate)
        for message in messages:
            self._publish(agv, message, now)
        self._store(agv, track)

    def _store(self, agv: AgvId, track: OrderTrack) -> None:
        old = self.tracks.get(track.order_id)
        self.tracks[track.order_id] = track
        if old is not track:
            self.live.order_changed(track.order_id)
        if old is not None and old.status != track.status:
            log.info(
                "order.status_changed",
                order_id=track.order_id,
                agv=str(agv),
                status=track.status.value,
                reason=track.reason or None,
            )
        if track.terminal and self.active.get(agv) == track.order_id:
            del self.active[agv]

    def _stamper(self, agv: AgvId) -> HeaderStamper:
        vehicle = self.fleet.get(agv)
        version = speaking_version(vehicle.version if vehicle else None)
        stamper = self._stampers.get(agv)
        if stamper is None:
            stamper = self._stampers[agv] = HeaderStamper(agv, version, self.clock)
        stamper.version = version  # follow a vehicle that changed its version
        return stamper

    def _publish(self, agv: AgvId, message: Order | InstantActions, now: float) -> None:
        kind = Topic.ORDER if isinstance(message, Order) else Topic.INSTANT_ACTIONS
        stamper = self._stamper(agv)
        if (
            isinstance(message, InstantActions)
            and self.config.legacy_instant_actions_key
            and stamper.version.startswith("2.0.")
        ):
            message = with_legacy_key(message)
        stamped = stamper.stamp(kind, message)
        topic = build_topic(self.config.interface_name, MAJOR_VERSION, agv, kind)
        self.publisher.publish(topic, kind, encode(stamped))
        if isinstance(message, Order):
            assert isinstance(stamped, Order)  # noqa: S101 - stamp() keeps the model class
            self._last_order_at[agv] = now
            self.sent[stamped.order_id] = stamped
            log.info(
                "order.published",
                order_id=stamped.order_id,
                order_update_id=stamped.order_update_id,
                agv=str(agv),
                header_id=stamped.header_id,
            )
        else:
            ids = [a.action_id for a in message.actions]
            log.info("instant_actions.published", agv=str(agv), action_ids=ids)

    def traffic_snapshot(self) -> Mapping[str, object] | None:
        """What ``GET /traffic`` answers (JSON-ready), or None while there is no traffic
        control; the live map reads reservations and waits only through this (issue 9)."""
        return None

    def _new_id(self) -> str:
        return str(next(self._ids))

    # -- requests (HTTP API) -----------------------------------------------------------------

    def create_order(self, request: OrderRequest) -> OrderTrack:
        """Plan, track and send a new order; raises :class:`RequestError` (404/409/422)."""
        now = self.clock.monotonic()
        vehicle, route = self._select(request, now)
        order_id = self._new_id()
        actions = {len(route.edge_ids): request.destination_actions}
        plan = plan_order(
            self.graph,
            PlanRequest(route, order_id, actions, {}),
            agv=vehicle.agv,
            version=speaking_version(vehicle.version),
            factsheet=vehicle.factsheet,
            action_ids=(self._new_id() for _ in itertools.count()),
        )
        if isinstance(plan, BuildProblem):
            raise RequestError(422, f"vehicle {vehicle.agv} cannot take this order: {plan.reason}")
        max_nodes = caps.max_order_nodes(vehicle.factsheet)
        track = start_track(
            plan,
            self.dispatch_settings,
            max_nodes=max_nodes,
            now=now,
            created_utc=format_timestamp(self.clock.now()),
        )
        size = caps.message_size_problem(vehicle.factsheet, len(encode(track.message)))
        if size is not None:
            raise RequestError(422, f"vehicle {vehicle.agv} cannot take this order: {size}")
        self.tracks[order_id] = track
        self.active[vehicle.agv] = order_id
        log.info(
            "order.created",
            order_id=order_id,
            agv=str(vehicle.agv),
            edges=list(route.edge_ids),
            length_m=round(route.length_m, 3),
        )
        self._pump(vehicle.agv, now)
        return self.tracks[order_id]

    def _select(self, request: OrderRequest, now: float) -> tuple[VehicleView, Route]:
        if request.agv is not None:
            vehicle = self.known_vehicle(request.agv)
            reason = self.availability(vehicle, now, automatic_only=False)
            if reason is not None:
                raise RequestError(409, f"vehicle {vehicle.agv} is not available: {reason}")
            route = route_for(self.graph, vehicle, request.target)
            if isinstance(route, RouteProblem):
                raise RequestError(PROBLEM_STATUS[route.kind], route.reason)
            return vehicle, route
        destination = request.target.destination
        if destination is not None and destination not in self.graph.nodes:
            raise RequestError(404, f"node {destination!r} is not in the graph")
        unknown = [e for e in request.target.route or () if e not in self.graph.edges]
        if unknown:
            raise RequestError(404, f"edge {unknown[0]!r} is not in the graph")
        return self._choose(request.target, now)

    def _choose(self, target: Target, now: float) -> tuple[VehicleView, Route]:
        candidates, reasons = [], []
        for vehicle in self.fleet:
            reason = self.availability(vehicle, now)
            if reason is None:
                candidates.append(vehicle)
            else:
                reasons.append(f"{vehicle.agv}: {reason}")
        chosen = choose_vehicle(self.graph, candidates, target)
        if chosen is None:
            detail = "; ".join(reasons[:5]) or "no vehicle has reported"
            where = target.destination or f"route {list(target.route or ())}"
            raise RequestError(409, f"no available vehicle can reach {where} ({detail})")
        return chosen

    def availability(
        self, vehicle: VehicleView, now: float, *, automatic_only: bool = True
    ) -> str | None:
        """Why ``vehicle`` cannot take a new order now, or None when it can.

        Never None while its next order would be rejected (issue 8): besides the fleet view's
        conditions, the next order must be plannable from where the vehicle stands.
        """
        running = self.active.get(vehicle.agv)
        if running is not None:
            return f"it runs order {running!r}"
        reason = unavailable_reason(
            vehicle, now, self.fleet_settings, automatic_only=automatic_only
        )
        if reason is not None:
            return reason
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
        return None

    def availability_of(self, agv: AgvId) -> str | None:
        """:meth:`availability` of a known vehicle now ("it is unknown" otherwise)."""
        vehicle = self.fleet.get(agv)
        if vehicle is None:
            return "it is unknown"
        return self.availability(vehicle, self.clock.monotonic())

    def list_orders(
        self,
        *,
        status: OrderStatus | None = None,
        manufacturer: str | None = None,
        serial_number: str | None = None,
        limit: int = 100,
    ) -> list[OrderTrack]:
        """Orders newest first, filtered by status and vehicle."""
        found: list[OrderTrack] = []
        for track in reversed(self.tracks.values()):
            agv = track.plan.agv
            if (
                (status is None or track.status == status)
                and (manufacturer is None or agv.manufacturer == manufacturer)
                and (serial_number is None or agv.serial_number == serial_number)
            ):
                found.append(track)
                if len(found) >= limit:
                    break
        return found

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

    def cancel_order(self, order_id: str) -> OrderTrack:
        """Send ``cancelOrder`` for an active order (§6.6.3); 404 unknown, 409 already ended."""
        track = self.known_order(order_id)
        action = Action(
            action_type="cancelOrder", action_id=self._new_id(), blocking_type=BlockingType.HARD
        )
        message = instant_actions_message(track.plan.agv, [action])
        cancelled = request_cancel(track, message)
        if isinstance(cancelled, str):
            raise RequestError(409, cancelled)
        self._store(track.plan.agv, cancelled)
        log.info("order.cancel_requested", order_id=order_id, action_id=action.action_id)
        self._pump(track.plan.agv, self.clock.monotonic())
        return self.tracks[order_id]

    def send_instant_actions(self, agv: AgvId, specs: list[ActionSpec]) -> list[str]:
        """Check and publish instant actions (§6.9, R84, R112); returns their actionIds."""
        vehicle = self.known_vehicle(agv)
        reason = not_ready_reason(vehicle, self.clock.monotonic(), self.fleet_settings)
        if reason is not None:
            raise RequestError(409, f"vehicle {agv} cannot take instant actions: {reason}")
        if agv in self.active and any(s.action_type == "cancelOrder" for s in specs):
            order_id = self.active[agv]
            raise RequestError(409, f"cancel the active order with DELETE /orders/{order_id}")
        actions = [self._instant_action(vehicle, spec) for spec in specs]
        problems = caps.array_problems(vehicle.factsheet, {"instantActions": len(actions)})
        if problems:
            raise RequestError(422, f"vehicle {agv} cannot take these actions: {problems[0]}")
        self._publish(agv, instant_actions_message(agv, actions), self.clock.monotonic())
        return [a.action_id for a in actions]

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
