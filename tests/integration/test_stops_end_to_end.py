"""An order with several stops end to end (docs/master.md, *Orders with several stops*): one
``POST /orders`` with a pick and a drop stop; our simulated vehicle picks at the first, the
drop is appended by an order update, and the load leaves the vehicle at the second. And the
stops still to come survive a restart of master control."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from tests.integration.master_helpers import (
    api_client,
    running_master,
    simulated_vehicle,
    wait_status,
    wait_until,
)
from tests.integration.service_on_store import drive, journaled, online, reconnect
from vda5050.topics import AgvId
from vda_master.api_models import CreateOrder
from vda_master.dispatcher import OrderStatus

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.integration

AGV = AgvId("acme", "r1")
ROBOT_0 = {"manufacturer": "acme", "serialNumber": "robot_0"}
LOAD = [{"key": "loadType", "value": "EPAL"}, {"key": "loadId", "value": "L-77"}]


async def test_one_order_picks_at_one_stop_and_drops_at_the_next(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    async with (
        running_master(embedded_broker, unique_interface_name) as master,
        simulated_vehicle(embedded_broker, unique_interface_name, time_lapse=8.0),
        api_client(master) as client,
    ):
        service = master.service
        await wait_until(lambda: service.availability_of(AGV) is None, 10)
        answer = await client.post(
            "/orders",
            json={
                "stops": [
                    {
                        "destination": "12",
                        "actions": [{"actionType": "pick", "actionParameters": LOAD}],
                    },
                    {"stationType": "drop", "actions": [{"actionType": "drop"}]},
                ]
            },
        )
        assert answer.status_code == 201, answer.text
        order_id = answer.json()["orderId"]
        assert answer.json()["destination"] == "12"
        view = (await client.get(f"/orders/{order_id}")).json()
        assert view["stopsAhead"] == [{"stationType": "drop", "actions": [_drop()]}]
        await wait_status(client, order_id, "FINISHED", timeout=60)
        view = (await client.get(f"/orders/{order_id}")).json()
        vehicle = (await client.get("/vehicles/acme/r1")).json()

    assert view["stopsAhead"] == []
    assert view["nodeIds"][0] == "7"  # where it stood: one order from start to the drop
    assert "12" in view["nodeIds"]
    assert master.service.graph.nodes[view["nodeIds"][-1]].station_type == "drop"
    assert view["orderUpdateId"] >= 1
    assert vehicle["loads"] == []  # picked at 12, dropped at the drop station
    states = vehicle["state"]["actionStates"]
    assert sorted(s["actionType"] for s in states) == ["drop", "pick"]  # the pick ran once
    assert {s["actionStatus"] for s in states} == {"FINISHED"}


def _drop() -> dict[str, object]:
    return {"actionType": "drop", "blockingType": None, "actionParameters": []}


async def test_an_order_with_stops_goes_on_to_its_next_stop_after_a_master_restart(
    tmp_path: Path,
) -> None:
    """The stops still to come are in the order's store record: a master restarted while the
    vehicle drives to the first stop appends the second once it stands there."""
    async with journaled(tmp_path) as (service, _, _, _):
        online(service)
        created = service.create_order(
            CreateOrder.model_validate(
                {**ROBOT_0, "stops": [{"destination": "n4"}, {"destination": "n8"}]}
            ).to_request()
        )
        await service.committed(created.order_id)
        drive(service, created.order_id, passed=1)

    async with journaled(tmp_path) as (service, publisher, store, writer):
        (resumed,) = await service.resume_from(store)
        assert [s.destination for s in resumed.onward] == ["n8"]
        reconnect(service)
        plan = service.tracks[created.order_id].plan
        for passed in range(1, plan.last_index + 1):
            drive(service, created.order_id, passed=passed)
        track = service.tracks[created.order_id]
        assert track.plan.destination == "n8"
        assert track.onward == ()
        await service.committed(created.order_id)
        assert publisher.orders()[-1]["nodes"][-1]["nodeId"] == "n8"
        for passed in range(plan.last_index, track.plan.last_index + 1):
            drive(service, created.order_id, passed=passed)
        assert service.tracks[created.order_id].status is OrderStatus.FINISHED
        await writer.flush()
        record = await store.get_order(created.order_id)
    assert record is not None
    assert record.status == "FINISHED"
    assert "onward" not in record.plan
