"""Energy management end to end (docs/master.md, *Charging*): master control sends a low vehicle
to charge, ends the charge, makes room at a taken charger, and gives no vehicle a route longer
than its battery's reach (VDA 5050 §6.8.2, §6.10.6 batteryState)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from tests.integration.master_helpers import (
    SIMULATED,
    SIMULATED_BODY,
    api_client,
    running_master,
    simulated_vehicle,
    wait_status,
    wait_until,
)
from vda5050.topics import AgvId

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress
    from vda_master.runtime import MasterProcess

pytestmark = pytest.mark.integration


def _charging_orders(master: MasterProcess, agv: AgvId) -> list[tuple[str, str]]:
    """(orderId, destination) of master control's own charging orders for ``agv``."""
    return [
        (order_id, track.plan.destination)
        for order_id, track in master.service.tracks.items()
        if track.plan.agv == agv and track.note.startswith("charging: ")
    ]


@pytest.mark.parametrize("version", ["2.0.0", "2.1.0", "3.0.0"])
async def test_a_low_vehicle_is_charged_and_takes_orders_again(
    embedded_broker: BrokerAddress, unique_interface_name: str, version: str
) -> None:
    """At 25 % (under charge_below_pct 30) the idle vehicle is sent to the nearest charger (node
    15, 4 m west of node 7) with startCharging; while it charges, an order for it is refused
    saying so; at charged_pct 80 it is sent stopCharging and takes the next order (R77: the
    state's charging flag follows both actions). The same
    for a 3.0 vehicle (powerSupply.stateOfCharge, 3.0 §6.6.6), under its own interface."""
    v3_interface = f"{unique_interface_name}3"
    vehicle_interface = v3_interface if version == "3.0.0" else unique_interface_name
    async with (
        running_master(
            embedded_broker, unique_interface_name, interface_name_v3=v3_interface
        ) as master,
        simulated_vehicle(
            embedded_broker,
            vehicle_interface,
            vda_version=version,
            battery_start_pct=25.0,
            charge_rate_pct_per_s=5.0,
            state_interval_s=0.5,  # the charge shows in the heartbeat states (no event)
        ) as vehicle,
        api_client(master) as client,
    ):
        runtime = vehicle.runtimes[0]
        await wait_until(lambda: runtime.state.charging, timeout=10)
        assert runtime.state.last_node_id == "15"
        [(order_id, charger)] = _charging_orders(master, SIMULATED)
        assert charger == "15"
        await wait_status(client, order_id, "FINISHED", timeout=10)  # as master control sees it
        view = (await client.get(f"/orders/{order_id}")).json()
        assert view["note"] == "charging: battery 25 % is below charge_below_pct 30 %"

        refused = await client.post("/orders", json={**SIMULATED_BODY, "destination": "3"})
        assert refused.status_code == 409, refused.text
        assert "it is charging (batteryCharge" in refused.json()["detail"]
        assert "charged_pct 80 %" in refused.json()["detail"]

        await wait_until(lambda: master.service.availability_of(SIMULATED) is None, timeout=20)
        assert not runtime.state.charging
        assert runtime.state.battery_charge >= 80.0
        again = await client.post("/orders", json={**SIMULATED_BODY, "destination": "3"})
        assert again.status_code == 201, again.text
        await wait_status(client, again.json()["orderId"], "FINISHED", timeout=20)
        assert len(_charging_orders(master, SIMULATED)) == 1  # charged once, not again


async def test_while_it_drives_to_the_charger_an_order_is_refused_naming_the_reason(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    async with (
        running_master(embedded_broker, unique_interface_name) as master,
        simulated_vehicle(
            embedded_broker, unique_interface_name, battery_start_pct=10.0, start_node="3"
        ),
        api_client(master) as client,
    ):
        await wait_until(lambda: SIMULATED in master.service.active, timeout=10)
        refused = await client.post("/orders", json={**SIMULATED_BODY, "destination": "1"})
        assert refused.status_code == 409, refused.text
        detail = refused.json()["detail"]
        assert "master control is sending it to node '15'" in detail, detail
        assert "battery 10 % is below charge_below_pct 30 %" in detail


async def test_a_route_beyond_the_battery_reach_is_refused(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """35 % at 5 %/m reaches 7 m: node 1 (5 m) may be ordered, node 3 (20 m) not; without a
    vehicle named, the only one cannot be chosen either, and the refusal says why."""
    async with (
        running_master(embedded_broker, unique_interface_name) as master,
        simulated_vehicle(
            embedded_broker,
            unique_interface_name,
            battery_start_pct=35.0,
            battery_drain_pct_per_m=5.0,
        ),
        api_client(master) as client,
    ):
        await wait_until(lambda: master.service.availability_of(SIMULATED) is None, timeout=5)
        far = await client.post("/orders", json={**SIMULATED_BODY, "destination": "3"})
        assert far.status_code == 409, far.text
        assert "its battery reaches 7 m (batteryState.reach" in far.json()["detail"]
        unnamed = await client.post("/orders", json={"destination": "3"})
        assert unnamed.status_code == 409, unnamed.text
        assert "acme/r1: its battery reaches 7 m" in unnamed.json()["detail"]
        near = await client.post("/orders", json={**SIMULATED_BODY, "destination": "1"})
        assert near.status_code == 201, near.text
        await wait_status(client, near.json()["orderId"], "FINISHED", timeout=10)


async def test_an_idle_vehicle_on_the_last_free_charger_makes_room(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """Both chargers (15, 16) are taken by idle vehicles that do not charge; a third one, low,
    waits for a charger. Master control moves one of the two to a parking node and sends the
    low one to the charger it left."""
    low = AgvId("acme", "r3")
    async with (
        running_master(embedded_broker, unique_interface_name) as master,
        simulated_vehicle(embedded_broker, unique_interface_name, start_node="15") as first,
        simulated_vehicle(
            embedded_broker, unique_interface_name, start_node="16", serial_number="r2"
        ) as second,
        api_client(master),
    ):
        await wait_until(lambda: master.service.availability_of(SIMULATED) is None, timeout=5)
        await wait_until(
            lambda: master.service.availability_of(AgvId("acme", "r2")) is None, timeout=5
        )
        async with simulated_vehicle(
            embedded_broker,
            unique_interface_name,
            start_node="7",
            serial_number="r3",
            battery_start_pct=20.0,
        ) as third:
            await wait_until(lambda: third.runtimes[0].state.charging, timeout=45)
            charger = third.runtimes[0].state.last_node_id
            assert charger in {"15", "16"}
            others = sorted(v.runtimes[0].state.last_node_id for v in (first, second))
            assert len(set(others) & {"17", "18"}) == 1, others  # one parked, one stays
            assert charger not in others
            assert [node for _, node in _charging_orders(master, low)] == [charger]
