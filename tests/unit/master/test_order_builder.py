"""Order building from a route (§6.6.1, §6.6.6; R22, R25, R56–R58, R86, R112–R114)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

from vda5050.models import BlockingType, Factsheet, Order
from vda5050.topics import AgvId
from vda5050.validation import check_order
from vda_master import capabilities as caps
from vda_master.capabilities import ActionSpec
from vda_master.graph import Graph
from vda_master.order_builder import (
    BuildProblem,
    OrderPlan,
    PlanRequest,
    build_message,
    plan_order,
)
from vda_master.routing import Route, check_route
from vda_master.testing import demo_graph, id_source, make_factsheet

AGV = AgvId("acme", "r1")


def _plan(
    edges: Sequence[str] = ("17", "12", "11"),
    *,
    factsheet: Factsheet | None = None,
    node_actions: Mapping[int, Sequence[ActionSpec]] | None = None,
    edge_actions: Mapping[int, Sequence[ActionSpec]] | None = None,
    graph: Graph | None = None,
    order_id: str = "o1",
) -> OrderPlan | BuildProblem:
    graph = graph or demo_graph()
    route = check_route(graph, graph.edges[edges[0]].start_node_id, list(edges))
    assert isinstance(route, Route)
    request = PlanRequest(route, order_id, node_actions or {}, edge_actions or {})
    return plan_order(
        graph, request, agv=AGV, version="2.1.0", factsheet=factsheet, action_ids=id_source()
    )


def _ok(plan: OrderPlan | BuildProblem) -> OrderPlan:
    assert isinstance(plan, OrderPlan), plan
    return plan


def _full(plan: OrderPlan) -> Order:
    return build_message(plan, first=0, release_end=plan.last_index, update_id=0, max_nodes=None)


def test_reference_route_nodes_and_sequence_ids() -> None:
    """Route [17, 12, 11] gives nodes [7, 1, 2, 10] with sequenceIds 0, 2, 4, 6 (R25)."""
    order = _full(_ok(_plan(factsheet=make_factsheet())))
    assert [n.node_id for n in order.nodes] == ["7", "1", "2", "10"]
    assert [n.sequence_id for n in order.nodes] == [0, 2, 4, 6]


def test_reference_route_edges_and_sequence_ids() -> None:
    """Route [17, 12, 11] gives edges 17, 12, 11 with sequenceIds 1, 3, 5 joining the nodes."""
    order = _full(_ok(_plan(factsheet=make_factsheet())))
    assert [(e.edge_id, e.sequence_id) for e in order.edges] == [("17", 1), ("12", 3), ("11", 5)]
    assert [(e.start_node_id, e.end_node_id) for e in order.edges] == [
        ("7", "1"),
        ("1", "2"),
        ("2", "10"),
    ]


def test_built_order_passes_the_semantic_check() -> None:
    """A built order breaks none of the static order rules (R21–R26)."""
    order = _full(_ok(_plan(factsheet=make_factsheet())))
    assert check_order(order, first_sequence_id=0) == []


def test_node_position_and_edge_fields_come_from_the_graph() -> None:
    """nodePosition (x, y, theta, mapId, deviations) and maxSpeed/length come from the graph."""
    plan = _ok(_plan(["17", "42"], factsheet=make_factsheet()))
    order = _full(plan)
    station = order.nodes[-1].node_position
    assert station is not None
    assert (station.x, station.y, station.map_id) == (5.0, -3.0, "demo")
    assert station.theta is not None
    assert (station.allowed_deviation_xy, station.allowed_deviation_theta) == (0.1, 0.1)
    assert [(e.max_speed, e.length) for e in order.edges] == [(1.5, 5.0), (0.5, 3.0)]


def test_without_factsheet_the_order_is_full() -> None:
    """A vehicle with no valid factsheet gets every field the graph provides: nodePosition with
    mapId, theta and deviations, edge length and maxSpeed (a factsheet narrows, never permits)."""
    order = _full(_ok(_plan(factsheet=None)))
    positions = [n.node_position for n in order.nodes]
    assert all(p is not None and p.map_id == "demo" for p in positions)
    assert all(e.length is not None for e in order.edges)


def test_unsupported_optional_fields_are_left_out() -> None:
    """Only the optional fields the factsheet lists are sent (R112)."""
    factsheet = make_factsheet(supported=[caps.NODE_POSITION, caps.EDGE_LENGTH])
    order = _full(_ok(_plan(["17", "42"], factsheet=factsheet)))
    position = order.nodes[-1].node_position
    assert position is not None
    assert position.theta is None
    assert position.allowed_deviation_xy is None
    assert all(e.max_speed is None and e.length is not None for e in order.edges)


def test_listed_sub_field_implies_its_parent_object() -> None:
    """Listing nodePosition.theta allows nodePosition itself, with only theta of its options."""
    order = _full(_ok(_plan(["17", "42"], factsheet=make_factsheet(supported=[caps.NODE_THETA]))))
    position = order.nodes[-1].node_position
    assert position is not None
    assert position.theta is not None
    assert position.allowed_deviation_xy is None


def test_required_field_is_filled_with_a_default() -> None:
    """A REQUIRED maxSpeed the graph lacks is filled from the factsheet's speedMax (R113)."""
    graph = demo_graph()
    plain = {**graph.edges}
    plain["17"] = plain["17"].model_copy(update={"max_speed": None})
    graph = Graph(graph.map_id, graph.nodes, plain, graph.outgoing, graph.source)
    factsheet = make_factsheet(supported=[], required=[caps.EDGE_MAX_SPEED])
    order = _full(_ok(_plan(["17"], factsheet=factsheet, graph=graph)))
    assert order.edges[0].max_speed == 2.0


def test_required_field_without_value_is_a_problem() -> None:
    """A REQUIRED theta on a node without one in the graph makes the order impossible (R113)."""
    factsheet = make_factsheet(supported=[], required=[caps.NODE_THETA])
    problem = _plan(factsheet=factsheet)
    assert isinstance(problem, BuildProblem)
    assert "order.nodes.nodePosition.theta" in problem.reason


def test_required_field_the_master_cannot_fill_is_a_problem() -> None:
    """A REQUIRED field such as a node's mapDescription is reported as unfillable (R113)."""
    factsheet = make_factsheet(required=["order.nodes.nodePosition.mapDescription"])
    problem = _plan(factsheet=factsheet)
    assert isinstance(problem, BuildProblem)
    assert "order.nodes.nodePosition.mapDescription" in problem.reason


def test_pick_action_gets_station_parameters_from_the_graph() -> None:
    """A pick at a station carries the predefined stationType/stationName keys (R86)."""
    plan = _ok(
        _plan(["17", "42"], factsheet=make_factsheet(), node_actions={2: [ActionSpec("pick")]})
    )
    action = _full(plan).nodes[2].actions[0]
    assert action.action_type == "pick"
    assert action.blocking_type == BlockingType.HARD
    assert action.parameter("stationType") == "pick"
    assert action.parameter("stationName") == "P1"


def test_action_ids_are_unique_and_listed() -> None:
    """Every action gets its own id, and the plan lists them in traversal order."""
    actions = {2: [ActionSpec("pick"), ActionSpec("startCharging")]}
    plan = _ok(_plan(["17", "42"], factsheet=make_factsheet(), node_actions=actions))
    assert plan.action_ids() == ("a1", "a2")


def test_unsupported_action_is_a_problem() -> None:
    """An action the factsheet does not list is refused before sending (R31 avoided, §6.15)."""
    problem = _plan(factsheet=make_factsheet(), node_actions={1: [ActionSpec("detectObject")]})
    assert isinstance(problem, BuildProblem)
    assert "does not list action 'detectObject'" in problem.reason


def test_action_in_wrong_scope_is_a_problem() -> None:
    """An action declared only for NODE cannot be sent on an edge (§6.8, R83)."""
    problem = _plan(factsheet=make_factsheet(), edge_actions={0: [ActionSpec("pick")]})
    assert isinstance(problem, BuildProblem)
    assert "not allowed as EDGE" in problem.reason


def test_undeclared_action_parameter_is_a_problem() -> None:
    """A parameter key the factsheet does not declare is not sent (§6.15)."""
    spec = ActionSpec("pick", parameters={"colour": "red"})
    problem = _plan(factsheet=make_factsheet(), node_actions={1: [spec]})
    assert isinstance(problem, BuildProblem)
    assert "'colour'" in problem.reason


def test_actions_go_to_a_vehicle_without_factsheet() -> None:
    """A vehicle without a valid factsheet gets the actions the request asks for."""
    plan = _ok(_plan(factsheet=None, node_actions={1: [ActionSpec("pick")]}))
    (action,) = plan.nodes[1].actions
    assert (action.action_type, action.blocking_type) == ("pick", BlockingType.HARD)


def test_numeric_only_ids_are_enforced() -> None:
    """A vehicle with idNumericalOnly cannot take a non-numeric orderId (R114)."""
    factsheet = make_factsheet(string_lens={"idNumericalOnly": True})
    assert isinstance(_plan(factsheet=factsheet, order_id="o1"), BuildProblem)
    assert isinstance(_plan(factsheet=factsheet, order_id="123"), OrderPlan)


def test_id_length_is_enforced() -> None:
    """An id longer than the vehicle's idLen is refused (R114)."""
    factsheet = make_factsheet(string_lens={"idLen": 4})
    problem = _plan(factsheet=factsheet, order_id="order-123")
    assert isinstance(problem, BuildProblem)
    assert "idLen 4" in problem.reason


def test_node_action_count_limit() -> None:
    """More node actions than node.actions allows is refused (R114)."""
    factsheet = make_factsheet(array_lens={"node.actions": 1})
    actions = {1: [ActionSpec("startCharging"), ActionSpec("startCharging")]}
    assert isinstance(_plan(factsheet=factsheet, node_actions=actions), BuildProblem)


def test_message_is_cut_to_the_node_limit() -> None:
    """A message holds at most order.nodes nodes; the rest of the horizon waits (R114)."""
    plan = _ok(_plan(factsheet=make_factsheet()))
    order = build_message(plan, first=0, release_end=3, update_id=0, max_nodes=2)
    assert [n.node_id for n in order.nodes] == ["7", "1"]
    assert [e.edge_id for e in order.edges] == ["17"]
    assert all(n.released for n in order.nodes)


def test_base_and_horizon_split() -> None:
    """Nodes up to release_end and the edges between them are released, the rest is horizon."""
    plan = _ok(_plan(factsheet=make_factsheet()))
    order = build_message(plan, first=0, release_end=1, update_id=0, max_nodes=None)
    assert [n.released for n in order.nodes] == [True, True, False, False]
    assert [e.released for e in order.edges] == [True, False, False]
    assert check_order(order, first_sequence_id=0) == []


def test_update_stitches_at_the_decision_point() -> None:
    """An update starts at the decision point with its nodeId and sequenceId (R56, R57)."""
    plan = _ok(_plan(factsheet=make_factsheet()))
    update = build_message(plan, first=1, release_end=3, update_id=1, max_nodes=None)
    assert (update.nodes[0].node_id, update.nodes[0].sequence_id) == ("1", 2)
    assert update.order_update_id == 1
    assert [e.sequence_id for e in update.edges] == [3, 5]
    assert check_order(update, first_sequence_id=2) == []


def test_stitching_node_content_is_unchanged() -> None:
    """The stitching node goes out exactly as first transmitted (R58)."""
    actions = {1: [ActionSpec("startCharging")]}
    plan = _ok(_plan(factsheet=make_factsheet(), node_actions=actions))
    first = build_message(plan, first=0, release_end=1, update_id=0, max_nodes=None)
    update = build_message(plan, first=1, release_end=3, update_id=1, max_nodes=None)
    assert update.nodes[0] == first.nodes[1]


def test_single_node_order() -> None:
    """A route of no edges is a one-node order with no edges (R21, R22)."""
    graph = demo_graph()
    request = PlanRequest(Route(("7",), (), 0.0), "o1", {}, {})
    plan = plan_order(
        graph, request, agv=AGV, version="2.0.0", factsheet=None, action_ids=id_source()
    )
    order = _full(_ok(plan))
    assert [n.node_id for n in order.nodes] == ["7"]
    assert order.edges == []
    assert order.version == "2.0.0"


def test_vehicle_stopped_on_an_edge_gets_a_temporary_first_node() -> None:
    """§6.6.3.1 method 1: a vehicle standing at (2, 0) on edge 17 (7→1) gets an order whose
    first node is a temporary node where it stands and whose first edge leads from there to
    node 1, the rest as usual; the order stays well-formed."""
    graph = demo_graph()
    route = check_route(graph, "7", ["17", "12"])
    assert isinstance(route, Route)
    request = PlanRequest(replace(route, start_position=(2.0, 0.0)), "o1", {}, {})
    plan = plan_order(
        graph, request, agv=AGV, version="2.1.0", factsheet=None, action_ids=id_source()
    )
    order = _full(_ok(plan))
    assert [n.node_id for n in order.nodes] == ["7~here", "1", "2"]
    first = order.nodes[0].node_position
    assert first is not None
    assert (first.x, first.y, first.map_id) == (2.0, 0.0, "demo")
    leg = order.edges[0]
    assert (leg.edge_id, leg.start_node_id, leg.end_node_id, leg.length) == (
        "17~here",
        "7~here",
        "1",
        3.0,
    )
    assert check_order(order, first_sequence_id=0) == []


def test_temporary_ids_are_numeric_for_numeric_only_vehicles() -> None:
    """A vehicle with idNumericalOnly gets numeric temporary ids (R114)."""
    graph = demo_graph()
    route = check_route(graph, "7", ["17"])
    assert isinstance(route, Route)
    request = PlanRequest(replace(route, start_position=(2.0, 0.0)), "123", {}, {})
    factsheet = make_factsheet(string_lens={"idNumericalOnly": True})
    plan = _ok(
        plan_order(
            graph, request, agv=AGV, version="2.1.0", factsheet=factsheet, action_ids=id_source()
        )
    )
    assert (plan.nodes[0].node_id, plan.edges[0].edge_id) == ("1230", "1231")


def test_temporary_start_needs_node_positions() -> None:
    """A factsheet without nodePosition makes a start between nodes impossible: a problem."""
    graph = demo_graph()
    route = check_route(graph, "7", ["17"])
    assert isinstance(route, Route)
    request = PlanRequest(replace(route, start_position=(2.0, 0.0)), "o1", {}, {})
    factsheet = make_factsheet(supported=[caps.EDGE_LENGTH])
    problem = plan_order(
        graph, request, agv=AGV, version="2.1.0", factsheet=factsheet, action_ids=id_source()
    )
    assert isinstance(problem, BuildProblem)
    assert "temporary start node" in problem.reason
