"""Route requests: the route for one vehicle, and the best vehicle for a destination.

Pure: the fleet view and the graph go in, a route (or the reason there is none) comes out.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from vda_master.fleet import VehicleView
from vda_master.graph import Graph
from vda_master.routing import (
    ProblemKind,
    Route,
    RouteProblem,
    check_route,
    find_start_node,
    shortest_route,
)


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
    """The route ``vehicle`` would drive to reach ``target`` from where it stands (§6.6.1)."""
    if target.destination is not None and target.destination not in graph.nodes:
        return RouteProblem(
            ProblemKind.UNKNOWN_NODE, f"node {target.destination!r} is not in the graph"
        )
    start = find_start_node(graph, vehicle.state)
    if start is None:
        return RouteProblem(
            ProblemKind.NO_POSITION,
            f"vehicle {vehicle.agv} stands on no graph node (lastNodeId unknown and its "
            "position matches no node)",
        )
    if target.route is not None:
        return check_route(graph, start, list(target.route))
    assert target.destination is not None  # noqa: S101 - guaranteed by Target
    return shortest_route(graph, start, target.destination)


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
