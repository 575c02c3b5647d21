"""VehicleState → wire ``State`` and ``Visualization`` (§6.10, §6.13), pure.

Every required field is always present, with the idle values of R96 before any order (R95).
The header is a placeholder here; the shell's HeaderStamper writes the real one at send time.

Two ways to the same bytes: :func:`build_state` and :func:`build_visualization` build the
models; :func:`state_body` and :func:`visualization_body`, which the runtime sends, write the
header-less JSON with orjson directly (several times faster; property tests hold them to the
models' bytes).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

import orjson

from vda5050.codec import EncodedBody
from vda5050.models import (
    ActionState,
    AgvPosition,
    BatteryState,
    Edge,
    EdgeState,
    Error,
    EStop,
    Load,
    Map,
    MapStatus,
    Node,
    NodeState,
    OperatingMode,
    SafetyState,
    State,
    Velocity,
    Visualization,
)
from vda5050.models.state import NodeStatePosition
from vda_vehicle.capabilities import Capabilities
from vda_vehicle.model import ActionRecord, HeldMap, Pose, VehicleState

#: Replaced by the HeaderStamper when the message is sent (§6.4).
PLACEHOLDER_HEADER: Final = {
    "header_id": 0,
    "timestamp": "1970-01-01T00:00:00.000Z",
    "version": "2.1.0",
    "manufacturer": "-",
    "serial_number": "-",
}


def held_maps(maps: Sequence[HeldMap]) -> list[Map]:
    """2.1 ``state.maps`` (§6.7.2): every map the vehicle holds, ENABLED or DISABLED."""
    return [
        Map(
            map_id=held.map_id,
            map_version=held.map_version,
            map_status=MapStatus.ENABLED if held.enabled else MapStatus.DISABLED,
        )
        for held in maps
    ]


def build_state(state: VehicleState, caps: Capabilities, *, maps: list[Map] | None) -> State:
    """The state message of ``state``; ``maps`` only for 2.1 vehicles (None leaves it out)."""
    return State(
        **PLACEHOLDER_HEADER,
        maps=maps,
        order_id=state.order_id,
        order_update_id=state.order_update_id,
        zone_set_id=state.zone_set_id,
        last_node_id=state.last_node_id,
        last_node_sequence_id=state.last_node_sequence_id,
        driving=state.driving,
        paused=state.paused,
        new_base_request=state.new_base_request,
        distance_since_last_node=state.distance_since_last_node,
        operating_mode=OperatingMode(state.operating_mode.value),
        node_states=[_node_state(node) for node in state.nodes],
        edge_states=[
            EdgeState(
                edge_id=edge.edge_id,
                sequence_id=edge.sequence_id,
                edge_description=edge.edge_description,
                released=edge.released,
            )
            # R63: while a cancel finishes the edge, only the next node's nodeState is kept.
            for edge in (() if state.cancel_action_id is not None else state.edges)
        ],
        agv_position=agv_position(state),
        velocity=velocity(state),
        loads=list(state.loads),
        action_states=[_action_state(record) for record in state.actions],
        battery_state=_battery(state, caps),
        errors=list(state.errors),
        safety_state=SafetyState(e_stop=state.e_stop, field_violation=state.field_violation),
    )


def build_visualization(state: VehicleState) -> Visualization:
    """Pose and velocity at the visualization rate (§6.13, R109); header stamped at send time."""
    return Visualization(agv_position=agv_position(state), velocity=velocity(state))


def visualization_body(state: VehicleState, pose: Pose | None = None) -> EncodedBody:
    """``EncodedBody.of(build_visualization(state))``, at ``pose`` if given instead of the
    state's own: the same bytes (a property test compares them), written by orjson from the
    pose without building the three models, in a tenth of the time. A moving vehicle sends one
    every second (docs/performance.md, lever 53)."""
    position = _position_fields(state, state.pose if pose is None else pose)
    fields = orjson.dumps({"agvPosition": position, "velocity": _velocity_fields(state)})
    return EncodedBody(Visualization.vda_major, Visualization.__name__, fields)


def state_body(
    state: VehicleState,
    caps: Capabilities,
    *,
    maps: list[Map] | None,
    more_errors: Sequence[Error] = (),
) -> EncodedBody:
    """``EncodedBody.of(build_state(...))`` with ``more_errors`` after the state's own: the same
    bytes (a property test compares them for any state), written by orjson from the vehicle
    state, the order's nodes and the action records without building a model per element, in
    about a fifth of the time. A vehicle sends one at every event of §6.10
    (docs/performance.md, lever 54). Loads, errors and maps, rare and built elsewhere as
    models, are encoded by their own models."""
    fields: dict[str, object] = {}
    if maps is not None:
        fields["maps"] = [_fragment(m) for m in maps]
    fields["orderId"] = state.order_id
    fields["orderUpdateId"] = state.order_update_id
    if state.zone_set_id is not None:
        fields["zoneSetId"] = state.zone_set_id
    fields["lastNodeId"] = state.last_node_id
    fields["lastNodeSequenceId"] = state.last_node_sequence_id
    fields["driving"] = state.driving
    fields["paused"] = state.paused
    fields["newBaseRequest"] = state.new_base_request
    fields["distanceSinceLastNode"] = float(state.distance_since_last_node)
    fields["operatingMode"] = state.operating_mode.value
    fields["nodeStates"] = [_node_state_fields(node) for node in state.nodes]
    # R63: while a cancel finishes the edge, only the next node's nodeState is kept.
    edges = () if state.cancel_action_id is not None else state.edges
    fields["edgeStates"] = [_edge_state_fields(edge) for edge in edges]
    fields["agvPosition"] = _position_fields(state, state.pose)
    fields["velocity"] = _velocity_fields(state)
    fields["loads"] = [_fragment(load) for load in state.loads]
    fields["actionStates"] = [_action_state_fields(record) for record in state.actions]
    battery: dict[str, object] = {
        "batteryCharge": float(round(state.battery_charge, 3)),
        "charging": state.charging,
    }
    reach = caps.reach_m(state.battery_charge)
    if reach is not None:
        battery["reach"] = float(reach)
    fields["batteryState"] = battery
    fields["errors"] = [_fragment(error) for error in (*state.errors, *more_errors)]
    fields["safetyState"] = (
        _NO_SAFETY_EVENT_JSON
        if state.e_stop is EStop.NONE and not state.field_violation
        else {"eStop": state.e_stop.value, "fieldViolation": state.field_violation}
    )
    return EncodedBody(State.vda_major, State.__name__, orjson.dumps(fields))


_NO_SAFETY_EVENT_JSON: Final = {"eStop": EStop.NONE.value, "fieldViolation": False}


def _fragment(model: Map | Load | Error) -> orjson.Fragment:
    """A nested model as it encodes itself inside a message (aliases, no None fields)."""
    return orjson.Fragment(
        model.__pydantic_serializer__.to_json(model, by_alias=True, exclude_none=True)
    )


def _position_fields(state: VehicleState, pose: Pose) -> dict[str, object]:
    return {
        "x": float(pose.x),
        "y": float(pose.y),
        "theta": float(pose.theta),
        "mapId": pose.map_id,
        "positionInitialized": state.position_initialized,
    }


def _velocity_fields(state: VehicleState) -> dict[str, object]:
    motion = state.motion
    return {"vx": float(motion.vx), "vy": float(motion.vy), "omega": float(motion.omega)}


def _node_state_fields(node: Node) -> dict[str, object]:
    fields: dict[str, object] = {"nodeId": node.node_id, "sequenceId": node.sequence_id}
    if node.node_description is not None:
        fields["nodeDescription"] = node.node_description
    fields["released"] = node.released
    position = node.node_position
    if position is not None:
        place: dict[str, object] = {"x": float(position.x), "y": float(position.y)}
        if position.theta is not None:
            place["theta"] = float(position.theta)
        place["mapId"] = position.map_id
        fields["nodePosition"] = place
    return fields


def _edge_state_fields(edge: Edge) -> dict[str, object]:
    fields: dict[str, object] = {"edgeId": edge.edge_id, "sequenceId": edge.sequence_id}
    if edge.edge_description is not None:
        fields["edgeDescription"] = edge.edge_description
    fields["released"] = edge.released
    return fields


def _action_state_fields(record: ActionRecord) -> dict[str, object]:
    action = record.action
    fields: dict[str, object] = {"actionId": action.action_id, "actionType": action.action_type}
    if action.action_description is not None:
        fields["actionDescription"] = action.action_description
    fields["actionStatus"] = record.status.value
    if record.result is not None:
        fields["resultDescription"] = record.result
    return fields


def agv_position(state: VehicleState) -> AgvPosition:
    """R102: the simulated vehicle always localises; theta lies in [-pi, pi]."""
    pose = state.pose
    return AgvPosition(
        x=pose.x,
        y=pose.y,
        theta=pose.theta,
        map_id=pose.map_id,
        position_initialized=state.position_initialized,
    )


def velocity(state: VehicleState) -> Velocity:
    motion = state.motion
    return Velocity(vx=motion.vx, vy=motion.vy, omega=motion.omega)


def _node_state(node: Node) -> NodeState:
    position = node.node_position
    return NodeState(
        node_id=node.node_id,
        sequence_id=node.sequence_id,
        node_description=node.node_description,
        released=node.released,
        node_position=None
        if position is None
        else NodeStatePosition(
            x=position.x, y=position.y, theta=position.theta, map_id=position.map_id
        ),
    )


def _action_state(record: ActionRecord) -> ActionState:
    return ActionState(
        action_id=record.action_id,
        action_type=record.action_type,
        action_description=record.action.action_description,
        action_status=record.status,
        result_description=record.result,
    )


def _battery(state: VehicleState, caps: Capabilities) -> BatteryState:
    """Charge in %, and reach in whole metres at the configured drain (§6.10.6)."""
    return BatteryState(
        battery_charge=round(state.battery_charge, 3),
        charging=state.charging,
        reach=caps.reach_m(state.battery_charge),
    )
