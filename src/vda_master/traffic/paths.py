"""Static paths on the graph for traffic decisions: detours that avoid resources, nearest nodes.

:class:`RoadMap` is the graph prepared once per load for traffic work: adjacency with costs in
both directions and the nodes of each ``stationType``. The searches are Dijkstra by edge cost
(detours: A* towards the destination), stopped once they have their answer; ties go to file
order (nearest nodes: to the lowest id), so every answer is deterministic.

**Cost.** An edge's cost is its length, times ``one_lane_factor`` for a one-lane edge (its
opposite edge exists): a vehicle in a one-lane stretch excludes every other vehicle from the
whole stretch (the release gate grants it whole), so a route through an aisle costs the fleet
far more than its metres. Routes therefore keep to two-way corridors and enter one-lane
stretches where their start or destination lies, or where the way round is much longer. The
time-aware planner chooses routes by this cost too, but estimates times from plain lengths
(:class:`vda_master.traffic.passages.SpeedModel`), so the passages others plan around are not
stretched inside one-lane stretches.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Container, Hashable, Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Final, TypeVar

from vda5050.nurbs import polyline_length
from vda_master.graph import Graph
from vda_master.routing import Route, route_of
from vda_master.traffic.conflicts import Resource, edge, node

T = TypeVar("T")

#: (edge id, node at the other end, cost: its length, times the one-lane factor if one-lane)
Arc = tuple[str, str, float]

#: Cheapest routes remembered per road map (start, destination); beyond this many the memo
#: starts afresh (149 nodes give at most 22,201 pairs: the warehouse never reaches it).
ROUTE_MEMO_LIMIT: Final = 50_000


@dataclass(frozen=True, slots=True)
class RoadMap:
    """The graph with both adjacency lists, edge lengths and station nodes."""

    graph: Graph
    outgoing: Mapping[str, tuple[Arc, ...]]
    incoming: Mapping[str, tuple[Arc, ...]]
    length: Mapping[str, float]
    #: Edge id → what the searches count: its length, times the one-lane factor if one-lane.
    cost: Mapping[str, float]
    #: Edge id → its maxSpeed (m/s), for edges that have one.
    max_speed: Mapping[str, float]
    #: stationType → node ids with that type, in file order.
    stations: Mapping[str, tuple[str, ...]]
    #: Answers of the static searches that every plan repeats (:func:`to_destination`,
    #: :func:`cheapest_route`, the planner's ``steps_for``): see :meth:`remembered`.
    _memo: dict[object, object] = field(default_factory=dict, compare=False, repr=False)

    def station_nodes(self, station_type: str) -> tuple[str, ...]:
        """Nodes whose ``stationType`` is ``station_type`` (e.g. ``parking``)."""
        return self.stations.get(station_type, ())

    def remembered(self, key: Hashable, make: Callable[[], T]) -> T:
        """``make()``, worked out once per map and ``key`` (the map never changes); beyond
        :data:`ROUTE_MEMO_LIMIT` answers the memo starts afresh."""
        if key in self._memo:
            return self._memo[key]  # type: ignore[return-value]
        found = make()
        if len(self._memo) >= ROUTE_MEMO_LIMIT:
            self._memo.clear()
        self._memo[key] = found
        return found


def build_roadmap(
    graph: Graph, *, one_lane_factor: float = 1.0, speed_factor: float = 1.0
) -> RoadMap:
    """Index ``graph`` for traffic searches; one-lane edges cost ``one_lane_factor`` times
    their length (module docstring); edges' ``maxSpeed`` count ``speed_factor`` times over (a
    fleet simulated that many times faster than real time)."""
    if one_lane_factor < 1:
        msg = f"one_lane_factor must be at least 1, got {one_lane_factor}"
        raise ValueError(msg)
    outgoing: dict[str, list[Arc]] = {node_id: [] for node_id in graph.nodes}
    incoming: dict[str, list[Arc]] = {node_id: [] for node_id in graph.nodes}
    length: dict[str, float] = {}
    cost: dict[str, float] = {}
    max_speed: dict[str, float] = {}
    ends = {(e.start_node_id, e.end_node_id) for e in graph.edges.values()}
    for graph_edge in graph.edges.values():
        meters = graph.edge_length(graph_edge.edge_id)
        one_lane = (graph_edge.end_node_id, graph_edge.start_node_id) in ends
        weight = meters * one_lane_factor if one_lane else meters
        length[graph_edge.edge_id] = meters
        cost[graph_edge.edge_id] = weight
        if graph_edge.max_speed is not None:
            max_speed[graph_edge.edge_id] = graph_edge.max_speed * speed_factor
        outgoing[graph_edge.start_node_id].append(
            (graph_edge.edge_id, graph_edge.end_node_id, weight)
        )
        incoming[graph_edge.end_node_id].append(
            (graph_edge.edge_id, graph_edge.start_node_id, weight)
        )
    for closed in graph.blocked_edges.values():  # no search takes them; routes planned before
        closed_id = closed.edge.edge_id  # a zone closed them still have their times estimated
        length[closed_id] = cost[closed_id] = closed.edge.length or polyline_length(
            graph.edge_path(closed.edge)
        )
        if closed.edge.max_speed is not None:
            max_speed[closed_id] = closed.edge.max_speed * speed_factor
    stations: dict[str, list[str]] = {}
    for graph_node in graph.nodes.values():  # none inside a BLOCKED zone (parking, say)
        if graph_node.station_type is not None and graph_node.node_id not in graph.blocked_nodes:
            stations.setdefault(graph_node.station_type, []).append(graph_node.node_id)
    return RoadMap(
        graph,
        MappingProxyType({k: tuple(v) for k, v in outgoing.items()}),
        MappingProxyType({k: tuple(v) for k, v in incoming.items()}),
        MappingProxyType(length),
        MappingProxyType(cost),
        MappingProxyType(max_speed),
        MappingProxyType({k: tuple(v) for k, v in stations.items()}),
    )


def distances(
    roads: RoadMap,
    origin: str,
    *,
    reverse: bool = False,
    allowed: Callable[[str, str], bool] | None = None,
    metres: bool = False,
) -> tuple[dict[str, float], dict[str, str]]:
    """Dijkstra from ``origin``: the cost to every reachable node and the edge it was reached by.

    ``reverse`` searches against the edge direction (distances *to* ``origin``). ``allowed(edge
    id, next node id)`` may forbid steps. ``metres``: plain lengths instead of costs.
    """
    via: dict[str, str] = {}
    distance = dict(settle(roads, origin, reverse=reverse, allowed=allowed, metres=metres, via=via))
    return distance, via


def settle(
    roads: RoadMap,
    origin: str,
    *,
    reverse: bool = False,
    allowed: Callable[[str, str], bool] | None = None,
    metres: bool = False,
    via: dict[str, str] | None = None,
) -> Iterator[tuple[str, float]]:
    """Dijkstra from ``origin`` as it goes: each reachable node with its cost, cheapest first
    (equal costs in the order reached), so a search for the nearest node of some kind stops
    there instead of settling the whole map. ``via``, if given, receives the edge each node was
    reached by (final for every node yielded). Options as :func:`distances`."""
    arcs = roads.incoming if reverse else roads.outgoing
    lengths = roads.length
    distance: dict[str, float] = {origin: 0.0}
    tree: dict[str, str] = {} if via is None else via
    queue: list[tuple[float, int, str]] = [(0.0, 0, origin)]
    counter = 1
    while queue:
        cost, _, at = heapq.heappop(queue)
        if cost > distance[at]:
            continue
        yield at, cost
        for edge_id, other, weight in arcs[at]:
            if allowed is not None and not allowed(edge_id, other):
                continue
            candidate = cost + (lengths[edge_id] if metres else weight)
            if candidate < distance.get(other, math.inf):
                distance[other], tree[other] = candidate, edge_id
                heapq.heappush(queue, (candidate, counter, other))
                counter += 1


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


def to_destination(
    roads: RoadMap, destination: str, *, metres: bool = False
) -> Mapping[str, float]:
    """The cost (``metres``: length) from every node that can reach ``destination`` to it;
    remembered per destination (every time-aware plan needs it for its heuristic)."""
    return roads.remembered(
        ("to", destination, metres),
        lambda: MappingProxyType(distances(roads, destination, reverse=True, metres=metres)[0]),
    )


def nearest_first(
    roads: RoadMap,
    origin: str,
    *,
    allowed: Callable[[str, str], bool] | None = None,
    via: dict[str, str] | None = None,
) -> Iterator[str]:
    """Every node reachable from ``origin``, nearest (by cost) first, equally near ones by id,
    found as far as asked. ``allowed`` and ``via`` as :func:`settle` (``via`` leads to every
    node yielded: :func:`path_to`)."""
    band: list[str] = []  # the nodes settled at ``band_cost``
    band_cost = 0.0
    for reached, cost in settle(roads, origin, allowed=allowed, via=via):
        if cost > band_cost:
            yield from sorted(band)
            band.clear()
            band_cost = cost
        band.append(reached)
    yield from sorted(band)


def nearest(
    roads: RoadMap,
    origin: str,
    accept: Callable[[str], bool],
    *,
    allowed: Callable[[str, str], bool] | None = None,
    via: dict[str, str] | None = None,
) -> str | None:
    """The node nearest ``origin`` (:func:`nearest_first`) for which ``accept`` holds, or None;
    the search stops there."""
    return next(filter(accept, nearest_first(roads, origin, allowed=allowed, via=via)), None)


def cheapest_route(roads: RoadMap, start: str, destination: str) -> Route | None:
    """The route of least cost from ``start`` to ``destination`` (None if there is none);
    remembered per pair, up to :data:`ROUTE_MEMO_LIMIT` pairs."""
    return roads.remembered(
        ("route", start, destination), lambda: route_avoiding(roads, start, destination, ())
    )


def route_avoiding(
    roads: RoadMap, start: str, destination: str, avoid: Container[Resource]
) -> Route | None:
    """Cheapest route from ``start`` to ``destination`` using no resource in ``avoid`` (the
    start node excepted: the vehicle stands there); None if there is none.

    A* guided by the cost to go on the open map (:func:`to_destination`, remembered per
    destination: exact with nothing avoided, never too high with something avoided), so a detour
    search looks at the nodes along the cheapest ways instead of the whole map (on a 40 x 30
    grid, tens of nodes instead of 1,200). Of equally cheap ways, the deeper node is taken
    first, then the one reached first: deterministic."""
    if start == destination:
        return route_of(roads.graph, start, [])
    to_go = to_destination(roads, destination)
    if start not in to_go or node(destination) in avoid:  # e.g. a queue stands on it
        return None
    best: dict[str, float] = {start: 0.0}
    via: dict[str, str] = {}
    queue: list[tuple[float, float, int, str]] = [(to_go[start], 0.0, 0, start)]
    counter = 1
    while queue:
        _, minus_cost, _, at = heapq.heappop(queue)
        cost = -minus_cost
        if cost > best[at]:
            continue
        if at == destination:
            return path_to(roads, start, destination, via)
        for edge_id, other, weight in roads.outgoing[at]:
            rest = to_go.get(other)
            if rest is None or edge(edge_id) in avoid or node(other) in avoid:
                continue
            candidate = cost + weight
            if candidate < best.get(other, math.inf):
                best[other], via[other] = candidate, edge_id
                heapq.heappush(queue, (candidate + rest, -candidate, counter, other))
                counter += 1
    return None
