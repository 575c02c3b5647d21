"""Idle vehicles in the way of a new order are sent to parking, and the parking orders clear
their own way in turn, within a budget of parking searches per request (issue 9 §3,
:mod:`vda_master.resolution`)."""

from __future__ import annotations

import pytest

from vda5050.clock import FakeClock
from vda_master import resolution
from vda_master.api_models import CreateOrder
from vda_master.config import MasterConfig
from vda_master.service import MasterService
from vda_master.testing import RecordingPublisher, report_online
from vda_master.traffic.testing import agv, make_graph

R0, V1, V2, V3 = agv("r0"), agv("v1"), agv("v2"), agv("v3")

# r0 drives s0 -> s2 through s1, where v1 stands idle. v1's nearest parking, P1, lies beyond
# t1, where v2 stands; v2's nearest free one, P2, beyond u1, where v3 stands; v3's, P3, next
# to u1. Sending each idle vehicle to parking puts the next one in the way.
CHAIN = make_graph(
    {
        "s0": (0, 0), "s1": (4, 0), "s2": (8, 0),
        "t1": (4, 4), "P1": (4, 8),
        "u1": (8, 4), "P2": (12, 4), "P3": (8, 8.5),
    },
    two_way=[("s0", "s1"), ("s1", "s2"), ("s1", "t1"), ("t1", "P1"), ("t1", "u1"),
             ("u1", "P2"), ("u1", "P3")],
    station_types={"P1": "parking", "P2": "parking", "P3": "parking"},
)  # fmt: skip


def _fleet() -> tuple[MasterService, RecordingPublisher]:
    publisher = RecordingPublisher()
    config = MasterConfig.model_validate({"traffic_control": True, "charge_below_pct": 0})
    service = MasterService(config, CHAIN, publisher, FakeClock())
    for vehicle, node_id in ((R0, "s0"), (V1, "s1"), (V2, "t1"), (V3, "u1")):
        report_online(service, vehicle, node_id)
    return service, publisher


def _destinations(publisher: RecordingPublisher) -> dict[str, str]:
    return {o["serialNumber"]: o["nodes"][-1]["nodeId"] for o in publisher.orders()}


def _order_for_r0(service: MasterService) -> None:
    body = {"manufacturer": R0.manufacturer, "serialNumber": R0.serial_number, "destination": "s2"}
    service.create_order(CreateOrder.model_validate(body).to_request())


def test_parking_orders_clear_their_own_way_in_turn() -> None:
    """One new order sends the whole chain of idle vehicles to parking at once."""
    service, publisher = _fleet()
    _order_for_r0(service)
    assert _destinations(publisher) == {"r0": "s2", "v1": "P1", "v2": "P2", "v3": "P3"}


def test_a_request_looks_for_a_bounded_number_of_parking_places_and_the_advice_goes_on(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With a budget of two parking searches, r0's order moves v1 (in r0's way) and v2 (in
    v1's), and leaves v3 standing; v2 then waits for v3 at t1, and the next look at the advice
    sends v3 away."""
    monkeypatch.setattr(resolution, "PARKING_SEARCHES_MAX", 2)
    service, publisher = _fleet()
    _order_for_r0(service)
    assert _destinations(publisher) == {"r0": "s2", "v1": "P1", "v2": "P2"}
    wait = service.coordinator.controller.vehicle(V2).wait
    assert wait is not None
    assert wait.blockers == frozenset({V3})
    service.resolve_traffic(0.0)
    assert _destinations(publisher)["v3"] == "P3"
