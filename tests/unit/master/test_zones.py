"""Zones of the graph file: BLOCKED areas and SPEED_LIMITs that master control honours for
every vehicle by what it routes and sends (docs/master.md, Zones; zone types of VDA 5050 3.0
§6.4.1)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import pytest

from vda5050.clock import FakeClock
from vda5050.topics import AgvId
from vda_master.api_documents import zones_document
from vda_master.config import MasterConfig
from vda_master.graph import Graph, GraphError, build_graph
from vda_master.planner import Target
from vda_master.requests import OrderRequest, RequestError
from vda_master.service import MasterService
from vda_master.testing import (
    DEMO_GRAPH,
    RecordingPublisher,
    demo_graph_with_zones,
    report_online,
    zone,
)

AGV = AgvId("acme", "robot_0")
#: Around node 10 (15, 0) of aisle A: the aisle's middle east part is closed.
AROUND_10 = [[13.0, -1.5], [17.0, -1.5], [17.0, 1.5], [13.0, 1.5]]
#: Aisle B's west half (nodes 4 at (0, 8) and 5 at (5, 8)) at walking pace.
AISLE_B_WEST = [[-1.0, 7.0], [6.0, 7.0], [6.0, 9.0], [-1.0, 9.0]]


def _demo(*zones: Mapping[str, object]) -> Graph:
    return demo_graph_with_zones(*zones)


def _edge(graph: Graph, start: str, end: str) -> str:
    every = {**graph.edges, **{k: c.edge for k, c in graph.blocked_edges.items()}}
    return next(
        e.edge_id for e in every.values() if (e.start_node_id, e.end_node_id) == (start, end)
    )


def _file_speeds() -> dict[str, float | None]:
    """Each edge's own maxSpeed in the demo graph file."""
    raw = json.loads(DEMO_GRAPH.read_text())
    return {e["edgeId"]: e.get("maxSpeed") for e in raw["edges"]}


ZONED = (
    zone("maintenance", "BLOCKED", AROUND_10, description="aisle A east, closed"),
    zone("slow", "SPEED_LIMIT", AISLE_B_WEST, maximumSpeed=0.4),
)


def test_a_blocked_zone_closes_the_edges_into_and_through_it_but_not_out() -> None:
    """Every edge that touches the zone and does not leave it is closed; one that leaves it
    (its start inside) stays, so a vehicle found inside can drive out; the node inside is
    listed, no longer a station, and no edge leads to it."""
    graph = _demo(*ZONED)
    closed = {(c.edge.start_node_id, c.edge.end_node_id) for c in graph.blocked_edges.values()}
    assert closed == {("2", "10"), ("3", "10"), ("12", "10")}
    assert {(e.start_node_id, e.end_node_id) for e in graph.edges.values()} >= {
        ("10", "2"),
        ("10", "3"),
        ("10", "12"),
    }
    assert all(e.end_node_id != "10" for e in graph.edges.values())
    assert dict(graph.blocked_nodes) == {"10": "maintenance"}
    assert {c.zone_id for c in graph.blocked_edges.values()} == {"maintenance"}


def test_a_margin_keeps_the_vehicles_bodies_out_not_only_their_reference_points() -> None:
    """zone_margin_m: a BLOCKED zone drawn 0.5 m short of node 10 and the aisle through it
    closes nothing without a margin; with 0.72 m (half the simulated vehicle's diagonal), the
    master service closes the edges into node 10, which counts as inside."""
    short = zone("spill", "BLOCKED", [[14.0, 0.5], [16.0, 0.5], [16.0, 2.0], [14.0, 2.0]])
    graph = _demo(short)
    assert graph.blocked_edges == {}
    service = MasterService(
        MasterConfig.model_validate({"zone_margin_m": 0.72}),
        graph,
        RecordingPublisher(),
        FakeClock(),
    )
    closed = {
        (c.edge.start_node_id, c.edge.end_node_id) for c in service.graph.blocked_edges.values()
    }
    assert closed == {("2", "10"), ("3", "10"), ("12", "10")}
    assert dict(service.graph.blocked_nodes) == {"10": "spill"}
    report_online(service, AGV, "7")
    with pytest.raises(RequestError, match="node '10' lies in BLOCKED zone 'spill'"):
        service.create_order(OrderRequest(Target(destination="10"), AGV))


def test_a_speed_limit_slows_every_edge_that_touches_it_and_never_speeds_one_up() -> None:
    """SPEED_LIMIT: maxSpeed becomes the zone's maximumSpeed on every edge touching the zone;
    an edge the file already limits lower keeps its own; overlapping zones take the lowest."""
    graph = _demo(*ZONED)
    for start, end in (("19", "4"), ("4", "5"), ("5", "6"), ("5", "13"), ("16", "4")):
        assert graph.edges[_edge(graph, start, end)].max_speed == 0.4, (start, end)
        assert graph.limited_edges[_edge(graph, start, end)] == "slow"
    assert graph.edges[_edge(graph, "6", "8")].max_speed == _file_speeds()[_edge(graph, "6", "8")]

    raw = json.loads(DEMO_GRAPH.read_text())
    slow_edge = _edge(graph, "4", "5")
    for edge in raw["edges"]:
        if edge["edgeId"] == slow_edge:
            edge["maxSpeed"] = 0.3
    tighter = zone("slower", "SPEED_LIMIT", [[4.0, 7.5], [7.0, 7.5], [7.0, 8.5]], maximumSpeed=0.35)
    zoned = build_graph({**raw, "zones": [*ZONED, tighter]})
    assert zoned.edges[slow_edge].max_speed == 0.3
    assert slow_edge not in zoned.limited_edges
    assert zoned.edges[_edge(zoned, "5", "6")].max_speed == 0.35
    assert zoned.limited_edges[_edge(zoned, "5", "6")] == "slower"


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        (zone("z", "SPEED_LIMIT", AROUND_10), "zone 'z': a SPEED_LIMIT zone needs maximumSpeed"),
        (
            zone("z", "BLOCKED", AROUND_10, maximumSpeed=1.0),
            "zone 'z': maximumSpeed applies to SPEED_LIMIT only",
        ),
        (
            zone("z", "BLOCKED", AROUND_10, mapId="upstairs"),
            "zone 'z': no node lies on its map 'upstairs'",
        ),
        (zone("z", "BLOCKED", AROUND_10[:2]), "zone 'z'"),
        (
            zone("z", "BLOCKED", [[13.0, -1.5], [17.0, 1.5], [17.0, -1.5], [13.0, 1.5]]),
            "zone 'z': its sides 1 and 3 cross; a zone is a simple polygon",
        ),
        (zone("z", "PRIORITY", AROUND_10), "PRIORITY"),
    ],
)
def test_a_zone_that_cannot_be_honoured_fails_the_load_naming_it(
    bad: dict[str, Any], message: str
) -> None:
    with pytest.raises(GraphError, match=message):
        _demo(bad)


def test_zone_ids_are_unique() -> None:
    with pytest.raises(GraphError, match="zone id 'z' is used 2 times"):
        _demo(zone("z", "BLOCKED", AROUND_10), zone("z", "BLOCKED", AISLE_B_WEST))


def _service(graph: Graph) -> tuple[MasterService, RecordingPublisher]:
    publisher, clock = RecordingPublisher(), FakeClock()
    service = MasterService(MasterConfig.model_validate({}), graph, publisher, clock)
    report_online(service, AGV, "7")
    return service, publisher


def test_orders_go_around_a_blocked_zone_and_keep_to_speed_limits() -> None:
    """From node 7 to node 3 the way along aisle A runs through the closed zone: the order
    goes round by the cross aisle instead. One into aisle B's slow part carries maxSpeed 0.4
    on the edges that touch it, the file's own elsewhere (the vehicle is told the limit,
    whatever its protocol version)."""
    service, _ = _service(_demo(*ZONED))
    track = service.create_order(OrderRequest(Target(destination="3"), AGV))
    nodes = [n.node_id for n in track.plan.nodes]
    assert (nodes[0], nodes[-1]) == ("7", "3")
    assert "10" not in nodes
    assert not {e.edge_id for e in track.plan.edges} & set(service.graph.blocked_edges)

    service, publisher = _service(_demo(*ZONED))
    service.create_order(OrderRequest(Target(destination="5"), AGV))
    speeds = {e["edgeId"]: e.get("maxSpeed") for e in publisher.orders()[-1]["edges"]}
    in_zone = [e for e in speeds if e in service.graph.limited_edges]
    assert in_zone
    assert all(speeds[e] == 0.4 for e in in_zone)
    own = _file_speeds()
    assert all(speeds[e] == own[e] for e in speeds if e not in in_zone)


def test_a_destination_or_route_in_a_blocked_zone_is_refused_saying_why() -> None:
    """409 naming the zone: the node lies in it, or an edge of the given route enters it; a
    station type whose every node lies in one; an edge that is not there at all stays 404."""
    service, _ = _service(_demo(*ZONED))
    with pytest.raises(RequestError) as inside:
        service.create_order(OrderRequest(Target(destination="10"), AGV))
    assert (inside.value.status, inside.value.message) == (
        409,
        "node '10' lies in BLOCKED zone 'maintenance'",
    )
    closed = _edge(service.graph, "2", "10")
    with pytest.raises(RequestError) as through:
        service.create_order(OrderRequest(Target(route=(closed,)), AGV))
    assert through.value.status == 409
    assert through.value.message == f"edge {closed!r} enters BLOCKED zone 'maintenance'"
    with pytest.raises(RequestError) as unknown:
        service.create_order(OrderRequest(Target(route=("no-such-edge",)), AGV))
    assert unknown.value.status == 404

    parked = _demo(
        zone("yard", "BLOCKED", [[19.0, -4.0], [21.0, -4.0], [21.0, -2.0]]),
        zone("yard2", "BLOCKED", [[19.0, 10.0], [21.0, 10.0], [21.0, 12.0]]),
    )
    service, _ = _service(parked)
    with pytest.raises(RequestError) as station:
        service.create_order(OrderRequest(Target(station_type="parking"), AGV))
    assert (station.value.status, station.value.message) == (
        409,
        "every node of stationType 'parking' lies in a BLOCKED zone",
    )


def test_the_zones_document_says_what_each_zone_does() -> None:
    """GET /zones: each zone as written, with its map, and the edges and nodes it affects."""
    graph = _demo(*ZONED)
    maintenance, slow = zones_document(graph)
    assert maintenance["zoneId"] == "maintenance"
    assert maintenance["mapId"] == "demo"
    assert maintenance["vertices"] == AROUND_10
    assert maintenance["nodesInside"] == ["10"]
    assert maintenance["closedEdges"] == sorted(graph.blocked_edges)
    assert maintenance["description"] == "aisle A east, closed"
    assert slow["maximumSpeed"] == 0.4
    assert slow["limitedEdges"] == sorted(graph.limited_edges)
