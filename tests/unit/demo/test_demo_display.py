"""The demo's line per robot says what master control's API says of it."""

from __future__ import annotations

from vda_demo.display import JsonObject, summary_lines, vehicle_line


def test_a_robot_out_of_service_says_so_with_the_note() -> None:
    vehicle: JsonObject = {"serialNumber": "robot_1", "lastNodeId": "DR2", "driving": False}
    assert vehicle_line({**vehicle, "inService": True}, None, "transport").endswith("transport")
    out = vehicle_line(
        {**vehicle, "inService": False, "outOfServiceNote": "brake check"}, None, "transport"
    )
    assert out.endswith("transport  out of service: brake check")
    bare = vehicle_line({**vehicle, "inService": False, "outOfServiceNote": ""}, None, "t")
    assert bare.endswith("t  out of service")


def test_a_robot_under_way_says_when_its_order_is_expected_done() -> None:
    """The order's expectedFinishAt (docs/master.md *Expected finish*) as a UTC clock time;
    nothing once the order has none (ended, or no order)."""
    vehicle: JsonObject = {"serialNumber": "robot_2", "lastNodeId": "A3", "driving": True}
    order: JsonObject = {"status": "RUNNING", "expectedFinishAt": "2026-12-03T14:03:45.120Z"}
    assert "  done by 14:03:45 UTC" in vehicle_line(vehicle, order, "pick at A3")
    ended: JsonObject = {"status": "FINISHED", "expectedFinishAt": None}
    assert "done by" not in vehicle_line(vehicle, ended, "pick at A3")
    assert "done by" not in vehicle_line(vehicle, None, "idle")


def test_the_summary_sets_each_order_beside_what_was_expected() -> None:
    finished = [("robot_0", "o1", 23.14), ("robot_1", "o2", 30.0)]
    assert summary_lines(finished, {"o1": 22.36}) == [
        "  robot_0   order o1 finished after 23.1 s (expected 22.4 s)",
        "  robot_1   order o2 finished after 30.0 s",
    ]
