"""Route requests: the route for one vehicle, and the best vehicle for a destination.

Pure: the fleet view and the graph go in, a route (or the reason there is none) comes out.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, replace

from vda_master.fleet import VehicleView
from vda_master.graph import Graph
from vda_master.routing import (
    ProblemKind,
    Route,
    RouteProblem,
    check_route,
    route_of,
    shortest_route,
)
from vda_master.start import StartPoint, find_start


@dataclass(frozen=True, slots=True)
class Target:
    """Where to go: a destination node, or an explicit edge sequence (exactly one is set)."""

    destination: str | None = None
    route: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        if (self.destination is None) == (self.route is None):
            msg = "give exactly one of destination and route"
            raise ValueError(msg)


def route_for(graph: Graph, vehicle: VehicleView, target: Target) -> Route | RouteProblem:
    """The route ``vehicle`` would drive to reach ``target`` from where it stands (§6.6.1).

    A vehicle standing off its last node (stopped on an edge) continues along that edge from a
    temporary first node where it stands (:mod:`vda_master.start`).
    """
    if target.destination is not None and target.destination not in graph.nodes:
        return RouteProblem(
            ProblemKind.UNKNOWN_NODE, f"node {target.destination!r} is not in the graph"
        )
    start = find_start(graph, vehicle.state)
    if isinstance(start, str):
        return RouteProblem(ProblemKind.NO_POSITION, f"vehicle {vehicle.agv}: {start}")
    route = _route_from(graph, start, target)
    if isinstance(route, RouteProblem) or start.position is None:
        return route
    return replace(route, start_position=start.position)


def _route_from(graph: Graph, start: StartPoint, target: Target) -> Route | RouteProblem:
    via = start.via_edge
    if target.route is not None:
        edges = list(target.route)
        if via is not None and edges and edges[0] != via:
            if (
                edges[0] in graph.edges
                and graph.edges[edges[0]].start_node_id == graph.edges[via].end_node_id
            ):
                edges = [via, *edges]  # drive on to the end of the edge it stands on first
            else:
                end = graph.edges[via].end_node_id
                return RouteProblem(
                    ProblemKind.DISCONTINUOUS,
                    f"the vehicle stands on edge {via!r} between nodes {start.node_id!r} and "
                    f"{end!r}: a route must begin with edge {via!r} or at node {end!r}",
                )
        return check_route(graph, start.node_id, edges)
    assert target.destination is not None  # noqa: S101 - guaranteed by Target
    if via is None:
        return shortest_route(graph, start.node_id, target.destination)
    onward = shortest_route(graph, graph.edges[via].end_node_id, target.destination)
    if isinstance(onward, RouteProblem):
        return onward
    return route_of(graph, start.node_id, [via, *onward.edge_ids])


def choose_vehicle(
    graph: Graph, candidates: Iterable[VehicleView], target: Target
) -> tuple[VehicleView, Route] | None:
    """The candidate with the shortest route to ``target``; ties go to the first candidate."""
    best: tuple[float, VehicleView, Route] | None = None
    for vehicle in candidates:
        route = route_for(graph, vehicle, target)
        if isinstance(route, Route) and (best is None or route.length_m < best[0]):
            best = (route.length_m, vehicle, route)
    return None if best is None else (best[1], best[2])
