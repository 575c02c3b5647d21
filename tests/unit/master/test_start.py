"""Where a vehicle's next order starts, also after it stopped between nodes (§6.6.1, §6.6.3.1;
issue 8: no dead end after a cancel)."""

from __future__ import annotations

from vda5050.models import AgvPosition
from vda5050.testing import make_state
from vda5050.topics import AgvId
from vda_master.fleet import VehicleView
from vda_master.planner import Target, route_for
from vda_master.routing import ProblemKind, Route, RouteProblem
from vda_master.start import StartPoint, find_start, point_segment_distance
from vda_master.testing import demo_graph


def _at(x: float, y: float, map_id: str = "demo") -> AgvPosition:
    return AgvPosition(x=x, y=y, theta=0.0, map_id=map_id, position_initialized=True)


def _vehicle(last_node: str, position: AgvPosition | None) -> VehicleView:
    state = make_state(last_node_id=last_node, agv_position=position)
    return VehicleView(AgvId("acme", "a"), 0.0, 0.0, state=state)


def test_vehicle_on_its_last_node_starts_there() -> None:
    """Standing on lastNodeId: the order starts there with the normal deviation."""
    assert find_start(demo_graph(), make_state(last_node_id="7", agv_position=_at(0, 0))) == (
        StartPoint("7")
    )


def test_vehicle_without_position_is_trusted_on_its_last_node() -> None:
    """A vehicle that cannot localise is taken to stand on its lastNodeId (§6.10.6)."""
    assert find_start(demo_graph(), make_state(last_node_id="7")) == StartPoint("7")


def test_start_from_position_when_last_node_unknown() -> None:
    """Without a known lastNodeId the vehicle starts from the node it stands near."""
    start = find_start(demo_graph(), make_state(last_node_id="", agv_position=_at(5.0, 0.0)))
    assert start == StartPoint("1")


def test_vehicle_stopped_on_an_edge_starts_where_it_stands() -> None:
    """Stopped 2 m along edge 17 (7→1): the order starts at the vehicle's position on edge 17
    (§6.6.3.1 method 1)."""
    start = find_start(demo_graph(), make_state(last_node_id="7", agv_position=_at(2.0, 0.0)))
    assert start == StartPoint("7", (2.0, 0.0), "17", 2.0)


def test_vehicle_off_the_graph_is_told_to_come_back() -> None:
    """A vehicle 3 m beside its last node, on no edge leaving it, gets no order; the reason
    says how to bring it back."""
    start = find_start(demo_graph(), make_state(last_node_id="7", agv_position=_at(-3.0, -3.0)))
    assert isinstance(start, str)
    assert "initPosition" in start


def test_route_after_a_stop_on_an_edge_continues_along_it() -> None:
    """A destination behind the vehicle is still reached via the end of the edge it stands on,
    so a line-guided vehicle never leaves its lane."""
    route = route_for(demo_graph(), _vehicle("7", _at(2.0, 0.0)), Target(destination="19"))
    assert isinstance(route, Route)
    assert route.node_ids[:2] == ("7", "1")
    assert route.node_ids[-1] == "19"
    assert route.start_position == (2.0, 0.0)


def test_explicit_route_from_the_edge_end_gets_the_edge_prepended() -> None:
    """An explicit route that starts where the vehicle's edge ends is accepted, with that edge
    first."""
    route = route_for(demo_graph(), _vehicle("7", _at(2.0, 0.0)), Target(route=("12",)))
    assert isinstance(route, Route)
    assert route.edge_ids == ("17", "12")


def test_explicit_route_elsewhere_is_refused_with_the_reason() -> None:
    """An explicit route that starts neither with the edge nor at its end is refused (422)."""
    problem = route_for(demo_graph(), _vehicle("7", _at(2.0, 0.0)), Target(route=("30",)))
    assert isinstance(problem, RouteProblem)
    assert problem.kind == ProblemKind.DISCONTINUOUS
    assert "stands on edge '17'" in problem.reason


def test_no_start_between_nodes_without_last_node() -> None:
    """A vehicle between nodes with an unknown lastNodeId cannot be planned for."""
    start = find_start(demo_graph(), make_state(last_node_id="", agv_position=_at(2.5, 0.0)))
    assert isinstance(start, str)
    assert "on no graph node" in start


def test_no_start_on_another_map() -> None:
    """A vehicle whose position is on another map than its last node is not planned for."""
    start = find_start(
        demo_graph(), make_state(last_node_id="7", agv_position=_at(0.0, 0.0, "floor2"))
    )
    assert isinstance(start, str)
    assert "map 'floor2'" in start


def test_no_start_without_state() -> None:
    """A vehicle that never sent a state has no start."""
    assert find_start(demo_graph(), None) == "it has not published a state yet"


def test_point_segment_distance() -> None:
    """Distance to a segment is to its closest point, ends included."""
    assert point_segment_distance((1, 1), (0, 0), (2, 0)) == 1.0
    assert point_segment_distance((3, 0), (0, 0), (2, 0)) == 1.0
    assert point_segment_distance((0, 0), (1, 1), (1, 1)) == 2**0.5
