"""VDA 5050 3.0 at master control's edge, pure (3.0 §6-§7; rules Tnn in docs/vda5050-3.md).

The master's core (fleet view, dispatcher, traffic control, order records) works on the 2.x
models. A 3.0 vehicle is served by translating at the edge:

- inbound, a 3.0 ``state``, ``connection`` or ``factsheet`` becomes the 2.x model the core
  reads, keeping ``version`` = the vehicle's 3.x version, so the vehicle stays addressed in 3.0;
- outbound, an order or instantActions message cut from the (version-neutral) plan becomes the
  3.0 model just before it is stamped: edges lose their start/end node ids (T18), ``maxSpeed``
  is ``maximumSpeed`` (T100), a circular deviation is an ellipse with a = b (T99), instant
  actions are blockingType NONE (T49) and use the 3.0 action names (T59).

What 2.x cannot hold is mapped to what master control must do with it: 3.0 CRITICAL and URGENT
errors are not FATAL (a CRITICAL robot takes new orders, T77), so they become WARNINGs whose
description starts with the 3.0 level; STARTUP (state not valid, T65) and INTERVENED (only
cancelOrder, T58) are modes master control does not drive in (SERVICE, MANUAL); HIBERNATING
is a robot that is not to be dispatched and sends no heartbeat (T09): OFFLINE. RETRIABLE (not
an end state) is RUNNING; instantActionStates join actionStates as in 2.x.
"""

from __future__ import annotations

from typing import Final

from vda5050.models import (
    Action,
    ActionState,
    ActionStatus,
    AgvPosition,
    BatteryState,
    Connection,
    ConnectionState,
    Corridor,
    CorridorRefPoint,
    Edge,
    EdgeState,
    Error,
    ErrorLevel,
    EStop,
    Factsheet,
    InstantActions,
    Load,
    Map,
    Node,
    NodeState,
    OperatingMode,
    Order,
    SafetyState,
    State,
    Trajectory,
    v3,
)
from vda5050.models.state import NodeStatePosition
from vda5050.models.v3.modes import V2_NAMES

#: Optional order fields: 3.0 path → the 2.x path the order builder asks about (T83).
V2_PARAMETER_OF: Final = {
    "order.nodes.nodeDescriptor": "order.nodes.nodeDescription",
    "order.edges.edgeDescriptor": "order.edges.edgeDescription",
    "order.nodes.actions.actionDescriptor": "order.nodes.actions.actionDescription",
    "order.edges.actions.actionDescriptor": "order.edges.actions.actionDescription",
    "order.edges.maximumSpeed": "order.edges.maxSpeed",
    "order.edges.maximumMobileRobotHeight": "order.edges.maxHeight",
    "order.edges.minimumLoadHandlingDeviceHeight": "order.edges.minHeight",
    "order.edges.maximumRotationSpeed": "order.edges.maxRotationSpeed",
    "order.edges.reachOrientationBeforeEntering": "order.edges.rotationAllowed",
}
#: Predefined actions renamed in 3.0 (T59): 2.x name → 3.0 name.
V3_ACTION_NAMES: Final = {"initPosition": "initializePosition"}
_V2_ACTION_NAMES: Final = {new: old for old, new in V3_ACTION_NAMES.items()}

_MODES: Final = {mode: OperatingMode(name) for mode, name in V2_NAMES.items()}
_CONNECTIONS: Final = {
    v3.ConnectionState.ONLINE: ConnectionState.ONLINE,
    v3.ConnectionState.OFFLINE: ConnectionState.OFFLINE,
    v3.ConnectionState.HIBERNATING: ConnectionState.OFFLINE,
    v3.ConnectionState.CONNECTION_BROKEN: ConnectionState.CONNECTIONBROKEN,
}


def is_v3(version: str | None) -> bool:
    return version is not None and version.startswith("3.")


# -- inbound ------------------------------------------------------------------------------------


def state_from_v3(state: v3.State) -> State:
    """A 3.0 state as the master's core reads it (T28, T70, T76, T77)."""
    return State(
        **state.header_fields(),
        maps=None
        if state.maps is None
        else [
            Map(map_id=m.map_id, map_version=m.map_version, map_status=m.map_status)
            for m in state.maps
        ],
        order_id=state.order_id,
        order_update_id=state.order_update_id,
        last_node_id=state.last_node_id,
        last_node_sequence_id=state.last_node_sequence_id,
        driving=state.driving,
        paused=state.paused,
        new_base_request=state.new_base_request,
        distance_since_last_node=state.distance_since_last_node,
        operating_mode=_MODES[state.operating_mode],
        node_states=[
            NodeState(
                node_id=n.node_id,
                sequence_id=n.sequence_id,
                node_description=n.node_descriptor,
                released=n.released,
                node_position=None
                if n.node_position is None
                else NodeStatePosition(
                    x=n.node_position.x,
                    y=n.node_position.y,
                    theta=n.node_position.theta,
                    map_id=n.node_position.map_id,
                ),
            )
            for n in state.node_states
        ],
        edge_states=[
            EdgeState(
                edge_id=e.edge_id,
                sequence_id=e.sequence_id,
                edge_description=e.edge_descriptor,
                released=e.released,
            )
            for e in state.edge_states
        ],
        agv_position=None
        if state.mobile_robot_position is None
        else AgvPosition(
            x=state.mobile_robot_position.x,
            y=state.mobile_robot_position.y,
            theta=state.mobile_robot_position.theta,
            map_id=state.mobile_robot_position.map_id,
            position_initialized=state.mobile_robot_position.localized,
            localization_score=state.mobile_robot_position.localization_score,
            deviation_range=state.mobile_robot_position.deviation_range,
        ),
        velocity=state.velocity,
        loads=None
        if state.loads is None
        else [Load.model_validate(load.model_dump()) for load in state.loads],
        action_states=[
            _action_state(a) for a in (*state.action_states, *state.instant_action_states)
        ],
        battery_state=BatteryState(
            battery_charge=state.power_supply.state_of_charge,
            battery_voltage=state.power_supply.battery_voltage,
            battery_health=state.power_supply.battery_health,
            charging=state.power_supply.charging,
            reach=state.power_supply.range,
        ),
        errors=[error_from_v3(e) for e in state.errors],
        safety_state=SafetyState(
            e_stop=EStop(state.safety_state.active_emergency_stop.value),
            field_violation=state.safety_state.field_violation,
        ),
    )


def error_from_v3(error: v3.Error) -> Error:
    """T77: only FATAL keeps a robot from new orders; URGENT and CRITICAL become WARNINGs that
    say their 3.0 level (the type, e.g. NODE_UNREACHABLE, is kept as it is, T76)."""
    level = error.error_level
    description = error.error_description
    if level in (v3.ErrorLevel.URGENT, v3.ErrorLevel.CRITICAL):
        description = f"{level.value}: {description}" if description else level.value
    return Error(
        error_type=error.error_type,
        error_references=error.error_references,
        error_description=description,
        error_hint=error.error_hint,
        error_level=ErrorLevel.FATAL if level is v3.ErrorLevel.FATAL else ErrorLevel.WARNING,
    )


def _action_state(state: v3.ActionState) -> ActionState:
    status = state.action_status
    return ActionState(
        action_id=state.action_id,
        action_type=None
        if state.action_type is None
        else _V2_ACTION_NAMES.get(state.action_type, state.action_type),
        action_description=state.action_descriptor,
        action_status=ActionStatus.RUNNING
        if status is v3.ActionStatus.RETRIABLE
        else ActionStatus(status.value),
        result_description=state.action_result,
    )


def connection_from_v3(message: v3.Connection) -> Connection:
    """T09: the connection state as MQTT-level liveness; HIBERNATING is not dispatchable."""
    return Connection(
        **message.header_fields(),
        connection_state=_CONNECTIONS[message.connection_state],
    )


_KINEMATICS: Final = {
    "DIFFERENTIAL": "DIFF",
    "OMNIDIRECTIONAL": "OMNI",
    "THREE_WHEEL": "THREEWHEEL",
}
_CLASSES: Final = frozenset({"FORKLIFT", "CONVEYOR", "TUGGER", "CARRIER"})
_WHEELS: Final = frozenset({"DRIVE", "CASTER", "FIXED", "MECANUM"})


def factsheet_from_v3(factsheet: v3.Factsheet) -> Factsheet:
    """A 3.0 factsheet as the master's capability checks read it (T80-T83): speeds, geometry,
    limits, actions (2.x names, INSTANT/NODE/EDGE scopes) and the optional fields under their
    2.x paths. Vendor kinematics and classes the 2.x enums lack read as DIFF and CARRIER
    (nothing in master control depends on them)."""
    kind, physical = factsheet.type_specification, factsheet.physical_parameters
    limits, features = factsheet.protocol_limits, factsheet.protocol_features
    strings, timing = limits.maximum_string_lengths, limits.timing
    geometry = factsheet.mobile_robot_geometry
    return Factsheet.model_validate(
        {
            "header_id": factsheet.header_id,
            "timestamp": factsheet.timestamp,
            "version": factsheet.version,
            "manufacturer": factsheet.manufacturer,
            "serial_number": factsheet.serial_number,
            "type_specification": {
                "series_name": kind.series_name,
                "series_description": kind.series_description,
                "agv_kinematic": _KINEMATICS.get(kind.mobile_robot_kinematics, "DIFF"),
                "agv_class": kind.mobile_robot_class
                if kind.mobile_robot_class in _CLASSES
                else "CARRIER",
                "max_load_mass": kind.maximum_load_mass,
                "localization_types": kind.localization_types,
                "navigation_types": kind.navigation_types,
            },
            "physical_parameters": {
                "speed_min": physical.minimum_speed,
                "speed_max": physical.maximum_speed,
                "angular_speed_min": physical.minimum_angular_speed,
                "angular_speed_max": physical.maximum_angular_speed,
                "acceleration_max": physical.maximum_acceleration,
                "deceleration_max": physical.maximum_deceleration,
                "height_min": physical.minimum_height,
                "height_max": physical.maximum_height,
                "width": physical.width,
                "length": physical.length,
            },
            "protocol_limits": {
                "max_string_lens": {
                    "msg_len": strings.maximum_message_length,
                    "topic_serial_len": strings.maximum_topic_serial_length,
                    "topic_elem_len": strings.maximum_topic_element_length,
                    "id_len": strings.maximum_id_length,
                    "id_numerical_only": strings.id_numerical_only,
                    "load_id_len": strings.maximum_load_id_length,
                },
                "max_array_lens": {
                    key: value
                    for key, value in limits.maximum_array_lengths.model_dump(by_alias=True).items()
                    if value is not None
                },
                "timing": {
                    "min_order_interval": timing.minimum_order_interval,
                    "min_state_interval": timing.minimum_state_interval,
                    "default_state_interval": timing.default_state_interval,
                    "visualization_interval": timing.visualization_interval,
                },
            },
            "protocol_features": {
                "optional_parameters": [
                    p.model_copy(
                        update={"parameter": V2_PARAMETER_OF.get(p.parameter, p.parameter)}
                    )
                    for p in features.optional_parameters
                ],
                "agv_actions": [_action_from_v3(a) for a in features.mobile_robot_actions],
            },
            "agv_geometry": {
                "wheel_definitions": [
                    w.model_dump() for w in geometry.wheel_definitions or () if w.type in _WHEELS
                ]
                or None,
                "envelopes2d": [
                    {
                        "set": e.envelope2d_id,
                        "polygon_points": [{"x": v.x, "y": v.y} for v in e.vertices],
                        "description": e.description,
                    }
                    for e in geometry.envelopes2d or ()
                ]
                or None,
            },
            "load_specification": {
                "load_positions": factsheet.load_specification.load_positions,
            },
        }
    )


def _action_from_v3(action: v3.MobileRobotAction) -> dict[str, object]:
    return {
        "action_type": _V2_ACTION_NAMES.get(action.action_type, action.action_type),
        "action_description": action.action_description,
        "action_scopes": [s.value for s in action.action_scopes if s is not v3.ActionScope.ZONE],
        "action_parameters": [
            {
                "key": p.key,
                "value_data_type": p.value_data_type.value,
                "description": p.description,
                "is_optional": p.is_optional,
            }
            for p in action.action_parameters or ()
        ]
        or None,
        "result_description": action.action_result,
        "blocking_types": None
        if action.blocking_types is None
        else [b.value for b in action.blocking_types if b is not v3.BlockingType.SINGLE],
    }


# -- outbound -----------------------------------------------------------------------------------


def order_to_v3(order: Order) -> v3.Order:
    """The 3.0 order of a message cut from a plan (T18, T39-T41, T99, T100). The stitching
    node of an update is the plan's node as sent before, actions included (T40)."""
    return v3.Order(
        **order.header_fields(),
        order_id=order.order_id,
        order_update_id=order.order_update_id,
        nodes=[_node_to_v3(node) for node in order.nodes],
        edges=[_edge_to_v3(edge) for edge in order.edges],
    )


def _node_to_v3(node: Node) -> v3.Node:
    position = node.node_position
    return v3.Node(
        node_id=node.node_id,
        sequence_id=node.sequence_id,
        node_descriptor=node.node_description,
        released=node.released,
        node_position=None
        if position is None
        else v3.NodePosition(
            x=position.x,
            y=position.y,
            theta=position.theta,
            allowed_deviation_xy=None
            if position.allowed_deviation_xy is None
            else v3.AllowedDeviationXY(
                a=position.allowed_deviation_xy, b=position.allowed_deviation_xy, theta=0.0
            ),
            allowed_deviation_theta=position.allowed_deviation_theta,
            map_id=position.map_id,
        ),
        actions=[action_to_v3(a) for a in node.actions],
    )


def _edge_to_v3(edge: Edge) -> v3.Edge:
    return v3.Edge(
        edge_id=edge.edge_id,
        sequence_id=edge.sequence_id,
        edge_descriptor=edge.edge_description,
        released=edge.released,
        maximum_speed=edge.max_speed,
        maximum_mobile_robot_height=edge.max_height,
        minimum_load_handling_device_height=edge.min_height,
        orientation=edge.orientation,
        orientation_type=edge.orientation_type,
        direction=edge.direction,
        # 2.x rotationAllowed false: turn before entering the edge, 3.0's
        # reachOrientationBeforeEntering true (the opposite sense).
        reach_orientation_before_entering=None
        if edge.rotation_allowed is None
        else not edge.rotation_allowed,
        maximum_rotation_speed=edge.max_rotation_speed,
        trajectory=None if edge.trajectory is None else _trajectory_to_v3(edge.trajectory),
        length=edge.length,
        corridor=None if edge.corridor is None else _corridor_to_v3(edge.corridor),
        actions=[action_to_v3(a) for a in edge.actions],
    )


def _trajectory_to_v3(trajectory: Trajectory) -> v3.Trajectory:
    return v3.Trajectory(
        degree=trajectory.degree,
        knot_vector=trajectory.knot_vector,
        control_points=[
            v3.ControlPoint(x=p.x, y=p.y, weight=p.weight) for p in trajectory.control_points
        ],
    )


def _corridor_to_v3(corridor: Corridor) -> v3.Corridor:
    reference = corridor.corridor_ref_point
    return v3.Corridor(
        left_width=corridor.left_width,
        right_width=corridor.right_width,
        corridor_reference_point=None
        if reference is None
        else v3.CorridorReferencePoint.KINEMATIC_CENTER
        if reference is CorridorRefPoint.KINEMATICCENTER
        else v3.CorridorReferencePoint.CONTOUR,
    )


def action_to_v3(action: Action) -> v3.Action:
    return v3.Action(
        action_type=V3_ACTION_NAMES.get(action.action_type, action.action_type),
        action_id=action.action_id,
        action_descriptor=action.action_description,
        blocking_type=v3.BlockingType(action.blocking_type.value),
        action_parameters=action.action_parameters,
    )


def instant_actions_to_v3(message: InstantActions) -> v3.InstantActions:
    """T49: instant actions are always blockingType NONE in 3.0; 3.0 names (T59)."""
    return v3.InstantActions(
        **message.header_fields(),
        actions=[
            v3.InstantAction(
                action_type=V3_ACTION_NAMES.get(a.action_type, a.action_type),
                action_id=a.action_id,
                action_descriptor=a.action_description,
                blocking_type=v3.BlockingType.NONE,
                action_parameters=a.action_parameters,
            )
            for a in message.actions
        ],
    )
