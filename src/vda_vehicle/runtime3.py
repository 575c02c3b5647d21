"""One simulated vehicle speaking VDA 5050 3.0 (``--vda-version 3.0.0``).

The same shell and core as 2.x (:class:`VehicleRuntime`); only the edges differ: 3.0 payloads
are decoded and decided by :mod:`vda_vehicle.v3_inbound`, and states, visualizations,
connection messages and the factsheet leave in the 3.0 shape built by
:mod:`vda_vehicle.v3_report`. Topics are those of ``v3`` (T01, T02), including ``zoneSet`` and
``responses``. RELEASE zones are asked for with zone requests whose lifecycle is
:mod:`vda_vehicle.v3_requests`; this shell feeds it the way ahead, the pose and the clock, and
keeps the vehicle out of a zone it holds no grant for (T91, T93).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from datetime import datetime
from typing import Any, Final, TypeVar

import structlog

from vda5050.codec import DecodeFailure, decode_as, encode
from vda5050.evolve import evolve
from vda5050.models import ActionScope, ActionStatus, ConnectionState, Error, v3
from vda5050.models.factsheet import ValueDataType
from vda5050.topics import Topic, parse_topic
from vda_vehicle.actions import ActionSpec, ParameterSpec, record_of
from vda_vehicle.factsheet import SHARED_FACTSHEETS
from vda_vehicle.faults import over_limits, with_errors
from vda_vehicle.instant import receive_instant_actions
from vda_vehicle.limits import instant_limit_problems
from vda_vehicle.model import RobotMode, VehicleState
from vda_vehicle.order_executor import Accept, Ignore, Reject, apply_order
from vda_vehicle.runtime import VehicleRuntime
from vda_vehicle.v3_inbound import (
    ENABLE_ZONE_SET,
    RETRY,
    SKIP_RETRY,
    START_HIBERNATION,
    STOP_HIBERNATION,
    begin_hibernation,
    blocked_ahead,
    capped_held_edges,
    decide_order_v3,
    finished_instant,
    keep_ended_instant_states,
    release_zones_ahead,
    retriable_action_ids,
    retry_action,
    retype_new_errors,
    shutdown_refusal,
    single_action_ids,
    split_instant_actions,
    stored,
    to_core_order,
    wake_up_time,
    with_cleared,
    with_refused,
    zone_capped,
)
from vda_vehicle.v3_report import (
    build_factsheet_v3,
    build_state_v3,
    build_visualization_v3,
    connection_v3,
)
from vda_vehicle.v3_requests import (
    RELEASE_LOST_DRIVING_ON,
    Answer,
    HeldRequest,
    Outcome,
    ZoneRequests,
    answer,
    cleared,
    first_closed,
    forget_refusals,
    loss_errors,
    track,
)
from vda_vehicle.v3_requests import reported as reported_requests
from vda_vehicle.v3_zones import (
    ReleaseZone,
    ZoneKey,
    ZoneSets,
    delete_zone_set,
    enable_zone_set,
    receive_zone_set,
    release_loss_defaulted,
    release_zones,
    reported,
)
from vda_vehicle.vehicle_status import RULES_3_0

log = structlog.get_logger()
#: The 2.x connection states the shell asks for, in their 3.0 spelling (T15).
_CONNECTION_STATES: Final = {
    ConnectionState.ONLINE: v3.ConnectionState.ONLINE,
    ConnectionState.OFFLINE: v3.ConnectionState.OFFLINE,
    ConnectionState.CONNECTIONBROKEN: v3.ConnectionState.CONNECTION_BROKEN,
}
#: startHibernation: an instant action that runs until the order is cleared (like cancelOrder).
HIBERNATION_SPEC: Final = ActionSpec(
    START_HIBERNATION,
    "clear the order, stand still, stay connected and silent (HIBERNATING)",
    frozenset({ActionScope.INSTANT}),
    (
        ParameterSpec(
            "wakeUpTime",
            ValueDataType.STRING,
            "when to wake up by itself, an ISO 8601 date-time with its offset",
            optional=True,
        ),
    ),
    run_s=math.inf,
)
#: The modes fleet control drives in; entering any other clears the zone requests (Table 11).
_REQUESTING_MODES: Final = frozenset({RobotMode.AUTOMATIC, RobotMode.SEMIAUTOMATIC})
#: A zoneSet or responses message, decoded.
_Input = TypeVar("_Input", v3.ZoneSetMessage, v3.Responses)
#: The errors of a release lost inside a zone (v3_requests.loss_errors), kept while it lasts.
_LOSS_ERROR_TYPES: Final = frozenset({v3.ErrorType.RELEASE_LOST.value, RELEASE_LOST_DRIVING_ON})


class VehicleRuntimeV3(VehicleRuntime):
    """A vehicle whose wire protocol is 3.0; its core is the version-neutral one.

    Hibernation (T06) lives here: ``startHibernation`` clears the order like a cancel; once it is
    FINISHED and that state is out, HIBERNATING is published and the vehicle goes silent (no
    state, no visualization, no motion) and ignores everything but ``stopHibernation``, which
    brings ONLINE and states back. The MQTT connection stays up throughout.
    """

    #: 3.0's modes: INTERVENED and STARTUP, lastNodeId forgotten (T62: SERVICE, TEACH_IN and
    #: STARTUP; MANUAL only when the robot was moved where it can start no order, which the
    #: stack does not report), a clearing reported once uncancellable actions end (T64).
    MODE_RULES = RULES_3_0

    _last_order: v3.Order | None = None
    #: The zone sets held (v3_zones), reported in state.zoneSets.
    zones: ZoneSets = ()
    #: Hibernating: connected, silent, deaf to all but stopHibernation.
    hibernating: bool = False
    #: The actionId of a startHibernation still clearing the order.
    _hibernation_action: str | None = None
    #: When a hibernating vehicle wakes up by itself (startHibernation's wakeUpTime, T06).
    _wake_at: datetime | None = None
    #: A shutdown FINISHED, waiting for the state that says so to be out (T07).
    _shutting_down: bool = False
    #: Shut down: disconnected, never ticked or heard again (T07).
    shut_down: bool = False
    #: Called once the shutdown is reported: the shell disconnects the vehicle with OFFLINE.
    _on_shutdown: Callable[[], None] | None = None
    #: The zone requests (v3_requests), reported in state.zoneRequests (T91, T93).
    requests: ZoneRequests = ZoneRequests()
    #: The RELEASE zones of the enabled zone sets (asked for when the way ahead reaches them).
    _release_zones: tuple[ReleaseZone, ...] = ()
    #: The state revision that carries the newest change of the requests.
    _requests_revision: int = 0
    #: Stop before the edge with this sequenceId: it enters an enabled BLOCKED zone (T89).
    _blocked_at: int | None = None
    #: Stop before the edge with this sequenceId: a RELEASE zone it reaches is not granted.
    _release_at: int | None = None

    def __init__(self, **kwargs: Any) -> None:  # noqa: ANN401 - VehicleRuntime's keywords
        super().__init__(**kwargs)
        # startHibernation runs like cancelOrder until the order is cleared (T06, T61).
        catalog = {**self._caps.catalog, START_HIBERNATION: HIBERNATION_SPEC}
        self._caps = replace(self._caps, catalog=catalog)
        #: §6.4.1.1: RELEASE zones are contour-based. The body is taken as the circle round its
        #: footprint (factsheet physicalParameters length and width): half its diagonal.
        self._reach = math.hypot(self._caps.length_m, self._caps.width_m) / 2

    def _publish_connection(self, connection_state: v3.ConnectionState) -> None:
        self._publish(
            self.topics[Topic.CONNECTION],
            Topic.CONNECTION,
            lambda: self._connection_v3(connection_state),
        )

    def _connection_v3(self, connection_state: v3.ConnectionState) -> bytes:
        return self._connection_bytes(
            connection_state,
            lambda: connection_v3(self.agv.manufacturer, self.agv.serial_number, connection_state),
        )

    def on_connected(self) -> None:
        """T05: ONLINE, factsheet, state after every (re)connect; a hibernating vehicle says
        HIBERNATING instead and sends no state (T06)."""
        if not self.hibernating:
            super().on_connected()
            return
        self._publish_connection(v3.ConnectionState.HIBERNATING)
        self.publish_factsheet()

    def publish_state(self, now: float | None = None) -> None:
        if not self.hibernating:  # T06: no states while hibernating
            super().publish_state(now)

    def on_shutdown(self, hook: Callable[[], None]) -> None:
        """T07: ``hook`` disconnects the vehicle (OFFLINE first) once a shutdown is reported."""
        self._on_shutdown = hook

    def tick(self, dt: float, now: float) -> None:
        if self.shut_down:
            return
        if self.hibernating:
            wake_at = self._wake_at
            if wake_at is None or self._clock.now() < wake_at:
                return  # T06: stands still, sends nothing
            self._wake_up(None)  # T06: the wake-up time has come
        super().tick(dt, now)
        self._maybe_hibernate()
        self._maybe_shut_down()

    def _maybe_hibernate(self) -> None:
        """Go HIBERNATING once startHibernation is FINISHED and a state saying so is out."""
        if self._hibernation_action is None:
            return
        record = record_of(self.state, self._hibernation_action)
        if record is None or record.status is ActionStatus.FAILED:
            self._hibernation_action = None
            return
        published = self._published_revision == self.state.revision and not self._state_deferred
        if record.status is ActionStatus.FINISHED and published:
            self._hibernation_action = None
            self.hibernating = True
            self._publish_connection(v3.ConnectionState.HIBERNATING)
            log.info("vehicle.hibernating", agv=str(self.agv))

    def _while_hibernating(self, message: v3.InstantActions | DecodeFailure) -> None:
        """T06: nothing but stopHibernation is answered."""
        wake = [] if isinstance(message, DecodeFailure) else message.actions
        wake = [a for a in wake if a.action_type == STOP_HIBERNATION]
        if wake:
            self._wake_up(wake[0])
        else:
            log.info("instant_actions.ignored_while_hibernating", agv=str(self.agv))

    def _edge_action(self, action: v3.InstantAction) -> None:
        """retry / skipRetry (T53), enableZoneSet / deleteZoneSet (T87)."""
        if action.action_type in (RETRY, SKIP_RETRY):
            self._retry_action(action)
        else:
            self._zone_action(action)

    def _begin_hibernation(self, action: v3.InstantAction) -> None:
        """T06: the order cleared first; HIBERNATING once a state says startHibernation is
        FINISHED (:meth:`_maybe_hibernate`); its wakeUpTime kept."""
        group = self.state.next_group
        self.state = begin_hibernation(self.state, action, group, self._caps)
        self.state = replace(self.state, next_group=group - 1)
        self._hibernation_action = action.action_id
        wake_at = wake_up_time(action)
        self._wake_at = wake_at if isinstance(wake_at, datetime) else None

    def _begin_shutdown(self, action: v3.InstantAction) -> None:
        """T07: FINISHED while idle (then OFFLINE and a coordinated disconnect once a state
        says so), else FAILED with the reason."""
        refusal = shutdown_refusal(self.state)
        self.state = finished_instant(self.state, action, self.state.next_group, failed=refusal)
        if refusal is None:
            self._shutting_down = True
            log.info("vehicle.shutting_down", agv=str(self.agv), action_id=action.action_id)

    def _maybe_shut_down(self) -> None:
        published = self._published_revision == self.state.revision and not self._state_deferred
        if not self._shutting_down or not published:
            return
        self._shutting_down = False
        self.shut_down = True
        log.info("vehicle.shut_down", agv=str(self.agv))
        if self._on_shutdown is not None:
            self._on_shutdown()

    def _wake_up(self, action: v3.InstantAction | None) -> None:
        """T06: ONLINE again and states resume, on stopHibernation (the action FINISHED in the
        next state) or, with ``action`` None, at startHibernation's wakeUpTime."""
        self.hibernating = False
        self._wake_at = None
        if action is not None:
            self.state = finished_instant(self.state, action, self.state.next_group)
        self._publish_connection(v3.ConnectionState.ONLINE)
        log.info(
            "vehicle.awake", agv=str(self.agv), by="stopHibernation" if action else "wakeUpTime"
        )
        self.publish_state()

    def connection_payload(self, connection_state: ConnectionState) -> bytes:
        """T05: ONLINE, OFFLINE and the CONNECTION_BROKEN last will, in 3.0 shape."""
        return self._connection_v3(_CONNECTION_STATES[connection_state])

    def publish_factsheet(self) -> None:
        """T80: the retained 3.0 factsheet, also sent on factsheetRequest."""
        timing = self._factsheet_timing()
        body = SHARED_FACTSHEETS.body(
            self._caps, timing, "3.0.0", lambda: build_factsheet_v3(self._caps, timing)
        )
        self._publish(
            self.topics[Topic.FACTSHEET],
            Topic.FACTSHEET,
            lambda: self._stamper.encode_body(Topic.FACTSHEET, body),
        )

    def handle_order(self, topic: str, payload: bytes) -> None:
        """3.0 Figure 8 on one order message (T17-T38); undecodable input: VALIDATION_FAILURE
        (T20)."""
        self._note_message()
        order = decode_as(
            v3.Order,
            Topic.ORDER,
            payload,
            address=parse_topic(topic),
            max_bytes=self._caps.limits.msg_len,
        )
        if self.hibernating:
            log.info("order.ignored_while_hibernating", agv=str(self.agv))
            return
        if isinstance(order, DecodeFailure):
            self._reject_input(order)
            return
        decision = decide_order_v3(
            self.state, order, self._caps, last=self._last_order, zones=self.zones
        )
        match decision:
            case Accept(mode=mode):
                alone = single_action_ids(order)
                core = zone_capped(to_core_order(order), order, self.zones)
                before = self.state
                retriable = retriable_action_ids(order)
                self.state = apply_order(
                    before, core, mode, self._caps, alone=alone, retriable=retriable
                )
                self.state = keep_ended_instant_states(before, self.state)
                self.requests = forget_refusals(self.requests)
                self._keep_out_of_zones()  # no BLOCKED zone ahead; RELEASE zones asked for
                self._set_off()
                self._last_order = order
                self._log_accepted(order.order_id, order.order_update_id, mode)
            case Reject(errors=errors):
                self._reject_order(order.order_id, errors)
            case Ignore():
                log.info("order.duplicate_ignored", agv=str(self.agv), order_id=order.order_id)
        self.publish_state()  # T68: every received order triggers a state

    def handle_instant_actions(self, topic: str, payload: bytes) -> None:
        """Every instant action gets an instantActionState at once; refusals raise
        INVALID_INSTANT_ACTION or NO_ORDER_TO_CANCEL (T46, Table 9)."""
        self._note_message()
        message = decode_as(
            v3.InstantActions,
            Topic.INSTANT_ACTIONS,
            payload,
            address=parse_topic(topic),
            max_bytes=self._caps.limits.msg_len,
        )
        if self.hibernating:
            self._while_hibernating(message)
            return
        if isinstance(message, DecodeFailure):
            self._reject_input(message)
            return
        split = split_instant_actions(self.state, message)
        problems = instant_limit_problems(split.core, self._caps.limits)
        if problems:
            self._reject_input(over_limits(split.core, problems))
            return
        before = self.state.errors
        self.state = with_cleared(self.state, split.clears, self.state.next_group)
        for action in split.edge_actions:
            self._edge_action(action)
        if split.core.actions:
            self.state = receive_instant_actions(self.state, split.core, self._caps)
            self._start_downloads(split.core.actions)
        if split.refused:
            self.state = with_refused(self.state, split.refused, self.state.next_group)
        if split.hibernation is not None:
            self._begin_hibernation(split.hibernation)
        if split.shutdown is not None:
            self._begin_shutdown(split.shutdown)
        self.state = self.state.bumped(errors=retype_new_errors(before, self.state.errors))
        log.info(
            "instant_actions.received",
            agv=str(self.agv),
            action_types=[a.action_type for a in message.actions],
        )
        self._after_change()
        self._maybe_hibernate()
        self._maybe_shut_down()

    def handle_zone_set(self, topic: str, payload: bytes) -> None:
        """T87, T88: a new zone set is stored DISABLED; one with a zone type this vehicle does
        not honour is not taken over (UNSUPPORTED_PARAMETER, CRITICAL), a zoneSetId already held
        is DUPLICATE_ZONE_SET, a malformed one VALIDATION_FAILURE (T85). A RELEASE zone without
        releaseLossBehavior is taken as STOP (Table 6), and logged."""
        defaulted: tuple[str, ...] = ()
        if len(payload) <= self._caps.limits.msg_len:
            payload, defaulted = release_loss_defaulted(payload)
        message = self._awake_input(v3.ZoneSetMessage, Topic.ZONE_SET, topic, payload)
        if message is None:
            return
        self.zones, errors = receive_zone_set(self.zones, message)
        if errors:
            stored_errors = [stored(error) for error in errors]
            self.state = self.state.bumped(errors=with_errors(self.state.errors, *stored_errors))
            log.warning(
                "zone_set.rejected",
                agv=str(self.agv),
                zone_set_id=message.zone_set.zone_set_id,
                error_types=sorted({e.error_type for e in errors}),
            )
        else:
            self.state = self.state.bumped()  # T68: zoneSets changed
            log.info("zone_set.stored", agv=str(self.agv), zone_set_id=message.zone_set.zone_set_id)
            if defaulted:
                log.warning(
                    "zone_set.release_loss_behavior_defaulted",
                    agv=str(self.agv),
                    zone_set_id=message.zone_set.zone_set_id,
                    zone_ids=list(defaulted),
                    release_loss_behavior="STOP",
                )
        self.publish_state()

    def _awake_input(
        self, model: type[_Input], kind: Topic, topic: str, payload: bytes
    ) -> _Input | None:
        """``payload`` as ``model``; None while hibernating (ignored) or when it does not decode
        (a VALIDATION_FAILURE in the state, T20)."""
        message = decode_as(
            model, kind, payload, address=parse_topic(topic), max_bytes=self._caps.limits.msg_len
        )
        if self.hibernating:
            return None
        if isinstance(message, DecodeFailure):
            self._reject_input(message)
            return None
        return message

    def handle_responses(self, topic: str, payload: bytes) -> None:
        """T92, T93: fleet control's answers to the zone requests (§6.4.3, §6.9, §7.5), applied
        by :func:`vda_vehicle.v3_requests.answer`. A REJECTED zone is not entered: the node
        beyond is NODE_UNREACHABLE (CRITICAL, §6.4.5) and the vehicle waits for fleet control.
        A response naming no request held is ignored and logged; a malformed message is a
        VALIDATION_FAILURE (T20). A change of the requests is reported at once (T68)."""
        self._note_message()
        message = self._awake_input(v3.Responses, Topic.RESPONSES, topic, payload)
        if message is None:
            return
        state = self.state
        book = self.requests
        inside = self._inside(state, book)
        errors: list[Error] = []
        for response in message.responses:
            book, result = answer(book, response, inside)
            self._log_answer(response, result)
            if result.outcome is Outcome.REJECTED and result.request is not None:
                errors.append(stored(self._unreachable(state, result.request)))
        if book is self.requests and not errors:
            return  # QUEUED, unknown ids: nothing the state shows changed
        self.requests = book
        self._requests_revision = state.revision + 1
        state = state.bumped(errors=with_errors(state.errors, *errors))
        self.state = self._track_requests(state)
        self._guard()
        self._after_change()

    def _log_answer(self, response: v3.Response, result: Answer) -> None:
        request = result.request
        if request is None:
            log.warning(
                "zone_request.unknown_response",
                agv=str(self.agv),
                request_id=response.request_id,
                grant_type=response.grant_type.value,
            )
            return
        log.info(
            "zone_request.answered",
            agv=str(self.agv),
            request_id=request.request_id,
            zone_id=request.zone.zone.zone_id,
            zone_set_id=request.zone.zone_set_id,
            grant_type=response.grant_type.value,
            lease_expiry=response.lease_expiry,
            outcome=result.outcome.value,
        )

    def _unreachable(self, state: VehicleState, request: HeldRequest) -> v3.Error:
        """§6.4.5: NODE_UNREACHABLE for the node beyond the first edge ahead that enters the
        zone fleet control rejected."""
        ahead = release_zones_ahead(state, self._release_zones, self._reach)
        edge = next((e for e in ahead if any(z.key == request.key for z in e.zones)), None)
        node_id = (
            edge.end_node_id
            if edge is not None
            else next((n.node_id for n in state.nodes), state.last_node_id)
        )
        zone_id = request.zone.zone.zone_id
        references = [
            ("nodeId", node_id),
            *([("edgeId", edge.edge_id)] if edge is not None else []),
            ("zoneId", zone_id),
            ("zoneSetId", request.zone.zone_set_id),
            ("requestId", request.request_id),
        ]
        return v3.predefined_error(
            v3.ErrorType.NODE_UNREACHABLE,
            *references,
            description=f"fleet control rejected request {request.request_id!r} for RELEASE "
            f"zone {zone_id!r}: the vehicle does not enter it and cannot reach node {node_id!r}",
        )

    def _retry_action(self, action: v3.InstantAction) -> None:
        """retry / skipRetry (T53): FINISHED once applied, FAILED if the action named is not
        RETRIABLE."""
        outcome = retry_action(self.state, action)
        failed = outcome if isinstance(outcome, str) else None
        if not isinstance(outcome, str):
            self.state = outcome
        self.state = finished_instant(self.state, action, self.state.next_group, failed=failed)

    def _zone_action(self, action: v3.InstantAction) -> None:
        """enableZoneSet / deleteZoneSet (T87): FINISHED, or FAILED for a zone set not held. An
        enabled speed limit also limits the edges of the running order."""
        zone_set_id = str(action.parameter("zoneSetId") or "")
        if action.action_type == ENABLE_ZONE_SET:
            changed = enable_zone_set(self.zones, zone_set_id)
        else:
            changed = delete_zone_set(self.zones, zone_set_id)
        failed = None if changed is not None else f"zone set {zone_set_id!r} is not held"
        group = self.state.next_group
        self.state = finished_instant(self.state, action, group, failed=failed)
        if changed is not None:
            self.zones = changed
            self._release_zones = release_zones(self.zones)
            self.state = capped_held_edges(self.state, self.zones)
            self._keep_out_of_zones()

    def _keep_out_of_zones(self) -> None:
        """After an order or a zone set change: BLOCKED zones ahead (T89) and the RELEASE zones
        the way ahead reaches (T91) are looked at, and the stack guarded (:meth:`_guard`)."""
        self._keep_out_of_blocked_zones()
        self._track_requests_now()

    def _keep_out_of_blocked_zones(self) -> None:
        """T89 for a zone set enabled (or deleted) while an order runs: the vehicle stops at the
        node before the first edge ahead that enters an enabled BLOCKED zone, and reports the
        node after it unreachable (NODE_UNREACHABLE, CRITICAL, until a new order is accepted:
        3.0 Table 9); with the way clear again it drives on."""
        if not self.zones and self._blocked_at is None:
            return  # nothing held, nothing guarded: the usual case
        ahead = blocked_ahead(self.state, self.zones)
        if ahead is None:
            self._blocked_at = None
            self._guard()
            return
        edge, zone_id = ahead
        if self._blocked_at == edge.sequence_id:
            return
        self._blocked_at = edge.sequence_id
        self._guard()
        error = v3.predefined_error(
            v3.ErrorType.NODE_UNREACHABLE,
            ("nodeId", edge.end_node_id),
            ("edgeId", edge.edge_id),
            ("zoneId", zone_id),
            description=f"edge {edge.edge_id!r} enters BLOCKED zone {zone_id!r}: the vehicle "
            f"stops before it and cannot reach node {edge.end_node_id!r}",
        )
        self.state = self.state.bumped(errors=with_errors(self.state.errors, stored(error)))
        log.warning(
            "zone.node_unreachable", agv=str(self.agv), node_id=edge.end_node_id, zone_id=zone_id
        )

    def _guard(self) -> None:
        """The vehicle stops before the first edge it may not start: one into an enabled
        BLOCKED zone (T89), or one reaching a RELEASE zone not granted (T91); the pure core
        neither enters that edge nor routes the stack onto it (``VehicleState.hold_before``)."""
        stops = [at for at in (self._blocked_at, self._release_at) if at is not None]
        hold = min(stops, default=None)
        if self.state.hold_before != hold:
            self.state = evolve(self.state, hold_before=hold)

    # -- zone requests (T91, T93; v3_requests) ----------------------------------------------------

    def _after_change(self, now: float | None = None) -> None:
        """Every event and full tick looks at the zone requests before the state goes out, so
        that a change of them comes in the same state (T68, T69)."""
        self._track_requests_now()
        super()._after_change(now)

    def _next_full_tick(self, now: float) -> float:
        """While requests are held, every tick is a full one: leases, entry and exit are
        checked at each (no cruise skipped)."""
        if self.requests.held:
            return -math.inf
        return super()._next_full_tick(now)

    def _track_requests_now(self) -> None:
        state = self.state
        tracked = self._track_requests(state)
        if tracked is not state:
            self.state = tracked
        self._guard()

    def _track_requests(self, state: VehicleState) -> VehicleState:
        """The requests brought up to date (v3_requests.track) for ``state``: only in AUTOMATIC
        and SEMIAUTOMATIC (Table 11: the other modes clear them, also inside a zone, and make
        none, T63); the errors of a lost release kept in step; the edge to stop before noted
        for :meth:`_guard`. A change bumps the state's revision (T68)."""
        book = self.requests
        if not book.held and not book.refused and not self._release_zones:
            self._release_at = None
            return state  # no RELEASE zone enabled, nothing asked: the usual case
        if state.operating_mode in _REQUESTING_MODES:
            ahead = release_zones_ahead(state, self._release_zones, self._reach)
            out = self._published_revision >= self._requests_revision and not self._state_deferred
            inside = self._inside(state, book)
            book = track(book, ahead, inside, self._clock.now(), reported=out)
        else:
            book, ahead = cleared(book), ()
        closed = first_closed(book, ahead)
        self._release_at = None if closed is None else closed.sequence_id
        errors = _with_loss_errors(state.errors, loss_errors(book))
        if book is self.requests and errors == state.errors:
            return state
        self._log_requests(self.requests, book)
        self.requests = book
        state = state.bumped(errors=errors)
        self._requests_revision = state.revision
        return state

    def _inside(self, state: VehicleState, book: ZoneRequests) -> frozenset[ZoneKey]:
        """The zones of ``book`` some part of the body is inside (§6.4.1.1)."""
        point, map_id = (state.pose.x, state.pose.y), state.pose.map_id
        return frozenset(r.key for r in book.held if r.zone.holds(map_id, point, self._reach))

    def _log_requests(self, before: ZoneRequests, after: ZoneRequests) -> None:
        old = {r.request_id: r for r in before.held}
        new = {r.request_id: r for r in after.held}
        for request_id, request in new.items():
            was = old.get(request_id)
            if was is None:
                event = "zone_request.asked"
            elif (was.status, was.lost) != (request.status, request.lost):
                event = "zone_request.changed"
            else:
                continue
            log.info(
                event,
                agv=str(self.agv),
                request_id=request_id,
                zone_id=request.zone.zone.zone_id,
                zone_set_id=request.zone.zone_set_id,
                status=request.status.value,
                lost=request.lost,
            )
        for request_id in old.keys() - new.keys():
            log.info("zone_request.removed", agv=str(self.agv), request_id=request_id)

    def _state_payload(self) -> bytes:
        self._metrics.state_lateness_s.append(self._clock.monotonic() - self._state_due_at)
        self._metrics.states_sent += 1
        state = build_state_v3(
            self.state,
            self._caps,
            zone_sets=reported(self.zones),
            zone_requests=reported_requests(self.requests),
        )
        if self._broker_errors:
            extra = [
                v3.Error(
                    error_type=e.error_type,
                    error_references=e.error_references,
                    error_description=e.error_description,
                    error_level=v3.ErrorLevel.WARNING,
                )
                for e in self._broker_errors
            ]
            state = state.model_copy(update={"errors": [*state.errors, *extra]})
        return encode(self._stamper.stamp(Topic.STATE, state))

    def _visualization(self) -> bytes:
        """T79: referenceStateHeaderId is the headerId of the last state sent."""
        reference = self._stamper.last_header_id(Topic.STATE) or 0
        message = build_visualization_v3(self._visible_state(), reference)
        return encode(self._stamper.stamp(Topic.VISUALIZATION, message))


def _with_loss_errors(
    current: tuple[Error, ...], wanted: tuple[v3.Error, ...]
) -> tuple[Error, ...]:
    """``current`` with exactly the lost-release errors ``wanted`` (Table 9: RELEASE_LOST lasts
    until the zone is left or granted again, whatever an order update clears)."""
    want = [stored(error) for error in wanted]
    kept = tuple(e for e in current if e.error_type not in _LOSS_ERROR_TYPES or e in want)
    new = [error for error in want if error not in kept]
    return with_errors(kept, *new) if new else kept
