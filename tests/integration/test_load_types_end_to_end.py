"""Load types end to end (docs/master.md, *Loads*): two simulated vehicles whose factsheets
declare different load sets (`load_types`); master control sends a pick of small load
carriers to the one that takes them, though the other stands nearer, and refuses it for the
other when it is named."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from tests.integration.master_helpers import (
    api_client,
    running_master,
    simulated_vehicle,
    wait_status,
    wait_until,
)
from vda5050.topics import AgvId

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.integration

FORKLIFT, AMR = AgvId("acme", "r1"), AgvId("acme", "amr")
KLT_PICK = {
    "actionType": "pick",
    "actionParameters": [
        {"key": "stationType", "value": "rack"},
        {"key": "loadType", "value": "KLT"},
        {"key": "loadId", "value": "K-5"},
    ],
}


async def test_a_pick_of_a_load_type_goes_to_the_vehicle_whose_load_sets_take_it(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    async with (
        running_master(embedded_broker, unique_interface_name) as master,
        simulated_vehicle(embedded_broker, unique_interface_name, start_node="10"),
        simulated_vehicle(
            embedded_broker,
            unique_interface_name,
            serial_number=AMR.serial_number,
            start_node="1",
            load_types=["KLT"],
        ),
        api_client(master) as client,
    ):
        service = master.service
        await wait_until(
            lambda: all(service.availability_of(a) is None for a in (FORKLIFT, AMR)), 10
        )
        listed = {v["serialNumber"]: v["loadTypes"] for v in (await client.get("/vehicles")).json()}
        assert listed == {"r1": ["EPAL"], "amr": ["KLT"]}
        named = await client.post(
            "/orders",
            json={**_vehicle(FORKLIFT), "destination": "12", "destinationActions": [KLT_PICK]},
        )
        assert named.status_code == 422, named.text
        assert named.json()["detail"] == (
            "vehicle acme/r1 cannot take this order: pick: its factsheet's load sets take "
            "'EPAL', not load type 'KLT'"
        )
        answer = await client.post(
            "/orders", json={"destination": "12", "destinationActions": [KLT_PICK]}
        )
        assert answer.status_code == 201, answer.text
        created = answer.json()
        assert {k: created[k] for k in ("manufacturer", "serialNumber")} == _vehicle(AMR)
        await wait_status(client, answer.json()["orderId"], "FINISHED", timeout=60)
        amr = (await client.get("/vehicles/acme/amr")).json()

    assert [(load["loadId"], load["loadType"]) for load in amr["loads"]] == [("K-5", "KLT")]


def _vehicle(agv: AgvId) -> dict[str, str]:
    return {"manufacturer": agv.manufacturer, "serialNumber": agv.serial_number}
