"""A real master reads visualization only while a live-map stream is open (vda_master.pose_feed):
not before the first stream, at once (v2 and v3) while one is open, for the grace period after
the last one closed, and not after it."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import httpx
import pytest

from tests.integration.master_helpers import running_master
from tests.integration.mqtt_helpers import client_for
from vda5050.broker import BrokerAddress
from vda5050.codec import encode
from vda5050.models import AgvPosition, Visualization
from vda5050.testing import HEADER
from vda5050.topics import AgvId
from vda_master.runtime import MasterProcess

pytestmark = pytest.mark.integration

AGV = AgvId("acme", "r1")


def visualization(x: float) -> bytes:
    position = AgvPosition(x=x, y=0.0, theta=0.0, map_id="demo", position_initialized=True)
    return encode(Visualization.model_validate({**HEADER, "agv_position": position}))


@asynccontextmanager
async def map_stream(master: MasterProcess) -> AsyncIterator[None]:
    """An open /events stream whose snapshot has arrived."""
    url = f"http://127.0.0.1:{master.api_port}/events"
    async with httpx.AsyncClient(timeout=5) as client, client.stream("GET", url) as response:
        lines = response.aiter_lines()
        assert await anext(lines) == "event: snapshot"
        yield


async def pose_arrives(master: MasterProcess, topic: str, x: float, within_s: float) -> bool:
    """Publish visualizations at ``x`` until the master holds that pose (True) or ``within_s``
    passed (False)."""
    async with client_for(master_address(master)) as vehicle:
        deadline = asyncio.get_running_loop().time() + within_s
        while asyncio.get_running_loop().time() < deadline:
            await vehicle.publish(topic, visualization(x), qos=1)
            await asyncio.sleep(0.05)
            pose = master.service.live.poses.get(AGV)
            if pose is not None and pose.x == x:
                return True
    return False


def master_address(master: MasterProcess) -> BrokerAddress:
    endpoint = master.session._endpoint
    return BrokerAddress(endpoint.host, endpoint.port)


async def test_visualization_is_read_only_while_a_map_stream_is_open(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """Without a stream the master does not receive visualization; with one it does, for 2.x
    and 3.0 vehicles; after the last stream closed it still does for the grace period, then
    not any more."""
    robots = [{"manufacturer": AGV.manufacturer, "serial_number": AGV.serial_number}]
    v2 = f"{unique_interface_name}/v2/acme/r1/visualization"
    async with running_master(
        embedded_broker, unique_interface_name, robots=robots, interface_name_v3="vda5050-test"
    ) as master:
        master.pose_feed.grace_s = 0.5
        assert not await pose_arrives(master, v2, 1.0, within_s=0.5)
        async with map_stream(master):
            assert master.pose_feed.subscribed
            assert await pose_arrives(master, v2, 2.0, within_s=3)
            v3 = "vda5050-test/v3/acme/r1/visualization"
            assert await pose_arrives(master, v3, 3.0, within_s=3)
        assert await pose_arrives(master, v2, 4.0, within_s=0.2)  # within the grace period
        async with asyncio.timeout(3):
            while master.pose_feed.subscribed:
                await asyncio.sleep(0.05)
        await asyncio.sleep(0.2)  # the UNSUBSCRIBE is not waited for
        assert not await pose_arrives(master, v2, 5.0, within_s=0.5)
        assert master.service.live.poses[AGV].x == 4.0
