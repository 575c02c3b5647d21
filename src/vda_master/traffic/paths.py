"""Static paths on the graph for traffic decisions: detours that avoid resources, nearest nodes.

:class:`RoadMap` is the graph prepared once per load for traffic work: adjacency with lengths in
both directions and the nodes of each ``stationType``. The searches are plain Dijkstra by edge
length; ties go to file order, so every answer is deterministic.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass
from types import MappingProxyType

from vda_master.graph import Graph
from vda_master.routing import Route, route_of
from vda_master.traffic.conflicts import Resource, edge, node

#: (edge id, node at the other end, length in metres)
Arc = tuple[str, str, float]


@dataclass(frozen=True, slots=True)
class RoadMap:
    """The graph with both adjacency lists, edge lengths and station nodes."""

    graph: Graph
    outgoing: Mapping[str, tuple[Arc, ...]]
    incoming: Mapping[str, tuple[Arc, ...]]
    length: Mapping[str, float]
    #: Edge id → its maxSpeed (m/s), for edges that have one.
    max_speed: Mapping[str, float]
    #: stationType → node ids with that type, in file order.
    stations: Mapping[str, tuple[str, ...]]

    def station_nodes(self, station_type: str) -> tuple[str, ...]:
        """Nodes whose ``stationType`` is ``station_type`` (e.g. ``parking``)."""
        return self.stations.get(station_type, ())


def build_roadmap(graph: Graph) -> RoadMap:
    """Index ``graph`` for traffic searches."""
    outgoing: dict[str, list[Arc]] = {node_id: [] for node_id in graph.nodes}
    incoming: dict[str, list[Arc]] = {node_id: [] for node_id in graph.nodes}
    length: dict[str, float] = {}
    max_speed: dict[str, float] = {}
    for graph_edge in graph.edges.values():
        meters = graph.edge_length(graph_edge.edge_id)
        length[graph_edge.edge_id] = meters
        if graph_edge.max_speed is not None:
            max_speed[graph_edge.edge_id] = graph_edge.max_speed
        outgoing[graph_edge.start_node_id].append(
            (graph_edge.edge_id, graph_edge.end_node_id, meters)
        )
        incoming[graph_edge.end_node_id].append(
            (graph_edge.edge_id, graph_edge.start_node_id, meters)
        )
    stations: dict[str, list[str]] = {}
    for graph_node in graph.nodes.values():
        if graph_node.station_type is not None:
            stations.setdefault(graph_node.station_type, []).append(graph_node.node_id)
    return RoadMap(
        graph,
        MappingProxyType({k: tuple(v) for k, v in outgoing.items()}),
        MappingProxyType({k: tuple(v) for k, v in incoming.items()}),
        MappingProxyType(length),
        MappingProxyType(max_speed),
        MappingProxyType({k: tuple(v) for k, v in stations.items()}),
    )


def distances(
    roads: RoadMap,
    origin: str,
    *,
    reverse: bool = False,
    allowed: Callable[[str, str], bool] | None = None,
) -> tuple[dict[str, float], dict[str, str]]:
    """Dijkstra from ``origin``: metres to every reachable node and the edge it was reached by.

    ``reverse`` searches against the edge direction (distances *to* ``origin``). ``allowed(edge
    id, next node id)`` may forbid steps.
    """
    arcs = roads.incoming if reverse else roads.outgoing
    distance: dict[str, float] = {origin: 0.0}
    via: dict[str, str] = {}
    queue: list[tuple[float, int, str]] = [(0.0, 0, origin)]
    counter = 1
    while queue:
        cost, _, at = heapq.heappop(queue)
        if cost > distance[at]:
            continue
        for edge_id, other, meters in arcs[at]:
            if allowed is not None and not allowed(edge_id, other):
                continue
            candidate = cost + meters
            if candidate < distance.get(other, math.inf):
                distance[other], via[other] = candidate, edge_id
                heapq.heappush(queue, (candidate, counter, other))
                counter += 1
    return distance, via


def path_to(roads: RoadMap, start: str, target: str, via: Mapping[str, str]) -> Route:
    """The route from ``start`` to ``target`` along the ``via`` tree of :func:`distances`."""
    edges: list[str] = []
    at = target
    while at != start:
        edge_id = via[at]
        edges.append(edge_id)
        at = roads.graph.edges[edge_id].start_node_id
    edges.reverse()
    return route_of(roads.graph, start, edges)


def route_avoiding(
    roads: RoadMap, start: str, destination: str, avoid: Collection[Resource]
) -> Route | None:
    """Shortest route from ``start`` to ``destination`` using no resource in ``avoid`` (the
    start node excepted: the vehicle stands there); None if there is none."""

    def allowed(edge_id: str, next_node: str) -> bool:
        return edge(edge_id) not in avoid and node(next_node) not in avoid

    distance, via = distances(roads, start, allowed=allowed)
    if destination not in distance:
        return None
    return path_to(roads, start, destination, via)
