"""What the vehicle can take in one message, declared in its factsheet and enforced on receipt
(§6.1.2, §6.15 protocolLimits; R36), and the physical sanity of an order.

The limits keep the work per message bounded and linear: a message over ``msg_len`` is refused
by size before it is parsed, and counts and string lengths are checked before any per-element
work. Every refusal names the limit it breaks. Pure.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Final

from vda5050.models import Action, InstantActions, Order
from vda_vehicle.trajectories import MAX_DEGREE

#: Metres beyond the extent of a map's nodes that an order may still place a node.
MAP_MARGIN_M: Final = 50.0
#: Without a known map extent, coordinates beyond this (m) are not a plant floor.
ABSOLUTE_BOUND_M: Final = 100_000.0


@dataclass(frozen=True, slots=True)
class ProtocolLimits:
    """Message, string and array limits (§6.15 ``maxStringLens``/``maxArrayLens``)."""

    msg_len: int = 262_144
    topic_serial_len: int = 64
    topic_elem_len: int = 64
    id_len: int = 128
    enum_len: int = 64
    load_id_len: int = 128
    order_nodes: int = 1000
    order_edges: int = 999
    node_actions: int = 10
    edge_actions: int = 10
    actions_parameters: int = 20
    instant_actions: int = 50
    #: Per trajectory: as many knots as that many control points of the highest degree the
    #: stack follows need.
    trajectory_control_points: int = 256
    trajectory_knot_vector: int = 256 + MAX_DEGREE + 1
    #: Terminal instant-action states kept until the next order (§6.10.6), oldest dropped first.
    kept_instant_action_states: int = 100


@dataclass(frozen=True, slots=True)
class MapExtent:
    """The bounding box of a map's nodes, metres."""

    min_x: float
    min_y: float
    max_x: float
    max_y: float

    def contains(self, x: float, y: float, margin: float = MAP_MARGIN_M) -> bool:
        return (
            self.min_x - margin <= x <= self.max_x + margin
            and self.min_y - margin <= y <= self.max_y + margin
        )


def extent_of(points: Iterable[tuple[float, float]]) -> MapExtent | None:
    """The bounding box of ``points``, None for none."""
    xs, ys = [], []
    for x, y in points:
        xs.append(x)
        ys.append(y)
    if not xs:
        return None
    return MapExtent(min(xs), min(ys), max(xs), max(ys))


def order_limit_problems(order: Order, limits: ProtocolLimits) -> list[str]:
    """Every protocol limit ``order`` breaks, as sentences naming the limit (R36, R114)."""
    trajectories = [e.trajectory for e in order.edges if e.trajectory is not None]
    problems = _counts(
        ("order.nodes", len(order.nodes), limits.order_nodes),
        ("order.edges", len(order.edges), limits.order_edges),
        (
            "node.actions",
            max((len(n.actions) for n in order.nodes), default=0),
            limits.node_actions,
        ),
        (
            "edge.actions",
            max((len(e.actions) for e in order.edges), default=0),
            limits.edge_actions,
        ),
        (
            "trajectory.knotVector",
            max((len(t.knot_vector) for t in trajectories), default=0),
            limits.trajectory_knot_vector,
        ),
        (
            "trajectory.controlPoints",
            max((len(t.control_points) for t in trajectories), default=0),
            limits.trajectory_control_points,
        ),
    )
    if problems:
        return problems  # counts first: string checks below walk every element
    ids = [("order.orderId", order.order_id)]
    if order.zone_set_id is not None:
        ids.append(("order.zoneSetId", order.zone_set_id))
    for node in order.nodes:
        ids.append(("node.nodeId", node.node_id))
        if node.node_position is not None:
            ids.append(("nodePosition.mapId", node.node_position.map_id))
    for edge in order.edges:
        ids.extend(
            (("edge.edgeId", edge.edge_id), ("edge.startNodeId", edge.start_node_id)),
        )
        ids.append(("edge.endNodeId", edge.end_node_id))
        if edge.direction is not None:
            problems.extend(_too_long("edge.direction", edge.direction, limits.enum_len))
    actions = [a for n in order.nodes for a in n.actions] + [
        a for e in order.edges for a in e.actions
    ]
    problems.extend(_action_problems(actions, limits))
    problems.extend(p for key, value in ids for p in _too_long(key, value, limits.id_len))
    return problems


def instant_limit_problems(message: InstantActions, limits: ProtocolLimits) -> list[str]:
    """Every protocol limit an instantActions message breaks (§6.15)."""
    problems = _counts(("instantActions", len(message.actions), limits.instant_actions))
    return problems or _action_problems(message.actions, limits)


def _action_problems(actions: list[Action], limits: ProtocolLimits) -> list[str]:
    problems: list[str] = []
    for action in actions:
        count = len(action.action_parameters or ())
        problems.extend(_counts(("actions.actionsParameters", count, limits.actions_parameters)))
        problems.extend(_too_long("action.actionId", action.action_id, limits.id_len))
        problems.extend(_too_long("action.actionType", action.action_type, limits.enum_len))
        for parameter in action.action_parameters or ():
            problems.extend(_too_long("actionParameter.key", parameter.key, limits.enum_len))
        if problems:
            return problems  # one broken action is reason enough; stay linear
    return problems


def _counts(*entries: tuple[str, int, int]) -> list[str]:
    return [
        f"{key} holds {count} entries, over the limit of {limit} (factsheet maxArrayLens)"
        for key, count, limit in entries
        if limit and count > limit
    ]


def _too_long(key: str, value: str, limit: int) -> Iterator[str]:
    if limit and len(value) > limit:
        yield f"{key} is {len(value)} characters long, over the limit of {limit} (maxStringLens)"


@dataclass(frozen=True, slots=True)
class Impossible:
    """Something in an order no vehicle can drive, and the element it concerns."""

    description: str
    reference: tuple[str, str]
    #: A position off the map (the vehicle cannot go there) rather than an invalid value.
    off_map: bool = False


def physical_problems(order: Order, extents: Mapping[str, MapExtent]) -> list[Impossible]:
    """Non-positive speeds, negative lengths and heights, positions off the map (its nodes'
    extent plus :data:`MAP_MARGIN_M`, or beyond :data:`ABSOLUTE_BOUND_M` on an unknown map)."""
    problems: list[Impossible] = []
    for edge in order.edges:
        ref = ("edgeId", edge.edge_id)
        for name, value in (
            ("maxSpeed", edge.max_speed),
            ("maxRotationSpeed", edge.max_rotation_speed),
        ):
            if value is not None and not value > 0:
                problems.append(
                    Impossible(f"edge {edge.edge_id} {name} {value} must be positive", ref)
                )
        for name, value in (
            ("length", edge.length),
            ("maxHeight", edge.max_height),
            ("minHeight", edge.min_height),
        ):
            if value is not None and value < 0:
                problems.append(Impossible(f"edge {edge.edge_id} {name} {value} is negative", ref))
    for node in order.nodes:
        position = node.node_position
        if position is None:
            continue
        extent = extents.get(position.map_id)
        inside = (
            extent.contains(position.x, position.y)
            if extent is not None
            else max(abs(position.x), abs(position.y)) <= ABSOLUTE_BOUND_M
        )
        if not inside:
            where = f"({position.x:g}, {position.y:g})"
            text = f"node {node.node_id} at {where} lies outside map {position.map_id!r}"
            problems.append(Impossible(text, ("nodeId", node.node_id), off_map=True))
    return problems
