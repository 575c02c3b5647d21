"""One simulated vehicle in the shell: decode → core → store → publish, without awaiting.

The service owns the MQTT sessions and the tick loop; a ``VehicleRuntime`` holds one vehicle's
state and turns inbound payloads and ticks into calls of the pure core and into messages.
Payloads are callables, so headers are stamped (and states built) when really sent.
"""

from __future__ import annotations

import asyncio
import math
from collections import deque
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, field, replace

import structlog

from vda5050.access import AccessProblem
from vda5050.clock import Clock
from vda5050.codec import DecodeFailure, EncodedBody, HeaderStamper, decode_as
from vda5050.evolve import evolve
from vda5050.models import (
    Action,
    Connection,
    ConnectionState,
    Error,
    InstantActions,
    Map,
    Order,
    WireModel,
)
from vda5050.mqtt import Payload, Will
from vda5050.topics import AgvId, Topic, build_topic, parse_topic, topics_of
from vda_vehicle.capabilities import Capabilities
from vda_vehicle.factsheet import SHARED_FACTSHEETS, FactsheetTiming, build_factsheet
from vda_vehicle.faults import broker_access_error, decode_error, over_limits, with_errors
from vda_vehicle.instant import receive_instant_actions
from vda_vehicle.limits import instant_limit_problems
from vda_vehicle.maps import DOWNLOAD_MAP, DownloadRequest, download_finished, download_request
from vda_vehicle.model import Pose, RobotMode, VehicleState
from vda_vehicle.navigation import NavigationStack, is_steady
from vda_vehicle.order_executor import Accept, Ignore, Mode, Reject, apply_order, decide_order
from vda_vehicle.reporter import held_maps, state_body, visualization_body
from vda_vehicle.translator import advance, arrival_time, cruise_pose, quiet_time, standing_by
from vda_vehicle.vehicle_status import (
    RULES_2X,
    ModeRules,
    StackStatus,
    apply_status,
    moved_by_hand,
)

log = structlog.get_logger()
Publish = Callable[[str, Topic, Payload], None]


#: How much earlier than a deferred state's due time its timer may read the clock.
_TIMER_SLACK_S = 1e-3


@dataclass
class Metrics:
    """Lateness samples in seconds (bounded), for the benchmark and diagnostics."""

    tick_lateness_s: deque[float] = field(default_factory=lambda: deque(maxlen=100_000))
    state_lateness_s: deque[float] = field(default_factory=lambda: deque(maxlen=100_000))
    states_sent: int = 0


@dataclass(frozen=True, slots=True)
class Timing:
    """Wall-clock publishing periods in seconds; visualization 0 = off."""

    state_interval_s: float
    visualization_interval_s: float
    tick_s: float
    #: The simulation's time lapse: the factsheet states speeds as seen in wall time.
    time_lapse: float = 1.0

    @property
    def min_state_interval_s(self) -> float:
        """The least gap between two states (R94), declared in the factsheet: half a tick, so a
        state deferred by the gate always goes out on the next tick despite timer jitter."""
        return self.tick_s / 2


class VehicleRuntime:
    """One vehicle: its state, its header stamper and what it publishes."""

    #: What the protocol version makes of the robot's operating modes (vehicle_status).
    MODE_RULES: ModeRules = RULES_2X

    def __init__(
        self,
        *,
        agv: AgvId,
        state: VehicleState,
        caps: Capabilities,
        stack: NavigationStack,
        stamper: HeaderStamper,
        interface_name: str,
        timing: Timing,
        clock: Clock,
        metrics: Metrics,
    ) -> None:
        self.agv = agv
        self._state = state
        #: Ticks are skipped until this time (monotonic) while nothing can happen (see tick).
        self._quiet_until = -math.inf
        #: Simulated seconds of skipped ticks, simulated when the state is next read or ticked.
        self._owed_s = 0.0
        self._caps = caps
        self._stack = stack
        self._steady_stack = is_steady(stack)
        self._stamper = stamper
        self._timing = timing
        self._clock = clock
        self._metrics = metrics
        major = int(stamper.version.split(".", 1)[0])
        self.topics = {t: build_topic(interface_name, major, agv, t) for t in topics_of(major)}
        #: 2.1 reports ``maps`` (2.0 has none; 3.0 builds its own): the list for the state's
        #: maps, rebuilt only when they change.
        self._reports_maps = stamper.version == "2.1.0"
        self._maps_of: tuple[object, ...] | None = None
        self._maps: list[Map] | None = None
        self._publish: Publish = _not_connected
        self._published_revision = -1
        self._state_due_at = 0.0
        self._last_state_at = float("-inf")
        self._state_deferred = False
        self._next_visualization_at = 0.0
        #: (pose, motion, position_initialized) of the last visualization, and its body.
        self._visualized: tuple[object, ...] = ()
        self._visualization_body: EncodedBody | None = None
        self._tolerated: set[str] = set()
        self._broker_errors: tuple[Error, ...] = ()
        self._last_tick_at: float | None = None
        self._woken_at: float | None = None
        #: Told the clock time of the next event while ticks are skipped (see on_next_event).
        self._on_next_event: Callable[[float], None] | None = None
        self._connection_bodies: dict[Hashable, EncodedBody] = {}
        #: Map downloads under way (downloadMap, vda_vehicle.map_download).
        self._downloads: set[asyncio.Task[None]] = set()
        #: Where the robot stood when it entered MANUAL (None in every other mode): a robot
        #: moved away from there forgets lastNodeId in 3.0 (T62).
        self._manual_anchor: tuple[float, float] | None = None

    @property
    def state(self) -> VehicleState:
        """The vehicle's state as of its last tick (skipped ticks are simulated first)."""
        if self._owed_s:
            owed, self._owed_s = self._owed_s, 0.0
            before = self._state
            self._state = advance(before, owed, caps=self._caps, stack=self._stack)
            if self._state.revision != before.revision:  # not expected: tick it in full next
                self._quiet_until = -math.inf
        return self._state

    @state.setter
    def state(self, value: VehicleState) -> None:
        """A new state (a message, a tick): the next tick runs in full."""
        self._state = value
        self._quiet_until = -math.inf

    def attach(self, publish: Publish, *, visualization_offset_s: float = 0.0) -> None:
        """Send through ``publish`` (the vehicle's MQTT session)."""
        self._publish = publish
        self._next_visualization_at = self._clock.monotonic() + visualization_offset_s

    def on_next_event(self, hook: Callable[[float], None]) -> None:
        """While ticks are skipped on a cruise along an edge, tell ``hook`` when (the clock's
        monotonic time) its end node will be reached, an event that calls for a state (R93). A
        caller that calls :meth:`tick_event` then reports it on time instead of at the next
        tick after it (up to a tick period late)."""
        self._on_next_event = hook

    # -- connection and factsheet (§6.14, §6.15) ------------------------------------------------

    def connection_payload(self, connection_state: ConnectionState) -> bytes:
        return self._connection_bytes(
            connection_state,
            lambda: Connection(
                header_id=0,
                timestamp="1970-01-01T00:00:00.000Z",
                version=self._stamper.version,
                manufacturer=self.agv.manufacturer,
                serial_number=self.agv.serial_number,
                connection_state=connection_state,
            ),
        )

    def _connection_bytes(self, key: Hashable, build: Callable[[], WireModel]) -> bytes:
        """The connection message ``build`` makes for ``key``, stamped afresh: its body is
        encoded once (a last will and an ONLINE at every connect of every vehicle)."""
        body = self._connection_bodies.get(key)
        if body is None:
            body = self._connection_bodies[key] = EncodedBody.of(build())
        return self._stamper.encode_body(Topic.CONNECTION, body)

    def will(self) -> Will:
        """R08: the last will, CONNECTIONBROKEN, QoS 1 retained (stamped at each connect)."""
        payload = self.connection_payload(ConnectionState.CONNECTIONBROKEN)
        return Will(self.topics[Topic.CONNECTION], payload)

    def on_connected(self) -> None:
        """R09: ONLINE after every (re)connect, then the retained factsheet and a state."""
        online = self.topics[Topic.CONNECTION]
        self._publish(
            online, Topic.CONNECTION, lambda: self.connection_payload(ConnectionState.ONLINE)
        )
        self.publish_factsheet()
        self.publish_state()

    def set_broker_problems(self, problems: tuple[AccessProblem, ...]) -> None:
        """What the broker refuses, as WARNINGs in every state while it lasts (issue 14)."""
        self._broker_errors = tuple(broker_access_error(problem) for problem in problems)
        self.publish_state()

    def on_stack_status(self, status: StackStatus) -> None:
        """The robot's operating mode or safety chain changed (its navigation stack calls this):
        fold it into the state and report it (§6.10.6; :mod:`vda_vehicle.vehicle_status`)."""
        before = self.state
        self.state = apply_status(before, status, self._caps.catalog, self.MODE_RULES)
        self._state = self._moved_by_hand(self._state)  # MANUAL entered or left: T62's reference
        if self.state is before:
            return
        self._quiet_until = -math.inf  # a held or released vehicle is stepped at once
        log.info(
            "vehicle.status_changed",
            agv=str(self.agv),
            operating_mode=status.operating_mode.value,
            e_stop=status.e_stop.value,
            field_violation=status.field_violation,
            order_cleared=bool(before.nodes) and not self.state.nodes,
        )
        self._after_change()

    def _factsheet_timing(self) -> FactsheetTiming:
        """The timings the factsheet states (wall time: speeds scaled by the time lapse)."""
        return FactsheetTiming(
            min_state_interval_s=self._timing.min_state_interval_s,
            state_interval_s=self._timing.state_interval_s,
            visualization_interval_s=self._timing.visualization_interval_s,
            time_lapse=self._timing.time_lapse,
        )

    def publish_factsheet(self) -> None:
        timing, version = self._factsheet_timing(), self._stamper.version
        body = SHARED_FACTSHEETS.body(
            self._caps,
            timing,
            version,
            lambda: build_factsheet(self._caps, timing, version=version),
        )
        self._publish(
            self.topics[Topic.FACTSHEET],
            Topic.FACTSHEET,
            lambda: self._stamper.encode_body(Topic.FACTSHEET, body),
        )

    # -- inbound ----------------------------------------------------------------------------------

    def handle_order(self, topic: str, payload: bytes) -> None:
        """Figure 8 on one order message; bad input becomes a validationError (issue item 7)."""
        self._note_message()
        order = decode_as(
            Order,
            Topic.ORDER,
            payload,
            address=parse_topic(topic),
            max_bytes=self._caps.limits.msg_len,
        )
        if isinstance(order, DecodeFailure):
            self._reject_input(order)
            return
        match decide_order(self.state, order, self._caps):
            case Accept(mode=mode):
                self.state = apply_order(self.state, order, mode, self._caps)
                self._set_off()
                self._log_accepted(order.order_id, order.order_update_id, mode)
            case Reject(errors=errors):
                self._reject_order(order.order_id, errors)
            case Ignore():
                log.info("order.duplicate_ignored", agv=str(self.agv), order_id=order.order_id)
        self.publish_state()  # §6.10: every received order triggers a state

    def _set_off(self) -> None:
        """After accepting an order: a step of no time, so that the state answering the order
        (§6.10) already says the vehicle drives, instead of a second state a tick later."""
        self.state = advance(self.state, 0.0, caps=self._caps, stack=self._stack)

    def _log_accepted(self, order_id: str, order_update_id: int, mode: Mode) -> None:
        log.info(
            "order.accepted",
            agv=str(self.agv),
            order_id=order_id,
            order_update_id=order_update_id,
            mode=mode,
        )

    def _reject_order(self, order_id: str, errors: Sequence[Error]) -> None:
        """Keep a rejected order's errors in the state and log them (the state follows)."""
        self.state = self.state.bumped(errors=with_errors(self.state.errors, *errors))
        log.warning(
            "order.rejected",
            agv=str(self.agv),
            order_id=order_id,
            error_types=sorted({e.error_type for e in errors}),
        )

    def handle_instant_actions(self, topic: str, payload: bytes) -> None:
        """§6.9: every instant action gets an actionState at once (R67)."""
        self._note_message()
        message = decode_as(
            InstantActions,
            Topic.INSTANT_ACTIONS,
            payload,
            address=parse_topic(topic),
            max_bytes=self._caps.limits.msg_len,
        )
        if isinstance(message, DecodeFailure):
            self._reject_input(message)
            return
        self._note_tolerated(Topic.INSTANT_ACTIONS, message.tolerated)
        problems = instant_limit_problems(message, self._caps.limits)
        if problems:
            self._reject_input(over_limits(message, problems))
            return
        self.state = receive_instant_actions(self.state, message, self._caps)
        log.info(
            "instant_actions.received",
            agv=str(self.agv),
            action_types=[a.action_type for a in message.actions],
        )
        self._start_downloads(message.actions)
        self._after_change()

    def _start_downloads(self, actions: Sequence[Action]) -> None:
        """Fetch the map of every downloadMap among ``actions`` in the background (§6.7.3); one
        that cannot start (R87: the map is held already) ends FAILED at once."""
        for action in actions:
            if action.action_type != DOWNLOAD_MAP:
                continue
            request = download_request(self.state, action.action_id)
            if isinstance(request, str):
                self._end_download(action.action_id, request)
                continue
            task = asyncio.get_running_loop().create_task(
                self._download(request), name=f"vehicle.{self.agv.serial_number}.download_map"
            )
            self._downloads.add(task)
            task.add_done_callback(self._downloads.discard)

    async def _download(self, request: DownloadRequest) -> None:
        # Imported here: httpx is not the vehicles' start-up (docs/performance.md, start-up).
        from vda_vehicle.map_download import fetch_map  # noqa: PLC0415

        log.info(
            "map.download_started",
            agv=str(self.agv),
            map_id=request.map_id,
            map_version=request.map_version,
            link=request.link,
        )
        self._end_download(request.action_id, await fetch_map(request))

    def _end_download(self, action_id: str, problem: str | None) -> None:
        self.state = download_finished(self.state, action_id, problem)
        if problem is None:
            log.info("map.downloaded", agv=str(self.agv), action_id=action_id)
        else:
            log.warning(
                "map.download_failed", agv=str(self.agv), action_id=action_id, reason=problem
            )
        self._quiet_until = -math.inf
        self._after_change()

    def _note_tolerated(self, topic: Topic, notes: tuple[str, ...]) -> None:
        """Tolerant reader: one INFO line per kind of deviation accepted, not one per message."""
        for note in notes:
            if note not in self._tolerated:
                self._tolerated.add(note)
                log.info("message.tolerated", agv=str(self.agv), topic=topic.value, note=note)

    def _reject_input(self, failure: DecodeFailure) -> None:
        error = decode_error(failure)
        self.state = self.state.bumped(errors=with_errors(self.state.errors, error))
        log.warning(
            "message.rejected",
            agv=str(self.agv),
            topic=failure.topic.value,
            header_id=failure.header_id,
            reason=failure.summary(limit=3),
        )
        self.publish_state()

    # -- tick and publishing ----------------------------------------------------------------------

    def _note_message(self) -> None:
        """A message arrives: it acts from now, and the next tick simulates only the time since
        now. What was advancing meanwhile (driving, an action) is simulated up to now first, so
        a vehicle set going by an order never drives in the part of the tick period before the
        order arrived (it did while, say, an instant action was still to finish)."""
        self._quiet_until = -math.inf
        if self._woken_at is not None:  # an earlier message of this tick period caught up
            return
        now = self._clock.monotonic()
        last = self._last_tick_at
        state = self.state
        if last is not None and now > last and not standing_by(state):
            self.state = self._simulate(state, (now - last) * self._timing.time_lapse)
        self._woken_at = now

    def _simulate(self, before: VehicleState, dt: float) -> VehicleState:
        """``before`` advanced by ``dt`` simulated seconds."""
        after = advance(before, dt, caps=self._caps, stack=self._stack)
        if after.last_node_sequence_id != before.last_node_sequence_id:
            log.debug("node.reached", agv=str(self.agv), node_id=after.last_node_id)
        if after.operating_mode is RobotMode.MANUAL or self._manual_anchor is not None:
            return self._moved_by_hand(after)  # a real stack reports a robot pushed by hand
        return after

    def move_by_hand(self, pose: Pose) -> str | None:
        """An operator pushes the robot to ``pose`` (a simulated vehicle: the control API; a real
        robot's stack reports its pose itself); why not, or None. Only in MANUAL: in every other
        mode the robot's own navigation decides where it is."""
        mode = self.state.operating_mode
        if mode is not RobotMode.MANUAL:
            return f"its operatingMode is {mode.value}: an operator moves it only in MANUAL"
        self.state = self._moved_by_hand(replace(self.state, pose=pose))
        log.info("vehicle.moved_by_hand", agv=str(self.agv), x=pose.x, y=pose.y)
        self._after_change()
        return None

    def _moved_by_hand(self, state: VehicleState) -> VehicleState:
        """T62 (3.0): lastNodeId forgotten once the robot is moved away in MANUAL; where it
        stood when MANUAL began is the reference (:func:`vehicle_status.moved_by_hand`)."""
        if state.operating_mode is not RobotMode.MANUAL:
            self._manual_anchor = None
            return state
        if self._manual_anchor is None:
            self._manual_anchor = (state.pose.x, state.pose.y)
            return state
        reach = self._caps.deviation_xy_m
        return moved_by_hand(state, self._manual_anchor, reach, self.MODE_RULES)

    def _simulated_dt(self, dt: float, now: float) -> float:
        """``dt``, or its share after the tick period's first message (:meth:`_note_message`
        simulated what came before it)."""
        last, woken = self._last_tick_at, self._woken_at
        self._last_tick_at, self._woken_at = now, None
        if woken is None:
            return dt
        if last is None:  # the first tick ever: dt runs from when the tick loop started
            return min(dt, max(0.0, now - woken) * self._timing.time_lapse)
        if now <= last:
            return dt
        return dt * min(1.0, max(0.0, (now - woken) / (now - last)))

    def tick(self, dt: float, now: float) -> None:
        """One simulation step; publish what §6.10/§6.13 call for. Nothing above DEBUG here.

        While nothing can happen before the next event (a node reached, an action's end, a
        heartbeat due: :func:`~vda_vehicle.translator.quiet_time`), the tick only counts its
        time; the next full tick (or a read of :attr:`state`) simulates it all in one step. A
        visualization due meanwhile shows the pose the cruise has reached
        (:meth:`_visible_pose`) without simulating it. A driving vehicle runs a full tick about
        once per node.
        """
        if now < self._quiet_until:
            self._owed_s += dt
            self._last_tick_at = now
            self._visualize_if_due(now)
            return
        dt += self._owed_s
        self._owed_s = 0.0
        dt = self._simulated_dt(dt, now)
        self.state = self._simulate(self.state, dt)
        self._after_change(now)
        self._visualize_if_due(now)
        self._quiet_until = self._next_full_tick(now)

    def _visualize_if_due(self, now: float) -> None:
        """§6.13: a visualization every ``visualization_interval_s`` (0: none)."""
        interval = self._timing.visualization_interval_s
        if interval and now >= self._next_visualization_at:
            self._next_visualization_at = max(self._next_visualization_at + interval, now)
            self._publish(
                self.topics[Topic.VISUALIZATION], Topic.VISUALIZATION, self._visualization
            )

    def _visible_state(self) -> VehicleState:
        """The state to visualize now: as of the last tick, with :meth:`_visible_pose`."""
        state = self._state
        pose = self._visible_pose()
        return state if pose is state.pose else evolve(state, pose=pose)

    def _visible_pose(self) -> Pose:
        """The pose to visualize now: as of the last tick, moved on by the skipped ticks' time
        during a cruise (:func:`~vda_vehicle.translator.cruise_pose`) instead of simulating
        them (they are simulated at the next full tick, in one step)."""
        state = self._state
        owed = self._owed_s
        if not owed or not state.motion.moving:
            return state.pose
        return cruise_pose(state, owed)

    def tick_to(self, now: float, first_dt: float) -> None:
        """:meth:`tick` at ``now`` over the time since this vehicle's own last tick (``first_dt``
        on its first), so that ticks of its own between the shared ones count once."""
        last = self._last_tick_at
        dt = first_dt if last is None else max(0.0, now - last) * self._timing.time_lapse
        self.tick(dt, now)

    def tick_event(self, now: float) -> None:
        """The time :meth:`on_next_event` announced has come: tick in full at ``now``."""
        self._quiet_until = -math.inf
        self.tick_to(now, 0.0)

    def _next_full_tick(self, now: float) -> float:
        """Until when ticks may be skipped: the next possible event or heartbeat (-inf: tick the
        next one in full); visualizations go out meanwhile (:meth:`_visualize_if_due`)."""
        if self._state_deferred:
            return -math.inf
        quiet_s = quiet_time(self._state, steady_stack=self._steady_stack)
        if quiet_s <= 0:
            return -math.inf
        lapse = self._timing.time_lapse
        if self._on_next_event is not None and quiet_s < math.inf:  # cruising, not at rest
            self._on_next_event(now + arrival_time(self._state, quiet_s) / lapse)
        return min(now + quiet_s / lapse, self._last_state_at + self._timing.state_interval_s)

    def _after_change(self, now: float | None = None) -> None:
        now = self._clock.monotonic() if now is None else now
        if self.state.factsheet_requested:
            self.state = replace(self.state, factsheet_requested=False)
            self.publish_factsheet()  # R80
        heartbeat_due = now - self._last_state_at >= self._timing.state_interval_s
        changed = self.state.revision != self._published_revision
        if changed or heartbeat_due or self._state_deferred:
            self.publish_state(now)

    def publish_state(self, now: float | None = None) -> None:
        """Queue a state; it is built and stamped from the newest state when really sent.

        R94: two states are never closer than the factsheet's minStateInterval. A state asked
        for sooner is deferred; the next tick sends it, with everything that changed meanwhile.
        """
        now = self._clock.monotonic() if now is None else now
        if now - self._last_state_at < self._timing.min_state_interval_s:
            self._state_deferred = True
            return
        self._state_deferred = False
        self._published_revision = self.state.revision
        self._last_state_at = now
        self._state_due_at = now
        self._publish(self.topics[Topic.STATE], Topic.STATE, self._state_payload)

    def deferred_state_due(self) -> float | None:
        """When a state deferred by R94 may go out (the clock's monotonic time); None if none
        waits."""
        if not self._state_deferred:
            return None
        return self._last_state_at + self._timing.min_state_interval_s

    def send_deferred_state(self) -> None:
        """Send a deferred state once minStateInterval has passed (R94), without waiting for the
        next full tick, which may be up to a tick later. A timer set for the due time may read
        the clock a rounding error before it: that counts as due."""
        due = self.deferred_state_due()
        if due is None:
            return
        now = self._clock.monotonic()
        if now >= due - _TIMER_SLACK_S:
            self.publish_state(max(now, due))

    def _state_payload(self) -> bytes:
        self._metrics.state_lateness_s.append(self._clock.monotonic() - self._state_due_at)
        self._metrics.states_sent += 1
        state = self.state
        body = state_body(
            state, self._caps, maps=self._reported_maps(state), more_errors=self._broker_errors
        )
        return self._stamper.encode_body(Topic.STATE, body)

    def _reported_maps(self, state: VehicleState) -> list[Map] | None:
        if not self._reports_maps:
            return None
        if state.maps is not self._maps_of:
            self._maps_of, self._maps = state.maps, held_maps(state.maps)
        return self._maps

    def _visualization(self) -> bytes:
        """A standing vehicle's visualization differs from its last only in the header: its
        body is encoded again only when pose, motion or localisation changed (a fleet mostly
        stands)."""
        state = self._state
        pose = self._visible_pose()
        key = (pose, state.motion, state.position_initialized)
        body = self._visualization_body
        if body is None or key != self._visualized:
            body = self._visualization_body = visualization_body(state, pose)
            self._visualized = key
        return self._stamper.encode_body(Topic.VISUALIZATION, body)


def _not_connected(_topic: str, _kind: Topic, _payload: Payload) -> None:
    msg = "VehicleRuntime.attach() must be called before publishing"
    raise RuntimeError(msg)
