"""One simulated vehicle speaking VDA 5050 3.0 (``--vda-version 3.0.0``).

The same shell and core as 2.x (:class:`VehicleRuntime`); only the edges differ: 3.0 payloads
are decoded and decided by :mod:`vda_vehicle.v3_inbound`, and states, visualizations,
connection messages and the factsheet leave in the 3.0 shape built by
:mod:`vda_vehicle.v3_report`. Topics are those of ``v3`` (T01, T02), including ``zoneSet``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from datetime import datetime
from typing import Any, Final

import structlog

from vda5050.codec import DecodeFailure, decode_as, encode
from vda5050.models import ActionScope, ActionStatus, ConnectionState, v3
from vda5050.models.factsheet import ValueDataType
from vda5050.topics import Topic, parse_topic
from vda_vehicle.actions import ActionSpec, ParameterSpec, record_of
from vda_vehicle.factsheet import SHARED_FACTSHEETS
from vda_vehicle.faults import over_limits, with_errors
from vda_vehicle.instant import receive_instant_actions
from vda_vehicle.limits import instant_limit_problems
from vda_vehicle.navigation import StopBefore, is_steady
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
from vda_vehicle.v3_zones import (
    ZoneSets,
    delete_zone_set,
    enable_zone_set,
    receive_zone_set,
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

    def __init__(self, **kwargs: Any) -> None:  # noqa: ANN401 - VehicleRuntime's keywords
        super().__init__(**kwargs)
        # startHibernation runs like cancelOrder until the order is cleared (T06, T61).
        catalog = {**self._caps.catalog, START_HIBERNATION: HIBERNATION_SPEC}
        self._caps = replace(self._caps, catalog=catalog)
        #: The navigation stack as given; ``_stack`` is it kept out of a BLOCKED zone enabled
        #: ahead of the running order (:meth:`_keep_out_of_blocked_zones`).
        self._free_stack = self._stack

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
                self._keep_out_of_blocked_zones()  # accepted: its way ahead enters none
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
        is DUPLICATE_ZONE_SET, a malformed one VALIDATION_FAILURE (T85)."""
        message = decode_as(
            v3.ZoneSetMessage,
            Topic.ZONE_SET,
            payload,
            address=parse_topic(topic),
            max_bytes=self._caps.limits.msg_len,
        )
        if self.hibernating:
            return
        if isinstance(message, DecodeFailure):
            self._reject_input(message)
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
        self.publish_state()

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
            self.state = capped_held_edges(self.state, self.zones)
            self._keep_out_of_blocked_zones()

    def _keep_out_of_blocked_zones(self) -> None:
        """T89 for a zone set enabled (or deleted) while an order runs: the vehicle stops at the
        node before the first edge ahead that enters an enabled BLOCKED zone, and reports the
        node after it unreachable (NODE_UNREACHABLE, CRITICAL, until a new order is accepted:
        3.0 Table 9); with the way clear again it drives on."""
        if not self.zones and self._stack is self._free_stack:
            return  # nothing held, nothing guarded: the usual case
        ahead = blocked_ahead(self.state, self.zones)
        if ahead is None:
            self._stack, self._steady_stack = self._free_stack, is_steady(self._free_stack)
            return
        edge, zone_id = ahead
        guard = StopBefore(self._free_stack, edge.sequence_id)
        if self._stack == guard:
            return
        self._stack, self._steady_stack = guard, False
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

    def _state_payload(self) -> bytes:
        self._metrics.state_lateness_s.append(self._clock.monotonic() - self._state_due_at)
        self._metrics.states_sent += 1
        state = build_state_v3(self.state, self._caps, zone_sets=reported(self.zones))
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
