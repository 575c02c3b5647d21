"""Routes on the graph: where a vehicle stands, shortest paths, explicit edge sequences.

A route is an ordered list of edge ids starting at the node the vehicle stands on; master control
turns it into an order (§6.6.1: the first node must be trivially reachable). Problems are values
(:class:`RouteProblem`), so the HTTP layer can answer 404 or 422 with the reason.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Collection
from dataclasses import dataclass
from enum import StrEnum

from vda_master.graph import Graph

#: How close (metres) a vehicle must be to a node without ``allowedDeviationXY`` to stand on it.
DEFAULT_ON_NODE_TOLERANCE_M = 0.5


class ProblemKind(StrEnum):
    """Why no route could be made; the API maps these to HTTP status codes."""

    UNKNOWN_NODE = "unknown_node"
    UNKNOWN_EDGE = "unknown_edge"
    NO_POSITION = "no_position"
    NO_ROUTE = "no_route"
    DISCONTINUOUS = "discontinuous"


@dataclass(frozen=True, slots=True)
class RouteProblem:
    """A route that cannot be made, and why (a lowercase sentence naming the ids)."""

    kind: ProblemKind
    reason: str


@dataclass(frozen=True, slots=True)
class Route:
    """Edges to drive from ``start_node_id``; ``node_ids`` has one more entry than ``edge_ids``."""

    node_ids: tuple[str, ...]
    edge_ids: tuple[str, ...]
    length_m: float
    #: The vehicle stands at (x, y) on the first edge, off the first node: the order starts with
    #: a temporary node there (§6.6.3.1, :mod:`vda_master.start`).
    start_position: tuple[float, float] | None = None

    @property
    def destination(self) -> str:
        """The node the route ends at."""
        return self.node_ids[-1]


def shortest_route(graph: Graph, start: str, destination: str) -> Route | RouteProblem:
    """Dijkstra by edge length from ``start`` to ``destination``; ties go to file order."""
    for node_id in (start, destination):
        if node_id not in graph.nodes:
            return RouteProblem(ProblemKind.UNKNOWN_NODE, f"node {node_id!r} is not in the graph")
    return nearest_route(graph, start, (destination,))


def nearest_route(graph: Graph, start: str, destinations: Collection[str]) -> Route | RouteProblem:
    """The shortest route from ``start`` to the nearest of ``destinations`` (known nodes);
    Dijkstra by edge length, ties go to file order."""
    distance: dict[str, float] = {start: 0.0}
    via: dict[str, str] = {}
    queue: list[tuple[float, int, str]] = [(0.0, 0, start)]
    counter = 1
    while queue:
        cost, _, node_id = heapq.heappop(queue)
        if node_id in destinations:
            return _walk_back(graph, start, node_id, via, cost)
        if cost > distance[node_id]:
            continue
        for edge_id in graph.outgoing[node_id]:
            end = graph.edges[edge_id].end_node_id
            candidate = cost + graph.edge_length(edge_id)
            if candidate < distance.get(end, math.inf):
                distance[end], via[end] = candidate, edge_id
                heapq.heappush(queue, (candidate, counter, end))
                counter += 1
    where = " or ".join(repr(d) for d in destinations)
    return RouteProblem(ProblemKind.NO_ROUTE, f"no route leads from node {start!r} to node {where}")


def _walk_back(
    graph: Graph, start: str, destination: str, via: dict[str, str], length: float
) -> Route:
    edges: list[str] = []
    node_id = destination
    while node_id != start:
        edge_id = via[node_id]
        edges.append(edge_id)
        node_id = graph.edges[edge_id].start_node_id
    edges.reverse()
    return route_of(graph, start, edges, length)


def route_of(graph: Graph, start: str, edge_ids: list[str], length: float | None = None) -> Route:
    """A :class:`Route` over edges already known to be continuous from ``start``."""
    nodes = [start, *(graph.edges[edge_id].end_node_id for edge_id in edge_ids)]
    total = sum(graph.edge_length(e) for e in edge_ids) if length is None else length
    return Route(tuple(nodes), tuple(edge_ids), total)


def check_route(graph: Graph, start: str, edge_ids: list[str]) -> Route | RouteProblem:
    """Check an explicit edge sequence: known edges, leaving ``start``, each continuing the last."""
    if not edge_ids:
        return RouteProblem(ProblemKind.DISCONTINUOUS, "a route needs at least one edge")
    at = start
    for index, edge_id in enumerate(edge_ids):
        edge = graph.edges.get(edge_id)
        if edge is None:
            return RouteProblem(ProblemKind.UNKNOWN_EDGE, f"edge {edge_id!r} is not in the graph")
        if edge.start_node_id != at:
            where = "the vehicle stands at" if index == 0 else "the previous edge ends at"
            return RouteProblem(
                ProblemKind.DISCONTINUOUS,
                f"route is not continuous: edge {edge_id!r} starts at node "
                f"{edge.start_node_id!r} but {where} node {at!r}",
            )
        at = edge.end_node_id
    return route_of(graph, start, edge_ids)
