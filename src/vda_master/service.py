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
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import replace
from typing import Final, Protocol

import structlog

from vda5050.clock import Clock
from vda5050.codec import DecodeFailure, HeaderStamper, SharedBodies, decode_as, encode
from vda5050.errors import TopicError
from vda5050.models import (
    Action,
    Connection,
    Factsheet,
    InstantActions,
    Order,
    State,
    v3,
)
from vda5050.mqtt import InboundMessage
from vda5050.topics import AgvId, Topic, TopicAddress, build_topic, parse_topic, subscription_filter
from vda_master import capabilities as caps
from vda_master.admission import Admission
from vda_master.alarm_reports import AlarmReports
from vda_master.charging import Charging
from vda_master.config import MasterConfig, interface_name
from vda_master.confirmation import ConfirmationTimer
from vda_master.coordination import Coordinator
from vda_master.dispatcher import (
    DispatchSettings,
    OrderTrack,
    SendGate,
    anything_due,
    due_messages,
    extend_track,
    release_wanted,
    unsettled,
)
from vda_master.finish_times import FinishTimes
from vda_master.fleet import (
    FactsheetProblem,
    FleetSettings,
    FleetView,
    Observation,
    VehicleView,
    forgettable,
    not_ready_reason,
    reduce_fleet,
)
from vda_master.graph import Graph
from vda_master.inquirer import Inquirer
from vda_master.journal import registry_changed
from vda_master.live import LiveView
from vda_master.map_rollout import MapRollout
from vda_master.metrics import Counters, order_origin
from vda_master.onward import OnwardStops
from vda_master.operations import Operations
from vda_master.order_queue import OrderQueue
from vda_master.out_of_service import OutOfService
from vda_master.persistence import Persistence
from vda_master.release import ReleasePolicy, progress_index
from vda_master.requests import (
    instant_actions_message,
    speaking_version,
    with_legacy_key,
)
from vda_master.resolution import ADVICE_EVERY_S
from vda_master.webhook_events import connection_event, order_event
from vda_master.webhooks import Webhooks
from vda_master.wire3 import (
    connection_from_v3,
    factsheet_from_v3,
    instant_actions_to_v3,
    order_to_v3,
    state_from_v3,
)
from vda_master.zone_answers import ZoneAnswers
from vda_master.zone_changes import ZoneChanges
from vda_master.zone_distribution import ZoneDistribution

log = structlog.get_logger()

#: The major versions served, each under its own interface name (config).
MAJOR_VERSIONS: Final = (2, 3)
#: Unread inbound bytes above which master control counts as lagging (some 15 states) ...
BEHIND_BYTES: Final = 16 * 1024
#: ... and messages waiting in its outbox above which it does too (a resend's clock starts
#: when the message is handed to the outbox, not when it leaves).
BEHIND_MESSAGES: Final = 50
#: Seconds between two sweeps for silent vehicles to forget.
SWEEP_EVERY_S: Final = 10.0
_TOPIC_CACHE_LIMIT: Final = 10_000
_INBOUND: Final[dict[Topic, type[State | Connection | Factsheet]]] = {
    Topic.STATE: State,
    Topic.CONNECTION: Connection,
    Topic.FACTSHEET: Factsheet,
}
#: 3.0 messages are decoded as 3.0 and translated for the core at the edge (vda_master.wire3).
_INBOUND_V3: Final[dict[Topic, type[v3.State | v3.Connection | v3.Factsheet]]] = {
    Topic.STATE: v3.State,
    Topic.CONNECTION: v3.Connection,
    Topic.FACTSHEET: v3.Factsheet,
}


class Publisher(Protocol):
    """Where outbound messages go (:class:`vda5050.mqtt.MqttSession` in production)."""

    def publish(self, topic: str, kind: Topic, payload: bytes | Callable[[], bytes]) -> None: ...


class MasterService(
    Operations,
    OnwardStops,
    Persistence,
    ZoneDistribution,
    ZoneAnswers,
    ZoneChanges,
    Charging,
    OrderQueue,
    OutOfService,
    MapRollout,
    FinishTimes,
):
    """Fleet view, order tracks, what the HTTP API asks for (:class:`Operations`), traffic
    resolution (:class:`Resolution`) and the next stop of an order with several
    (:class:`OnwardStops`, built on it), the store (:class:`Persistence`), the zone sets of
    3.0 robots (:class:`ZoneDistribution`) and the answers to their zone and edge requests
    (:class:`ZoneAnswers`), zones changed at run time (:class:`ZoneChanges`),
    energy management (:class:`Charging`), orders waiting for a vehicle
    (:class:`OrderQueue`), vehicles an operator took out of service (:class:`OutOfService`) and
    the map files it serves and rolls out to the fleet (:class:`MapRollout`)."""

    def __init__(
        self, config: MasterConfig, graph: Graph, publisher: Publisher, clock: Clock
    ) -> None:
        self.config = config
        graph = graph.with_zone_margin(config.zone_margin_m)
        self.graph = graph
        self.clock = clock
        self.publisher = publisher
        self.fleet = FleetView()
        self.tracks: dict[str, OrderTrack] = {}
        self.active: dict[AgvId, str] = {}
        #: Vehicles whose active order may have something unsent or unconfirmed: the tick
        #: visits only these, not every active order (a fleet's orders are mostly confirmed).
        self._unsettled: set[AgvId] = set()
        #: The latest order message sent per orderId, with its real header.
        self.sent: dict[str, Order] = {}
        self.fleet_settings = FleetSettings(
            config.unreachable_after_intervals,
            charged_pct=config.charged_pct if config.charge_below_pct else None,
        )
        self.dispatch_settings = DispatchSettings(
            config.confirm_timeout_s, config.max_sends, ReleasePolicy(config.release_window_nodes)
        )
        #: The confirmation timeout in force: the configured one, longer under load.
        self.confirmations = ConfirmationTimer(config.confirm_timeout_s)
        #: (inbound bytes not read yet, messages not sent yet) of the MQTT session: the
        #: runtime passes :meth:`vda5050.mqtt.MqttSession.backlog`.
        self.backlog: Callable[[], tuple[int, int]] = lambda: (0, 0)
        self._behind = False
        self._stampers: dict[AgvId, HeaderStamper] = {}
        self._last_order_at: dict[AgvId, float] = {}
        #: The topic of the last order message sent to each vehicle.
        self._order_topics: dict[AgvId, str] = {}
        #: Told the topic when a vehicle's state confirms an order message: the runtime passes
        #: :meth:`vda5050.mqtt.MqttSession.delivered` (no echo check needed, vda5050.access).
        self.on_order_delivered: Callable[[str], None] = lambda _topic: None
        self._addresses: dict[str, TopicAddress] = {}
        self._factsheet_bodies = (SharedBodies(Factsheet), SharedBodies(v3.Factsheet))
        listed = frozenset(AgvId(r.manufacturer, r.serial_number) for r in config.robots)
        self.admission = Admission(listed, accept_unlisted=config.accept_unlisted_vehicles)
        self._next_sweep = 0.0
        self._next_advice = 0.0
        self.inquirer = Inquirer(self._send_instant_action, self._new_id)
        self.coordinator = Coordinator(graph, config)
        self._init_persistence()
        self._init_zone_distribution()
        self._init_zone_answers()
        self._init_finish_times()
        self._init_zone_changes()
        self._init_charging()
        self._init_queue()
        self._init_onward()
        self._init_out_of_service()
        self._init_map_rollout()
        #: Events for the plant's systems: orders, connections, alarms (docs/master.md).
        self.webhooks = Webhooks(config, clock)
        #: Every vehicle's errors and safety chain: log lines, events, ``GET /alarms``.
        self.alarms = AlarmReports(self.webhooks, clock)
        #: Latest poses (visualization) and the change feed of the live map (vda_master.web).
        self.live = LiveView()
        #: What ``GET /metrics`` counts (vda_master.metrics).
        self.counters = Counters()
        # Numeric ids unique across restarts (idNumericalOnly vehicles take them too, R114).
        self._ids: Iterator[int] = itertools.count(int(clock.now().timestamp() * 1000) * 1000)
        now = clock.monotonic()
        for robot in config.robots:
            agv = AgvId(robot.manufacturer, robot.serial_number)
            self.fleet = self.fleet.with_vehicle(VehicleView(agv, first_seen=now, last_seen=now))

    # -- inbound ------------------------------------------------------------------------------

    def subscriptions(self) -> list[tuple[str, Topic]]:
        """Filters for every vehicle's state, connection, factsheet and visualization topics
        (§6.5), under ``v2`` and ``v3`` (3.0 T01); visualization only feeds the live map's
        poses, and the process subscribes to it only while a map is open
        (:mod:`vda_master.pose_feed`)."""
        return [
            (subscription_filter(interface_name(self.config, major), major, topic), topic)
            for major in MAJOR_VERSIONS
            for topic in (*_INBOUND, Topic.VISUALIZATION)
        ]

    async def on_message(self, message: InboundMessage) -> None:
        """MqttSession handler: the per-message boundary that never lets an error escape."""
        try:
            self.ingest(message.topic, message.payload, retained=message.retain)
        except Exception:
            log.exception("message.handling_failed", topic=message.topic)

    def ingest(self, topic: str, payload: bytes, *, retained: bool | None = None) -> None:
        """Decode one vehicle message, drop it if invalid, fold it in otherwise; ``retained``:
        the broker's retain flag (True: stored before master control subscribed, False: just
        published, None: not known)."""
        address = self._address(topic)
        if address is None or not self.admission.admits(address.agv):
            return
        if address.topic is Topic.VISUALIZATION:
            if self.fleet.get(address.agv) is not None:
                self.live.observe_visualization(address.agv, payload, self.clock.monotonic())
            return
        if address.interface_name != interface_name(self.config, address.major_version):
            return  # another major's interface name: not this master's fleet
        self.counters.received[address.topic, address.major_version] += 1
        decoded = self._decode(address, payload)
        if isinstance(decoded, DecodeFailure):
            self.counters.dropped[address.topic] += 1
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
        if decoded is None:
            return
        self._observe(address.agv, from_v3(decoded), live=retained is False)
        if isinstance(decoded, v3.Connection | v3.State | v3.Factsheet):
            self._after_v3(address.agv, decoded)

    def _after_v3(self, agv: AgvId, message: v3.Connection | v3.State | v3.Factsheet) -> None:
        """What a 3.0 message says beyond its 2.x reading: hibernation (T06), zone sets."""
        if isinstance(message, v3.Connection):
            hibernating = message.connection_state is v3.ConnectionState.HIBERNATING
            self._note_hibernation(agv, hibernating=hibernating)
        elif isinstance(message, v3.State):
            self._note_own_mode(agv, message.operating_mode.value)
            now = self.clock.monotonic()
            self.note_zone_sets(agv, message, now)
            self.note_requests(agv, message, now)
        else:
            self.note_zone_support(agv, message)

    def _decode(self, address: TopicAddress, payload: bytes) -> Inbound | DecodeFailure | None:
        """The message in the model of its topic and major (None: a topic not read here)."""
        v3_topic = address.major_version == 3  # noqa: PLR2004
        if address.topic is Topic.FACTSHEET:  # 7 KB, alike across a fleet: validated once
            bodies = self._factsheet_bodies[1 if v3_topic else 0]
            return bodies.decode(
                Topic.FACTSHEET, payload, address=address, max_bytes=self.config.max_message_bytes
            )
        models = _INBOUND_V3 if v3_topic else _INBOUND
        model = models.get(address.topic)
        if model is None:
            return None
        return decode_as(
            model, address.topic, payload, address=address, max_bytes=self.config.max_message_bytes
        )

    def _note_hibernation(self, agv: AgvId, *, hibernating: bool) -> None:
        """3.0 T09: HIBERNATING reads as OFFLINE for the core, and the view remembers that the
        vehicle can still be woken (stopHibernation)."""
        vehicle = self.fleet.get(agv)
        if vehicle is not None and vehicle.hibernating != hibernating:
            self.fleet = self.fleet.with_vehicle(replace(vehicle, hibernating=hibernating))
            self.live.vehicle_changed(agv)
            log.info("vehicle.hibernation", agv=str(agv), hibernating=hibernating)

    def _note_own_mode(self, agv: AgvId, mode: str) -> None:
        """A 3.0 robot's operatingMode in its own words (the core reads INTERVENED as MANUAL,
        STARTUP as SERVICE): the view keeps them for the API and the map, and so that a
        cancelOrder still goes in INTERVENED (Table 11, T58)."""
        vehicle = self.fleet.get(agv)
        if vehicle is None or vehicle.own_mode == mode:
            return
        was_intervened = vehicle.intervened
        self.fleet = self.fleet.with_vehicle(replace(vehicle, own_mode=mode))
        self.live.vehicle_changed(agv)
        if not was_intervened and mode == "INTERVENED" and agv in self.active:
            self._unsettled.add(agv)  # a cancel held back may go now

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
            if len(self._addresses) >= _TOPIC_CACHE_LIMIT:
                self._addresses.clear()  # made-up topics must not grow the cache forever
            self._addresses[topic] = address
        return address

    def _observe(
        self, agv: AgvId, message: State | Connection | Factsheet, *, live: bool = False
    ) -> None:
        now = self.clock.monotonic()
        before = self.fleet.get(agv)
        self.fleet = reduce_fleet(self.fleet, Observation(agv, message), now)
        vehicle = self.fleet.get(agv)
        assert vehicle is not None  # noqa: S101 - reduce_fleet just added it
        if self.journal is not None and registry_changed(before, vehicle):
            self.journal.vehicle(vehicle)
        self.live.vehicle_changed(agv)
        if isinstance(message, State):
            self.alarms.observe(agv, None if before is None else before.state, message)
            self.inquirer.observe_state(vehicle, message, now)
            self._on_state(agv, message, now)
            return
        if isinstance(message, Connection):
            if before is None or before.connection != message.connection_state:
                log.info("vehicle.connection_changed", agv=str(agv), state=message.connection_state)
                self.alarms.connection_changed(agv, message.connection_state.value)
                previous = None if before is None else before.connection
                self.webhooks.emit(
                    connection_event(
                        agv,
                        message.connection_state.value,
                        None if previous is None else previous.value,
                    )
                )
                self.inquirer.vehicle_reconnected(vehicle, now, live=live)
        else:
            log.info("vehicle.factsheet_received", agv=str(agv), version=message.version)
            self.inquirer.observe_factsheet(vehicle, message)
            self.inquirer.consider(vehicle, now)
            self.coordinator.note_factsheet(agv, message)
        self._pump(agv, now)

    def _on_state(self, agv: AgvId, state: State, now: float) -> None:
        """A state: fold it into the vehicle's order, tell traffic control where the vehicle
        is, release more base if traffic allows, and retry vehicles it was in the way of."""
        order_id = self.active.get(agv)
        before = self.tracks[order_id].pending if order_id is not None else None
        track = self._fold_state(agv, order_id, state)
        progress = None
        if track is not None:
            if before is not None and before.last_sent is not None and track.pending is None:
                self._confirmed_after(now - before.last_sent, now)
                topic = self._order_topics.get(agv)
                if topic is not None:
                    self.on_order_delivered(topic)  # the broker let the order through
            progress = progress_index(track.plan, state)
            self._note_progress(track, progress)
            self.note_order_progress(track, state, progress, now)
            if track.terminal:
                progress = None  # an ended order holds nothing on its route
        woken = self.coordinator.observe(agv, state, progress, now)
        if track is not None:
            self._store(agv, self._extended(track, state, now))
        self._wake(woken, now)
        if track is not None and track.resume is not None:
            # After the vehicles it made way for: a backed-off vehicle yields to them first.
            self.resume_after_back_off(agv, state, now)
        elif track is not None and track.onward:
            self.go_on_to_next_stop(agv, state, now)
        if self._stitched_at_stop and order_id is not None:
            self.check_stitched_stop(agv, order_id, state)
        self._pump(agv, now)
        self._after_state(agv, state, track, now)

    def _after_state(self, agv: AgvId, state: State, track: OrderTrack | None, now: float) -> None:
        """What a state may start besides its order: a low vehicle sent to charge and the
        queue served once its order ended, a downloaded map enabled."""
        if track is not None and track.terminal:
            self.charge_if_low(agv, state, now)  # before a client's next order can take it
            self.serve_queue(now, freed=agv)  # then the orders waiting for a vehicle
        if self._map_enables:
            self.follow_map_downloads(agv, state)

    def _confirmed_after(self, latency_s: float, now: float) -> None:
        """An order message was confirmed ``latency_s`` after its (last) send: the timeout
        follows the latencies (:mod:`vda_master.confirmation`)."""
        self.counters.confirm_latency.observe(latency_s)
        if self.confirmations.observe(latency_s, now):
            self._timeout_changed()

    def _timeout_changed(self) -> None:
        timeout = self.confirmations.timeout_s
        self.dispatch_settings = replace(self.dispatch_settings, confirm_timeout_s=timeout)
        log.debug("order.confirm_timeout_changed", confirm_timeout_s=round(timeout, 3))

    def _extended(self, track: OrderTrack, state: State, now: float) -> OrderTrack:
        """The track with its base extended as far as the window wants and traffic allows
        (first looked at again if a change of zones left it to review)."""
        if self._way_review and track.order_id in self._way_review and _reviewable(track):
            track = self._reviewed_way(track, now)
        wanted = release_wanted(track, state, self.dispatch_settings)
        if wanted is None:
            return track
        route = track.plan.route
        end = wanted.desired_end
        if route is not None:
            end = self.coordinator.grant(
                track.plan.agv,
                route,
                progress=wanted.progress,
                released_end=track.released_end,
                desired_end=wanted.desired_end,
                now=now,
            )
        return extend_track(track, end)

    def _wake(self, woken: Iterable[AgvId], now: float) -> None:
        """Vehicles that waited for one that moved on: ask for their release again."""
        for agv in woken:
            order_id = self.active.get(agv)
            vehicle = self.fleet.get(agv)
            if order_id is None or vehicle is None or vehicle.state is None:
                continue
            self._store(agv, self._extended(self.tracks[order_id], vehicle.state, now))
            self._pump(agv, now)

    # -- outbound -----------------------------------------------------------------------------

    def tick(self) -> None:
        """Resends and delayed sends of the active orders with a message unsent or unconfirmed
        (O(such orders), not O(active orders)), and the state and factsheet requests still open
        (O(vehicles asked)). While the MQTT session lags (unread inbound, unsent outbound), no
        resend and no request unless long overdue: what would confirm or answer them may be
        among the unread messages, or the message itself may not have left yet."""
        now = self.clock.monotonic()
        unread, unsent = self.backlog()
        self._behind = unread > BEHIND_BYTES or unsent > BEHIND_MESSAGES
        self.inquirer.behind = self._behind
        if self._way_review:
            self.review_ways(now)
        for agv in list(self._unsettled):
            order_id = self.active.get(agv)
            if order_id is None or not unsettled(self.tracks[order_id]):
                self._unsettled.discard(agv)
            else:
                self._pump(agv, now)
        self.inquirer.tick(self.fleet, now)
        if now >= self._next_sweep:
            self._next_sweep = now + SWEEP_EVERY_S
            self._forget_silent(now)
            if self.confirmations.expire(now):
                self._timeout_changed()
        if now >= self._next_advice:
            self._next_advice = now + ADVICE_EVERY_S / self.config.time_lapse
            self.resolve_traffic(now)
            self.answer_open_requests(now)
            self.manage_charging(now)
            self.serve_queue(now)
        self._check_recovering(now)

    def _forget_silent(self, now: float) -> None:
        """Unlisted vehicles silent for ``forget_after_s`` leave the live view (issue 14); one
        out of service stays, so that it can be seen and put back."""
        gone = [
            vehicle.agv
            for vehicle in self.fleet
            if vehicle.agv not in self.admission.listed
            and vehicle.agv not in self.active
            and vehicle.agv not in self.out_of_service  # listed until put back
            and forgettable(vehicle, now, self.config.forget_after_s)
        ]
        for agv in gone:
            self.forget_vehicle(agv)
        if gone:
            log.info("vehicles.forgotten", count=len(gone), first=str(gone[0]))

    def forget_vehicle(self, agv: AgvId) -> None:
        """Drop everything kept about the vehicle (it is heard of again as a new one)."""
        self.fleet = self.fleet.without(agv)
        self.inquirer.forget(agv)
        self.coordinator.forget(agv)
        self.forget_requests(agv)
        self.live.forget(agv)
        self._stampers.pop(agv, None)
        self._last_order_at.pop(agv, None)

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
        cancel_ready = ready or (
            vehicle.intervened
            and not_ready_reason(vehicle, now, self.fleet_settings, cancel_order=True) is None
        )
        return SendGate(
            ready, last is None or now - last >= interval, not self._behind, cancel_ready
        )

    def _pump(self, agv: AgvId, now: float) -> None:
        order_id = self.active.get(agv)
        if order_id is None or self._held(order_id):
            return
        track = self.tracks[order_id]
        if not anything_due(track, now, self.dispatch_settings, resend=not self._behind):
            return
        gate = self._gate(agv, now)
        before = track
        track, messages = due_messages(track, now, self.dispatch_settings, gate)
        for message in messages:
            self._publish(agv, message, now)
        for sent, was in ((track.pending, before.pending), (track.cancel, before.cancel)):
            if sent is not None and sent is not was and sent.sends > 1:
                topic = Topic.ORDER if isinstance(sent.message, Order) else Topic.INSTANT_ACTIONS
                self.counters.resent[topic.value] += 1
        self._store(agv, track)

    def _store(self, agv: AgvId, track: OrderTrack) -> None:
        old = self.tracks.get(track.order_id)
        self.tracks[track.order_id] = track
        self.note_order_stored(old, track)
        if unsettled(track):
            self._unsettled.add(agv)
        self._record(agv, old, track)
        if old is not track:
            self.live.order_changed(track.order_id)
        if old is None:
            self.counters.orders_created[order_origin(track.note)] += 1
        elif old.status != track.status and track.terminal:
            self.counters.orders_ended[track.status.value] += 1
        if old is not None and old.status != track.status:
            log.info(
                "order.status_changed",
                order_id=track.order_id,
                agv=str(agv),
                status=track.status.value,
                reason=track.reason or None,
            )
        if self.webhooks.enabled and (old is None or old.status != track.status):
            # A queued order leaves the queue only once its track is stored.
            previous = "QUEUED" if old is None and track.order_id in self.queue else None
            self.webhooks.emit(
                order_event(
                    track.order_id,
                    track.status.value,
                    old.status.value if old is not None else previous,
                    agv,
                    track.reason,
                    expected_finish=self.expected_finish_utc(track),
                )
            )
        if track.terminal and self.active.get(agv) == track.order_id:
            del self.active[agv]
            vehicle = self.fleet.get(agv)
            now = self.clock.monotonic()
            self._wake(self.coordinator.finish(agv, vehicle.state if vehicle else None, now), now)

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
        if stamper.major == 3:  # noqa: PLR2004 - 3.0: translated at the edge, then stamped
            wire = stamper.stamp(kind, to_v3(message))
            header = {"header_id": wire.header_id, "timestamp": wire.timestamp}
            stamped = message.model_copy(update={**header, "version": wire.version})
            payload = encode(wire)
        else:
            stamped = stamper.stamp(kind, message)
            payload = encode(stamped)
        topic = build_topic(interface_name(self.config, stamper.major), stamper.major, agv, kind)
        self.publisher.publish(topic, kind, payload)
        self.counters.published[kind.value] += 1
        if kind is Topic.ORDER:
            self._order_topics[agv] = topic
        if self.journal is not None:
            order = stamped if isinstance(stamped, Order) else None
            self.journal.published(agv, kind, stamped.header_id, order)
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
        """What ``GET /traffic`` answers (JSON-ready): ``enabled``, and per vehicle what it
        holds and waits for (docs/traffic.md); the live map reads traffic only through this."""
        snapshot = self.coordinator.snapshot(self.clock.monotonic()).as_json()
        return {"enabled": self.coordinator.enabled, **snapshot}

    def _new_id(self) -> str:
        return str(next(self._ids))


Inbound = State | Connection | Factsheet | v3.State | v3.Connection | v3.Factsheet


def from_v3(message: Inbound) -> State | Connection | Factsheet:
    """A 3.0 vehicle message as the core reads it (vda_master.wire3); 2.x ones as they are."""
    if isinstance(message, State | Connection | Factsheet):
        return message
    if isinstance(message, v3.State):
        return state_from_v3(message)
    if isinstance(message, v3.Connection):
        return connection_from_v3(message)
    return factsheet_from_v3(message)


def to_v3(message: Order | InstantActions) -> v3.Order | v3.InstantActions:
    """A message cut from the plan, in 3.0 shape (vda_master.wire3)."""
    if isinstance(message, Order):
        return order_to_v3(message)
    return instant_actions_to_v3(message)


def _reviewable(track: OrderTrack) -> bool:
    """No message of it in flight and settled after a restart (:mod:`vda_master.zone_changes`)."""
    return track.pending is None and track.recovering_since is None
