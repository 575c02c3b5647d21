"""Routing: shortest paths and explicit edge sequences (§6.6.1)."""

from __future__ import annotations

import math

from vda_master.graph import build_graph
from vda_master.routing import (
    ProblemKind,
    Route,
    RouteProblem,
    check_route,
    shortest_route,
)
from vda_master.testing import demo_graph, line_graph


def test_shortest_route_follows_the_reference_route() -> None:
    """From node 7 to node 10 the shortest path is edges 17, 12, 11."""
    route = shortest_route(demo_graph(), "7", "10")
    assert isinstance(route, Route)
    assert route.edge_ids == ("17", "12", "11")
    assert route.node_ids == ("7", "1", "2", "10")
    assert math.isclose(route.length_m, 15.0)


def test_shortest_route_prefers_shorter_total_length() -> None:
    """Dijkstra picks the path with the smaller summed edge length, not fewer edges."""
    nodes = [{"nodeId": n, "x": x, "y": 0.0} for n, x in (("a", 0), ("b", 2), ("c", 4))]
    edges = [
        {"edgeId": "direct", "startNodeId": "a", "endNodeId": "c", "length": 10.0},
        {"edgeId": "ab", "startNodeId": "a", "endNodeId": "b"},
        {"edgeId": "bc", "startNodeId": "b", "endNodeId": "c"},
    ]
    route = shortest_route(build_graph({"mapId": "m", "nodes": nodes, "edges": edges}), "a", "c")
    assert isinstance(route, Route)
    assert route.edge_ids == ("ab", "bc")
    assert math.isclose(route.length_m, 4.0)


def test_route_to_own_node_has_no_edges() -> None:
    """A destination equal to the start gives a one-node route."""
    route = shortest_route(demo_graph(), "7", "7")
    assert isinstance(route, Route)
    assert route.edge_ids == ()
    assert route.node_ids == ("7",)


def test_unknown_destination_is_a_problem() -> None:
    """A destination missing from the graph is reported as unknown_node."""
    problem = shortest_route(demo_graph(), "7", "999")
    assert problem == RouteProblem(ProblemKind.UNKNOWN_NODE, "node '999' is not in the graph")


def test_unreachable_destination_is_a_problem() -> None:
    """A destination no directed path reaches is reported as no_route."""
    graph = line_graph(3)
    one_way = type(graph)(
        graph.map_id,
        graph.nodes,
        graph.edges,
        {**graph.outgoing, "n1": ("r0",)},
        graph.source,
    )
    problem = shortest_route(one_way, "n0", "n2")
    assert isinstance(problem, RouteProblem)
    assert problem.kind == ProblemKind.NO_ROUTE


def test_explicit_route_is_accepted_when_continuous() -> None:
    """An explicit edge sequence starting at the vehicle's node becomes a route."""
    route = check_route(demo_graph(), "7", ["17", "12", "11"])
    assert isinstance(route, Route)
    assert route.node_ids == ("7", "1", "2", "10")


def test_explicit_route_must_start_at_vehicle() -> None:
    """An explicit route whose first edge leaves another node is discontinuous."""
    problem = check_route(demo_graph(), "4", ["17", "12"])
    assert isinstance(problem, RouteProblem)
    assert problem.kind == ProblemKind.DISCONTINUOUS
    assert "vehicle stands at node '4'" in problem.reason


def test_explicit_route_gap_is_named() -> None:
    """A gap between two edges is reported with the edge that does not continue."""
    problem = check_route(demo_graph(), "7", ["17", "11"])
    assert isinstance(problem, RouteProblem)
    assert "edge '11' starts at node '2'" in problem.reason


def test_explicit_route_unknown_edge() -> None:
    """An unknown edge id is reported as unknown_edge."""
    problem = check_route(demo_graph(), "7", ["17", "nope"])
    assert problem == RouteProblem(ProblemKind.UNKNOWN_EDGE, "edge 'nope' is not in the graph")


def test_explicit_route_must_not_be_empty() -> None:
    """An empty edge list is not a route."""
    problem = check_route(demo_graph(), "7", [])
    assert isinstance(problem, RouteProblem)
