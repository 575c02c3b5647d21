"""The demo's line per robot says what master control's API says of it."""

from __future__ import annotations

from vda_demo.display import JsonObject, vehicle_line


def test_a_robot_out_of_service_says_so_with_the_note() -> None:
    vehicle: JsonObject = {"serialNumber": "robot_1", "lastNodeId": "DR2", "driving": False}
    assert vehicle_line({**vehicle, "inService": True}, None, "transport").endswith("transport")
    out = vehicle_line(
        {**vehicle, "inService": False, "outOfServiceNote": "brake check"}, None, "transport"
    )
    assert out.endswith("transport  out of service: brake check")
    bare = vehicle_line({**vehicle, "inService": False, "outOfServiceNote": ""}, None, "t")
    assert bare.endswith("t  out of service")
