"""vda-inspect on zone requests and their answers (3.0 §6.4.3, §6.9, §7.5; T91, T92;
docs/inspect.md), on crafted traffic through the Inspector as the listener feeds it."""

from __future__ import annotations

from typing import Any

from vda5050.codec import encode
from vda5050.models import v3
from vda5050.models.v3.state import RequestStatus, ZoneRequest, ZoneRequestType, ZoneSetStatus
from vda5050.testing import make_responses_v3, make_state_v3, make_zone_set_v3, make_zone_v3
from vda_inspect.rules import Inspector
from vda_inspect.severity import Severity

BASE = "vda5050/v3/acme/robot_0/"
DOOR = make_zone_v3("door", v3.ZoneType.RELEASE, releaseLossBehavior="STOP")  # the unit square
ZONES = make_zone_set_v3(DOOR, zone_set_id="demo.zones.1", map_id="map")


class _Run:
    """Messages in order, each with its own headerId per topic, at the given times."""

    def __init__(self) -> None:
        self.inspector = Inspector()
        self.header_ids: dict[str, int] = {}

    def send(self, topic: str, message: Any, now: float) -> list[tuple[str, str, str]]:
        header_id = self.header_ids.get(topic, -1) + 1
        self.header_ids[topic] = header_id
        payload = encode(message.model_copy(update={"header_id": header_id}))
        found = self.inspector.observe(BASE + topic, payload, qos=0, retain=False, now=now)
        return [(f.rule, f.side, f.text) for f in found if f.severity is Severity.VIOLATION]


def _state(x: float, *requests: ZoneRequest) -> v3.State:
    return make_state_v3(
        mobile_robot_position={"x": x, "y": 0.5, "theta": 0.0, "mapId": "map", "localized": True},
        zone_sets=[
            {"zoneSetId": "demo.zones.1", "mapId": "map", "zoneSetStatus": ZoneSetStatus.ENABLED}
        ],
        zone_requests=list(requests),
    )


def _request(status: RequestStatus, request_id: str = "zr-1") -> ZoneRequest:
    return ZoneRequest(
        request_id=request_id,
        request_type=ZoneRequestType.ACCESS,
        zone_id="door",
        zone_set_id="demo.zones.1",
        request_status=status,
    )


def test_entering_a_release_zone_without_a_grant_is_t91_with_one_it_is_fine() -> None:
    """The robot's position crosses into the RELEASE zone of an enabled set: with a GRANTED
    request that is what §6.4.3 asks; without one it is T91 on the robot's side."""
    run = _Run()
    run.send("zoneSet", ZONES, 0.0)
    assert run.send("state", _state(-1.0, _request(RequestStatus.REQUESTED)), 0.1) == []
    assert run.send("responses", make_responses_v3(("zr-1", v3.GrantType.GRANTED)), 0.2) == []
    assert run.send("state", _state(0.5, _request(RequestStatus.GRANTED)), 0.3) == []
    assert run.send("state", _state(2.0), 0.4) == []  # out, request dropped

    (finding,) = run.send("state", _state(0.5), 0.5)
    assert finding[:2] == ("T91", "vehicle")
    assert "entered RELEASE zone 'door'" in finding[2]


def test_master_control_must_answer_requests_it_is_asked_and_only_those() -> None:
    """T92: a request stated for longer than the answer time without a response; a response
    to a request the robot does not hold; a leaseExpiry on anything but GRANTED. A robot that
    keeps a QUEUED request at REQUESTED (Fig. 16) is not asked for a second answer."""
    run = _Run()
    run.send("zoneSet", ZONES, 0.0)
    run.send("state", _state(-1.0, _request(RequestStatus.REQUESTED)), 0.0)
    (late,) = [f for f in run.inspector.tick(3.0) if f.rule == "T92"]
    assert (late.side, late.text) == ("master control", "no response to request 'zr-1' within 2 s")
    assert run.inspector.tick(10.0) == []  # once

    run = _Run()
    run.send("state", _state(-1.0, _request(RequestStatus.REQUESTED)), 0.0)
    assert run.send("responses", make_responses_v3(("zr-1", v3.GrantType.QUEUED)), 0.5) == []
    run.send("state", _state(-1.0, _request(RequestStatus.REQUESTED)), 1.0)
    assert [f for f in run.inspector.tick(5.0) if f.rule == "T92"] == []
    stray = v3.Response(
        request_id="zr-7", grant_type=v3.GrantType.REJECTED, lease_expiry="2026-12-03T10:00:00.000Z"
    )
    found = run.send("responses", make_responses_v3(stray), 6.0)
    assert [(rule, side) for rule, side, _ in found] == [("T92", "master control")] * 2
    assert "latest state lacks" in found[0][2]
    assert "leaseExpiry with REJECTED" in found[1][2]
