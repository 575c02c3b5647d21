"""Map distribution through master control (§6.7, Figure 13): downloadMap, enableMap and
deleteMap sent with ``POST /vehicles/{m}/{s}/instantActions`` reach the simulated vehicle,
which fetches the map from a map server; the vehicle's state, as master control shows it,
follows (R87-R91)."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import pytest

from tests.integration.master_helpers import (
    SIMULATED,
    SIMULATED_BODY,
    master_with_simulated_vehicle,
)
from tests.map_server import serving_map
from tests.system.stack import capturing

if TYPE_CHECKING:
    import httpx

    from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.integration

MAP_FILE = b"a map file\n" * 100
VEHICLE = f"/vehicles/{SIMULATED.manufacturer}/{SIMULATED.serial_number}"


@pytest.fixture
def map_server() -> Iterator[str]:
    with serving_map("/demo-2", MAP_FILE) as url:
        yield url


def _action(kind: str, version: str, **extra: str) -> dict[str, Any]:
    parameters = {"mapId": "demo", "mapVersion": version, **extra}
    return {
        "actionType": kind,
        "actionParameters": [{"key": k, "value": v} for k, v in parameters.items()],
    }


async def _send(client: httpx.AsyncClient, action: dict[str, Any]) -> str:
    response = await client.post(f"{VEHICLE}/instantActions", json={"actions": [action]})
    assert response.status_code == 202, response.text
    (action_id,) = response.json()["actionIds"]
    return str(action_id)


async def _ended(client: httpx.AsyncClient, action_id: str) -> dict[str, Any]:
    """The vehicle's state once it reports ``action_id`` FINISHED or FAILED."""
    async with asyncio.timeout(10):
        while True:
            state: dict[str, Any] = (await client.get(VEHICLE)).json()["state"]
            done = {a["actionId"]: a["actionStatus"] for a in state["actionStates"]}
            if done.get(action_id) in ("FINISHED", "FAILED"):
                return state
            await asyncio.sleep(0.05)


def _maps(state: dict[str, Any]) -> set[tuple[str, str]]:
    return {(m["mapVersion"], m["mapStatus"]) for m in state["maps"]}


def _status(state: dict[str, Any], action_id: str) -> str:
    return str(next(a["actionStatus"] for a in state["actionStates"] if a["actionId"] == action_id))


async def test_master_control_distributes_a_map_version(
    embedded_broker: BrokerAddress, unique_interface_name: str, map_server: str
) -> None:
    """Download (DISABLED), a second download of the same version refused (R87), enable (the
    old version DISABLED, R89), delete the old version (R91); the vehicle stays usable. And
    ``vda-inspect``, listening, finds nothing against the standard in any of it."""
    async with (
        capturing(embedded_broker, unique_interface_name) as captured,
        master_with_simulated_vehicle(embedded_broker, unique_interface_name) as (
            _,
            _vehicle,
            client,
        ),
    ):
        link = f"{map_server}/demo-2"
        download = await _send(client, _action("downloadMap", "2", mapDownloadLink=link))
        state = await _ended(client, download)
        assert _status(state, download) == "FINISHED"
        assert _maps(state) == {("1", "ENABLED"), ("2", "DISABLED")}

        again = await _send(client, _action("downloadMap", "2", mapDownloadLink=link))
        state = await _ended(client, again)
        assert _status(state, again) == "FAILED"
        assert _maps(state) == {("1", "ENABLED"), ("2", "DISABLED")}

        enable = await _send(client, _action("enableMap", "2"))
        state = await _ended(client, enable)
        assert _maps(state) == {("1", "DISABLED"), ("2", "ENABLED")}

        delete = await _send(client, _action("deleteMap", "1"))
        state = await _ended(client, delete)
        assert _status(state, delete) == "FINISHED"
        assert _maps(state) == {("2", "ENABLED")}

        order = await client.post("/orders", json={**SIMULATED_BODY, "destination": "10"})
        assert order.status_code == 201, order.text
        await asyncio.sleep(0.3)  # the last states reach the listener
    sent = [m for m in captured.messages if str(m.topic).endswith("/instantActions")]
    assert len(sent) >= 4  # the listener heard the map actions it judges (R87-R91)
    assert captured.inspect_violations() == []


async def test_master_control_serves_the_map_and_rolls_it_out(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """No map server of its own: the file is uploaded to master control, which sends the
    vehicle a link to its own HTTP API (the real port of ``api_port: 0``) with the file's
    SHA-256; the vehicle fetches and checks it, and master control enables it once the vehicle
    lists it. The vehicle then drives on the new version."""
    async with master_with_simulated_vehicle(embedded_broker, unique_interface_name) as (
        master,
        _vehicle,
        client,
    ):
        assert (await client.put("/maps/demo/2", content=MAP_FILE)).status_code == 201
        answer = await client.post("/maps/demo/2/distribute", json={"enable": True})
        assert answer.status_code == 200, answer.text
        assert [r["status"] for r in answer.json()["results"]] == [202]
        async with asyncio.timeout(10):
            while True:
                state = (await client.get(VEHICLE)).json()["state"]
                if _maps(state) == {("1", "DISABLED"), ("2", "ENABLED")}:
                    break
                await asyncio.sleep(0.05)
        listed = (await client.get("/maps/demo/2")).json()
        assert listed["vehicles"] == [
            {"manufacturer": "acme", "serialNumber": "r1", "mapStatus": "ENABLED"}
        ]
        assert listed["enablingAfterDownload"] == []
        assert master.service.availability_of(SIMULATED) is None
        order = await client.post("/orders", json={**SIMULATED_BODY, "destination": "10"})
        assert order.status_code == 201, order.text
