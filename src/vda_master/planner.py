"""Route requests: the route for one vehicle, and the best vehicle for a destination (a node, or
any node of a ``stationType``).

Pure: the fleet view and the graph go in, a route (or the reason there is none) comes out.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable
from dataclasses import dataclass, replace

from vda5050.topics import AgvId
from vda_master.fleet import VehicleView
from vda_master.graph import Graph
from vda_master.routing import (
    ProblemKind,
    Route,
    RouteProblem,
    check_route,
    nearest_route,
    route_of,
    shortest_route,
)
from vda_master.start import StartPoint, find_start


@dataclass(frozen=True, slots=True)
class Target:
    """Where to go: a destination node, an explicit edge sequence, or any node whose
    ``stationType`` is ``station_type`` (exactly one is set)."""

    destination: str | None = None
    route: tuple[str, ...] | None = None
    station_type: str | None = None

    def __post_init__(self) -> None:
        problem = target_problem(self.destination, self.route, self.station_type)
        if problem is not None:
            raise ValueError(problem)

    def nodes(self, graph: Graph) -> tuple[str, ...]:
        """The nodes that would do as the destination (none for an explicit route)."""
        if self.station_type is not None:
            return graph.station_nodes(self.station_type)
        return () if self.destination is None else (self.destination,)

    def describe(self) -> str:
        """The target in words, for refusals."""
        if self.station_type is not None:
            return f"a node of stationType {self.station_type!r}"
        return self.destination or f"route {list(self.route or ())}"


def target_problem(destination: object, route: object, station_type: object) -> str | None:
    """Why these do not make a target (exactly one must be given), or None."""
    if sum(t is not None for t in (destination, route, station_type)) != 1:
        return "give exactly one of destination, route and stationType"
    return None


#: Plans a route from a node to a destination node (the time-aware planner, when traffic
#: control is on); None means "no better idea", and the shortest route is used.
Router = Callable[[AgvId, str, str], Route | None]
#: Picks, among (vehicle, node it leaves from) and destination nodes, the vehicle to send and its
#: route from that node to one of them; None means "no better idea", and the shortest route
#: decides.
Chooser = Callable[[list[tuple[AgvId, str]], tuple[str, ...]], tuple[AgvId, Route] | None]


def route_for(
    graph: Graph, vehicle: VehicleView, target: Target, router: Router | None = None
) -> Route | RouteProblem:
    """The route ``vehicle`` would drive to reach ``target`` from where it stands (§6.6.1).

    A vehicle standing off its last node (stopped on an edge) continues along that edge from a
    temporary first node where it stands (:mod:`vda_master.start`). ``router`` plans the part
    to a destination (default: the shortest route); a station type goes to the nearest node of
    that type (:func:`choose_vehicle` also counts traffic and busy stations).
    """
    if target.destination is not None and target.destination not in graph.nodes:
        return RouteProblem(
            ProblemKind.UNKNOWN_NODE, f"node {target.destination!r} is not in the graph"
        )
    start = find_start(graph, vehicle.state)
    if isinstance(start, str):
        return RouteProblem(ProblemKind.NO_POSITION, f"vehicle {vehicle.agv}: {start}")
    if target.route is not None:
        return _with_start(start, _explicit_route(graph, start, list(target.route)))
    leaves = departure_node(graph, start)
    if target.destination is None:  # a station type: its nearest node
        onward = nearest_route(graph, leaves, target.nodes(graph))
    else:
        planned = router(vehicle.agv, leaves, target.destination) if router else None
        onward = planned or shortest_route(graph, leaves, target.destination)
    return _with_start(start, _joined(graph, start, onward))


def departure_node(graph: Graph, start: StartPoint) -> str:
    """The node a route to a destination is planned from: the start node, or the end of the
    edge the vehicle stands on."""
    via = start.via_edge
    return start.node_id if via is None else graph.edges[via].end_node_id


def _joined(graph: Graph, start: StartPoint, onward: Route | RouteProblem) -> Route | RouteProblem:
    """``onward`` (from the departure node), preceded by the edge the vehicle stands on."""
    if isinstance(onward, RouteProblem) or start.via_edge is None:
        return onward
    return route_of(graph, start.node_id, [start.via_edge, *onward.edge_ids])


def _with_start(start: StartPoint, route: Route | RouteProblem) -> Route | RouteProblem:
    if isinstance(route, RouteProblem) or start.position is None:
        return route
    return replace(route, start_position=start.position)


def _explicit_route(graph: Graph, start: StartPoint, edges: list[str]) -> Route | RouteProblem:
    via = start.via_edge
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


def choose_vehicle(
    graph: Graph,
    candidates: Iterable[VehicleView],
    target: Target,
    chooser: Chooser | None = None,
    *,
    busy: Collection[str] = frozenset(),
) -> tuple[VehicleView, Route] | None:
    """The candidate expected at ``target`` first (``chooser``, counting traffic, which also
    picks the station of a type) or, without one or for an explicit route, the one with the
    shortest route; ties to the first. Without ``chooser``, a station of the type that is not
    ``busy`` (bound for or held by another vehicle) is preferred to a nearer busy one."""
    vehicles = list(candidates)
    destinations = target.nodes(graph)
    if chooser is not None and destinations:
        starts = {v.agv: find_start(graph, v.state) for v in vehicles}
        options = [
            (agv, departure_node(graph, start))
            for agv, start in starts.items()
            if not isinstance(start, str)
        ]
        chosen = chooser(options, destinations) if options else None
        if chosen is not None:
            agv, onward = chosen
            start = starts[agv]
            assert not isinstance(start, str)  # noqa: S101 - only started vehicles are options
            route = _with_start(start, _joined(graph, start, onward))
            vehicle = next(v for v in vehicles if v.agv == agv)
            if isinstance(route, Route):
                return vehicle, route
    free = tuple(d for d in destinations if d not in busy) or destinations
    best: tuple[float, VehicleView, Route] | None = None
    for vehicle in vehicles:
        route = _nearest(graph, vehicle, free) if free else route_for(graph, vehicle, target)
        if isinstance(route, Route) and (best is None or route.length_m < best[0]):
            best = (route.length_m, vehicle, route)
    return None if best is None else (best[1], best[2])


def _nearest(
    graph: Graph, vehicle: VehicleView, destinations: tuple[str, ...]
) -> Route | RouteProblem:
    """The shortest route from where ``vehicle`` stands to the nearest of ``destinations``."""
    start = find_start(graph, vehicle.state)
    if isinstance(start, str):
        return RouteProblem(ProblemKind.NO_POSITION, f"vehicle {vehicle.agv}: {start}")
    onward = nearest_route(graph, departure_node(graph, start), destinations)
    return _with_start(start, _joined(graph, start, onward))
