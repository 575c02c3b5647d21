"""Zones added and lifted at random while an order runs (docs/master.md, Zones; property-based):
master control never fails on a zone, refuses with 409/422 what it cannot take and then changes
nothing, routes nothing over a closed edge, never changes the released base (R66), and lifting
the zone gives the floor back as it was."""

from __future__ import annotations

import asyncio
import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.graph_file import GraphZone
from vda5050.polygons import inside, touches
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.config import MasterConfig
from vda_master.planner import Target
from vda_master.requests import OrderRequest, RequestError
from vda_master.routing import RouteProblem, shortest_route
from vda_master.service import MasterService
from vda_master.testing import (
    RecordingPublisher,
    demo_graph,
    plan_state,
    report_online,
)

AGV = AgvId("acme", "robot_0")
GRAPH = demo_graph()

corner = st.tuples(
    st.floats(min_value=-6.0, max_value=22.0, allow_nan=False),
    st.floats(min_value=-5.0, max_value=13.0, allow_nan=False),
)


@st.composite
def star(draw: st.DrawFn) -> list[tuple[float, float]]:
    """A simple polygon: corners at increasing angles round a centre on the floor."""
    cx, cy = draw(corner)
    count = draw(st.integers(min_value=3, max_value=6))
    radii = draw(st.lists(st.floats(min_value=0.3, max_value=6.0), min_size=count, max_size=count))
    step = 2 * math.pi / count
    return [(cx + r * math.cos(i * step), cy + r * math.sin(i * step)) for i, r in enumerate(radii)]


zones = st.builds(
    lambda kind, corners, speed: {
        "zoneId": "z",
        "zoneType": kind,
        "vertices": [{"x": x, "y": y} for x, y in corners],
        **({"maximumSpeed": speed} if kind == "SPEED_LIMIT" else {}),
    },
    st.sampled_from(["BLOCKED", "BLOCKED", "SPEED_LIMIT"]),
    star() | st.lists(corner, min_size=3, max_size=6),  # the second mostly not simple
    st.floats(min_value=0.1, max_value=2.0),
)


def _driving(traffic_control: bool, passed: int) -> tuple[MasterService, str]:
    """robot_0 sent from node 7 to node 9 (7 1 2 20 6 8 9, release window 2), its first update
    confirmed, reporting node ``passed`` of the route as its last."""
    config = MasterConfig.model_validate(
        {"traffic_control": traffic_control, "release_window_nodes": 2}
    )
    service = MasterService(config, GRAPH, RecordingPublisher(), FakeClock())
    report_online(service, AGV, "7")
    order_id = service.create_order(OrderRequest(Target(destination="9"), AGV)).order_id
    _confirm(service, order_id, passed)
    return service, order_id


def _confirm(service: MasterService, order_id: str, passed: int) -> None:
    """robot_0 confirms the order's latest update, at node ``passed`` of it."""
    track = service.tracks[order_id]
    state = plan_state(
        track.plan, update_id=track.update_id, passed=passed, released_end=track.released_end
    )
    service.ingest(build_topic("uagv", 2, AGV, Topic.STATE), encode(state))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    raw=zones,
    traffic_control=st.booleans(),
    passed=st.integers(min_value=0, max_value=1),
)
def test_any_zone_added_and_lifted_while_an_order_runs(
    raw: dict[str, object], traffic_control: bool, passed: int
) -> None:
    service, order_id = _driving(traffic_control, passed)
    before = service.tracks[order_id]
    base = [n.node_id for n in before.plan.nodes[: before.released_end + 1]]
    zone = GraphZone.model_validate(raw)
    refused = _added(service, zone)
    if refused is not None:
        assert refused in (409, 422)
        assert service.graph.zones == ()
        assert service.tracks[order_id] == before
        return
    _confirm(service, order_id, passed)  # an update in flight: the order is looked at now
    graph = service.graph
    for closed in graph.blocked_edges.values():  # closed: touches, and does not lead out
        start, end = graph.nodes[closed.edge.start_node_id], graph.nodes[closed.edge.end_node_id]
        assert touches(zone.vertices, (start.x, start.y), (end.x, end.y))
        assert not (
            inside(zone.vertices, (start.x, start.y)) and not inside(zone.vertices, (end.x, end.y))
        )
    track = service.tracks[order_id]
    assert [n.node_id for n in track.plan.nodes[: len(base)]] == base  # R66
    route = track.plan.route
    assert route is not None
    unreleased = route.edge_ids[track.released_end :]
    if track.cancel_action_id is None:  # going on: never over a closed edge
        assert not set(unreleased) & set(graph.blocked_edges)
    else:
        assert "BLOCKED zone 'z'" in track.cancel_reason
    for a, b in (("7", "9"), ("16", "18"), ("11", "14")):
        found = shortest_route(graph, a, b)
        if not isinstance(found, RouteProblem):
            assert not set(found.edge_ids) & set(graph.blocked_edges)

    asyncio.run(service.remove_zone("z"))
    assert service.graph.edges == GRAPH.edges
    assert service.graph.blocked_edges == {}


def _added(service: MasterService, zone: GraphZone) -> int | None:
    """Put ``zone`` in force; the refusal's HTTP status, or None."""
    try:
        asyncio.run(service.add_zone(zone))
    except RequestError as refused:
        return refused.status
    return None
