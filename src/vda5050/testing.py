"""Factories for tests and tools, shipped with the package (the structlog.testing idea)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence

from vda5050.models import (
    Action,
    BatteryState,
    BlockingType,
    Edge,
    EStop,
    InstantActions,
    Node,
    NodePosition,
    OperatingMode,
    Order,
    SafetyState,
    State,
)

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
