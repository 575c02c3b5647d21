"""VehicleState → VDA 5050 3.0 ``state``, ``visualization``, ``connection`` and ``factsheet``,
pure (3.0 §6.5-§6.10, §7.7-§7.10).

The 2.x reporter's facts in the 3.0 shape: ``mobileRobotPosition``/``localized``,
``powerSupply``, instant actions in ``instantActionStates`` (T28: they do not count for idle),
UPPER_SNAKE modes (T15), errors with their Table 9 level (T76). The factsheet is the 2.x one
of the same capabilities, renamed, with 3.0's optional fields and the zone types of
:mod:`vda_vehicle.v3_zones`. Headers
are placeholders; the shell's HeaderStamper writes the real ones at send time.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from vda5050.models import ActionScope, Error, ErrorLevel, EStop, v3
from vda5050.models.factsheet import AgvKinematic, Factsheet
from vda5050.models.v3.state import NodeStatePosition, StoredZoneSet, ZoneRequest
from vda_vehicle.actions import ActionSpec
from vda_vehicle.capabilities import FIELD_NOTES, Capabilities
from vda_vehicle.factsheet import FactsheetTiming, build_factsheet
from vda_vehicle.faults import DUPLICATE_MAP
from vda_vehicle.model import ActionRecord, RobotMode, VehicleState
from vda_vehicle.reporter import agv_position, velocity
from vda_vehicle.v3_inbound import (
    CLEAR_INSTANT_ACTIONS,
    DELETE_ZONE_SET,
    ENABLE_ZONE_SET,
    RETRY,
    SHUTDOWN,
    SKIP_RETRY,
    START_HIBERNATION,
    STOP_HIBERNATION,
    V3_ACTION_NAMES,
    V3_REQUIRED_FIELDS,
    V3_SUPPORTED_FIELDS,
)
from vda_vehicle.v3_zones import SUPPORTED_ZONES

PLACEHOLDER_HEADER_V3: Final = {
    "header_id": 0,
    "timestamp": "1970-01-01T00:00:00.000Z",
    "version": v3.VERSION,
    "manufacturer": "-",
    "serial_number": "-",
}
#: The core's 2.x error names and their 3.0 types (Table 9; T96 for an aborted edge).
_V3_ERROR_TYPES: Final = {
    "validationError": v3.ErrorType.VALIDATION_FAILURE,
    "noOrderToCancel": v3.ErrorType.NO_ORDER_TO_CANCEL,
    "navigationError": v3.ErrorType.NODE_UNREACHABLE,
    DUPLICATE_MAP: v3.ErrorType.DUPLICATE_MAP,
}


def build_state_v3(
    state: VehicleState,
    caps: Capabilities,
    *,
    zone_sets: list[StoredZoneSet] | None = None,
    zone_requests: list[ZoneRequest] | None = None,
) -> v3.State:
    """The 3.0 state message of ``state`` (T70: every required field, idle values before any
    order); ``zone_sets`` are the zone sets held (§7.8 ``zoneSets``), ``zone_requests`` the
    zone requests (§7.8 ``zoneRequests``, an empty list when none is active)."""
    order_records = [r for r in state.actions if r.scope.value != "INSTANT"]
    instant_records = [r for r in state.actions if r.scope.value == "INSTANT"]
    return v3.State(
        **PLACEHOLDER_HEADER_V3,
        maps=[
            v3.Map(
                map_id=held.map_id,
                map_version=held.map_version,
                map_status=v3.MapStatus.ENABLED if held.enabled else v3.MapStatus.DISABLED,
            )
            for held in state.maps
        ],
        zone_sets=zone_sets,
        zone_requests=zone_requests,
        order_id=state.order_id,
        order_update_id=state.order_update_id,
        last_node_id=state.last_node_id,
        last_node_sequence_id=state.last_node_sequence_id,
        node_states=[
            v3.NodeState(
                node_id=node.node_id,
                sequence_id=node.sequence_id,
                node_descriptor=node.node_description,
                released=node.released,
                node_position=None
                if node.node_position is None
                else NodeStatePosition(
                    x=node.node_position.x,
                    y=node.node_position.y,
                    theta=node.node_position.theta,
                    map_id=node.node_position.map_id,
                ),
            )
            for node in state.nodes
        ],
        edge_states=[
            v3.EdgeState(
                edge_id=edge.edge_id,
                sequence_id=edge.sequence_id,
                edge_descriptor=edge.edge_description,
                released=edge.released,
            )
            # While a cancel finishes its edge only the next node's state is kept (T45).
            for edge in (() if state.cancel_action_id is not None else state.edges)
        ],
        mobile_robot_position=mobile_robot_position(state),
        velocity=velocity(state),
        loads=[v3.Load.model_validate(load.model_dump()) for load in state.loads],
        driving=state.driving,
        paused=state.paused,
        new_base_request=state.new_base_request,
        distance_since_last_node=state.distance_since_last_node,
        action_states=[_action_state(r) for r in order_records],
        instant_action_states=[_action_state(r) for r in instant_records],
        power_supply=v3.PowerSupply(
            state_of_charge=round(state.battery_charge, 3),
            charging=state.charging,
            range=None if (reach := caps.reach_m(state.battery_charge)) is None else float(reach),
        ),
        operating_mode=operating_mode_v3(state.operating_mode),
        errors=errors_v3(state.errors),
        safety_state=safety_state_v3(state.e_stop, field_violation=state.field_violation),
    )


def build_visualization_v3(state: VehicleState, reference_state_header_id: int) -> v3.Visualization:
    """T79: pose and velocity, naming the headerId of the last state sent."""
    return v3.Visualization(
        **PLACEHOLDER_HEADER_V3,
        reference_state_header_id=reference_state_header_id,
        mobile_robot_position=mobile_robot_position(state),
        velocity=velocity(state),
    )


def connection_v3(
    agv_manufacturer: str, serial: str, connection_state: v3.ConnectionState
) -> v3.Connection:
    return v3.Connection(
        **{**PLACEHOLDER_HEADER_V3, "manufacturer": agv_manufacturer, "serial_number": serial},
        connection_state=connection_state,
    )


def mobile_robot_position(state: VehicleState) -> v3.MobileRobotPosition:
    """T72: the simulated vehicle always localises (``localized`` is 2.x
    positionInitialized)."""
    position = agv_position(state)
    return v3.MobileRobotPosition(
        x=position.x,
        y=position.y,
        theta=position.theta,
        map_id=position.map_id,
        localized=position.position_initialized,
    )


def safety_state_v3(e_stop: EStop, *, field_violation: bool) -> v3.SafetyState:
    """3.0 §7.8: no AUTOACK any more; an auto-acknowledgeable stop (a bumper, a protective
    field) is a field violation there."""
    if e_stop is EStop.AUTOACK:
        return v3.SafetyState(active_emergency_stop=v3.EmergencyStop.NONE, field_violation=True)
    return v3.SafetyState(
        active_emergency_stop=v3.EmergencyStop(e_stop.value), field_violation=field_violation
    )


def operating_mode_v3(mode: RobotMode) -> v3.OperatingMode:
    """T15: the 3.0 spelling (TEACHIN → TEACH_IN)."""
    return v3.OperatingMode.TEACH_IN if mode == RobotMode.TEACHIN else v3.OperatingMode(mode.value)


def errors_v3(errors: Sequence[Error]) -> list[v3.Error]:
    """T76: predefined 3.0 types with their Table 9 level; other (vendor) types keep the
    level the core gave them."""
    return [error_v3(error) for error in errors]


def error_v3(error: Error) -> v3.Error:
    error_type = _V3_ERROR_TYPES.get(error.error_type, error.error_type)
    try:
        level = v3.PREDEFINED_ERROR_LEVELS[v3.ErrorType(error_type)]
    except ValueError:
        level = (
            v3.ErrorLevel.FATAL if error.error_level is ErrorLevel.FATAL else v3.ErrorLevel.WARNING
        )
    return v3.Error(
        error_type=error_type,
        error_references=error.error_references,
        error_description=error.error_description,
        error_hint=error.error_hint,
        error_level=level,
    )


def _action_state(record: ActionRecord) -> v3.ActionState:
    return v3.ActionState(
        action_id=record.action_id,
        action_type=V3_ACTION_NAMES.get(record.action_type, record.action_type),
        action_descriptor=record.action.action_description,
        action_status=v3.ActionStatus.RETRIABLE
        if record.is_retriable_now
        else v3.ActionStatus(record.status.value),
        action_result=record.result,
    )


# -- factsheet (T80-T82) --------------------------------------------------------------------------

_NO_PAUSE: Final = frozenset({"startPause", "stopPause", START_HIBERNATION})
#: 3.0 instant actions done by the 3.0 edge rather than the core's catalog (T06, T57, T87):
#: type, description, parameters (key, description).
_EDGE_ACTIONS: Final[tuple[tuple[str, str, tuple[tuple[str, str], ...]], ...]] = (
    (CLEAR_INSTANT_ACTIONS, "forget the ended instant action states", ()),
    (STOP_HIBERNATION, "end hibernation: ONLINE again, states resume", ()),
    (SHUTDOWN, "while idle: OFFLINE and a coordinated disconnect (no restart over MQTT)", ()),
    (ENABLE_ZONE_SET, "enable a zone set held (others of its map off)", (("zoneSetId", "id"),)),
    (DELETE_ZONE_SET, "forget a zone set held", (("zoneSetId", "id"),)),
    (RETRY, "run a RETRIABLE action again", (("actionId", "the RETRIABLE action"),)),
    (SKIP_RETRY, "end a RETRIABLE action FAILED", (("actionId", "the RETRIABLE action"),)),
)


def build_factsheet_v3(caps: Capabilities, timing: FactsheetTiming) -> v3.Factsheet:
    """The 3.0 factsheet: every action with 3.0 name, scopes, blocking types (SINGLE wherever
    the vehicle may drive during the action), ``pauseAllowed``/``cancelAllowed`` (T81); the
    3.0 optional order fields it acts on (T83); ``supportedZones``: BLOCKED, SPEED_LIMIT and
    RELEASE (T82, v3_zones). ``startHibernation`` and
    ``stopHibernation`` are offered (T06), with the optional ``wakeUpTime``."""
    legacy: Factsheet = build_factsheet(caps, timing, version="2.1.0")
    kind, physical, limits = (
        legacy.type_specification,
        legacy.physical_parameters,
        legacy.protocol_limits,
    )
    strings, arrays = limits.max_string_lens, limits.max_array_lens
    geometry = legacy.agv_geometry
    return v3.Factsheet.model_validate(
        {
            **PLACEHOLDER_HEADER_V3,
            "type_specification": {
                "series_name": kind.series_name,
                "series_description": kind.series_description,
                "mobile_robot_kinematics": (
                    v3.MobileRobotKinematics.DIFFERENTIAL
                    if kind.agv_kinematic is AgvKinematic.DIFF
                    else v3.MobileRobotKinematics.OMNIDIRECTIONAL
                ),
                "mobile_robot_class": v3.MobileRobotClass.CARRIER,
                "maximum_load_mass": kind.max_load_mass,
                "localization_types": list(kind.localization_types),
                "navigation_types": list(kind.navigation_types),
                "supported_zones": sorted(SUPPORTED_ZONES),
            },
            "physical_parameters": {
                "minimum_speed": physical.speed_min,
                "maximum_speed": physical.speed_max,
                "minimum_angular_speed": physical.angular_speed_min,
                "maximum_angular_speed": physical.angular_speed_max,
                "maximum_acceleration": physical.acceleration_max,
                "maximum_deceleration": physical.deceleration_max,
                "minimum_height": physical.height_min,
                "maximum_height": physical.height_max,
                "width": physical.width,
                "length": physical.length,
            },
            "protocol_limits": {
                "maximum_string_lengths": {
                    "maximum_message_length": strings.msg_len,
                    "maximum_topic_serial_length": strings.topic_serial_len,
                    "maximum_topic_element_length": strings.topic_elem_len,
                    "maximum_id_length": strings.id_len,
                    "id_numerical_only": strings.id_numerical_only,
                    "maximum_load_id_length": strings.load_id_len,
                },
                "maximum_array_lengths": {
                    key: value
                    for key, value in arrays.model_dump(by_alias=True).items()
                    if value is not None
                },
                "timing": {
                    "minimum_order_interval": limits.timing.min_order_interval,
                    "minimum_state_interval": limits.timing.min_state_interval,
                    "default_state_interval": limits.timing.default_state_interval,
                    "visualization_interval": limits.timing.visualization_interval,
                },
            },
            "protocol_features": {
                "optional_parameters": [
                    {
                        "parameter": path,
                        "support": "REQUIRED" if path in V3_REQUIRED_FIELDS else "SUPPORTED",
                        "description": FIELD_NOTES.get(path),
                    }
                    for path in sorted(V3_SUPPORTED_FIELDS)
                ],
                "mobile_robot_actions": [
                    *(_action(spec) for spec in caps.catalog.values()),
                    *(
                        {
                            "action_type": action_type,
                            "action_description": description,
                            "action_scopes": ["INSTANT"],
                            "action_parameters": [
                                {"key": key, "value_data_type": "STRING", "description": text}
                                for key, text in parameters
                            ]
                            or None,
                            "blocking_types": ["NONE"],
                            "pause_allowed": False,
                            "cancel_allowed": False,
                        }
                        for action_type, description, parameters in _EDGE_ACTIONS
                    ),
                ],
            },
            "mobile_robot_geometry": {
                "wheel_definitions": [w.model_dump() for w in geometry.wheel_definitions or ()],
                "envelopes2d": [
                    {
                        "envelope2d_id": envelope.set,
                        "vertices": [{"x": p.x, "y": p.y} for p in envelope.polygon_points],
                        "description": envelope.description,
                    }
                    for envelope in geometry.envelopes2d or ()
                ],
            },
            "load_specification": legacy.load_specification.model_dump(
                exclude_none=True, by_alias=False
            )
            | {
                "load_sets": [
                    {
                        "set_name": s.set_name,
                        "load_type": s.load_type,
                        "load_positions": s.load_positions,
                        "maximum_weight": s.max_weight,
                    }
                    for s in legacy.load_specification.load_sets or ()
                ]
            },
            "mobile_robot_configuration": None
            if legacy.vehicle_config is None
            else {"versions": [v.model_dump() for v in legacy.vehicle_config.versions or ()]},
        }
    )


def _action(spec: ActionSpec) -> dict[str, object]:
    blocking = {b.value for b in spec.blocking_types}
    if spec.scopes == {ActionScope.INSTANT}:
        blocking = {"NONE"}  # T49: instant actions are always NONE
    elif "NONE" in blocking:
        blocking.add("SINGLE")  # Table 3: the vehicle can run it alone while driving
    return {
        "action_type": V3_ACTION_NAMES.get(spec.action_type, spec.action_type),
        "action_description": spec.description,
        "action_scopes": sorted(scope.value for scope in spec.scopes),
        "action_parameters": [
            {
                "key": p.key,
                "value_data_type": "NUMBER"
                if p.value_type.value == "FLOAT"
                else p.value_type.value,
                "description": p.description,
                "is_optional": p.optional,
            }
            for p in spec.parameters
        ]
        or None,
        "action_result": spec.result_description,
        "blocking_types": sorted(blocking),
        "pause_allowed": spec.action_type not in _NO_PAUSE,
        "cancel_allowed": spec.interruptible,
    }
