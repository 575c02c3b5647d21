"""Factories for traffic tests and benchmarks: small graphs, routes through named nodes."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from itertools import pairwise
from pathlib import Path

from vda5050.topics import AgvId
from vda_master.eta import Drive, graph_legs, leg_times, turn_s
from vda_master.graph import Graph, build_graph, load_graph
from vda_master.routing import Route, route_of

#: The warehouse shipped in ``config/graphs/warehouse.json`` (``scripts/make_warehouse_graph.py``).
WAREHOUSE_GRAPH = Path(__file__).resolve().parents[3] / "config" / "graphs" / "warehouse.json"
#: The safety distance for the simulated 1.2 m × 0.8 m vehicles with the default margin.
SIM_SAFETY_M = 1.69


def warehouse_graph() -> Graph:
    """The shipped warehouse graph."""
    return load_graph(WAREHOUSE_GRAPH)


def agv(serial: str) -> AgvId:
    """A test vehicle of manufacturer ``acme``."""
    return AgvId("acme", serial)


def make_graph(
    positions: Mapping[str, tuple[float, float]],
    *,
    one_way: Iterable[tuple[str, str]] = (),
    two_way: Iterable[tuple[str, str]] = (),
    map_of: Mapping[str, str] | None = None,
    station_types: Mapping[str, str] | None = None,
) -> Graph:
    """A graph with nodes at ``positions``; edge ids are ``<start>-<end>``."""
    nodes = []
    for node_id, (x, y) in positions.items():
        item: dict[str, object] = {"nodeId": node_id, "x": x, "y": y}
        if map_of and node_id in map_of:
            item["mapId"] = map_of[node_id]
        if station_types and node_id in station_types:
            item["stationType"] = station_types[node_id]
        nodes.append(item)
    pairs = list(one_way)
    for a, b in two_way:
        pairs += [(a, b), (b, a)]
    edges = [{"edgeId": f"{a}-{b}", "startNodeId": a, "endNodeId": b} for a, b in pairs]
    return build_graph({"mapId": "test", "nodes": nodes, "edges": edges}, source="test")


def route_through(graph: Graph, *node_ids: str) -> Route:
    """The route visiting ``node_ids`` in order along edges ``<a>-<b>``."""
    edges = [f"{a}-{b}" for a, b in pairwise(node_ids)]
    unknown = [e for e in edges if e not in graph.edges]
    if unknown:
        msg = f"no edge {unknown[0]!r} in the graph"
        raise ValueError(msg)
    return route_of(graph, node_ids[0], edges)


def free_flow_s(
    graph: Graph,
    route: Route,
    *,
    speed_mps: float,
    turn_radps: float,
    action_s: float,
    start_theta: float | None = None,
) -> float:
    """How long ``route`` takes a simulated vehicle alone (benchmarks' free-flow time): drive
    every edge at ``speed_mps``, turn to each edge's heading at ``turn_radps`` (from
    ``start_theta`` for the first edge, when known), then ``action_s`` at the destination."""
    drive = Drive(speed_mps, turn_radps)
    times = leg_times(graph, graph_legs(graph, route.edge_ids), drive)
    start = turn_s(start_theta, times.heading_in[0], drive) if times.heading_in else 0.0
    return times.to_node[-1] + start + action_s


def bypass_graph() -> Graph:
    """A one-lane stretch l - m1 - m2 - r with spurs sl and sr at its ends and a bypass
    m2 - z - l: two vehicles meeting head-on between m1 and m2 can part by backing off into a
    spur or by one of them taking the bypass."""
    return make_graph(
        {"l": (0, 0), "m1": (4, 0), "m2": (8, 0), "r": (12, 0), "z": (4, 4),
         "sl": (0, -3), "sr": (12, -3)},
        two_way=[("l", "m1"), ("m1", "m2"), ("m2", "r"), ("m2", "z"), ("z", "l"),
                 ("l", "sl"), ("r", "sr")],
    )  # fmt: skip
