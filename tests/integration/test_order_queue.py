"""Queued orders end to end (docs/master.md, *Queued orders*): a wave of transports bigger than
the fleet is posted at once with ``queue: true``; master control sends each as a vehicle comes
free, the urgent one first, and every one finishes."""

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

FLEET = (AgvId("acme", "r-1"), AgvId("acme", "r-2"))


async def test_a_wave_bigger_than_the_fleet_is_served_as_vehicles_come_free(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    destinations = ["1", "2", "3", "10", "12", "13"]
    async with (
        running_master(embedded_broker, unique_interface_name) as master,
        simulated_vehicle(
            embedded_broker, unique_interface_name, serial_number="r", count=2, time_lapse=8.0
        ),
        api_client(master) as client,
    ):
        service = master.service
        await wait_until(lambda: all(service.availability_of(a) is None for a in FLEET), 10)
        wave = [{"destination": node, "queue": True} for node in destinations]
        wave.append({"destination": "11", "queue": True, "priority": 9})  # urgent, sent last
        answer = await client.post("/orders/batch", json={"orders": wave})
        assert answer.status_code == 200, answer.text
        results = answer.json()["results"]
        assert [r["status"] for r in results] == [201, 201, 202, 202, 202, 202, 202]
        assert results[-1]["queuePosition"] == 1  # ahead of the four queued before it
        queued = await client.get("/orders", params={"status": "QUEUED"})
        assert len(queued.json()) == 5

        await wait_until(lambda: not service.queue, timeout=60)
        for result in results:
            await wait_status(client, result["orderId"], "FINISHED", timeout=60)
        views = [(await client.get(f"/orders/{r['orderId']}")).json() for r in results]

    assert {(v["manufacturer"], v["serialNumber"]) for v in views} == {
        (a.manufacturer, a.serial_number) for a in FLEET
    }
    assert [v["nodeIds"][-1] for v in views] == [*destinations, "11"]
    started = {
        r["orderId"]: service.tracks[r["orderId"]].created_at for r in results if r["status"] == 202
    }
    urgent = results[-1]["orderId"]
    assert started[urgent] == min(started.values())  # the first to get a free vehicle
