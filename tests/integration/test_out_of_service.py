"""Vehicles taken out of service (``PATCH /vehicles/{manufacturer}/{serialNumber}``;
docs/master.md, *Out of service*), in one process on SQLite with hand-made states: master
control sends such a vehicle no order, named or chosen, queued orders wait for it, an order it
runs runs to its end, and the mark outlives a restart until the vehicle is put back."""

from __future__ import annotations

from pathlib import Path

import pytest
from structlog.testing import capture_logs

from tests.integration.service_on_store import AGV, drive, in_process_api, journaled, online
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import Connection
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.dispatcher import OrderStatus
from vda_master.planner import Target
from vda_master.requests import OrderRequest
from vda_master.service import MasterService
from vda_master.testing import parse_exposition

pytestmark = pytest.mark.integration

VEHICLE = f"/vehicles/{AGV.manufacturer}/{AGV.serial_number}"
TO_N5 = {"manufacturer": AGV.manufacturer, "serialNumber": AGV.serial_number, "destination": "n5"}


async def test_out_of_service_takes_no_order_and_its_queued_orders_wait_across_a_restart(
    tmp_path: Path,
) -> None:
    """Taken out with a note: GET says so and why, an order naming it is refused with the note,
    none without a vehicle goes to it, a queued one waits. After a restart it is still out;
    put back, the queued order goes to it at once."""
    async with journaled(tmp_path) as (service, publisher, _, _), in_process_api(service) as client:
        online(service)
        with capture_logs() as logs:
            taken = await client.patch(VEHICLE, json={"inService": False, "note": " brakes "})
        assert taken.status_code == 200, taken.text
        body = taken.json()
        assert (body["inService"], body["available"], body["outOfServiceNote"]) == (
            False,
            False,
            "brakes",
        )
        since = body["outOfServiceSince"]
        assert body["unavailableReason"] == f"it is out of service since {since}: brakes"
        assert {"event": "vehicle.out_of_service", "log_level": "info"}.items() <= logs[0].items()
        listed = (await client.get("/vehicles")).json()
        assert [(v["inService"], v["outOfServiceNote"]) for v in listed] == [(False, "brakes")]

        named = await client.post("/orders", json=TO_N5)
        assert named.status_code == 409
        assert named.json()["detail"] == (
            f"vehicle acme/robot_0 is not available: it is out of service since {since}: brakes"
        )
        anyone = await client.post("/orders", json={"destination": "n5"})
        assert anyone.status_code == 409
        assert "out of service" in anyone.json()["detail"]
        queued = await client.post("/orders", json={**TO_N5, "queue": True})
        assert queued.status_code == 202, queued.text
        assert "out of service" in queued.json()["reason"]
        samples = parse_exposition((await client.get("/metrics")).text)
        assert samples["vda_master_vehicles_out_of_service"] == 1
        assert samples["vda_master_vehicles_available"] == 0
        assert publisher.orders() == []

    async with (
        journaled(tmp_path) as (service, publisher, store, _),
        in_process_api(service) as client,
    ):
        await service.resume_from(store)
        silent = (await client.get(VEHICLE)).json()  # listed before it is heard from again
        assert (silent["inService"], silent["connectionState"]) == (False, None)
        online(service)
        service.tick()
        again = (await client.get(VEHICLE)).json()
        assert (again["inService"], again["outOfServiceSince"]) == (False, since)
        assert publisher.orders() == []  # the queued order still waits
        (waiting,) = service.queue.values()

        back = await client.patch(VEHICLE, json={"inService": True, "note": "ignored"})
        assert back.status_code == 200, back.text
        assert back.json()["inService"] is True
        assert back.json()["outOfServiceNote"] is None
        await service.committed(waiting.order_id)  # written ahead, then published
        (order,) = publisher.orders()
        assert order["orderId"] == waiting.order_id
        assert await store.load_out_of_service() == ()


async def test_the_order_it_runs_when_taken_out_runs_to_its_end(tmp_path: Path) -> None:
    """Taken out of service while it drives, the vehicle finishes its order; then it takes
    none. A second PATCH changes the note and keeps the time it was taken out."""
    async with journaled(tmp_path) as (service, _, _, _):
        online(service)
        track = service.create_order(OrderRequest(Target(destination="n3"), AGV))
        await service.committed(track.order_id)
        first = await service.set_in_service(AGV, in_service=False, note="scanner")
        assert first.agv == AGV
        since = service.out_of_service[AGV].since
        await service.set_in_service(AGV, in_service=False, note="scanner and brakes")
        assert service.out_of_service[AGV].since == since
        assert service.out_of_service[AGV].note == "scanner and brakes"
        drive(service, track.order_id, passed=1)
        drive(service, track.order_id, passed=3)
        assert service.tracks[track.order_id].status is OrderStatus.FINISHED
        reason = service.availability_of(AGV)
        assert reason is not None
        assert reason.endswith(": scanner and brakes")


async def test_the_api_says_what_it_refuses(tmp_path: Path) -> None:
    """An unknown vehicle is 404; a body without inService, with a note over 500 characters, an
    unknown key or a control character in the note is 422, each saying what is wrong."""
    async with journaled(tmp_path) as (service, _, _, _), in_process_api(service) as client:
        online(service)
        unknown = await client.patch("/vehicles/acme/nobody", json={"inService": False})
        assert unknown.status_code == 404
        assert "acme/nobody" in unknown.json()["detail"]
        cases = [
            ({}, "inService"),
            ({"inService": False, "note": "x" * 501}, "note"),
            ({"inService": False, "colour": "red"}, "colour"),
            ({"inService": False, "note": "a\u0000b"}, "control character '\\x00' in note"),
        ]
        for body, named in cases:
            refused = await client.patch(VEHICLE, json=body)
            assert refused.status_code == 422, refused.text
            assert named in refused.json()["detail"]
        assert service.out_of_service == {}


async def test_a_silent_vehicle_out_of_service_is_not_forgotten(tmp_path: Path) -> None:
    """Silent past forget_after_s, a vehicle in service leaves the fleet view; one out of
    service stays listed, so it can be put back."""
    clock = FakeClock()
    async with journaled(tmp_path, clock=clock, forget_after_s=60.0) as (service, _, _, _):
        online(service)
        await service.set_in_service(AGV, in_service=False, note="switched off")
        clock.advance(120.0)
        service.tick()
        assert service.fleet.get(AGV) is not None
        await service.set_in_service(AGV, in_service=True)
        clock.advance(10.0)
        service.tick()
        assert service.fleet.get(AGV) is None


async def test_an_order_to_the_node_a_vehicle_out_of_service_stands_on_is_refused(
    tmp_path: Path,
) -> None:
    """robot_0 stands on n3 out of service: an order for robot_1 to n3 would wait for good
    (master control does not move robot_0), so it is refused saying why; with queue: true it
    waits until robot_0 is put back. An order to n3 for robot_0 itself is refused for being out
    of service, not for the node."""
    robot_1 = AgvId("acme", "robot_1")
    async with journaled(tmp_path) as (service, _, _, _), in_process_api(service) as client:
        online(service, node="n3")
        _online_as(service, robot_1, "n0")
        await service.set_in_service(AGV, in_service=False, note="brakes")
        to_n3 = {"manufacturer": "acme", "serialNumber": "robot_1", "destination": "n3"}
        refused = await client.post("/orders", json=to_n3)
        assert refused.status_code == 409
        detail = refused.json()["detail"]
        assert detail.startswith("node 'n3' is taken by acme/robot_0, which stands there out of")
        assert detail.endswith(": brakes); put it back in service or choose another node")
        own = await client.post("/orders", json={**to_n3, "serialNumber": "robot_0"})
        assert "is not available: it is out of service" in own.json()["detail"]
        queued = await client.post("/orders", json={**to_n3, "queue": True})
        assert queued.status_code == 202, queued.text
        await service.set_in_service(AGV, in_service=True)
        assert service.queue == {}  # robot_0 is movable again: the order went to robot_1


def _online_as(service: MasterService, agv: AgvId, node: str) -> None:
    """``agv`` ONLINE, standing on ``node``."""
    header = {"manufacturer": agv.manufacturer, "serial_number": agv.serial_number}
    online = Connection.model_validate({**HEADER, **header, "connection_state": "ONLINE"})
    service.ingest(build_topic("uagv", 2, agv, Topic.CONNECTION), encode(online))
    state = make_state(last_node_id=node, **header)
    service.ingest(build_topic("uagv", 2, agv, Topic.STATE), encode(state))
