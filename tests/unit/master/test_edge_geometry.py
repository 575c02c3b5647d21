"""Edges driven along a trajectory, and the other driving fields of the graph (§6.6.5, §6.6.6).

The graph: a quarter circle of radius 5 m from ``a`` (5, 0) to ``b`` (0, 5) round the origin
(a rational degree 2 NURBS), a straight way back, and a straight spur from ``b`` to ``c``.
"""

from __future__ import annotations

import json
import math
from typing import Any

import pytest

from vda5050.models import Factsheet, OrientationType
from vda5050.nurbs import polyline_length
from vda5050.topics import AgvId
from vda5050.validation import check_order
from vda_master import capabilities as caps
from vda_master.graph import Graph, GraphError, build_graph
from vda_master.order_builder import (
    BuildProblem,
    OrderPlan,
    PlanRequest,
    build_message,
    plan_order,
)
from vda_master.routing import Route, check_route
from vda_master.testing import id_source, make_factsheet, quarter_circle
from vda_master.traffic.conflicts import build_conflicts, edge, node
from vda_master.web.payloads import graph_payload
from vda_master.wire3 import order_to_v3

AGV = AgvId("acme", "r1")
RADIUS = 5.0
ARC = quarter_circle(RADIUS)


def _raw(**arc_edge: Any) -> dict[str, Any]:
    return {
        "mapId": "hall",
        "nodes": [
            {"nodeId": "a", "x": RADIUS, "y": 0.0},
            {"nodeId": "b", "x": 0.0, "y": RADIUS},
            {"nodeId": "c", "x": -4.0, "y": RADIUS},
            {"nodeId": "m", "x": 3.2, "y": 3.2},
        ],
        "edges": [
            {"edgeId": "ab", "startNodeId": "a", "endNodeId": "b", "trajectory": ARC, **arc_edge},
            {"edgeId": "ba", "startNodeId": "b", "endNodeId": "a"},
            {"edgeId": "bc", "startNodeId": "b", "endNodeId": "c"},
            {"edgeId": "cb", "startNodeId": "c", "endNodeId": "b"},
            {"edgeId": "mb", "startNodeId": "m", "endNodeId": "b"},
            {"edgeId": "bm", "startNodeId": "b", "endNodeId": "m"},
        ],
    }


def _graph(**arc_edge: Any) -> Graph:
    return build_graph(_raw(**arc_edge))


def _plan(
    graph: Graph,
    edges: list[str],
    factsheet: Factsheet | None,
    *,
    start_position: tuple[float, float] | None = None,
) -> OrderPlan | BuildProblem:
    route = check_route(graph, graph.edges[edges[0]].start_node_id, edges)
    assert isinstance(route, Route)
    if start_position is not None:
        route = Route(route.node_ids, route.edge_ids, route.length_m, start_position)
    return plan_order(
        graph,
        PlanRequest(route, "o1", {}, {}),
        agv=AGV,
        version="2.1.0",
        factsheet=factsheet,
        action_ids=id_source(),
    )


def _edges(plan: OrderPlan | BuildProblem) -> list[Any]:
    assert isinstance(plan, OrderPlan), plan
    order = build_message(plan, first=0, release_end=plan.last_index, update_id=0, max_nodes=None)
    assert check_order(order) == [], "the order breaks a VDA 5050 rule"
    return list(order.edges)


def test_a_curved_edge_is_as_long_as_its_arc_and_runs_from_node_to_node() -> None:
    graph = _graph()
    assert graph.edge_length("ab") == pytest.approx(math.pi * RADIUS / 2, rel=1e-3)
    path = graph.edge_path(graph.edges["ab"])
    assert path[0] == (RADIUS, 0.0)
    assert path[-1] == (0.0, RADIUS)
    assert all(math.hypot(x, y) == pytest.approx(RADIUS, abs=1e-9) for x, y in path)
    assert graph.edge_length("ba") == pytest.approx(RADIUS * math.sqrt(2))


@pytest.mark.parametrize(
    ("trajectory", "expected"),
    [
        ({**ARC, "knotVector": [0, 0, 1, 1]}, "edge 'ab': trajectory: knotVector has 4 knots"),
        ({**ARC, "knotVector": [0, 0, 0.5, 0.2, 1, 1]}, "knotVector must not decrease"),
        ({**ARC, "degree": 3}, "a degree 3 curve needs at least 4 control points"),
        (
            {**ARC, "controlPoints": [{"x": 7, "y": 0}, *ARC["controlPoints"][1:]]},
            "edge 'ab': trajectory starts at (7.000, 0.000), 2.00 m from node 'a'",
        ),
    ],
)
def test_a_trajectory_that_is_no_nurbs_from_node_to_node_is_refused_naming_the_edge(
    trajectory: dict[str, Any], expected: str
) -> None:
    raw = _raw()
    raw["edges"][0]["trajectory"] = trajectory
    with pytest.raises(GraphError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        build_graph(raw, source="hall.json")


def test_a_trajectory_ends_within_the_nodes_own_deviation_when_that_is_smaller() -> None:
    """A vehicle holds the curve to the node's allowedDeviationXY: 3 cm off passes the 5 cm
    default but not a node that allows 1 cm."""
    raw = _raw()
    off = {"x": RADIUS + 0.03, "y": 0.0}
    raw["edges"][0]["trajectory"] = {**ARC, "controlPoints": [off, *ARC["controlPoints"][1:]]}
    assert build_graph(raw).edge_length("ab") > 0
    raw["nodes"][0]["allowedDeviationXY"] = 0.01
    with pytest.raises(
        GraphError, match=r"edge 'ab': trajectory starts at .* 0.03 m from node 'a'"
    ):
        build_graph(raw)


def test_the_schema_refuses_a_weight_of_zero_naming_the_edge() -> None:
    raw = _raw()
    raw["edges"][0]["trajectory"] = {
        **ARC,
        "controlPoints": [{"x": RADIUS, "y": 0, "weight": 0}, *ARC["controlPoints"][1:]],
    }
    with pytest.raises(GraphError, match="edge 'ab'"):
        build_graph(raw, source="hall.json")


def test_3_0_defaults_a_graph_may_leave_out_are_written_out_in_the_order() -> None:
    """No degree and no knotVector: degree 1 and the clamped uniform knots, as 2.x needs."""
    raw = _raw()
    raw["edges"][0]["trajectory"] = {
        "controlPoints": [{"x": RADIUS, "y": 0}, {"x": 3, "y": 3}, {"x": 0, "y": RADIUS}]
    }
    graph = build_graph(raw)
    (sent,) = _edges(_plan(graph, ["ab"], make_factsheet()))
    assert sent.trajectory.degree == 1
    assert sent.trajectory.knot_vector == [0, 0, 0.5, 1, 1]
    assert sent.length == pytest.approx(2 * math.hypot(3 - RADIUS, 3))


def test_a_vehicle_that_lists_trajectories_and_corridors_gets_them_with_the_driving_fields() -> (
    None
):
    """R112: every §6.6.6 field the factsheet lists goes out as the graph gives it."""
    graph = _graph(
        corridor={"leftWidth": 0.5, "rightWidth": 0.25, "corridorRefPoint": "CONTOUR"},
        orientation=math.pi,
        orientationType="TANGENTIAL",
        rotationAllowed=False,
        maxRotationSpeed=0.5,
        direction="left",
        maxHeight=2.2,
        minHeight=0.1,
    )
    (sent,) = _edges(_plan(graph, ["ab"], make_factsheet()))
    assert sent.trajectory.degree == 2
    assert [(p.x, p.y) for p in sent.trajectory.control_points] == [(5, 0), (5, 5), (0, 5)]
    assert sent.trajectory.control_points[1].weight == pytest.approx(math.sqrt(2) / 2)
    assert sent.corridor.left_width == 0.5
    assert sent.corridor.corridor_ref_point == "CONTOUR"
    assert sent.orientation == math.pi
    assert sent.orientation_type is OrientationType.TANGENTIAL
    assert sent.rotation_allowed is False
    assert (sent.max_rotation_speed, sent.direction) == (0.5, "left")
    assert (sent.max_height, sent.min_height) == (2.2, 0.1)
    assert sent.length == pytest.approx(math.pi * RADIUS / 2, rel=1e-3)


def test_without_a_factsheet_no_trajectory_nor_corridor_goes_out_but_the_orientation_does() -> None:
    """§6.6.6: a vehicle that cannot process trajectories must not be sent one."""
    graph = _graph(corridor={"leftWidth": 0.5, "rightWidth": 0.5}, orientation=math.pi)
    (sent,) = _edges(_plan(graph, ["ab"], None))
    assert sent.trajectory is None
    assert sent.corridor is None
    assert sent.orientation == math.pi


def test_a_factsheet_narrows_the_driving_fields_to_what_it_lists() -> None:
    """R112: a field the factsheet does not list is not sent."""
    graph = _graph(orientation=math.pi, direction="left")
    listed = [caps.EDGE_LENGTH, caps.EDGE_ORIENTATION, caps.NODE_POSITION]
    (sent,) = _edges(_plan(graph, ["ab"], make_factsheet(supported=listed)))
    assert sent.orientation == math.pi
    assert (sent.trajectory, sent.direction) == (None, None)


def test_a_vehicle_that_requires_trajectories_gets_straight_edges_as_degree_1_lines() -> None:
    """R113: a REQUIRED trajectory is filled in for an edge the graph draws straight."""
    factsheet = make_factsheet(required=[caps.EDGE_TRAJECTORY])
    ab, bc = _edges(_plan(_graph(), ["ab", "bc"], factsheet))
    assert ab.trajectory.degree == 2
    assert bc.trajectory.degree == 1
    assert bc.trajectory.knot_vector == [0, 0, 1, 1]
    assert [(p.x, p.y) for p in bc.trajectory.control_points] == [(0, RADIUS), (-4, RADIUS)]


def test_a_vehicle_that_requires_a_direction_the_graph_lacks_cannot_take_the_order() -> None:
    """R113: a REQUIRED field with no value and no sensible default refuses the order."""
    problem = _plan(_graph(), ["ab"], make_factsheet(required=[caps.EDGE_DIRECTION]))
    assert isinstance(problem, BuildProblem)
    assert "order.edges.direction" in problem.reason


def test_a_trajectory_over_the_vehicles_control_point_limit_is_a_problem() -> None:
    """R114: maxArrayLens trajectory.controlPoints."""
    factsheet = make_factsheet(array_lens={"trajectory.controlPoints": 2})
    problem = _plan(_graph(), ["ab"], factsheet)
    assert isinstance(problem, BuildProblem)
    assert "trajectory.controlPoints holds 3 entries, over the vehicle's limit of 2" in (
        problem.reason
    )


def test_a_vehicle_standing_on_the_curve_is_sent_the_rest_of_it() -> None:
    """§6.6.3.1: the temporary start node's edge follows the arc from where the vehicle is."""
    here = (RADIUS * math.cos(math.pi / 4), RADIUS * math.sin(math.pi / 4))
    (sent,) = _edges(_plan(_graph(), ["ab"], make_factsheet(), start_position=here))
    points = [(p.x, p.y) for p in sent.trajectory.control_points]
    assert sent.trajectory.degree == 1
    assert points[0] == here
    assert points[-1] == (0.0, RADIUS)
    assert all(math.hypot(x, y) == pytest.approx(RADIUS, abs=1e-9) for x, y in points)
    assert sent.length == pytest.approx(math.pi * RADIUS / 4, rel=1e-2)
    assert sent.length == pytest.approx(polyline_length(points))


def test_a_3_0_robot_gets_the_trajectory_the_corridor_and_the_orientation_rule() -> None:
    graph = _graph(corridor={"leftWidth": 0.5, "rightWidth": 0.5}, rotationAllowed=False)
    plan = _plan(graph, ["ab"], make_factsheet())
    assert isinstance(plan, OrderPlan)
    order = build_message(plan, first=0, release_end=plan.last_index, update_id=0, max_nodes=None)
    wire = json.loads(order_to_v3(order).model_dump_json(by_alias=True, exclude_none=True))
    (sent,) = wire["edges"]
    assert sent["trajectory"]["knotVector"] == [0, 0, 0, 1, 1, 1]
    assert sent["corridor"] == {
        "leftWidth": 0.5,
        "rightWidth": 0.5,
    }
    assert sent["reachOrientationBeforeEntering"] is True
    assert "rotationAllowed" not in sent


def test_traffic_control_takes_the_curve_and_the_corridor_for_the_edges_shape() -> None:
    """Node m (3.2, 3.2) is 0.48 m from the arc (radius 4.53 m from the origin) but 0.92 m
    from its chord; a 0.6 m corridor widens the arc's reach."""
    straight = build_graph(
        {**_raw(), "edges": [{**e, "trajectory": None} for e in _raw()["edges"]]}
    )
    assert node("m") not in build_conflicts(straight, 0.75)[edge("ab")]
    curved = build_conflicts(_graph(), 0.75)
    assert node("m") in curved[edge("ab")]
    assert node("c") not in build_conflicts(_graph(), 1.0)[edge("ab")]
    widened = build_conflicts(_graph(corridor={"leftWidth": 0.0, "rightWidth": 3.5}), 1.0)
    assert node("c") in widened[edge("ab")]


def test_a_blocked_zone_on_the_curves_bulge_closes_the_edge() -> None:
    """The zone covers the arc's middle only, far from the chord."""
    zone = {
        "zoneId": "spill",
        "zoneType": "BLOCKED",
        "vertices": [{"x": 3.3, "y": 3.3}, {"x": 4.5, "y": 3.3}, {"x": 4.5, "y": 4.5}],
    }
    graph = build_graph({**_raw(), "zones": [zone]})
    assert "ab" in graph.blocked_edges
    assert "ba" not in graph.blocked_edges


def test_the_live_map_gets_the_points_between_a_curved_edges_nodes() -> None:
    payload: Any = graph_payload(_graph())
    entries = {e[0]: e for e in payload["edges"]}
    assert entries["ba"] == ["ba", "b", "a"]
    inner = entries["ab"][3]
    assert len(inner) > 10
    assert all(math.hypot(x, y) == pytest.approx(RADIUS, abs=1e-3) for x, y in inner)
