"""The Coordinator's safety distance from factsheets: applied at once with traffic control on,
put off until the controller is used with it off (a fleet's start-up does not pay the rebuild)."""

from __future__ import annotations

import pytest

from vda5050.models import AgvPosition, State
from vda5050.testing import make_state
from vda5050.topics import AgvId
from vda_master.config import MasterConfig
from vda_master.coordination import Coordinator
from vda_master.testing import demo_graph, make_factsheet
from vda_master.traffic import default_safety_distance_m
from vda_master.traffic.conflicts import edge, node

AGV = AgvId("acme", "robot_0")
FACTSHEET = make_factsheet()
WIDER = default_safety_distance_m((FACTSHEET,))


def _coordinator(*, enabled: bool) -> Coordinator:
    return Coordinator(demo_graph(), MasterConfig(traffic_control=enabled))


def test_with_traffic_control_on_a_wider_footprint_applies_at_once() -> None:
    """The first factsheet widens the safety distance when it arrives."""
    coordinator = _coordinator(enabled=True)
    assert coordinator.safety_distance_m < WIDER
    coordinator.note_factsheet(AGV, FACTSHEET)
    assert coordinator.safety_distance_m == WIDER


def test_with_traffic_control_off_the_rebuild_waits_for_the_first_use() -> None:
    """Off, the factsheet only marks the rebuild; a snapshot or a choice makes it (off, no
    route is ever held, so the result is the same)."""
    for use in ("snapshot", "choose"):
        coordinator = _coordinator(enabled=False)
        before = coordinator.safety_distance_m
        coordinator.note_factsheet(AGV, FACTSHEET)
        assert coordinator.safety_distance_m == before
        if use == "snapshot":
            coordinator.snapshot(0.0)
        else:
            coordinator.choose([(AGV, "7")], ("10",), 0.0)
        assert coordinator.safety_distance_m == WIDER, use


def test_speeds_from_factsheets_are_kept_only_with_traffic_control_on() -> None:
    """On, the factsheet's speedMax is what plans assume; off, nothing plans, and a fleet's
    thousand factsheets at start-up do not rebuild the controller's state one by one."""
    speed = FACTSHEET.physical_parameters.speed_max
    on = _coordinator(enabled=True)
    on.note_factsheet(AGV, FACTSHEET)
    assert on.controller.state.speed_of(AGV).speed_mps == speed
    off = _coordinator(enabled=False)
    untouched = off.controller
    off.note_factsheet(AGV, FACTSHEET)
    assert off.controller is untouched


def test_the_time_lapse_reaches_traffic_control_and_survives_a_rebuild() -> None:
    """``time_lapse`` 10 (vehicles simulated ten times faster): ``max_wait_s`` and the plans'
    expected stays are simulated seconds, ten times shorter on the master's clock, and edges'
    ``maxSpeed`` simulated m/s, ten times higher; the rebuild for a wider footprint keeps them."""
    real = Coordinator(demo_graph(), MasterConfig(max_wait_s=30.0))
    fast = Coordinator(demo_graph(), MasterConfig(max_wait_s=30.0, time_lapse=10.0))
    fast.note_factsheet(AGV, FACTSHEET)
    assert fast.safety_distance_m == WIDER  # rebuilt
    settings, real_settings = fast.controller.state.settings, real.controller.state.settings
    assert settings.max_wait_s == pytest.approx(3.0)
    assert settings.passages.hold_s == pytest.approx(real_settings.passages.hold_s / 10)
    limits = real.controller.state.roads.max_speed
    assert limits, "the demo graph limits some edges' speed"
    for edge_id, limit in limits.items():
        assert fast.controller.state.roads.max_speed[edge_id] == pytest.approx(limit * 10)


OTHER = AgvId("acme", "robot_1")


def _idle_state(x: float, y: float, last_node_id: str = "7") -> State:
    position = AgvPosition(x=x, y=y, theta=0.0, map_id="demo", position_initialized=True)
    return make_state(last_node_id=last_node_id, agv_position=position)


def test_a_vehicle_off_the_graphs_nodes_holds_what_it_covers() -> None:
    """Issue 9 §2, a vehicle without an order that stands between nodes 7 (0, 0) and 1 (5, 0)
    (moved by hand, stopped on the edge): it holds every resource within the safety distance
    of where it is, edge 7→1 among them and neither end node (2.5 m away), so no other
    vehicle is released across it; back on node 1 it holds that node alone."""
    coordinator = _coordinator(enabled=True)
    coordinator.observe(AGV, _idle_state(2.5, 0.0), None, 0.0)
    held = {str(r) for r in coordinator.controller.state.table.held_by(AGV)}
    assert {"edge:17", "edge:18"} <= held
    assert not {"node:7", "node:1"} & held
    assert coordinator.controller.vehicle(AGV).node_id is None
    coordinator.observe(OTHER, _idle_state(15.0, 0.0, "10"), None, 0.0)
    refused = coordinator.controller.state.table.refusal(OTHER, [edge("17")])
    assert refused is not None
    assert refused.holder == AGV
    coordinator.observe(AGV, _idle_state(5.0, 0.0, "1"), None, 1.0)
    assert coordinator.controller.state.table.held_by(AGV) == {node("1")}


def test_a_vehicle_within_the_margin_of_its_node_stands_on_it() -> None:
    """Localisation and deviation within the safety margin (0.25 m) are the node itself."""
    coordinator = _coordinator(enabled=True)
    coordinator.observe(AGV, _idle_state(0.2, 0.0), None, 0.0)
    assert coordinator.controller.state.table.held_by(AGV) == {node("7")}
    assert coordinator.controller.vehicle(AGV).node_id == "7"


def test_what_an_off_graph_vehicle_covers_follows_a_wider_safety_distance() -> None:
    """A factsheet that widens the safety distance widens what the vehicle covers too."""
    coordinator = _coordinator(enabled=True)
    coordinator.observe(AGV, _idle_state(1.2, 0.0), None, 0.0)  # 1.2 m from node 7
    narrow = coordinator.controller.state.table.held_by(AGV)
    assert node("7") not in narrow
    coordinator.note_factsheet(OTHER, FACTSHEET)
    assert coordinator.safety_distance_m == WIDER
    wide = coordinator.controller.state.table.held_by(AGV)
    assert narrow < wide
    assert node("7") in wide
