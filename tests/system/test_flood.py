"""A flood of hostile MQTT messages at both services (issue 14): 10,000 each, paced so that the
broker keeps them all. Afterwards both are alive, their memory is bounded, and the reference
order still FINISHES. The figures (messages handled per second, RSS before and after) are
printed; docs/reliability.md records them."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import httpx
import pytest

from tests.integration.mqtt_helpers import client_for
from tests.mosquitto import run_mosquitto
from tests.system.hostile import Message, at_master, at_vehicle
from tests.system.stack import Stack
from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.mosquitto

FLOOD = 10_000
#: Messages per second the flood is paced at (the broker keeps every one at this rate).
PACE = 2_500
#: Allowed RSS growth of a service over the flood, MiB (measured: well under half of this).
RSS_GROWTH_MIB = 60


def rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    msg = f"no VmRSS for pid {pid}"
    raise RuntimeError(msg)


async def flood(address: BrokerAddress, messages: list[Message]) -> float:
    """Publish ``messages`` at PACE per second; returns the seconds it took."""
    started = time.monotonic()
    async with client_for(address) as client:
        for index, (topic, payload) in enumerate(messages):
            await client.publish(topic, payload, qos=0)
            if index % 250 == 249:
                behind = started + (index + 1) / PACE - time.monotonic()
                await asyncio.sleep(max(0.0, behind))
    return time.monotonic() - started


async def test_flood_of_hostile_messages_leaves_both_services_working(tmp_path: Path) -> None:
    """10,000 hostile messages per service: alive, bounded RSS, the reference order FINISHES."""
    with run_mosquitto(tmp_path / "mosquitto") as mosquitto:
        stack = Stack(mosquitto, "flood", tmp_path)
        master = stack.start_master("--log-level", "ERROR")
        vehicle = stack.start_vehicle("robot_0", "--log-level", "ERROR")
        try:
            async with httpx.AsyncClient(timeout=5) as http:
                await stack.wait_vehicle(http, "robot_0", lambda v: bool(v.get("available")))
                assert master.process is not None
                assert vehicle.process is not None
                before = (rss_mib(master.process.pid), rss_mib(vehicle.process.pid))
                prefix = f"{stack.interface}/v2/vda-sim"
                messages = [
                    *at_master(prefix, "robot_0", FLOOD),
                    *at_vehicle(f"{prefix}/robot_0", FLOOD),
                ]
                messages.sort(key=lambda m: hash(m[0]) % 7)  # interleave both targets
                seconds = await flood(mosquitto.address, messages)
                health = await http.get(f"{stack.api}/health")
                assert health.status_code == 200
                vehicle_view = await stack.wait_vehicle(
                    http, "robot_0", lambda v: bool(v.get("available")), timeout=30
                )
                after = (rss_mib(master.process.pid), rss_mib(vehicle.process.pid))
                answer = await http.post(
                    f"{stack.api}/orders",
                    json={
                        "manufacturer": "vda-sim",
                        "serialNumber": "robot_0",
                        "route": ["17", "12", "11"],
                    },
                )
                assert answer.status_code == 201, answer.text
                await stack.wait_order(http, answer.json()["orderId"], "FINISHED", timeout=40)
                detail = (await http.get(f"{stack.api}/vehicles/vda-sim/robot_0")).json()
        except BaseException:
            print(stack.logs_text())  # noqa: T201 - shown with the failure
            raise
        finally:
            await stack.stop_all()
    rate = len(messages) / seconds
    print(  # noqa: T201 - the figures docs/reliability.md records
        f"\nflood: {len(messages)} messages in {seconds:.1f} s ({rate:.0f}/s); "
        f"RSS master {before[0]:.1f} -> {after[0]:.1f} MiB, vehicle {before[1]:.1f} -> "
        f"{after[1]:.1f} MiB"
    )
    assert vehicle_view["connectionState"] == "ONLINE"
    assert after[0] - before[0] < RSS_GROWTH_MIB
    assert after[1] - before[1] < RSS_GROWTH_MIB
    state = detail["state"]
    assert len(state["errors"]) <= 20
    assert len(state["actionStates"]) <= 200
