"""Where a vehicle's next order starts, wherever the vehicle stands (§6.6.1, §6.6.3.1).

A new order's first node must be trivially reachable: the vehicle stands on it or within its
``allowedDeviationXY``. A vehicle normally stands on its ``lastNodeId``. One that stopped
between two nodes (a cancel on a vehicle that can stop anywhere, vda-5050-lib's virtual AGV for
one) does not, and an order starting at its last node with the normal tolerance is rejected.
Master control then uses the second restart method of §6.6.3.1: the first node is the last
traversed node, sent with an ``allowedDeviationXY`` that covers the vehicle, which counts it as
traversed at once. So that the vehicle stays on the lane it stopped on, the route continues
along the edge it stands on (:attr:`StartPoint.via_edge`): the vehicle drives on to that edge's
end and is routed from there.

Pure: the graph and the vehicle's last state go in, a :class:`StartPoint` or a problem comes out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from vda5050.models import AgvPosition, State
from vda_master.graph import Graph
from vda_master.routing import DEFAULT_ON_NODE_TOLERANCE_M

#: Farther than this (m) from its node's coordinates, a vehicle is treated as off the node and
#: the first node is sent with an explicit deviation that covers it.
ON_NODE_M: Final = 0.05
#: Margin (m) added to the vehicle's distance for the first node's allowedDeviationXY.
DEVIATION_MARGIN_M: Final = 0.25
#: A vehicle this close (m) to an edge leaving its last node is taken to stand on that edge.
ON_EDGE_M: Final = 0.5


@dataclass(frozen=True, slots=True)
class StartPoint:
    """The first node of the vehicle's next order.

    ``deviation_xy_m`` is set when the vehicle stands off that node: the first node must then be
    sent with at least this allowedDeviationXY. ``via_edge`` is the edge leaving it that the
    vehicle stands on: routes continue along it.
    """

    node_id: str
    deviation_xy_m: float | None = None
    via_edge: str | None = None
    #: Distance (m) from the vehicle to the node.
    offset_m: float = 0.0


def find_start(
    graph: Graph, state: State | None, *, tolerance_m: float = DEFAULT_ON_NODE_TOLERANCE_M
) -> StartPoint | str:
    """Where the vehicle's next order starts, or why it cannot be planned (a sentence)."""
    if state is None:
        return "it has not published a state yet"
    position = state.agv_position
    located = position is not None and position.position_initialized
    if state.last_node_id in graph.nodes:
        if not located or position is None:
            return StartPoint(state.last_node_id)  # trust lastNodeId (line-guided, §6.10.6)
        return _from_known_node(graph, state.last_node_id, position)
    if not located or position is None:
        return "its lastNodeId is not a graph node and it reports no position"
    nearest = _nearest_node(graph, position.x, position.y, position.map_id, tolerance_m)
    if nearest is None:
        return (
            f"it stands at ({position.x:.2f}, {position.y:.2f}) on map {position.map_id!r}, "
            "on no graph node"
        )
    return _from_last_node(graph, nearest, position.x, position.y)


def _from_known_node(graph: Graph, node_id: str, position: AgvPosition) -> StartPoint | str:
    node = graph.nodes[node_id]
    if position.map_id != graph.node_map_id(node):
        return (
            f"it is on map {position.map_id!r} but its last node {node_id!r} is on map "
            f"{graph.node_map_id(node)!r}"
        )
    return _from_last_node(graph, node_id, position.x, position.y)


def _from_last_node(graph: Graph, node_id: str, x: float, y: float) -> StartPoint:
    node = graph.nodes[node_id]
    offset = math.hypot(x - node.x, y - node.y)
    if offset <= ON_NODE_M:
        return StartPoint(node_id)
    deviation = max(offset + DEVIATION_MARGIN_M, node.allowed_deviation_xy or 0.0)
    return StartPoint(node_id, round(deviation, 3), _edge_under(graph, node_id, x, y), offset)


def _edge_under(graph: Graph, node_id: str, x: float, y: float) -> str | None:
    """The edge leaving ``node_id`` closest to (x, y), if the vehicle is on it."""
    best: tuple[float, str] | None = None
    for edge_id in graph.outgoing[node_id]:
        end = graph.nodes[graph.edges[edge_id].end_node_id]
        start = graph.nodes[node_id]
        distance = point_segment_distance((x, y), (start.x, start.y), (end.x, end.y))
        if distance <= ON_EDGE_M and (best is None or distance < best[0]):
            best = (distance, edge_id)
    return None if best is None else best[1]


def _nearest_node(graph: Graph, x: float, y: float, map_id: str, tolerance_m: float) -> str | None:
    best: tuple[float, str] | None = None
    for node in graph.nodes.values():
        if graph.node_map_id(node) != map_id:
            continue
        distance = math.hypot(node.x - x, node.y - y)
        radius = node.allowed_deviation_xy or tolerance_m
        if distance <= radius and (best is None or distance < best[0]):
            best = (distance, node.node_id)
    return None if best is None else best[1]


Point = tuple[float, float]


def point_segment_distance(p: Point, a: Point, b: Point) -> float:
    """Distance from point ``p`` to the segment ``a``-``b``."""
    (px, py), (ax, ay), (bx, by) = p, a, b
    dx, dy = bx - ax, by - ay
    length_sq = dx * dx + dy * dy
    if length_sq == 0:
        return math.hypot(px - ax, py - ay)
    t = max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / length_sq))
    return math.hypot(px - (ax + t * dx), py - (ay + t * dy))
