"""Where a vehicle's next order starts, wherever the vehicle stands (§6.6.1, §6.6.3.1).

A new order's first node must be trivially reachable: the vehicle stands on it or within its
``allowedDeviationXY``. A vehicle normally stands on its ``lastNodeId``. One that stopped
between two nodes (a cancel on a vehicle that can stop anywhere, vda-5050-lib's virtual AGV for
one) does not, and an order starting at its last node with the normal tolerance is rejected.
Master control then uses the first restart method of §6.6.3.1, which every vehicle that can stop
between nodes must accept: the first node is a temporary node at the vehicle's position, and the
first edge leads from there to the end of the edge the vehicle stands on
(:attr:`StartPoint.via_edge`), so the vehicle stays on its lane; the route goes on from that
edge's end. (The second method, the last node with a wide ``allowedDeviationXY``, is not used:
vda-5050-lib 1.4 reads that field under another name and ignores it.)

Pure: the graph and the vehicle's last state go in, a :class:`StartPoint` or a problem comes out.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Final

from vda5050.models import AgvPosition, State
from vda_master.graph import Graph
from vda_master.routing import DEFAULT_ON_NODE_TOLERANCE_M

#: Farther than this (m) from its node's coordinates, a vehicle is treated as off the node and
#: its next order starts with a temporary node where it stands.
ON_NODE_M: Final = 0.05
#: A vehicle this close (m) to an edge leaving its last node is taken to stand on that edge.
ON_EDGE_M: Final = 0.5


@dataclass(frozen=True, slots=True)
class StartPoint:
    """Where the vehicle's next order starts: node ``node_id``, or, when the vehicle stands off
    it (``position`` is set), a temporary node at ``position`` on edge ``via_edge``."""

    node_id: str
    #: The vehicle's (x, y) when it stands more than :data:`ON_NODE_M` off ``node_id``.
    position: tuple[float, float] | None = None
    #: The edge leaving ``node_id`` that the vehicle stands on (set with ``position``).
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


def _from_last_node(graph: Graph, node_id: str, x: float, y: float) -> StartPoint | str:
    node = graph.nodes[node_id]
    offset = math.hypot(x - node.x, y - node.y)
    if offset <= ON_NODE_M:
        return StartPoint(node_id)
    via = _edge_under(graph, node_id, x, y)
    if via is None:
        return (
            f"it stands {offset:.2f} m from its last node {node_id!r} and on no edge leaving "
            "it: bring it back onto the graph (e.g. the instant action initPosition)"
        )
    return StartPoint(node_id, (x, y), via, offset)


def _edge_under(graph: Graph, node_id: str, x: float, y: float) -> str | None:
    """The edge leaving ``node_id`` closest to (x, y), if the vehicle is on it."""
    best: tuple[float, str] | None = None
    for edge_id in graph.outgoing[node_id]:
        path = graph.edge_path(graph.edges[edge_id])
        distance = min(point_segment_distance((x, y), a, b) for a, b in itertools.pairwise(path))
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
