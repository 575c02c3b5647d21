"""``vda-inspect`` against a real Mosquitto (docs/inspect.md): our master control and a simulated
vehicle run an order and give no violation, QoS included; a misbehaving vehicle next to them is
caught, and the command line exits 1 with a JSON report naming what it did."""

from __future__ import annotations

import asyncio
import json
import sys
from pathlib import Path

import aiomqtt
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
from tests.mosquitto import Mosquitto
from vda5050.codec import encode
from vda5050.testing import make_state
from vda_inspect.cli import InspectConfig, Listener

pytestmark = pytest.mark.mosquitto


async def _misbehave(broker: Mosquitto, interface: str) -> None:
    """A vehicle ``acme/rogue`` whose states go out at QoS 1 with a headerId that goes back."""
    topic = f"{interface}/v2/acme/rogue/state"
    async with aiomqtt.Client(broker.address.host, broker.address.port) as client:
        for header_id in (5, 6, 4):
            state = make_state(header_id=header_id, manufacturer="acme", serial_number="rogue")
            await client.publish(topic, encode(state), qos=1)


def _station(node_id: str, action_type: str) -> dict[str, object]:
    """An order to ``node_id`` with a HARD ``action_type`` there, as the demo sends it."""
    action = {
        "actionType": action_type,
        "blockingType": "HARD",
        "actionParameters": [{"key": "loadType", "value": "EPAL"}],
    }
    return {"destination": node_id, "destinationActions": [action]}


#: A pick at station 11 (the demo graph's pick station): a HARD node action whose state the
#: inspector follows (R68-R75), and the drop of that load at station 13 (R81: the load leaves
#: ``loads``).
PICK = _station("11", "pick")
DROP = _station("13", "drop")
#: The same transport as one order with two stops (docs/master.md, *Orders with several
#: stops*): the drop is appended by an update stitched at the pick station (R58, R51).
STOPS = {
    "stops": [
        {"destination": "11", "actions": PICK["destinationActions"]},
        {"destination": "13", "actions": DROP["destinationActions"]},
    ]
}
#: The vehicle's pose set again where it stands after the drop (R78), as an operator would
#: after moving it by hand.
INIT_AT_13 = {
    "actionType": "initPosition",
    "blockingType": "NONE",
    "actionParameters": [
        {"key": "x", "value": 5.0},
        {"key": "y", "value": 11.0},
        {"key": "theta", "value": 1.5707963267948966},
        {"key": "mapId", "value": "demo"},
        {"key": "lastNodeId", "value": "13"},
    ],
}


@pytest.mark.parametrize("version", ["2.0.0", "3.0.0"])
async def test_our_stack_passes_and_a_rogue_vehicle_is_caught(
    mosquitto: Mosquitto, unique_interface_name: str, tmp_path: Path, version: str
) -> None:
    """Four orders, a drive, a pick, a drop, and both again as one order with two stops, and an
    initPosition; states and action states judged against them too."""
    interface = unique_interface_name
    interface3 = f"{interface}3"
    config = InspectConfig(
        broker_url=mosquitto.address.url, interface_names=[interface, interface3]
    )
    listener = Listener(config)
    stop = asyncio.Event()
    async with asyncio.TaskGroup() as group:
        inspecting = group.create_task(listener.run(stop))
        await listener.session.wait_connected()
        async with (
            running_master(mosquitto.address, interface, interface_name_v3=interface3) as master,
            simulated_vehicle(
                mosquitto.address,
                interface3 if version == "3.0.0" else interface,
                vda_version=version,
                visualization_interval_s=0.5,
            ),
            api_client(master) as client,
        ):
            await wait_until(lambda: master.service.availability_of(SIMULATED) is None, timeout=10)
            for body in ({"destination": "3"}, PICK, DROP, STOPS):
                created = await client.post("/orders", json={**SIMULATED_BODY, **body})
                assert created.status_code == 201, created.text
                await wait_status(client, created.json()["orderId"], "FINISHED", timeout=40)
                await wait_until(
                    lambda: master.service.availability_of(SIMULATED) is None, timeout=10
                )
            url = f"/vehicles/{SIMULATED.manufacturer}/{SIMULATED.serial_number}/instantActions"
            sent = await client.post(url, json={"actions": [INIT_AT_13]})
            assert sent.status_code == 202, sent.text
            await _misbehave(mosquitto, interface)
            await asyncio.sleep(1.0)
        stop.set()
        report = await inspecting
    ours = report["vehicles"]["acme/r1"]  # type: ignore[index]
    violations = [f for f in ours["findings"] if f["severity"] == "violation"]
    assert violations == [], ours["findings"]  # a notice (a lost QoS 0 message) may happen
    assert {"connection", "factsheet", "order", "state", "visualization"} <= set(ours["messages"])
    rogue = report["vehicles"]["acme/rogue"]  # type: ignore[index]
    assert sorted((f["rule"], f["count"]) for f in rogue["findings"]) == [("R04", 3), ("R15", 1)]


async def test_the_command_line_exits_1_and_writes_the_report(
    mosquitto: Mosquitto, unique_interface_name: str, tmp_path: Path
) -> None:
    report_path = tmp_path / "report.json"
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "vda_inspect",
        "--broker-url",
        mosquitto.address.url,
        "--interface-names",
        json.dumps([unique_interface_name]),
        "--duration-s",
        "3",
        "--report",
        str(report_path),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
    )
    await asyncio.sleep(1.5)  # connected and subscribed
    await _misbehave(mosquitto, unique_interface_name)
    output, _ = await asyncio.wait_for(process.communicate(), timeout=15)
    text = output.decode()
    assert process.returncode == 1, text
    assert "violation R15      acme/rogue state (vehicle): headerId went back from 6 to 4" in text
    report = json.loads(report_path.read_text())
    assert report["violations"] == 4
    assert report["vehicles"]["acme/rogue"]["messages"] == {"state": 3}
