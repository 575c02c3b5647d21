"""Vehicle shutdown and crash as master control and the broker see them (R08–R11)."""

from __future__ import annotations

import signal

import httpx

from tests.system.stack import Captured, Stack, retained


def connection_topic(stack: Stack, robot: str) -> str:
    return f"{stack.interface}/v2/vda-sim/{robot}/connection"


def connection_states(capture: Captured, topic: str) -> list[object]:
    return [p["connectionState"] for p in capture.payloads(topic)]


async def test_sigterm_publishes_offline_and_no_will(stack: Stack, capture: Captured) -> None:
    """R10: SIGTERM → OFFLINE (retained), clean DISCONNECT (no CONNECTIONBROKEN), exit 0."""
    stack.start_master()
    vehicle = stack.start_vehicle("robot_0")
    topic = connection_topic(stack, "robot_0")
    async with httpx.AsyncClient(timeout=5) as http:
        await stack.wait_vehicle(http, "robot_0", lambda v: v.get("connectionState") == "ONLINE")
        vehicle.signal(signal.SIGTERM)
        assert await vehicle.wait() == 0
        await stack.wait_vehicle(http, "robot_0", lambda v: v.get("connectionState") == "OFFLINE")
    await capture.wait_until(lambda: "OFFLINE" in connection_states(capture, topic))
    assert (await retained(stack.broker.address, topic))["connectionState"] == "OFFLINE"
    assert "CONNECTIONBROKEN" not in connection_states(capture, topic)


async def test_sigkill_delivers_the_will_and_a_restart_is_online(
    stack: Stack, capture: Captured
) -> None:
    """R11: a killed vehicle's CONNECTIONBROKEN arrives; the master marks it unavailable; after a
    restart it is ONLINE and available again."""
    stack.start_master()
    vehicle = stack.start_vehicle("robot_1")
    topic = connection_topic(stack, "robot_1")
    async with httpx.AsyncClient(timeout=5) as http:
        await stack.wait_vehicle(http, "robot_1", lambda v: bool(v.get("available")))
        vehicle.signal(signal.SIGKILL)
        await vehicle.wait()
        view = await stack.wait_vehicle(
            http, "robot_1", lambda v: v.get("connectionState") == "CONNECTIONBROKEN"
        )
        assert view["available"] is False
        assert "CONNECTIONBROKEN" in str(view["unavailableReason"])
        assert (await retained(stack.broker.address, topic))["connectionState"] == (
            "CONNECTIONBROKEN"
        )
        stack.start_vehicle("robot_1")
        await stack.wait_vehicle(http, "robot_1", lambda v: bool(v.get("available")))
    assert connection_states(capture, topic)[-1] == "ONLINE"


async def test_vehicle_restart_mid_order_fails_the_order_and_frees_the_vehicle(
    stack: Stack, capture: Captured
) -> None:
    """A vehicle killed and restarted mid-order reports orderId "": the master ends that order
    FAILED with the reason at once, and the vehicle takes and finishes a new order (issue 14)."""
    stack.start_master()
    vehicle = stack.start_vehicle("robot_0", "--time-lapse", "2")
    async with httpx.AsyncClient(timeout=5) as http:
        await stack.wait_vehicle(http, "robot_0", lambda v: bool(v.get("available")))
        answer = await http.post(
            f"{stack.api}/orders",
            json={"manufacturer": "vda-sim", "serialNumber": "robot_0", "destination": "3"},
        )
        order_id = answer.json()["orderId"]
        await stack.wait_order(http, order_id, "RUNNING")
        vehicle.signal(signal.SIGKILL)
        await vehicle.wait()
        stack.start_vehicle("robot_0", "--time-lapse", "4")
        failed = await stack.wait_order(http, order_id, "FAILED", timeout=20)
        assert "no longer holds the order" in str(failed["reason"])
        await stack.wait_vehicle(http, "robot_0", lambda v: bool(v.get("available")))
        again = await http.post(
            f"{stack.api}/orders",
            json={"manufacturer": "vda-sim", "serialNumber": "robot_0", "route": ["17"]},
        )
        assert again.status_code == 201, again.text
        await stack.wait_order(http, again.json()["orderId"], "FINISHED")
    assert capture.messages
