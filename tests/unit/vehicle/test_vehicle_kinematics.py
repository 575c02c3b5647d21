"""R34 (§6.6.6 edge ``orientation``): which orientations each drive holds; a differential-drive
vehicle rejects an order whose edge orientation it cannot hold, in 2.x and in 3.0."""

from __future__ import annotations

import math

from tests.unit.vehicle.test_vehicle_v3 import Robot
from vda5050.models import Order, OrientationType, v3
from vda5050.testing import make_order, make_order_v3
from vda_vehicle.factsheet import FactsheetTiming, build_factsheet
from vda_vehicle.kinematics import unreachable_orientations
from vda_vehicle.order_executor import Accept, Reject, decide_order
from vda_vehicle.testing import make_caps, make_vehicle
from vda_vehicle.v3_report import build_factsheet_v3

DIFF = make_caps(kinematic="DIFF")
#: A vehicle's heading tolerance when an order gives none (Capabilities.deviation_theta_rad).
TOLERANCE = DIFF.deviation_theta_rad


def _oriented(orientation: float, kind: OrientationType | None = None) -> Order:
    """An order a -> b driving north-east (45 degrees), its edge asking ``orientation``."""
    order = make_order(["a", "b"], positions=[(0.0, 0.0), (5.0, 5.0)])
    edge = order.edges[0].model_copy(update={"orientation": orientation, "orientation_type": kind})
    return order.model_copy(update={"edges": [edge]})


def _problems(orientation: float, kind: OrientationType | None = None) -> list[str]:
    order = _oriented(orientation, kind)
    return [p.edge_id for p in unreachable_orientations(order, "DIFF", TOLERANCE)]


def test_a_differential_drive_holds_only_its_axis_of_travel() -> None:
    north_east = math.pi / 4
    assert _problems(0.0) == []  # tangential: forwards
    assert _problems(math.pi) == []  # backwards
    assert _problems(-math.pi + TOLERANCE / 2) == []
    assert _problems(math.pi / 2) == ["a-b"]  # crab sideways: only an omni can
    assert _problems(TOLERANCE * 1.5) == ["a-b"]
    assert _problems(north_east, OrientationType.GLOBAL) == []  # the edge's own direction
    assert _problems(north_east - math.pi, OrientationType.GLOBAL) == []  # reversed
    assert _problems(0.0, OrientationType.GLOBAL) == ["a-b"]  # facing east on a NE edge
    omni = unreachable_orientations(_oriented(math.pi / 2), "OMNI", TOLERANCE)
    assert list(omni) == []


def test_a_differential_drive_rejects_an_order_whose_orientation_it_cannot_hold() -> None:
    """2.x: orderError naming the edge; an orientation along the edge is taken; an
    omnidirectional vehicle takes both."""
    sideways = _oriented(math.pi / 2)
    decision = decide_order(make_vehicle(), sideways, DIFF)
    assert isinstance(decision, Reject)
    (error,) = decision.errors
    assert error.error_type == "orderError"
    refs = {r.reference_key: r.reference_value for r in error.error_references or []}
    assert refs["edgeId"] == "a-b"
    assert "cannot be held by a differential-drive vehicle" in (error.error_description or "")
    assert isinstance(decide_order(make_vehicle(), _oriented(math.pi), DIFF), Accept)
    assert isinstance(decide_order(make_vehicle(), sideways, make_caps()), Accept)


def test_3_0_rejects_it_as_no_route_to_target_and_factsheets_name_the_drive() -> None:
    robot = Robot(kinematics="DIFF")
    order = make_order_v3(["a", "b"], positions=[(0.0, 0.0), (6.0, 0.0)])
    edge = order.edges[0].model_copy(update={"orientation": math.pi / 2})
    robot.order(order.model_copy(update={"edges": [edge]}))
    state = robot.state()
    assert state["orderId"] != "order-1"
    assert [e["errorType"] for e in state["errors"]] == ["NO_ROUTE_TO_TARGET"]
    timing = FactsheetTiming(1.0, 30.0, 1.0)
    legacy = build_factsheet(DIFF, timing, version="2.1.0")
    assert legacy.type_specification.agv_kinematic == "DIFF"
    kinematics = build_factsheet_v3(DIFF, timing).type_specification.mobile_robot_kinematics
    assert kinematics == v3.MobileRobotKinematics.DIFFERENTIAL
