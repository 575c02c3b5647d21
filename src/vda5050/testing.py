"""Factories for tests and tools, shipped with the package (the structlog.testing idea)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence

from vda5050.models import (
    Action,
    ActionParameter,
    BatteryState,
    BlockingType,
    Edge,
    EdgeState,
    EStop,
    InstantActions,
    Node,
    NodePosition,
    NodeState,
    OperatingMode,
    Order,
    SafetyState,
    State,
    v3,
)
from vda5050.models.common import ParameterValue

HEADER = {
    "header_id": 0,
    "timestamp": "2026-01-01T00:00:00.000Z",
    "version": "2.1.0",
    "manufacturer": "acme",
    "serial_number": "robot_0",
}


def make_action(
    action_type: str, action_id: str, blocking_type: BlockingType = BlockingType.NONE
) -> Action:
    """An action without parameters."""
    return Action(action_type=action_type, action_id=action_id, blocking_type=blocking_type)


def make_instant_actions(*actions: Action, **header: object) -> InstantActions:
    """An instantActions message (a stateRequest ``q1`` when no action is given)."""
    chosen = list(actions) or [make_action("stateRequest", "q1")]
    return InstantActions.model_validate({**HEADER, **header, "actions": chosen})


def make_order(
    node_ids: Sequence[str],
    *,
    order_id: str = "order-1",
    order_update_id: int = 0,
    released: int | None = None,
    first_sequence_id: int = 0,
    positions: Sequence[tuple[float, float]] | None = None,
    map_id: str = "map",
    node_actions: dict[str, list[Action]] | None = None,
    edge_actions: dict[str, list[Action]] | None = None,
    **header: object,
) -> Order:
    """A well-formed order over ``node_ids`` with edges named ``<start>-<end>``.

    ``released`` counts released nodes (default: all); edges between released nodes are released.
    Nodes sit at ``positions`` (default: 10 m apart on the x axis).
    """
    released_nodes = len(node_ids) if released is None else released
    coordinates = positions or [(10.0 * index, 0.0) for index in range(len(node_ids))]
    nodes = [
        Node(
            node_id=node_id,
            sequence_id=first_sequence_id + 2 * index,
            released=index < released_nodes,
            node_position=NodePosition(
                x=coordinates[index][0], y=coordinates[index][1], map_id=map_id
            ),
            actions=(node_actions or {}).get(node_id, []),
        )
        for index, node_id in enumerate(node_ids)
    ]
    edges = [
        Edge(
            edge_id=f"{start}-{end}",
            sequence_id=first_sequence_id + 2 * index + 1,
            released=index + 1 < released_nodes,
            start_node_id=start,
            end_node_id=end,
            actions=(edge_actions or {}).get(f"{start}-{end}", []),
        )
        for index, (start, end) in enumerate(itertools.pairwise(node_ids))
    ]
    return Order.model_validate(
        {
            **HEADER,
            **header,
            "order_id": order_id,
            "order_update_id": order_update_id,
            "nodes": nodes,
            "edges": edges,
        }
    )


def make_state(**fields: object) -> State:
    """An idle state with every required field (R95, R96), overridden by ``fields``."""
    base: dict[str, object] = {
        **HEADER,
        "order_id": "",
        "order_update_id": 0,
        "last_node_id": "",
        "last_node_sequence_id": 0,
        "node_states": [],
        "edge_states": [],
        "driving": False,
        "action_states": [],
        "battery_state": BatteryState(battery_charge=80.0, charging=False),
        "operating_mode": OperatingMode.AUTOMATIC,
        "errors": [],
        "safety_state": SafetyState(e_stop=EStop.NONE, field_violation=False),
    }
    return State.model_validate({**base, **fields})


def state_at(order: Order, index: int, **fields: object) -> State:
    """What a conforming vehicle reports having reached node ``index`` of ``order``: that
    node as its last, the nodes and edges after it listed as the order gives them."""
    reached = order.nodes[index]
    listing: dict[str, object] = {
        "order_id": order.order_id,
        "order_update_id": order.order_update_id,
        "last_node_id": reached.node_id,
        "last_node_sequence_id": reached.sequence_id,
        "node_states": [
            NodeState(node_id=n.node_id, sequence_id=n.sequence_id, released=n.released)
            for n in order.nodes[index + 1 :]
        ],
        "edge_states": [
            EdgeState(edge_id=e.edge_id, sequence_id=e.sequence_id, released=e.released)
            for e in order.edges[index:]
        ],
    }
    return make_state(**{**listing, **fields})


# -- VDA 5050 3.0 -----------------------------------------------------------------------------

HEADER_V3 = {**HEADER, "version": "3.0.0"}


def make_action_v3(
    action_type: str,
    action_id: str,
    blocking_type: v3.BlockingType = v3.BlockingType.NONE,
    *,
    retriable: bool | None = None,
    **parameters: ParameterValue,
) -> v3.Action:
    """A 3.0 node/edge action; keyword arguments become its actionParameters."""
    return v3.Action(
        action_type=action_type,
        action_id=action_id,
        blocking_type=blocking_type,
        retriable=retriable,
        action_parameters=_parameters(parameters),
    )


def make_instant_action_v3(
    action_type: str, action_id: str, **parameters: ParameterValue
) -> v3.InstantAction:
    """A 3.0 instant action (blockingType NONE, T49); keyword arguments become parameters."""
    return v3.InstantAction(
        action_type=action_type,
        action_id=action_id,
        blocking_type=v3.BlockingType.NONE,
        action_parameters=_parameters(parameters),
    )


def _parameters(parameters: dict[str, ParameterValue]) -> list[ActionParameter] | None:
    return [ActionParameter(key=k, value=v) for k, v in parameters.items()] or None


def make_order_v3(
    node_ids: Sequence[str],
    *,
    order_id: str = "order-1",
    order_update_id: int = 0,
    released: int | None = None,
    first_sequence_id: int = 0,
    positions: Sequence[tuple[float, float]] | None = None,
    map_id: str = "map",
    deviation: v3.AllowedDeviationXY | None = None,
    node_actions: dict[int, list[v3.Action]] | None = None,
    edge_actions: dict[int, list[v3.Action]] | None = None,
    **header: object,
) -> v3.Order:
    """A well-formed 3.0 order over ``node_ids`` (T17–T19); edges are named ``<start>-<end>``.

    ``released`` counts released nodes (default: all). Nodes sit at ``positions`` (default:
    10 m apart on the x axis), each with the ``deviation`` ellipse if given. ``node_actions``
    and ``edge_actions`` are keyed by the element's index in its list (node ids may repeat).
    """
    released_nodes = len(node_ids) if released is None else released
    coordinates = positions or [(10.0 * index, 0.0) for index in range(len(node_ids))]
    nodes = [
        v3.Node(
            node_id=node_id,
            sequence_id=first_sequence_id + 2 * index,
            released=index < released_nodes,
            node_position=v3.NodePosition(
                x=coordinates[index][0],
                y=coordinates[index][1],
                allowed_deviation_xy=deviation,
                map_id=map_id,
            ),
            actions=(node_actions or {}).get(index, []),
        )
        for index, node_id in enumerate(node_ids)
    ]
    edges = [
        v3.Edge(
            edge_id=f"{start}-{end}",
            sequence_id=first_sequence_id + 2 * index + 1,
            released=index + 1 < released_nodes,
            actions=(edge_actions or {}).get(index, []),
        )
        for index, (start, end) in enumerate(itertools.pairwise(node_ids))
    ]
    return v3.Order.model_validate(
        {
            **HEADER_V3,
            **header,
            "order_id": order_id,
            "order_update_id": order_update_id,
            "nodes": nodes,
            "edges": edges,
        }
    )


def make_stitching_update_v3(
    previous: v3.Order,
    new_node_ids: Sequence[str],
    *,
    released: int | None = None,
    positions: Sequence[tuple[float, float]] | None = None,
    decision_point_actions: list[v3.Action] | None = None,
) -> v3.Order:
    """The next update of ``previous``: its decision point resent unchanged (T40), then
    ``new_node_ids`` at ``positions`` (default: 10 m steps along x from the decision point).

    With ``decision_point_actions`` a node with the decision point's id and position comes
    first, with sequenceId + 2, carrying those actions (T41). ``released`` counts released
    nodes among the new ones (default: all).
    """
    decision = previous.decision_point()
    if decision is None or decision.node_position is None:
        msg = f"order {previous.order_id!r} has no released, positioned node to stitch onto"
        raise ValueError(msg)
    here = (decision.node_position.x, decision.node_position.y)
    ids = list(new_node_ids)
    coordinates = list(positions or [(here[0] + 10.0 * (i + 1), here[1]) for i in range(len(ids))])
    if decision_point_actions is not None:
        ids.insert(0, decision.node_id)
        coordinates.insert(0, here)
    grown = make_order_v3(
        [decision.node_id, *ids],
        order_id=previous.order_id,
        order_update_id=previous.order_update_id + 1,
        released=1 + (len(ids) if released is None else released),
        first_sequence_id=decision.sequence_id,
        positions=[here, *coordinates],
        map_id=decision.node_position.map_id,
        node_actions={1: decision_point_actions} if decision_point_actions else None,
        header_id=previous.header_id,
        timestamp=previous.timestamp,
        manufacturer=previous.manufacturer,
        serial_number=previous.serial_number,
    )
    return grown.model_copy(update={"nodes": [decision, *grown.nodes[1:]]})


def make_state_v3(**fields: object) -> v3.State:
    """An idle 3.0 state with every required field (T70), overridden by ``fields``."""
    base: dict[str, object] = {
        **HEADER_V3,
        "order_id": "",
        "order_update_id": 0,
        "last_node_id": "",
        "last_node_sequence_id": 0,
        "node_states": [],
        "edge_states": [],
        "driving": False,
        "action_states": [],
        "instant_action_states": [],
        "power_supply": v3.PowerSupply(state_of_charge=80.0, charging=False),
        "operating_mode": v3.OperatingMode.AUTOMATIC,
        "errors": [],
        "safety_state": v3.SafetyState(
            active_emergency_stop=v3.EmergencyStop.NONE, field_violation=False
        ),
    }
    return v3.State.model_validate({**base, **fields})


def make_instant_actions_v3(*actions: v3.InstantAction, **header: object) -> v3.InstantActions:
    """A 3.0 instantActions message carrying ``actions``."""
    return v3.InstantActions.model_validate({**HEADER_V3, **header, "actions": list(actions)})


def make_connection_v3(
    state: v3.ConnectionState = v3.ConnectionState.ONLINE, **header: object
) -> v3.Connection:
    """A 3.0 connection message."""
    return v3.Connection.model_validate({**HEADER_V3, **header, "connection_state": state})


def make_visualization_v3(reference_state_header_id: int = 0, **fields: object) -> v3.Visualization:
    """A 3.0 visualization message pointing at state ``reference_state_header_id`` (T79)."""
    return v3.Visualization.model_validate(
        {**HEADER_V3, "reference_state_header_id": reference_state_header_id, **fields}
    )


def make_zone_set_v3(
    *zones: v3.Zone, zone_set_id: str = "zones-1", map_id: str = "map", **header: object
) -> v3.ZoneSetMessage:
    """A 3.0 zoneSet message; by default one BLOCKED square of 1 m at the origin."""
    content = v3.ZoneSet(
        map_id=map_id,
        zone_set_id=zone_set_id,
        zones=list(zones) or [make_zone_v3("blocked-1", v3.ZoneType.BLOCKED)],
    )
    return v3.ZoneSetMessage.model_validate({**HEADER_V3, **header, "zone_set": content})


def make_zone_v3(
    zone_id: str,
    zone_type: v3.ZoneType,
    corners: Sequence[tuple[float, float]] = ((0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)),
    **parameters: object,
) -> v3.Zone:
    """A zone over ``corners`` (counterclockwise); ``parameters`` are the type's fields (T84)."""
    return v3.Zone.model_validate(
        {
            "zone_id": zone_id,
            "zone_type": zone_type,
            "vertices": [v3.Vertex(x=x, y=y) for x, y in corners],
            **parameters,
        }
    )


def make_responses_v3(
    *grants: tuple[str, v3.GrantType] | v3.Response, **header: object
) -> v3.Responses:
    """A 3.0 responses message; ``grants`` are (requestId, grantType) pairs or responses."""
    responses = [
        grant
        if isinstance(grant, v3.Response)
        else v3.Response(request_id=grant[0], grant_type=grant[1])
        for grant in grants
    ]
    return v3.Responses.model_validate({**HEADER_V3, **header, "responses": responses})


def make_factsheet_v3(
    *,
    actions: Sequence[v3.MobileRobotAction] = (),
    supported_zones: Sequence[v3.ZoneType] | None = None,
    optional_parameters: Sequence[str] = (),
    **header: object,
) -> v3.Factsheet:
    """A small 3.0 factsheet of a differential-drive carrier (T80). It always declares the
    mandatory ``cancelOrder``, ``startPause`` and ``stopPause`` (T55) besides ``actions``."""
    mandatory = [
        v3.MobileRobotAction(
            action_type=action_type,
            action_scopes=[v3.ActionScope.INSTANT],
            blocking_types=[v3.BlockingType.NONE],
            pause_allowed=False,
            cancel_allowed=False,
        )
        for action_type in ("cancelOrder", "startPause", "stopPause")
    ]
    return v3.Factsheet.model_validate(
        {
            **HEADER_V3,
            **header,
            "type_specification": {
                "series_name": "sim",
                "mobile_robot_kinematics": v3.MobileRobotKinematics.DIFFERENTIAL,
                "mobile_robot_class": v3.MobileRobotClass.CARRIER,
                "maximum_load_mass": 500.0,
                "localization_types": ["NATURAL"],
                "navigation_types": [v3.NavigationType.VIRTUAL_LINE_GUIDED],
                "supported_zones": supported_zones,
            },
            "physical_parameters": {
                "minimum_speed": 0.01,
                "maximum_speed": 2.0,
                "maximum_acceleration": 1.0,
                "maximum_deceleration": 1.0,
                "minimum_height": 0.3,
                "maximum_height": 0.5,
                "width": 0.8,
                "length": 1.2,
            },
            "protocol_limits": {
                "maximum_string_lengths": {},
                "maximum_array_lengths": {},
                "timing": {"minimum_order_interval": 0.5, "minimum_state_interval": 0.1},
            },
            "protocol_features": {
                "optional_parameters": [
                    {"parameter": name, "support": "SUPPORTED"} for name in optional_parameters
                ],
                "mobile_robot_actions": [*mandatory, *actions],
            },
            "mobile_robot_geometry": {},
            "load_specification": {},
        }
    )
